//! `fes osp`: optimal stimulation patterns (thesis ch. 6) on a model, on the Ding
//! muscle of sim-muscle, or on both side by side (the thesis compared its models with
//! Kwende's experiments on the real muscles):
//!
//! - `random` (6.2, Figs. 6.1-6.2): FTIpP of random patterns (the thesis protocol, 5.1)
//!   against their average frequency; best and worst patterns;
//! - `trains` (6.3, Fig. 6.3): FTIpP of constant-IPI trains, 1-10 pulses x IPI 2-100 ms,
//!   as heat maps;
//! - `iterative` (6.4, Fig. 6.4): pulses added one at a time at the best IPI;
//! - `lcn` (6.5, Figs. 6.9 / 6.11): the pattern generator of `--controller` driven by step
//!   references; its pattern also drives `--model` and/or the Ding muscle (Fig. 6.6(b)).
//!
//! FTI (eq. 6.2) is summed over one window of `--window-ms` from the pattern's start (the
//! twitch included), with the rest force removed (`fes_ident::analysis::osp`).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use fes_ident::analysis::osp::iterative::{Iterative, iterative_method};
use fes_ident::analysis::osp::lcn::{
    LcnRun, PatternShape, ShapeCriteria, pattern_shape, run_pattern_generator, steady_mean,
    step_reference,
};
use fes_ident::analysis::osp::random::{RandomPattern, best_and_worst, random_method};
use fes_ident::analysis::osp::trains::{TrainSurface, train_surface};
use fes_ident::analysis::osp::{Evaluator, ForceResponse, ModelResponse};
use rt_core::control::file::Controller;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::preset::Preset;
use sim_muscle::protocol::ProtocolConfig;
use sim_muscle::simulate::MuscleResponse;

use super::inputs::{md_table, open_model, out_dir, parse_list, progress, write_csv};
use super::plots::{self, Figure, HeatMap, Line, Markers, Panel, color};

/// The methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Random patterns: FTIpP vs average frequency (6.2).
    Random,
    /// Constant-IPI trains: the FTIpP surface (6.3).
    Trains,
    /// The iterative method (6.4).
    Iterative,
    /// The LCN pattern generator on step references (6.5); needs --controller.
    Lcn,
}

/// `--muscle` presets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MuscleArg {
    /// Fast muscle with the catch-like effect.
    Fast,
    /// Slow (chronically stimulated) muscle.
    Slow,
}

impl From<MuscleArg> for Preset {
    fn from(m: MuscleArg) -> Self {
        match m {
            MuscleArg::Fast => Preset::Fast,
            MuscleArg::Slow => Preset::Slow,
        }
    }
}

/// Arguments of `fes osp`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A model file (fes-lmn/1): the methods run on its output.
    #[arg(long, required_unless_present_any = ["muscle", "controller"])]
    pub model: Option<PathBuf>,
    /// A controller file (fes-lcn/1), for `--method lcn`.
    #[arg(long)]
    pub controller: Option<PathBuf>,
    /// The Ding muscle of sim-muscle (no fatigue, 7 ms delay): the methods run on it too.
    #[arg(long, value_enum)]
    pub muscle: Option<MuscleArg>,
    /// Methods, comma-separated (random, trains, iterative, lcn).
    #[arg(long, value_enum, value_delimiter = ',', required = true)]
    pub method: Vec<Method>,
    /// Output directory (created if needed).
    #[arg(long)]
    pub out: PathBuf,
    /// FTI window from the pattern's start, ms (the twitch's too).
    #[arg(long, default_value_t = 2000)]
    pub window_ms: u32,
    /// Shortest IPI of the trains and iterative sweeps, ms.
    #[arg(long, default_value_t = 2)]
    pub ipi_min_ms: u32,
    /// Longest IPI of the trains and iterative sweeps, ms.
    #[arg(long, default_value_t = 100)]
    pub ipi_max_ms: u32,
    /// Largest pulse count of the train surface.
    #[arg(long, default_value_t = 10)]
    pub train_pulses: usize,
    /// Pulses of the iterative method.
    #[arg(long, default_value_t = 5)]
    pub iterative_pulses: usize,
    /// Random patterns (thesis protocol 5.1: IPI 1-70 ms, trains <= 300 ms).
    #[arg(long, default_value_t = 300)]
    pub patterns: usize,
    /// Seed of the random patterns.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Step reference levels for `lcn` (normalised force), comma-separated.
    #[arg(long, default_value = "0.15,0.3,0.5,0.7")]
    pub levels: String,
    /// Length of each `lcn` run, ms (the step comes at 50 ms).
    #[arg(long, default_value_t = 800)]
    pub lcn_ms: u32,
}

/// One muscle or model the methods run on.
struct Subject {
    name: String,
    unit: &'static str,
    response: Box<dyn ForceResponse>,
    /// Multiplies this subject's force into the controller model's normalised units.
    to_normalised: f64,
}

/// Samples of `ms` milliseconds at `ts`, which must be a whole number.
fn samples(flag: &str, ms: f64, ts: f64) -> Result<usize> {
    let k = ms * 1e-3 / ts;
    if (k - k.round()).abs() > 1e-9 * k.max(1.0) {
        bail!(
            "{flag} {ms} ms is not a whole number of {} ms samples",
            ts * 1e3
        );
    }
    Ok(k.round() as usize)
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if args.ipi_min_ms == 0 || args.ipi_min_ms > args.ipi_max_ms {
        bail!(
            "--ipi-min-ms {} / --ipi-max-ms {}: need 1 <= min <= max",
            args.ipi_min_ms,
            args.ipi_max_ms
        );
    }
    if args.method.contains(&Method::Lcn) && args.controller.is_none() {
        bail!("--method lcn needs --controller (a fes-lcn/1 file from `fes design`)");
    }
    let controller = args
        .controller
        .as_deref()
        .map(|p| Controller::load(p).with_context(|| format!("controller file {}", p.display())))
        .transpose()?;
    let mut subjects = Vec::new();
    if let Some(path) = &args.model {
        let m = open_model(path)?;
        let scale = controller
            .as_ref()
            .map_or(1.0, |c| m.lmn.force_scale_n / c.lmn.force_scale_n);
        subjects.push(Subject {
            name: format!(
                "model {}",
                path.file_name().map_or_else(
                    || path.display().to_string(),
                    |s| s.to_string_lossy().into()
                )
            ),
            unit: "normalised",
            response: Box::new(ModelResponse::new(&m.lmn).context("model")?),
            to_normalised: scale,
        });
    }
    if let Some(p) = args.muscle {
        let preset = Preset::from(p);
        let muscle = Muscle::new(MuscleConfig::preset(preset)).context("Ding muscle")?;
        subjects.push(Subject {
            name: format!("Ding {} muscle", preset.name()),
            unit: "N",
            response: Box::new(MuscleResponse::new(muscle)),
            to_normalised: controller
                .as_ref()
                .map_or(1.0, |c| 1.0 / c.lmn.force_scale_n),
        });
    }
    let levels = parse_list("--levels", &args.levels)?;
    if let Some(l) = levels.iter().find(|l| !(0.0..=1.0).contains(*l)) {
        bail!("--levels: {l} is outside [0, 1] (normalised force)");
    }
    out_dir(&args.out)?;
    let mut md = String::new();
    let names: Vec<String> = subjects.iter().map(|s| s.name.clone()).collect();
    let _ = writeln!(md, "# Optimal stimulation patterns (thesis ch. 6)\n");
    let _ = writeln!(
        md,
        "Subjects: {}. FTI (eq. 6.2) over {} ms from the start of each pattern, rest force removed; FTIpP = FTI_p / (FTI_1 p) (eq. 6.3), FTI_1 the twitch's over the same window.\n",
        if names.is_empty() {
            "(none: only the controller's loop)".into()
        } else {
            names.join(", ")
        },
        args.window_ms
    );
    let mut methods = args.method.clone();
    methods.dedup();
    for m in methods {
        match m {
            Method::Random => random(&args, &subjects, &mut md)?,
            Method::Trains => trains(&args, &subjects, &mut md)?,
            Method::Iterative => iterative(&args, &subjects, &mut md)?,
            Method::Lcn => {
                let c = controller
                    .as_ref()
                    .context("--method lcn needs --controller")?;
                lcn(&args, c, &subjects, &levels, &mut md)?
            }
        }
    }
    let path = args.out.join("report.md");
    std::fs::write(&path, md).with_context(|| format!("writing {}", path.display()))?;
    println!("report written to {}", path.display());
    Ok(())
}

fn need_subjects(subjects: &[Subject], method: &str) -> Result<()> {
    if subjects.is_empty() {
        bail!("--method {method} needs --model and/or --muscle");
    }
    Ok(())
}

/// An evaluator whose window covers patterns ending at `last_ms` plus 200 ms.
fn evaluator<'a>(
    args: &Args,
    s: &'a Subject,
    last_ms: f64,
) -> Result<Evaluator<'a, dyn ForceResponse>> {
    if (args.window_ms as f64) < last_ms + 200.0 {
        bail!(
            "--window-ms {} is too short: the longest pattern ends at {last_ms} ms and the force needs time to return to rest (give at least {} ms)",
            args.window_ms,
            last_ms + 200.0
        );
    }
    let ts = s.response.ts();
    let window = samples("--window-ms", args.window_ms as f64, ts)?;
    Evaluator::new(s.response.as_ref(), window).with_context(|| format!("{}: twitch", s.name))
}

fn pulses_ms(p: &[usize], ts: f64) -> String {
    p.iter()
        .map(|&k| format!("{}", (k as f64 * ts * 1e6).round() / 1e3))
        .collect::<Vec<_>>()
        .join(";")
}

fn truncation_note(md: &mut String, worst: f64) {
    if worst > 0.01 {
        let _ = writeln!(
            md,
            "**Note:** some responses had not returned to rest at the end of the window (largest remaining force {:.1} % of the peak); lengthen `--window-ms`.\n",
            100.0 * worst
        );
    }
}

fn random(args: &Args, subjects: &[Subject], md: &mut String) -> Result<()> {
    need_subjects(subjects, "random")?;
    let mut proto = ProtocolConfig::thesis(Preset::Fast);
    proto.records = args.patterns.max(2);
    proto.train_records = 1;
    proto.const_every = 0;
    let plans = proto
        .plan(args.seed)
        .context("random patterns (thesis protocol 5.1)")?;
    let patterns: Vec<Vec<usize>> = plans
        .iter()
        .map(|p| {
            (0..p.pulses.len())
                .filter(|&k| p.pulses[k])
                .collect::<Vec<_>>()
        })
        .filter(|p: &Vec<usize>| !p.is_empty())
        .take(args.patterns)
        .collect();
    let record_ms = proto.record_ms as f64;
    let mut columns = Vec::new();
    let mut rows = Vec::new();
    let mut summary = Vec::new();
    let mut worst_end: f64 = 0.0;
    for s in subjects {
        let ev = evaluator(args, s, record_ms)?;
        let ts = s.response.ts();
        let bar = progress(patterns.len(), &format!("random patterns, {}", s.name));
        let res = random_method(&ev, &patterns, &|| bar.inc(1))
            .with_context(|| format!("{}: random patterns", s.name))?;
        bar.finish_and_clear();
        for (i, r) in res.iter().enumerate() {
            worst_end = worst_end.max(r.result.end_fraction);
            rows.push(vec![
                s.name.clone(),
                i.to_string(),
                r.result.pulses.len().to_string(),
                r.average_frequency_hz.map_or("".into(), |f| format!("{f}")),
                format!("{}", r.result.fti),
                format!("{}", r.result.ftipp),
                pulses_ms(&r.result.pulses, ts),
            ]);
        }
        let (best, worst) = best_and_worst(&res, 3);
        summary.push(random_summary(s, &res, &best, &worst, ts));
        columns.push(random_panels(s, &res, &best, &worst, ts, record_ms));
    }
    plots::save(
        &Figure {
            title: format!(
                "random pattern method (6.2): {} patterns of the thesis protocol",
                patterns.len()
            ),
            columns,
        },
        &args.out.join("random.png"),
        (560 * subjects.len() as u32 + 80, 760),
    )?;
    write_csv(
        &args.out.join("random.csv"),
        &[
            "subject",
            "pattern",
            "pulses",
            "average_frequency_hz",
            "fti",
            "ftipp",
            "pulse_times_ms",
        ],
        &rows,
    )?;
    let _ = writeln!(md, "## Random pattern method (6.2, Figs. 6.1-6.2)\n");
    let _ = writeln!(
        md,
        "{} patterns drawn with the thesis protocol (5.1: random IPIs 1-70 ms, trains of 100-300 ms; seed {}); average frequency eq. (6.6). Table: `random.csv`.\n",
        patterns.len(),
        args.seed
    );
    let _ = writeln!(md, "![random pattern method](random.png)\n");
    md.push_str(&md_table(
        &[
            "subject",
            "best FTIpP (f_av)",
            "worst FTIpP (f_av)",
            "corr(FTIpP, f_av)",
        ],
        &summary,
    ));
    md.push('\n');
    truncation_note(md, worst_end);
    Ok(())
}

fn pearson(xy: &[(f64, f64)]) -> f64 {
    let n = xy.len() as f64;
    let (mx, my) = xy
        .iter()
        .fold((0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for &(x, y) in xy {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx).powi(2);
        syy += (y - my).powi(2);
    }
    sxy / (sxx * syy).sqrt()
}

fn random_summary(
    s: &Subject,
    res: &[RandomPattern],
    best: &[usize],
    worst: &[usize],
    _ts: f64,
) -> Vec<String> {
    let f = |i: Option<&usize>| {
        i.map_or("-".into(), |&i| {
            format!(
                "{:.3} ({:.1} Hz)",
                res[i].result.ftipp,
                res[i].average_frequency_hz.unwrap_or(0.0)
            )
        })
    };
    let xy: Vec<(f64, f64)> = res
        .iter()
        .filter_map(|r| r.average_frequency_hz.map(|f| (f, r.result.ftipp)))
        .collect();
    vec![
        s.name.clone(),
        f(best.first()),
        f(worst.first()),
        format!("{:+.2}", pearson(&xy)),
    ]
}

fn random_panels(
    s: &Subject,
    res: &[RandomPattern],
    best: &[usize],
    worst: &[usize],
    ts: f64,
    record_ms: f64,
) -> Vec<(u32, Panel)> {
    let pts: Vec<(f64, f64)> = res
        .iter()
        .filter_map(|r| r.average_frequency_hz.map(|f| (f, r.result.ftipp)))
        .collect();
    let mark = |idx: &[usize]| -> Vec<(f64, f64)> {
        idx.iter()
            .filter_map(|&i| {
                res[i]
                    .average_frequency_hz
                    .map(|f| (f, res[i].result.ftipp))
            })
            .collect()
    };
    let scatter = Panel {
        title: Some(format!("{}: FTIpP vs average frequency", s.name)),
        x_label: "average stimulation frequency (Hz), eq. 6.6".into(),
        y_label: "FTIpP".into(),
        markers: vec![
            Markers {
                label: None,
                points: pts,
                color: color(7),
                size: 3,
                filled: true,
            },
            Markers {
                label: Some("best 3".into()),
                points: mark(best),
                color: color(3),
                size: 5,
                filled: true,
            },
            Markers {
                label: Some("worst 3".into()),
                points: mark(worst),
                color: color(0),
                size: 5,
                filled: true,
            },
        ],
        hline: Some(1.0),
        legend: true,
        ..Panel::default()
    };
    let mut lines = Vec::new();
    let mut texts = Vec::new();
    let ms = ts * 1e3;
    for (row, (&i, tag, c)) in best
        .iter()
        .map(|i| (i, "best", color(3)))
        .chain(worst.iter().map(|i| (i, "worst", color(0))))
        .enumerate()
    {
        let y = -(row as f64);
        for &k in &res[i].result.pulses {
            let t = k as f64 * ms;
            lines.push(Line::new(None, vec![(t, y - 0.35), (t, y + 0.35)], c));
        }
        texts.push((
            record_ms * 0.62,
            y + 0.3,
            format!("{tag}: FTIpP {:.3}", res[i].result.ftipp),
        ));
    }
    let n = (best.len() + worst.len()) as f64;
    let patterns = Panel {
        title: Some("best (red) and worst (blue) patterns".into()),
        x_label: "time (ms)".into(),
        y_label: "".into(),
        x: Some((0.0, record_ms)),
        y: Some((-n + 0.4, 0.6)),
        lines,
        texts,
        ..Panel::default()
    };
    vec![(3, scatter), (2, patterns)]
}

fn trains(args: &Args, subjects: &[Subject], md: &mut String) -> Result<()> {
    need_subjects(subjects, "trains")?;
    let last = (args.train_pulses.saturating_sub(1)) as f64 * args.ipi_max_ms as f64;
    let mut surfaces: Vec<(String, TrainSurface, f64)> = Vec::new();
    let mut rows = Vec::new();
    let mut worst_end: f64 = 0.0;
    for s in subjects {
        let ev = evaluator(args, s, last)?;
        let ts = s.response.ts();
        let lo = samples("--ipi-min-ms", args.ipi_min_ms as f64, ts)?;
        let hi = samples("--ipi-max-ms", args.ipi_max_ms as f64, ts)?;
        let n = args.train_pulses * (hi - lo + 1);
        let bar = progress(n, &format!("constant trains, {}", s.name));
        let surf = train_surface(&ev, args.train_pulses, lo, hi, &|| bar.inc(1))
            .with_context(|| format!("{}: train surface", s.name))?;
        bar.finish_and_clear();
        for (i, row) in surf.results.iter().enumerate() {
            for (j, r) in row.iter().enumerate() {
                worst_end = worst_end.max(r.end_fraction);
                rows.push(vec![
                    s.name.clone(),
                    surf.pulses[i].to_string(),
                    format!("{}", surf.ipis[j] as f64 * ts * 1e3),
                    format!("{}", r.fti),
                    format!("{}", r.ftipp),
                    format!("{}", r.peak),
                ]);
            }
        }
        surfaces.push((s.name.clone(), surf, ts));
    }
    let all: Vec<f64> = surfaces
        .iter()
        .flat_map(|(_, s, _)| s.ftipp().into_iter().flatten())
        .filter(|v| v.is_finite())
        .collect();
    let lo = all.iter().copied().fold(1.0, f64::min).min(0.95);
    let hi = all.iter().copied().fold(1.0, f64::max).max(1.05);
    let maps: Vec<HeatMap> = surfaces
        .iter()
        .map(|(name, s, ts)| {
            let (bp, bi, bv) = s.best();
            let ms = ts * 1e3;
            HeatMap {
                title: name.clone(),
                xs: s.ipis.iter().map(|&i| i as f64 * ms).collect(),
                ys: s.pulses.iter().map(|&p| p as f64).collect(),
                z: s.ftipp(),
                x_label: "IPI (ms)".into(),
                y_label: "pulses".into(),
                marks: vec![(
                    bi as f64 * ms,
                    bp as f64,
                    if bp == 1 {
                        format!("max {bv:.3}: the twitch")
                    } else {
                        format!("max {bv:.3}: {bp} pulses, IPI {} ms", bi as f64 * ms)
                    },
                )],
            }
        })
        .collect();
    plots::save_heatmaps(
        &maps,
        "constant-frequency train method (6.3, Fig. 6.3): FTIpP (red > 1 > blue)",
        (lo, 1.0, hi),
        "FTIpP",
        &args.out.join("trains.png"),
        (520 * surfaces.len() as u32 + 110, 520),
    )?;
    plots::save_surfaces(
        &maps,
        "constant-frequency train method (6.3, Fig. 6.3): FTIpP surface",
        (lo, 1.0, hi),
        "FTIpP",
        &args.out.join("trains_3d.png"),
        (560 * surfaces.len() as u32, 520),
    )?;
    write_csv(
        &args.out.join("trains.csv"),
        &["subject", "pulses", "ipi_ms", "fti", "ftipp", "peak"],
        &rows,
    )?;
    let _ = writeln!(md, "## Constant-frequency train method (6.3, Fig. 6.3)\n");
    let _ = writeln!(
        md,
        "Trains of 1..{} pulses at constant IPIs of {}..{} ms, first pulse at 0. Table: `trains.csv`.\n",
        args.train_pulses, args.ipi_min_ms, args.ipi_max_ms
    );
    let _ = writeln!(md, "![constant-frequency trains](trains.png)\n");
    let _ = writeln!(md, "![constant-frequency trains, surface](trains_3d.png)\n");
    let summary: Vec<Vec<String>> = surfaces
        .iter()
        .map(|(name, s, ts)| {
            let (bp, bi, bv) = s.best();
            let above = s.ftipp().iter().flatten().filter(|v| **v > 1.0).count();
            let short = |ipi_ms: f64, p: usize| {
                let j = s
                    .ipis
                    .iter()
                    .position(|&i| (i as f64 * ts * 1e3 - ipi_ms).abs() < 1e-9);
                j.and_then(|j| {
                    s.results
                        .get(p - 1)
                        .map(|row| format!("{:.3}", row[j].ftipp))
                })
                .unwrap_or("-".into())
            };
            vec![
                name.clone(),
                if bp == 1 {
                    format!("{bv:.3} (1 pulse: the twitch)")
                } else {
                    format!("{bv:.3} ({bp} pulses, {} ms)", bi as f64 * ts * 1e3)
                },
                format!("{above} of {}", s.pulses.len() * s.ipis.len()),
                short(5.0, 3.min(s.pulses.len())),
                short(20.0, 5.min(s.pulses.len())),
            ]
        })
        .collect();
    md.push_str(&md_table(
        &[
            "subject",
            "largest FTIpP",
            "cells with FTIpP > 1",
            "3 pulses at 5 ms",
            "5 pulses at 20 ms",
        ],
        &summary,
    ));
    md.push('\n');
    truncation_note(md, worst_end);
    Ok(())
}

fn iterative(args: &Args, subjects: &[Subject], md: &mut String) -> Result<()> {
    need_subjects(subjects, "iterative")?;
    let last = (args.iterative_pulses.saturating_sub(1)) as f64 * args.ipi_max_ms as f64;
    let mut columns = Vec::new();
    let mut rows = Vec::new();
    let mut table = Vec::new();
    let mut worst_end: f64 = 0.0;
    for s in subjects {
        let ev = evaluator(args, s, last)?;
        let ts = s.response.ts();
        let lo = samples("--ipi-min-ms", args.ipi_min_ms as f64, ts)?;
        let hi = samples("--ipi-max-ms", args.ipi_max_ms as f64, ts)?;
        let n = args.iterative_pulses.saturating_sub(1) * (hi - lo + 1);
        let bar = progress(n, &format!("iterative method, {}", s.name));
        let it = iterative_method(&ev, args.iterative_pulses, lo, hi, &|| bar.inc(1))
            .with_context(|| format!("{}: iterative method", s.name))?;
        bar.finish_and_clear();
        let ms = ts * 1e3;
        table.push(vec![
            s.name.clone(),
            "1".into(),
            "-".into(),
            format!("{:.4}", it.twitch.fti),
            "1.000".into(),
            "0".into(),
        ]);
        for st in &it.stages {
            let (ipi, r) = st.best();
            table.push(vec![
                s.name.clone(),
                st.pulses.to_string(),
                format!("{}", *ipi as f64 * ms),
                format!("{:.4}", r.fti),
                format!("{:.3}", r.ftipp),
                pulses_ms(&r.pulses, ts).replace(';', ", "),
            ]);
            for (ipi, r) in &st.sweep {
                worst_end = worst_end.max(r.end_fraction);
                rows.push(vec![
                    s.name.clone(),
                    st.pulses.to_string(),
                    format!("{}", *ipi as f64 * ms),
                    format!("{}", r.peak),
                    format!("{}", r.fti),
                    format!("{}", r.ftipp),
                ]);
            }
        }
        columns.push(iterative_panels(s, &it, ms));
    }
    plots::save(
        &Figure {
            title: format!(
                "iterative method (6.4, Fig. 6.4): up to {} pulses",
                args.iterative_pulses
            ),
            columns,
        },
        &args.out.join("iterative.png"),
        (560 * subjects.len() as u32 + 80, 820),
    )?;
    write_csv(
        &args.out.join("iterative.csv"),
        &["subject", "pulses", "last_ipi_ms", "peak", "fti", "ftipp"],
        &rows,
    )?;
    let _ = writeln!(md, "## Iterative method (6.4, Fig. 6.4)\n");
    let _ = writeln!(
        md,
        "Each stage adds one pulse after the previous one, sweeping its IPI over {}..{} ms in 1-sample steps, and keeps the IPI of the largest FTIpP. Table of every sweep: `iterative.csv`.\n",
        args.ipi_min_ms, args.ipi_max_ms
    );
    let _ = writeln!(md, "![iterative method](iterative.png)\n");
    md.push_str(&md_table(
        &[
            "subject",
            "pulses",
            "optimal IPI (ms)",
            "FTI",
            "FTIpP",
            "pattern (ms)",
        ],
        &table,
    ));
    md.push('\n');
    truncation_note(md, worst_end);
    Ok(())
}

fn iterative_panels(s: &Subject, it: &Iterative, ms: f64) -> Vec<(u32, Panel)> {
    let mk = |title: &str,
              y_label: String,
              f: &dyn Fn(&fes_ident::analysis::osp::PatternResult) -> f64,
              twitch: f64| {
        let mut lines = Vec::new();
        let mut best = Vec::new();
        for (i, st) in it.stages.iter().enumerate() {
            lines.push(Line::new(
                Some(format!("{} pulses", st.pulses)),
                st.sweep
                    .iter()
                    .map(|(ipi, r)| (*ipi as f64 * ms, f(r)))
                    .collect(),
                color(i),
            ));
            let (ipi, r) = st.best();
            best.push((*ipi as f64 * ms, f(r)));
        }
        let x1 = it
            .stages
            .first()
            .and_then(|s| s.sweep.last())
            .map_or(100.0, |(i, _)| *i as f64 * ms);
        lines.push(
            Line::new(
                Some("1 pulse (twitch)".to_string()),
                vec![(0.0, twitch), (x1, twitch)],
                color(7),
            )
            .dashed(),
        );
        Panel {
            title: Some(title.to_string()),
            x_label: "IPI to the previous pulse (ms)".into(),
            y_label,
            x: Some((0.0, 1.32 * x1)),
            lines,
            markers: vec![Markers {
                label: Some("optimal IPI".into()),
                points: best,
                color: BLACKISH,
                size: 5,
                filled: true,
            }],
            legend: true,
            ..Panel::default()
        }
    };
    vec![
        (
            1,
            mk(
                &format!("{}: peak force", s.name),
                format!("peak ({})", s.unit),
                &|r| r.peak,
                it.twitch.peak,
            ),
        ),
        (
            1,
            mk(
                "force-time integral (eq. 6.2)",
                format!("FTI ({} s)", s.unit),
                &|r| r.fti,
                it.twitch.fti,
            ),
        ),
        (1, mk("FTIpP (eq. 6.3)", "FTIpP".into(), &|r| r.ftipp, 1.0)),
    ]
}

const BLACKISH: plotters::style::RGBColor = plotters::style::RGBColor(20, 20, 20);

fn lcn(
    args: &Args,
    c: &Controller,
    subjects: &[Subject],
    levels: &[f64],
    md: &mut String,
) -> Result<()> {
    let mut pg = c.pattern_generator().context("pattern generator")?;
    let ts = c.lmn.ts;
    let n = samples("--lcn-ms", args.lcn_ms as f64, ts)?;
    let onset = samples("step onset", 50.0, ts)?.min(n.saturating_sub(1));
    let criteria = ShapeCriteria::default();
    let ms = ts * 1e3;
    let mut column = Vec::new();
    let mut table = Vec::new();
    let mut csv = Vec::new();
    for (li, &level) in levels.iter().enumerate() {
        let run: LcnRun = run_pattern_generator(&mut pg, &step_reference(level, onset, n));
        let times = run.pulse_times();
        let shape: Option<PatternShape> = pattern_shape(&times, &criteria);
        let mut lines = vec![
            Line::new(
                Some("reference".to_string()),
                run.reference
                    .iter()
                    .enumerate()
                    .map(|(k, &r)| (k as f64 * ms, r))
                    .collect(),
                color(7),
            )
            .dashed(),
        ];
        let loop_line = Line::new(
            Some("loop model (design LMN)".to_string()),
            run.model_force
                .iter()
                .enumerate()
                .map(|(k, &y)| (k as f64 * ms, y))
                .collect(),
            color(0),
        );
        let mut extra = Vec::new();
        for (si, s) in subjects.iter().enumerate() {
            let f = s
                .response
                .force(&run.pulse)
                .with_context(|| format!("{} driven by the LCN pattern", s.name))?;
            let y: Vec<(f64, f64)> = f
                .iter()
                .enumerate()
                .map(|(k, &v)| (k as f64 * ms, v * s.to_normalised))
                .collect();
            let mean = steady_mean(&f, &times, n / 2).unwrap_or(f64::NAN) * s.to_normalised;
            extra.push(format!("{}: {:.3}", s.name, mean));
            lines.push(Line::new(
                Some(format!("{} (driven by the pattern)", s.name)),
                y,
                color(1 + si),
            ));
        }
        lines.push(loop_line);
        let loop_mean = steady_mean(&run.model_force, &times, n / 2).unwrap_or(f64::NAN);
        column.push((
            1,
            Panel {
                y_label: "pulse".into(),
                x: Some((0.0, n as f64 * ms)),
                y: Some((0.0, 1.1)),
                y_ticks: Some(2),
                compact: true,
                impulses: times.iter().map(|&k| k as f64 * ms).collect(),
                ..Panel::default()
            },
        ));
        column.push((
            3,
            Panel {
                title: Some(format!("r = {level}: {} pulses (above)", times.len())),
                x_label: if li + 1 == levels.len() {
                    "time (ms)".into()
                } else {
                    String::new()
                },
                y_label: "force (normalised)".into(),
                x: Some((0.0, n as f64 * ms)),
                lines,
                legend: li == 0,
                ..Panel::default()
            },
        ));
        let sh = |f: &dyn Fn(&PatternShape) -> String| shape.as_ref().map_or("-".into(), f);
        table.push(vec![
            format!("{level}"),
            times.len().to_string(),
            sh(&|s| s.burst_pulses.to_string()),
            sh(&|s| s.pause.map_or("-".into(), |p| format!("{}", p as f64 * ms))),
            sh(&|s| {
                s.steady_median
                    .map_or("-".into(), |m| format!("{:.1}", m * ms))
            }),
            sh(&|s| s.steady_cv.map_or("-".into(), |c| format!("{c:.3}"))),
            sh(&|s| {
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
            }),
            format!(
                "{loop_mean:.3}{}",
                if extra.is_empty() {
                    String::new()
                } else {
                    format!("; {}", extra.join("; "))
                }
            ),
        ]);
        csv.push(vec![
            format!("{level}"),
            times.len().to_string(),
            pulses_ms(&times, ts),
        ]);
    }
    let h = 260 * levels.len() as u32 + 60;
    plots::save(
        &Figure {
            title: "LCN pattern generator on step references (6.5, Figs. 6.9 / 6.11)".into(),
            columns: vec![column],
        },
        &args.out.join("lcn.png"),
        (1000, h.min(2400)),
    )?;
    write_csv(
        &args.out.join("lcn.csv"),
        &["reference", "pulses", "pulse_times_ms"],
        &csv,
    )?;
    let _ = writeln!(md, "## LCN-generated patterns (6.5, Figs. 6.9 / 6.11)\n");
    let _ = writeln!(
        md,
        "The controller's pattern generator (LCN -> pulse shaper -> its design LMN, Fig. 6.8) runs on step references from rest (step at 50 ms, {} ms); the pattern also drives the subjects outside the loop (Fig. 6.6(b)), their force in the controller model's normalised units (rest force removed). Shape criteria (6.5.4): burst = initial IPIs <= {} ms; pause = next IPI >= {} x the median of the later IPIs; even = later IPIs with coefficient of variation <= {} (at least 3). Pulse times: `lcn.csv`.\n",
        args.lcn_ms,
        criteria.burst_ipi as f64 * ms,
        criteria.pause_factor,
        criteria.even_cv
    );
    let _ = writeln!(md, "![LCN patterns](lcn.png)\n");
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
    Ok(())
}
