//! Figures of a run (PNG or SVG, by the file's extension: [`FigureFormat`]): reference,
//! measured and model force with the pulse raster; per-beat contraction (outer loop
//! on/off); latency percentile curves.

use std::path::{Path, PathBuf};

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// A drawing failure.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot draw the plot: {message}", path.display())]
pub struct PlotError {
    /// Output file.
    pub path: PathBuf,
    /// plotters' reason.
    pub message: String,
}

impl PlotError {
    /// The error of a figure's `path` that is neither a `.png` nor an `.svg` file.
    pub fn not_a_figure(path: &Path) -> Self {
        PlotError {
            path: path.to_path_buf(),
            message: "figures are written as .png or .svg files".into(),
        }
    }
}

/// The formats figures are written in, chosen by the output file's extension (plotters'
/// bitmap and SVG backends; plotters has no PDF backend).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum FigureFormat {
    /// Raster (`.png`).
    #[default]
    Png,
    /// Vector (`.svg`), for papers.
    Svg,
}

impl FigureFormat {
    /// The file extension.
    pub const fn ext(self) -> &'static str {
        match self {
            FigureFormat::Png => "png",
            FigureFormat::Svg => "svg",
        }
    }

    /// `stem.<ext>` in `dir`.
    pub fn file(self, dir: &Path, stem: &str) -> PathBuf {
        dir.join(format!("{stem}.{}", self.ext()))
    }
}

/// Runs `$body` with `$root` the drawing area of a `$size` figure at `$path`, drawn with
/// the bitmap or the SVG backend by the path's extension (`fes_figure::by_extension!`); for
/// any other name, [`PlotError::not_a_figure`] is returned with `?`. The body is compiled
/// once per backend.
#[macro_export]
macro_rules! on_figure {
    ($path:expr, $size:expr, |$root:ident| $body:block) => {{
        match ::fes_figure::by_extension!($path, $size, |$root| $body) {
            ::std::option::Option::Some(drawn) => drawn,
            ::std::option::Option::None => {
                ::std::result::Result::Err($crate::plots::PlotError::not_a_figure($path))?
            }
        }
    }};
}
pub use on_figure;

fn fail(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Draws the chart's legend in a white, black-bordered box at `position`.
fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    e: &dyn Fn(&dyn std::fmt::Display) -> PlotError,
) -> Result<(), PlotError> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .position(position)
        .draw()
        .map_err(|x| e(&x))
}

/// The legend entry of a 2 px line in `color`.
fn line_legend(color: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
}

/// Time series of a run, 1 ms apart.
#[derive(Debug, Clone, Default)]
pub struct RunSeries {
    /// Sample times, s (from the start of the run).
    pub t_s: Vec<f64>,
    /// Reference handed to the pattern generator.
    pub reference: Vec<f64>,
    /// Model force (rt-core).
    pub model: Vec<f64>,
    /// Measured force.
    pub measured: Vec<f64>,
    /// Times of the pulses, s.
    pub pulses_s: Vec<f64>,
}

/// Draws the run between `from_s` and `to_s`: pulse raster on top, reference (black),
/// model force (blue) and measured force (red) below.
pub fn plot_run(
    out: &Path,
    title: &str,
    run: &RunSeries,
    (from_s, to_s): (f64, f64),
) -> Result<(), PlotError> {
    let e = fail(out);
    let size = (1400u32, 700u32);
    on_figure!(out, size, |root| {
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(|x| e(&x))?;
        let (upper, lower) = root.split_vertically(size.1 * 15 / 100);
        let mut top = fes_figure::pulse_strip(&upper)
            .build_cartesian_2d(from_s..to_s, 0.0..1.2)
            .map_err(|x| e(&x))?;
        top.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_labels(2)
            .y_desc("pulse")
            .draw()
            .map_err(|x| e(&x))?;
        top.draw_series(
            run.pulses_s
                .iter()
                .filter(|t| (from_s..to_s).contains(*t))
                .map(|&t| fes_figure::pulse_mark(t)),
        )
        .map_err(|x| e(&x))?;
        let in_window = |v: &[f64]| -> Vec<(f64, f64)> {
            run.t_s
                .iter()
                .zip(v)
                .filter(|(t, _)| (from_s..to_s).contains(*t))
                .map(|(&t, &y)| (t, y))
                .collect()
        };
        let ymax = run
            .measured
            .iter()
            .chain(&run.model)
            .chain(&run.reference)
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.1, f64::max)
            * 1.1;
        let mut bottom = fes_figure::time_panel(&lower)
            .build_cartesian_2d(from_s..to_s, -0.05..ymax)
            .map_err(|x| e(&x))?;
        bottom
            .configure_mesh()
            .light_line_style(WHITE.mix(0.0))
            .x_desc("time (s)")
            .y_desc("force (normalised)")
            .draw()
            .map_err(|x| e(&x))?;
        for (series, color, label) in [
            (&run.reference, BLACK, "reference"),
            (&run.model, BLUE, "model force (rt-core LMN)"),
            (&run.measured, RED, "measured force"),
        ] {
            bottom
                .draw_series(LineSeries::new(in_window(series), color.stroke_width(2)))
                .map_err(|x| e(&x))?
                .label(label)
                .legend(line_legend(color));
        }
        legend(&mut bottom, SeriesLabelPosition::UpperRight, &e)?;
        root.present().map_err(|x| e(&x))?;
        Ok(())
    })
}

/// A labelled line of points.
#[derive(Debug, Clone)]
pub struct Curve {
    /// Legend text.
    pub label: String,
    /// The points (x, y).
    pub points: Vec<(f64, f64)>,
}

/// One line of per-beat values: (time of the beat, s; value).
pub type BeatLine = Curve;

/// Draws per-beat contraction lines with the target and a +-`band` fraction around it.
pub fn plot_beats(
    out: &Path,
    title: &str,
    y_desc: &str,
    lines: &[BeatLine],
    target: f64,
    band: f64,
) -> Result<(), PlotError> {
    let e = fail(out);
    on_figure!(out, (1200, 600), |root| {
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let t_max = lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.0))
            .fold(1.0, f64::max);
        let y_max = lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.1))
            .fold(target * (1.0 + 2.0 * band), f64::max)
            * 1.05;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..t_max, 0.0..y_max)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .light_line_style(WHITE.mix(0.0))
            .x_desc("time (s)")
            .y_desc(y_desc)
            .draw()
            .map_err(|x| e(&x))?;
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(0.0, target * (1.0 - band)), (t_max, target * (1.0 + band))],
                RGBColor(220, 235, 220).filled(),
            )))
            .map_err(|x| e(&x))?
            .label(format!("target +-{:.0} %", band * 100.0))
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 5), (x + 20, y + 5)],
                    RGBColor(220, 235, 220).filled(),
                )
            });
        chart
            .draw_series(LineSeries::new(
                vec![(0.0, target), (t_max, target)],
                BLACK.stroke_width(1),
            ))
            .map_err(|x| e(&x))?;
        let colors = [RED, BLUE, GREEN, MAGENTA];
        for (i, l) in lines.iter().enumerate() {
            let c = colors[i % colors.len()];
            chart
                .draw_series(LineSeries::new(l.points.clone(), c.stroke_width(2)))
                .map_err(|x| e(&x))?
                .label(l.label.clone())
                .legend(line_legend(c));
            chart
                .draw_series(l.points.iter().map(|&p| Circle::new(p, 3, c.filled())))
                .map_err(|x| e(&x))?;
        }
        legend(&mut chart, SeriesLabelPosition::LowerLeft, &e)?;
        root.present().map_err(|x| e(&x))?;
        Ok(())
    })
}

/// One latency distribution: (percentile in [0, 100), latency in µs) points.
pub type LatencyCurve = Curve;

/// Percentiles drawn: 0, 50, 90, 99, 99.9, 99.99 and the steps between, as
/// `-log10(1 - q)` on the x axis (the usual HdrHistogram percentile plot).
pub fn percentile_grid() -> Vec<f64> {
    (0..=80)
        .map(|i| 1.0 - 10f64.powf(-(i as f64) / 20.0))
        .collect()
}

/// Draws latency percentile curves (log latency axis).
pub fn plot_latency(out: &Path, title: &str, curves: &[LatencyCurve]) -> Result<(), PlotError> {
    let e = fail(out);
    on_figure!(out, (1200, 600), |root| {
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let y_max = curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.1))
            .fold(10.0, f64::max)
            * 2.0;
        let y_min = curves
            .iter()
            .flat_map(|c| c.points.iter().map(|p| p.1))
            .filter(|v| *v > 0.0)
            .fold(y_max, f64::min)
            .max(0.01)
            / 2.0;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..4.0, (y_min..y_max).log_scale())
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_labels(5)
            .x_label_formatter(&|x| format!("{}", 100.0 - 100.0 * 10f64.powf(-x)))
            .x_desc("percentile")
            .y_desc("latency (µs)")
            .draw()
            .map_err(|x| e(&x))?;
        let colors = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];
        for (i, c) in curves.iter().enumerate() {
            let color = colors[i % colors.len()];
            let pts: Vec<(f64, f64)> = c
                .points
                .iter()
                .map(|&(q, v)| (-(1.0 - q / 100.0).max(1e-4).log10(), v.max(y_min)))
                .collect();
            chart
                .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                .map_err(|x| e(&x))?
                .label(c.label.clone())
                .legend(line_legend(color));
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft, &e)?;
        root.present().map_err(|x| e(&x))?;
        Ok(())
    })
}

/// The CFT front ([`fes_bench::cft`]): RMS tracking error against pulses per
/// contraction of every constant-frequency train (labelled every 10 Hz), the trains of
/// equal FTI (within 5 %) filled green, and the LCN's point.
pub fn plot_front(
    out: &Path,
    title: &str,
    verdict: &fes_bench::cft::FrontVerdict,
) -> Result<(), PlotError> {
    plot_front_compare(out, title, verdict, &[])
}

/// [`plot_front`] with more runs' points (label, point), e.g. the same controller with
/// planning off, drawn in orange.
pub fn plot_front_compare(
    out: &Path,
    title: &str,
    verdict: &fes_bench::cft::FrontVerdict,
    others: &[(&str, &fes_bench::cft::FrontPoint)],
) -> Result<(), PlotError> {
    let e = fail(out);
    on_figure!(out, (1000, 650), |root| {
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let pts: Vec<&fes_bench::cft::FrontPoint> = verdict
            .cft_front
            .iter()
            .chain(std::iter::once(&verdict.lcn))
            .chain(others.iter().map(|(_, p)| *p))
            .filter(|p| p.rms_error.is_finite() && p.pulses_per_contraction.is_finite())
            .collect();
        let x_max = pts
            .iter()
            .map(|p| p.pulses_per_contraction)
            .fold(1.0, f64::max)
            * 1.05;
        let y_max = pts.iter().map(|p| p.rms_error).fold(0.01, f64::max) * 1.1;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x_max, 0.0..y_max)
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_desc("pulses per contraction")
            .y_desc("RMS tracking error (normalised force)")
            .draw()
            .map_err(|x| e(&x))?;
        draw_trains(&mut chart, verdict, &e)?;
        draw_runs(&mut chart, verdict, others, &e)?;
        legend(&mut chart, SeriesLabelPosition::UpperRight, &e)?;
        root.present().map_err(|x| e(&x))?;
        Ok(())
    })
}

/// The chart of a front: pulses per contraction against RMS error.
type FrontChart<'a, 'b, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The trains of a front: the best for each pulse count as a line, every train as a
/// circle (filled green where its FTI equals the reference's), every 10 Hz train's last
/// point named.
fn draw_trains<DB: DrawingBackend>(
    chart: &mut FrontChart<'_, '_, DB>,
    verdict: &fes_bench::cft::FrontVerdict,
    e: &dyn Fn(&dyn std::fmt::Display) -> PlotError,
) -> Result<(), PlotError> {
    let reference = verdict.reference_fti_per_contraction;
    let equal = |p: &fes_bench::cft::FrontPoint| {
        (p.fti_per_contraction - reference).abs() <= fes_bench::cft::EQUAL_FTI * reference
    };
    // The lower envelope: the best train for each pulse count.
    let mut best: std::collections::BTreeMap<u64, f64> = std::collections::BTreeMap::new();
    for p in &verdict.cft_front {
        let k = p.pulses_per_contraction.round() as u64;
        let b = best.entry(k).or_insert(f64::INFINITY);
        *b = b.min(p.rms_error);
    }
    let line: Vec<(f64, f64)> = best.iter().map(|(&k, &r)| (k as f64, r)).collect();
    chart
        .draw_series(LineSeries::new(line, BLUE.stroke_width(2)))
        .map_err(|x| e(&x))?
        .label("CFT(f, n), 5-100 Hz: the best train for each pulse count")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(1)));
    chart
        .draw_series(verdict.cft_front.iter().map(|p| {
            if equal(p) {
                Circle::new((p.pulses_per_contraction, p.rms_error), 5, GREEN.filled())
            } else {
                Circle::new(
                    (p.pulses_per_contraction, p.rms_error),
                    3,
                    BLUE.stroke_width(1),
                )
            }
        }))
        .map_err(|x| e(&x))?;
    chart
        .draw_series(
            verdict
                .cft_front
                .iter()
                .filter(|p| {
                    p.hz.is_some_and(|h| h % 10 == 0)
                        && !verdict.cft_front.iter().any(|q| q.hz == p.hz && q.n > p.n)
                })
                .map(|p| {
                    Text::new(
                        format!("{} Hz", p.hz.unwrap_or(0)),
                        (p.pulses_per_contraction, p.rms_error),
                        ("sans-serif", 13),
                    )
                }),
        )
        .map_err(|x| e(&x))?;
    Ok(())
}

/// The pattern generator's point (red) and the other runs' (orange), each in the legend.
fn draw_runs<DB: DrawingBackend>(
    chart: &mut FrontChart<'_, '_, DB>,
    verdict: &fes_bench::cft::FrontVerdict,
    others: &[(&str, &fes_bench::cft::FrontPoint)],
    e: &dyn Fn(&dyn std::fmt::Display) -> PlotError,
) -> Result<(), PlotError> {
    let l = &verdict.lcn;
    chart
        .draw_series(std::iter::once(Circle::new(
            (l.pulses_per_contraction, l.rms_error),
            7,
            RED.filled(),
        )))
        .map_err(|x| e(&x))?
        .label(format!(
            "pattern generator: {:.2} pulses, RMS {:.4}{}",
            l.pulses_per_contraction,
            l.rms_error,
            if verdict.lcn_dominated {
                " (dominated)"
            } else {
                ""
            }
        ))
        .legend(|(x, y)| Circle::new((x + 10, y), 5, RED.filled()));
    for (label, p) in others {
        chart
            .draw_series(std::iter::once(Circle::new(
                (p.pulses_per_contraction, p.rms_error),
                7,
                RGBColor(230, 120, 0).filled(),
            )))
            .map_err(|x| e(&x))?
            .label(format!(
                "{label}: {:.2} pulses, RMS {:.4}",
                p.pulses_per_contraction, p.rms_error
            ))
            .legend(|(x, y)| Circle::new((x + 10, y), 5, RGBColor(230, 120, 0).filled()));
    }
    Ok(())
}
