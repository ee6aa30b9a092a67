//! `--method lcn` (thesis 6.5, Figs. 6.9 / 6.11): the pattern generator of `--controller` on
//! step references from rest; its pattern also drives each subject outside the loop
//! (Fig. 6.6(b)).

use std::fmt::Write as _;

use anyhow::{Context, Result};
use fes_ident::analysis::osp::lcn::{
    LcnRun, PatternShape, ShapeCriteria, pattern_shape, run_pattern_generator, steady_mean,
    step_reference,
};
use fes_model::control::file::Controller;

use super::super::inputs::{md_table, write_csv};
use super::super::plots::{self, Figure, Line, Panel, color};
use super::{Args, Subject, pulses_ms, samples};

/// The step runs of every level.
struct LcnOutcome {
    /// The controller's sample time, s.
    ts: f64,
    /// Samples of each run.
    samples: usize,
    /// The pattern-shape criteria (6.5.4).
    criteria: ShapeCriteria,
    /// One run per `--levels` value, in order.
    levels: Vec<LevelRun>,
}

/// The pattern generator on one step reference.
struct LevelRun {
    level: f64,
    run: LcnRun,
    /// Pulse samples of the generated pattern.
    times: Vec<usize>,
    shape: Option<PatternShape>,
    /// Each subject driven by the pattern, in the order given.
    driven: Vec<Driven>,
    /// Mean force of the loop's own model over the second half (whole IPIs).
    loop_mean: f64,
}

/// A subject driven by a generated pattern.
struct Driven {
    name: String,
    /// Its force in the controller model's normalised units.
    force: Vec<f64>,
    /// Mean force over the second half (whole IPIs), normalised.
    mean: f64,
}

/// Runs the method on every level and reports it.
pub(super) fn run(
    args: &Args,
    c: &Controller,
    subjects: &[Subject],
    levels: &[f64],
    md: &mut String,
) -> Result<()> {
    let outcome = compute(args, c, subjects, levels)?;
    report(args, c, &outcome, md)
}

fn compute(
    args: &Args,
    c: &Controller,
    subjects: &[Subject],
    levels: &[f64],
) -> Result<LcnOutcome> {
    let mut pg = c.pattern_generator().context("pattern generator")?;
    let ts = c.lmn.ts;
    let n = samples("--lcn-ms", args.lcn_ms as f64, ts)?;
    let onset = samples("step onset", 50.0, ts)?.min(n.saturating_sub(1));
    let criteria = ShapeCriteria::default();
    let mut runs = Vec::new();
    for &level in levels {
        let run: LcnRun = run_pattern_generator(&mut pg, &step_reference(level, onset, n));
        let times = run.pulse_times();
        let shape = pattern_shape(&times, &criteria);
        let driven = subjects
            .iter()
            .map(|s| drive(s, &run, &times, n))
            .collect::<Result<Vec<_>>>()?;
        let loop_mean = steady_mean(&run.model_force, &times, n / 2).unwrap_or(f64::NAN);
        runs.push(LevelRun {
            level,
            run,
            times,
            shape,
            driven,
            loop_mean,
        });
    }
    Ok(LcnOutcome {
        ts,
        samples: n,
        criteria,
        levels: runs,
    })
}

/// Subject `s` driven by the pattern of `run` (pulses at `times`) for `n` samples.
fn drive(s: &Subject, run: &LcnRun, times: &[usize], n: usize) -> Result<Driven> {
    let f = s
        .response
        .force(&run.pulse)
        .with_context(|| format!("{} driven by the LCN pattern", s.name))?;
    let mean = steady_mean(&f, times, n / 2).unwrap_or(f64::NAN) * s.to_normalised;
    Ok(Driven {
        name: s.name.clone(),
        force: f.iter().map(|&v| v * s.to_normalised).collect(),
        mean,
    })
}

/// `lcn.png`, `lcn.csv` and the report's section.
fn report(args: &Args, c: &Controller, out: &LcnOutcome, md: &mut String) -> Result<()> {
    let count = out.levels.len();
    let column = out
        .levels
        .iter()
        .enumerate()
        .flat_map(|(li, l)| panels(out, l, li == 0, li + 1 == count))
        .collect();
    let h = 260 * count as u32 + 60;
    plots::save(
        &Figure {
            title: "LCN pattern generator on step references (6.5, Figs. 6.9 / 6.11)".into(),
            columns: vec![column],
        },
        &args.format.file(&args.out, "lcn"),
        (1000, h.min(2400)),
    )?;
    let csv: Vec<Vec<String>> = out
        .levels
        .iter()
        .map(|l| {
            vec![
                format!("{}", l.level),
                l.times.len().to_string(),
                pulses_ms(&l.times, out.ts),
            ]
        })
        .collect();
    write_csv(
        &args.out.join("lcn.csv"),
        &["reference", "pulses", "pulse_times_ms"],
        &csv,
    )?;
    markdown(args, c, out, md);
    Ok(())
}

/// The report's section: the criteria, a row per level and the controller.
fn markdown(args: &Args, c: &Controller, out: &LcnOutcome, md: &mut String) {
    let ms = out.ts * 1e3;
    let _ = writeln!(md, "## LCN-generated patterns (6.5, Figs. 6.9 / 6.11)\n");
    let _ = writeln!(
        md,
        "The controller's pattern generator (LCN -> pulse shaper -> its design LMN, Fig. 6.8) runs on step references from rest (step at 50 ms, {} ms); the pattern also drives the subjects outside the loop (Fig. 6.6(b)), their force in the controller model's normalised units (rest force removed). Shape criteria (6.5.4): burst = initial IPIs <= {} ms; pause = next IPI >= {} x the median of the later IPIs; even = later IPIs with coefficient of variation <= {} (at least 3). Pulse times: `lcn.csv`.\n",
        args.lcn_ms,
        out.criteria.burst_ipi as f64 * ms,
        out.criteria.pause_factor,
        out.criteria.even_cv
    );
    let _ = writeln!(md, "![LCN patterns](lcn.png)\n");
    let table: Vec<Vec<String>> = out.levels.iter().map(|l| table_row(l, ms)).collect();
    md.push_str(&md_table(
        &[
            "r",
            "pulses",
            "burst pulses",
            "pause (ms)",
            "later IPI median (ms)",
            "later IPI CV",
            "shape",
            "mean force over the 2nd half (whole IPIs)",
        ],
        &table,
    ));
    md.push('\n');
    let _ = writeln!(
        md,
        "Controller: {} units, rise times {} ms.\n",
        c.units.len(),
        c.units
            .iter()
            .map(|u| format!("{:.1}", u.spec.rise_time_s * 1e3))
            .collect::<Vec<_>>()
            .join(", ")
    );
}

/// One level's row: the pattern's shape and the mean forces.
fn table_row(l: &LevelRun, ms: f64) -> Vec<String> {
    let sh = |f: &dyn Fn(&PatternShape) -> String| l.shape.as_ref().map_or("-".into(), f);
    let extra: Vec<String> = l
        .driven
        .iter()
        .map(|d| format!("{}: {:.3}", d.name, d.mean))
        .collect();
    vec![
        format!("{}", l.level),
        l.times.len().to_string(),
        sh(&|s| s.burst_pulses.to_string()),
        sh(&|s| s.pause.map_or("-".into(), |p| format!("{}", p as f64 * ms))),
        sh(&|s| {
            s.steady_median
                .map_or("-".into(), |m| format!("{:.1}", m * ms))
        }),
        sh(&|s| s.steady_cv.map_or("-".into(), |c| format!("{c:.3}"))),
        sh(&shape_name),
        format!(
            "{:.3}{}",
            l.loop_mean,
            if extra.is_empty() {
                String::new()
            } else {
                format!("; {}", extra.join("; "))
            }
        ),
    ]
}

fn shape_name(s: &PatternShape) -> String {
    if s.is_doublet_pause_even() {
        "doublet/triplet, pause, even".into()
    } else if s.is_even && !s.has_burst {
        "even".into()
    } else {
        format!(
            "burst {} / pause {} / even {}",
            s.has_burst, s.has_pause, s.is_even
        )
    }
}

/// One level's panels: the pulses, and below them the reference, each driven subject and
/// the loop's model force.
fn panels(out: &LcnOutcome, l: &LevelRun, first: bool, last: bool) -> [(u32, Panel); 2] {
    let ms = out.ts * 1e3;
    let n = out.samples;
    let timed = |v: &[f64]| -> Vec<(f64, f64)> {
        v.iter()
            .enumerate()
            .map(|(k, &y)| (k as f64 * ms, y))
            .collect()
    };
    let mut lines = vec![
        Line::new(
            Some("reference".to_string()),
            timed(&l.run.reference),
            color(7),
        )
        .dashed(),
    ];
    for (si, d) in l.driven.iter().enumerate() {
        lines.push(Line::new(
            Some(format!("{} (driven by the pattern)", d.name)),
            timed(&d.force),
            color(1 + si),
        ));
    }
    lines.push(Line::new(
        Some("loop model (design LMN)".to_string()),
        timed(&l.run.model_force),
        color(0),
    ));
    let pulses = Panel {
        y_label: "pulse".into(),
        x: Some((0.0, n as f64 * ms)),
        y: Some((0.0, 1.1)),
        y_ticks: Some(2),
        compact: true,
        impulses: l.times.iter().map(|&k| k as f64 * ms).collect(),
        ..Panel::default()
    };
    let force = Panel {
        title: Some(format!("r = {}: {} pulses (above)", l.level, l.times.len())),
        x_label: if last {
            "time (ms)".into()
        } else {
            String::new()
        },
        y_label: "force (normalised)".into(),
        x: Some((0.0, n as f64 * ms)),
        lines,
        legend: first,
        ..Panel::default()
    };
    [(1, pulses), (3, force)]
}
