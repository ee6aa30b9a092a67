//! `--method random` (thesis 6.2, Figs. 6.1-6.2): FTIpP of random patterns of the thesis
//! protocol (5.1) against their average frequency; best and worst patterns.

use anyhow::{Context, Result};
use fes_ident::analysis::osp::random::{RandomPattern, best_and_worst, random_method};
use sim_muscle::preset::Preset;
use sim_muscle::protocol::ProtocolConfig;

use super::super::inputs::progress;
use super::super::plots::{Line, Markers, Panel, color};
use super::{
    Args, Section, Subject, SubjectInfo, evaluator, need_subjects, pulses_ms, save_subject_columns,
};

/// The random patterns of every subject.
struct RandomOutcome {
    /// Patterns run on each subject.
    patterns: usize,
    /// Length of a protocol record, ms (the longest pattern).
    record_ms: f64,
    /// Per subject, in the order given.
    subjects: Vec<SubjectPatterns>,
}

/// One subject's random patterns.
struct SubjectPatterns {
    subject: SubjectInfo,
    /// Every pattern's result, in pattern order.
    results: Vec<RandomPattern>,
    /// Indices of the 3 best and 3 worst patterns (by FTIpP).
    best: Vec<usize>,
    worst: Vec<usize>,
}

impl RandomOutcome {
    /// The largest force left at the end of the window relative to its peak.
    fn worst_end(&self) -> f64 {
        self.subjects
            .iter()
            .flat_map(|s| &s.results)
            .fold(0.0, |w: f64, r| w.max(r.result.end_fraction))
    }
}

/// Runs the method on every subject and reports it.
pub(super) fn run(args: &Args, subjects: &[Subject], md: &mut String) -> Result<()> {
    let outcome = compute(args, subjects)?;
    report(args, &outcome, md)
}

fn compute(args: &Args, subjects: &[Subject]) -> Result<RandomOutcome> {
    need_subjects(subjects, "random")?;
    let (patterns, record_ms) = protocol_patterns(args)?;
    let mut out = Vec::new();
    for s in subjects {
        let ev = evaluator(args, s, record_ms)?;
        let bar = progress(patterns.len(), &format!("random patterns, {}", s.name));
        let results = random_method(&ev, &patterns, &|| bar.inc(1))
            .with_context(|| format!("{}: random patterns", s.name))?;
        bar.finish_and_clear();
        let (best, worst) = best_and_worst(&results, 3);
        out.push(SubjectPatterns {
            subject: s.info(),
            results,
            best,
            worst,
        });
    }
    Ok(RandomOutcome {
        patterns: patterns.len(),
        record_ms,
        subjects: out,
    })
}

/// `--patterns` non-empty patterns (pulse samples) of the thesis protocol (5.1) and the
/// length of its records, ms.
fn protocol_patterns(args: &Args) -> Result<(Vec<Vec<usize>>, f64)> {
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
    Ok((patterns, proto.record_ms as f64))
}

/// `random.png`, `random.csv` and the report's section.
fn report(args: &Args, out: &RandomOutcome, md: &mut String) -> Result<()> {
    let columns = out
        .subjects
        .iter()
        .map(|s| panels(s, out.record_ms))
        .collect();
    let title = format!(
        "random pattern method (6.2): {} patterns of the thesis protocol",
        out.patterns
    );
    save_subject_columns(args, "random", title, columns, 760)?;
    Section {
        stem: "random",
        csv_header: &[
            "subject",
            "pattern",
            "pulses",
            "average_frequency_hz",
            "fti",
            "ftipp",
            "pulse_times_ms",
        ],
        csv_rows: csv_rows(out),
        heading: "Random pattern method (6.2, Figs. 6.1-6.2)",
        intro: format!(
            "{} patterns drawn with the thesis protocol (5.1: random IPIs 1-70 ms, trains of 100-300 ms; seed {}); average frequency eq. (6.6). Table: `random.csv`.",
            out.patterns, args.seed
        ),
        figures: &[("random pattern method", "random")],
        summary_header: &[
            "subject",
            "best FTIpP (f_av)",
            "worst FTIpP (f_av)",
            "corr(FTIpP, f_av)",
        ],
        summary: out.subjects.iter().map(summary_row).collect(),
        worst_end: out.worst_end(),
    }
    .write(args, md)
}

/// One row per subject and pattern.
fn csv_rows(out: &RandomOutcome) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    for s in &out.subjects {
        for (i, r) in s.results.iter().enumerate() {
            rows.push(vec![
                s.subject.name.clone(),
                i.to_string(),
                r.result.pulses.len().to_string(),
                r.average_frequency_hz.map_or("".into(), |f| format!("{f}")),
                format!("{}", r.result.fti),
                format!("{}", r.result.ftipp),
                pulses_ms(&r.result.pulses, s.subject.ts),
            ]);
        }
    }
    rows
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

/// (average frequency, FTIpP) of the patterns that have an average frequency.
fn frequency_points<'a>(
    res: &'a [RandomPattern],
    idx: impl Iterator<Item = usize> + 'a,
) -> Vec<(f64, f64)> {
    idx.filter_map(|i| {
        res[i]
            .average_frequency_hz
            .map(|f| (f, res[i].result.ftipp))
    })
    .collect()
}

/// The report's row of one subject: best, worst, correlation with the average frequency.
fn summary_row(s: &SubjectPatterns) -> Vec<String> {
    let res = &s.results;
    let f = |i: Option<&usize>| {
        i.map_or("-".into(), |&i| {
            format!(
                "{:.3} ({:.1} Hz)",
                res[i].result.ftipp,
                res[i].average_frequency_hz.unwrap_or(0.0)
            )
        })
    };
    let xy = frequency_points(res, 0..res.len());
    vec![
        s.subject.name.clone(),
        f(s.best.first()),
        f(s.worst.first()),
        format!("{:+.2}", pearson(&xy)),
    ]
}

/// One subject's column: the FTIpP scatter and the best and worst patterns.
fn panels(s: &SubjectPatterns, record_ms: f64) -> Vec<(u32, Panel)> {
    let res = &s.results;
    let mark = |idx: &[usize]| frequency_points(res, idx.iter().copied());
    let scatter = Panel {
        title: Some(format!("{}: FTIpP vs average frequency", s.subject.name)),
        x_label: "average stimulation frequency (Hz), eq. 6.6".into(),
        y_label: "FTIpP".into(),
        markers: vec![
            Markers {
                label: None,
                points: frequency_points(res, 0..res.len()),
                color: color(7),
                size: 3,
                filled: true,
            },
            Markers {
                label: Some("best 3".into()),
                points: mark(&s.best),
                color: color(3),
                size: 5,
                filled: true,
            },
            Markers {
                label: Some("worst 3".into()),
                points: mark(&s.worst),
                color: color(0),
                size: 5,
                filled: true,
            },
        ],
        hline: Some(1.0),
        legend: true,
        ..Panel::default()
    };
    vec![(3, scatter), (2, pattern_panel(s, record_ms))]
}

/// The best (red) and worst (blue) patterns as rows of pulse strokes.
fn pattern_panel(s: &SubjectPatterns, record_ms: f64) -> Panel {
    let (res, best, worst) = (&s.results, &s.best, &s.worst);
    let mut lines = Vec::new();
    let mut texts = Vec::new();
    let ms = s.subject.ts * 1e3;
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
    Panel {
        title: Some("best (red) and worst (blue) patterns".into()),
        x_label: "time (ms)".into(),
        y_label: "".into(),
        x: Some((0.0, record_ms)),
        y: Some((-n + 0.4, 0.6)),
        lines,
        texts,
        ..Panel::default()
    }
}
