//! Latency-by-percentile curves (HdrHistogram style): the x axis is `1 / (1 - q)` on a log
//! scale, labelled as percentiles (90 %, 99 %, 99.9 %, ...), the y axis latency in µs on
//! a log scale; one panel per load condition.

use std::path::Path;

use anyhow::{Context, anyhow};
use fes_rt::rt::histogram::LatencyHistogram;
use plotters::prelude::*;

/// One named curve.
pub struct Curve {
    /// Legend text.
    pub name: String,
    /// The samples.
    pub histogram: LatencyHistogram,
}

/// One panel: a title and its curves.
pub struct Panel {
    /// Title (the condition).
    pub title: String,
    /// Curves drawn in it.
    pub curves: Vec<Curve>,
}

/// Points per decade of `1 / (1 - q)`.
const POINTS_PER_DECADE: u32 = 20;

/// The curve's points `(1 / (1 - q), latency µs)` from q = 0 up to the percentile its
/// sample count resolves (`1 / (1 - q) <= count`), then the maximum.
pub fn percentile_points(h: &LatencyHistogram) -> Vec<(f64, f64)> {
    let count = h.count();
    if count == 0 {
        return Vec::new();
    }
    let mut points = Vec::new();
    let mut k = 0;
    loop {
        let x = 10f64.powf(f64::from(k) / f64::from(POINTS_PER_DECADE));
        if x > count as f64 {
            break;
        }
        let q = 1.0 - 1.0 / x;
        points.push((x, (h.quantile_ns(q) as f64 / 1000.0).max(0.01)));
        k += 1;
    }
    points.push((count as f64, (h.max_ns() as f64 / 1000.0).max(0.01)));
    points
}

fn percentile_label(x: f64) -> String {
    let q = 100.0 * (1.0 - 1.0 / x);
    if x < 1.5 {
        "0%".to_owned()
    } else {
        let decimals = (x.log10().round() as i32 - 2).max(0) as usize;
        format!("{q:.decimals$}%")
    }
}

/// Draws the panels side by side into the PNG `out`.
pub fn draw(panels: &[Panel], out: &Path) -> anyhow::Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: drawing failed: {e}", out.display());
    let width = 700 * panels.len().max(1) as u32;
    let root = BitMapBackend::new(out, (width, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let areas = root.split_evenly((1, panels.len().max(1)));
    let colours = [RED, BLUE, RGBColor(0, 140, 0), BLACK];
    for (panel, area) in panels.iter().zip(areas.iter()) {
        let series: Vec<(&Curve, Vec<(f64, f64)>)> = panel
            .curves
            .iter()
            .map(|c| (c, percentile_points(&c.histogram)))
            .collect();
        let x_max = series
            .iter()
            .flat_map(|(_, p)| p.iter().map(|&(x, _)| x))
            .fold(10.0, f64::max)
            * 1.5;
        let (y_min, y_max) = series
            .iter()
            .flat_map(|(_, p)| p.iter().map(|&(_, y)| y))
            .fold((f64::INFINITY, 1.0f64), |(lo, hi), y| {
                (lo.min(y), hi.max(y))
            });
        let y_min = if y_min.is_finite() { y_min / 1.5 } else { 0.1 };
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((1.0..x_max).log_scale(), (y_min..y_max * 1.5).log_scale())
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("percentile")
            .y_desc("latency (µs)")
            .x_label_formatter(&|x| percentile_label(*x))
            .draw()
            .map_err(|e| err(&e))?;
        for (i, (curve, points)) in series.into_iter().enumerate() {
            let colour = colours[i % colours.len()];
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(curve.name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present()
        .with_context(|| format!("writing {}", out.display()))
}
