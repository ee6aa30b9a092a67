//! `--method trains` (thesis 6.3, Fig. 6.3): FTIpP of constant-IPI trains, 1..`--train-pulses`
//! pulses x IPI `--ipi-min-ms`..`--ipi-max-ms`, as heat maps and 3-D surfaces.

use anyhow::{Context, Result};
use fes_ident::analysis::osp::trains::{TrainSurface, train_surface};

use super::super::inputs::progress;
use super::super::plots::{self, HeatMap, MapView};
use super::{Args, Section, Subject, SubjectInfo, evaluator, ipi_samples, need_subjects};

/// One subject's train surface.
struct SubjectSurface {
    subject: SubjectInfo,
    surface: TrainSurface,
}

/// The train surfaces of every subject, in the order given.
struct TrainsOutcome {
    surfaces: Vec<SubjectSurface>,
}

impl TrainsOutcome {
    /// The largest force left at the end of the window relative to its peak.
    fn worst_end(&self) -> f64 {
        self.surfaces
            .iter()
            .flat_map(|s| s.surface.results.iter().flatten())
            .fold(0.0, |w: f64, r| w.max(r.end_fraction))
    }

    /// The shared colour scale (lo, hi) around 1: every finite FTIpP, at least 0.95..1.05.
    fn scale(&self) -> (f64, f64) {
        let all: Vec<f64> = self
            .surfaces
            .iter()
            .flat_map(|s| s.surface.ftipp().into_iter().flatten())
            .filter(|v| v.is_finite())
            .collect();
        let lo = all.iter().copied().fold(1.0, f64::min).min(0.95);
        let hi = all.iter().copied().fold(1.0, f64::max).max(1.05);
        (lo, hi)
    }
}

/// Runs the method on every subject and reports it.
pub(super) fn run(args: &Args, subjects: &[Subject], md: &mut String) -> Result<()> {
    let outcome = compute(args, subjects)?;
    report(args, &outcome, md)
}

fn compute(args: &Args, subjects: &[Subject]) -> Result<TrainsOutcome> {
    need_subjects(subjects, "trains")?;
    let last = (args.train_pulses.saturating_sub(1)) as f64 * args.ipi_max_ms as f64;
    let mut surfaces = Vec::new();
    for s in subjects {
        let ev = evaluator(args, s, last)?;
        let (lo, hi) = ipi_samples(args, s.response.ts())?;
        let n = args.train_pulses * (hi - lo + 1);
        let bar = progress(n, &format!("constant trains, {}", s.name));
        let surface = train_surface(&ev, args.train_pulses, lo, hi, &|| bar.inc(1))
            .with_context(|| format!("{}: train surface", s.name))?;
        bar.finish_and_clear();
        surfaces.push(SubjectSurface {
            subject: s.info(),
            surface,
        });
    }
    Ok(TrainsOutcome { surfaces })
}

/// `trains.png`, `trains_3d.png`, `trains.csv` and the report's section.
fn report(args: &Args, out: &TrainsOutcome, md: &mut String) -> Result<()> {
    let (lo, hi) = out.scale();
    let maps: Vec<HeatMap> = out.surfaces.iter().map(heat_map).collect();
    let n = out.surfaces.len() as u32;
    // The same maps drawn flat and in 3-D: view, title, file stem, size.
    let figures = [
        (
            MapView::Flat,
            "constant-frequency train method (6.3, Fig. 6.3): FTIpP (red > 1 > blue)",
            "trains",
            (520 * n + 110, 520),
        ),
        (
            MapView::Surface,
            "constant-frequency train method (6.3, Fig. 6.3): FTIpP surface",
            "trains_3d",
            (560 * n, 520),
        ),
    ];
    for (view, title, stem, size) in figures {
        plots::save_maps(
            view,
            &maps,
            title,
            (lo, 1.0, hi),
            "FTIpP",
            &args.format.file(&args.out, stem),
            size,
        )?;
    }
    Section {
        stem: "trains",
        csv_header: &["subject", "pulses", "ipi_ms", "fti", "ftipp", "peak"],
        csv_rows: csv_rows(out),
        heading: "Constant-frequency train method (6.3, Fig. 6.3)",
        intro: format!(
            "Trains of 1..{} pulses at constant IPIs of {}..{} ms, first pulse at 0. Table: `trains.csv`.",
            args.train_pulses, args.ipi_min_ms, args.ipi_max_ms
        ),
        figures: &[
            ("constant-frequency trains", "trains"),
            ("constant-frequency trains, surface", "trains_3d"),
        ],
        summary_header: &[
            "subject",
            "largest FTIpP",
            "cells with FTIpP > 1",
            "3 pulses at 5 ms",
            "5 pulses at 20 ms",
        ],
        summary: out.surfaces.iter().map(summary_row).collect(),
        worst_end: out.worst_end(),
    }
    .write(args, md)
}

/// One row per subject, pulse count and IPI.
fn csv_rows(out: &TrainsOutcome) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    for SubjectSurface { subject, surface } in &out.surfaces {
        for (i, row) in surface.results.iter().enumerate() {
            for (j, r) in row.iter().enumerate() {
                rows.push(vec![
                    subject.name.clone(),
                    surface.pulses[i].to_string(),
                    format!("{}", surface.ipis[j] as f64 * subject.ts * 1e3),
                    format!("{}", r.fti),
                    format!("{}", r.ftipp),
                    format!("{}", r.peak),
                ]);
            }
        }
    }
    rows
}

/// One subject's FTIpP grid, its largest cell ringed.
fn heat_map(s: &SubjectSurface) -> HeatMap {
    let surface = &s.surface;
    let (bp, bi, bv) = surface.best();
    let ms = s.subject.ts * 1e3;
    HeatMap {
        title: s.subject.name.clone(),
        xs: surface.ipis.iter().map(|&i| i as f64 * ms).collect(),
        ys: surface.pulses.iter().map(|&p| p as f64).collect(),
        z: surface.ftipp(),
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
}

/// The report's row of one subject: the largest FTIpP, the cells above 1, two sample cells.
fn summary_row(s: &SubjectSurface) -> Vec<String> {
    let (surface, ts) = (&s.surface, s.subject.ts);
    let (bp, bi, bv) = surface.best();
    let above = surface
        .ftipp()
        .iter()
        .flatten()
        .filter(|v| **v > 1.0)
        .count();
    let short = |ipi_ms: f64, p: usize| {
        let j = surface
            .ipis
            .iter()
            .position(|&i| (i as f64 * ts * 1e3 - ipi_ms).abs() < 1e-9);
        j.and_then(|j| {
            surface
                .results
                .get(p - 1)
                .map(|row| format!("{:.3}", row[j].ftipp))
        })
        .unwrap_or("-".into())
    };
    vec![
        s.subject.name.clone(),
        if bp == 1 {
            format!("{bv:.3} (1 pulse: the twitch)")
        } else {
            format!("{bv:.3} ({bp} pulses, {} ms)", bi as f64 * ts * 1e3)
        },
        format!("{above} of {}", surface.pulses.len() * surface.ipis.len()),
        short(5.0, 3.min(surface.pulses.len())),
        short(20.0, 5.min(surface.pulses.len())),
    ]
}
