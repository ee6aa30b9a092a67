//! `--method iterative` (thesis 6.4, Fig. 6.4): pulses added one at a time, each at the IPI
//! of the largest FTIpP.

use anyhow::{Context, Result};
use fes_ident::analysis::osp::PatternResult;
use fes_ident::analysis::osp::iterative::{Iterative, iterative_method};

use super::super::inputs::progress;
use super::super::plots::{Line, Markers, Panel, color};
use super::{
    Args, Section, Subject, SubjectInfo, evaluator, ipi_samples, need_subjects, pulses_ms,
    save_subject_columns,
};

/// One subject's iterative method.
struct SubjectIterative {
    subject: SubjectInfo,
    result: Iterative,
}

/// The iterative method on every subject, in the order given.
struct IterativeOutcome {
    subjects: Vec<SubjectIterative>,
}

impl IterativeOutcome {
    /// The largest force left at the end of the window relative to its peak, over every
    /// swept pattern.
    fn worst_end(&self) -> f64 {
        self.subjects
            .iter()
            .flat_map(|s| &s.result.stages)
            .flat_map(|st| &st.sweep)
            .fold(0.0, |w: f64, (_, r)| w.max(r.end_fraction))
    }
}

/// Runs the method on every subject and reports it.
pub(super) fn run(args: &Args, subjects: &[Subject], md: &mut String) -> Result<()> {
    let outcome = compute(args, subjects)?;
    report(args, &outcome, md)
}

fn compute(args: &Args, subjects: &[Subject]) -> Result<IterativeOutcome> {
    need_subjects(subjects, "iterative")?;
    let last = (args.iterative_pulses.saturating_sub(1)) as f64 * args.ipi_max_ms as f64;
    let mut out = Vec::new();
    for s in subjects {
        let ev = evaluator(args, s, last)?;
        let (lo, hi) = ipi_samples(args, s.response.ts())?;
        let n = args.iterative_pulses.saturating_sub(1) * (hi - lo + 1);
        let bar = progress(n, &format!("iterative method, {}", s.name));
        let result = iterative_method(&ev, args.iterative_pulses, lo, hi, &|| bar.inc(1))
            .with_context(|| format!("{}: iterative method", s.name))?;
        bar.finish_and_clear();
        out.push(SubjectIterative {
            subject: s.info(),
            result,
        });
    }
    Ok(IterativeOutcome { subjects: out })
}

/// `iterative.png`, `iterative.csv` and the report's section.
fn report(args: &Args, out: &IterativeOutcome, md: &mut String) -> Result<()> {
    let columns = out.subjects.iter().map(panels).collect();
    let title = format!(
        "iterative method (6.4, Fig. 6.4): up to {} pulses",
        args.iterative_pulses
    );
    save_subject_columns(args, "iterative", title, columns, 820)?;
    Section {
        stem: "iterative",
        csv_header: &["subject", "pulses", "last_ipi_ms", "peak", "fti", "ftipp"],
        csv_rows: csv_rows(out),
        heading: "Iterative method (6.4, Fig. 6.4)",
        intro: format!(
            "Each stage adds one pulse after the previous one, sweeping its IPI over {}..{} ms in 1-sample steps, and keeps the IPI of the largest FTIpP. Table of every sweep: `iterative.csv`.",
            args.ipi_min_ms, args.ipi_max_ms
        ),
        figures: &[("iterative method", "iterative")],
        summary_header: &[
            "subject",
            "pulses",
            "optimal IPI (ms)",
            "FTI",
            "FTIpP",
            "pattern (ms)",
        ],
        summary: out.subjects.iter().flat_map(chosen_rows).collect(),
        worst_end: out.worst_end(),
    }
    .write(args, md)
}

/// The report's rows of one subject: the twitch, then each stage's chosen pattern.
fn chosen_rows(s: &SubjectIterative) -> Vec<Vec<String>> {
    let (name, ts, it) = (&s.subject.name, s.subject.ts, &s.result);
    let ms = ts * 1e3;
    let mut table = vec![vec![
        name.clone(),
        "1".into(),
        "-".into(),
        format!("{:.4}", it.twitch.fti),
        "1.000".into(),
        "0".into(),
    ]];
    for st in &it.stages {
        let (ipi, r) = st.best();
        table.push(vec![
            name.clone(),
            st.pulses.to_string(),
            format!("{}", *ipi as f64 * ms),
            format!("{:.4}", r.fti),
            format!("{:.3}", r.ftipp),
            pulses_ms(&r.pulses, ts).replace(';', ", "),
        ]);
    }
    table
}

/// One row per subject, stage and swept IPI.
fn csv_rows(out: &IterativeOutcome) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    for s in &out.subjects {
        let ms = s.subject.ts * 1e3;
        for st in &s.result.stages {
            for (ipi, r) in &st.sweep {
                rows.push(vec![
                    s.subject.name.clone(),
                    st.pulses.to_string(),
                    format!("{}", *ipi as f64 * ms),
                    format!("{}", r.peak),
                    format!("{}", r.fti),
                    format!("{}", r.ftipp),
                ]);
            }
        }
    }
    rows
}

/// One subject's column: peak, FTI and FTIpP against the swept IPI per stage.
fn panels(s: &SubjectIterative) -> Vec<(u32, Panel)> {
    let (it, ms, unit) = (&s.result, s.subject.ts * 1e3, s.subject.unit);
    vec![
        (
            1,
            sweep_panel(
                it,
                ms,
                &format!("{}: peak force", s.subject.name),
                format!("peak ({unit})"),
                &|r| r.peak,
                it.twitch.peak,
            ),
        ),
        (
            1,
            sweep_panel(
                it,
                ms,
                "force-time integral (eq. 6.2)",
                format!("FTI ({unit} s)"),
                &|r| r.fti,
                it.twitch.fti,
            ),
        ),
        (
            1,
            sweep_panel(it, ms, "FTIpP (eq. 6.3)", "FTIpP".into(), &|r| r.ftipp, 1.0),
        ),
    ]
}

/// `f` of every swept pattern against its IPI, one line per stage, the twitch's value
/// dashed and each stage's optimal IPI marked.
fn sweep_panel(
    it: &Iterative,
    ms: f64,
    title: &str,
    y_label: String,
    f: &dyn Fn(&PatternResult) -> f64,
    twitch: f64,
) -> Panel {
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
}

const BLACKISH: plotters::style::RGBColor = plotters::style::RGBColor(20, 20, 20);
