//! Plotting helpers of the analysis commands (plotters, PNG or SVG by the file's extension): figures made of line panels
//! arranged in columns, and FTIpP heat maps.
//!
//! Values outside a panel's range are clamped to its edge (a diverging simulation runs along
//! the border instead of vanishing); non-finite values break a line.

use std::ops::Range;
use std::path::Path;

use anyhow::{Context, Result, anyhow};
use fes_figure::TAB10;
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// Shading of extrapolated ranges (orange).
pub const EXTRAPOLATION_BAND: RGBColor = RGBColor(255, 150, 0);
/// Shading of ranges where a model is unstable (tab10's red).
pub const UNSTABLE_BAND: RGBColor = TAB10[3];

/// `c` mixed with white: `f` = 0 keeps it, 1 gives white (opaque, so PNGs stay small).
pub fn lighten(c: RGBColor, f: f64) -> RGBColor {
    let m = |v: u8| (v as f64 + (255.0 - v as f64) * f).round() as u8;
    RGBColor(m(c.0), m(c.1), m(c.2))
}

/// Colour number `i` of the tab10 palette (wrapping): distinguishable line colours.
pub fn color(i: usize) -> RGBColor {
    TAB10[i % TAB10.len()]
}

/// A polyline.
#[derive(Debug, Clone)]
pub struct Line {
    /// Legend entry (none: not in the legend).
    pub label: Option<String>,
    /// Points (x, y).
    pub points: Vec<(f64, f64)>,
    /// Colour.
    pub color: RGBColor,
    /// Dashed instead of solid.
    pub dashed: bool,
    /// Stroke width, px.
    pub width: u32,
}

impl Line {
    /// A solid 2 px line.
    pub fn new(label: impl Into<Option<String>>, points: Vec<(f64, f64)>, color: RGBColor) -> Self {
        Self {
            label: label.into(),
            points,
            color,
            dashed: false,
            width: 2,
        }
    }

    /// The same line dashed.
    pub fn dashed(mut self) -> Self {
        self.dashed = true;
        self
    }
}

/// Markers at points.
#[derive(Debug, Clone)]
pub struct Markers {
    /// Legend entry.
    pub label: Option<String>,
    /// Points.
    pub points: Vec<(f64, f64)>,
    /// Colour.
    pub color: RGBColor,
    /// Radius, px.
    pub size: u32,
    /// Filled circles (else crosses).
    pub filled: bool,
}

/// A shaded x interval (e.g. an extrapolation region).
#[derive(Debug, Clone)]
pub struct Band {
    /// From x.
    pub x0: f64,
    /// To x.
    pub x1: f64,
    /// Colour (drawn with transparency).
    pub color: RGBColor,
    /// Legend entry.
    pub label: Option<String>,
}

/// One chart.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    /// Caption above the chart.
    pub title: Option<String>,
    /// x axis description.
    pub x_label: String,
    /// y axis description.
    pub y_label: String,
    /// x range (default: the data's).
    pub x: Option<(f64, f64)>,
    /// y range (default: the data's, padded).
    pub y: Option<(f64, f64)>,
    /// Lines.
    pub lines: Vec<Line>,
    /// Marker sets.
    pub markers: Vec<Markers>,
    /// Shaded x intervals.
    pub bands: Vec<Band>,
    /// Vertical strokes from y = 0 to y = 1 at these x (pulses).
    pub impulses: Vec<f64>,
    /// Thin vertical separators at these x.
    pub separators: Vec<f64>,
    /// Text (x, y, text) in data coordinates.
    pub texts: Vec<(f64, f64, String)>,
    /// A horizontal reference line at this y.
    pub hline: Option<f64>,
    /// Draw the legend (when some element has a label).
    pub legend: bool,
    /// Number of y tick labels (default: plotters' choice).
    pub y_ticks: Option<usize>,
    /// A strip without caption and x axis (e.g. pulses above a force panel).
    pub compact: bool,
}

/// Panels arranged in columns; each panel has a relative height within its column.
#[derive(Debug, Clone, Default)]
pub struct Figure {
    /// Title over the whole figure.
    pub title: String,
    /// Columns of (relative height, panel).
    pub columns: Vec<Vec<(u32, Panel)>>,
}

fn finite_range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.filter(|v| v.is_finite()).fold(None, |r, v| match r {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

fn padded((lo, hi): (f64, f64), frac: f64) -> (f64, f64) {
    let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
    (lo - frac * span, hi + frac * span)
}

impl Panel {
    /// The points of the lines and the markers, which both axes' default ranges span.
    fn points(&self) -> impl Iterator<Item = &(f64, f64)> {
        let lines = self.lines.iter().flat_map(|l| &l.points);
        lines.chain(self.markers.iter().flat_map(|m| &m.points))
    }

    fn ranges(&self) -> (Range<f64>, Range<f64>) {
        let xs = self
            .points()
            .map(|p| p.0)
            .chain(self.impulses.iter().copied());
        let x = self.x.or_else(|| finite_range(xs)).unwrap_or((0.0, 1.0));
        let x = if x.1 > x.0 { x } else { padded(x, 0.05) };
        let ys = self
            .points()
            .map(|p| p.1)
            .chain(self.hline)
            .chain((!self.impulses.is_empty()).then_some(1.0));
        let y = self
            .y
            .unwrap_or_else(|| padded(finite_range(ys).unwrap_or((0.0, 1.0)), 0.05));
        (x.0..x.1, y.0..y.1)
    }
}

/// Splits `points` at non-finite values and clamps them into the ranges (y slightly beyond).
fn segments(points: &[(f64, f64)], x: &Range<f64>, y: &Range<f64>) -> Vec<Vec<(f64, f64)>> {
    let margin = 0.005 * (y.end - y.start);
    let (lo, hi) = (y.start - margin, y.end + margin);
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for &(px, py) in points {
        if px.is_finite() && py.is_finite() {
            cur.push((px.clamp(x.start, x.end), py.clamp(lo, hi)));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// A panel's chart: linear axes over f64 ranges.
type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A plotters error as the commands report it.
fn drawing_failed(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing failed: {e}")
}

/// Draws one panel into `area`: axes, then (bottom to top) shaded bands, the reference
/// line, separators, impulses, lines, markers, texts and the legend.
fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &Panel) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let (xr, yr) = p.ranges();
    let chart = panel_chart(area, p, &xr, &yr)?;
    let mut steps = PanelChart { chart, p, xr, yr };
    steps.bands()?;
    steps.guides()?;
    steps.lines()?;
    steps.markers()?;
    let chart = &mut steps.chart;
    for (x, y, t) in &p.texts {
        chart
            .draw_series(std::iter::once(Text::new(
                t.clone(),
                (*x, *y),
                ("sans-serif", 13),
            )))
            .map_err(drawing_failed)?;
    }
    let labelled = p.lines.iter().any(|l| l.label.is_some())
        || p.markers.iter().any(|m| m.label.is_some())
        || p.bands.iter().any(|b| b.label.is_some());
    if p.legend && labelled {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font(("sans-serif", 12))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(drawing_failed)?;
    }
    Ok(())
}

/// The panel's chart over `xr` x `yr` with its caption, axes and grid drawn (a compact
/// panel has neither caption nor x axis).
fn panel_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    p: &Panel,
    xr: &Range<f64>,
    yr: &Range<f64>,
) -> Result<Chart<'a, DB>>
where
    DB::ErrorType: 'static,
{
    let mut builder = ChartBuilder::on(area);
    builder
        .margin(if p.compact { 2 } else { 8 })
        .margin_right(16)
        .x_label_area_size(if p.compact { 0 } else { 38 })
        .y_label_area_size(62);
    if let (Some(t), false) = (&p.title, p.compact) {
        builder.caption(t, ("sans-serif", 15));
    }
    let mut chart = builder
        .build_cartesian_2d(xr.clone(), yr.clone())
        .map_err(drawing_failed)?;
    let mut mesh = chart.configure_mesh();
    if p.compact {
        mesh.disable_x_axis().disable_x_mesh();
    }
    mesh.y_labels(p.y_ticks.unwrap_or(10))
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(225, 225, 225))
        .x_desc(p.x_label.as_str())
        .y_desc(p.y_label.as_str())
        .label_style(("sans-serif", 12))
        .axis_desc_style(("sans-serif", 13))
        .x_label_formatter(&|v| fmt_tick(*v))
        .y_label_formatter(&|v| fmt_tick(*v))
        .draw()
        .map_err(drawing_failed)?;
    Ok(chart)
}

/// A panel's chart over its ranges `xr` x `yr`: what each of [`draw_panel`]'s steps draws on.
struct PanelChart<'a, 'p, DB: DrawingBackend> {
    chart: Chart<'a, DB>,
    p: &'p Panel,
    xr: Range<f64>,
    yr: Range<f64>,
}

impl<DB: DrawingBackend> PanelChart<'_, '_, DB>
where
    DB::ErrorType: 'static,
{
    /// The shaded x intervals, clipped to `xr`, over the whole height.
    fn bands(&mut self) -> Result<()> {
        let Self { chart, p, xr, yr } = self;
        for b in &p.bands {
            let x0 = b.x0.max(xr.start);
            let x1 = b.x1.min(xr.end);
            if x1 <= x0 {
                continue;
            }
            let color = b.color;
            let s = chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(x0, yr.start), (x1, yr.end)],
                    lighten(color, 0.8).filled(),
                )))
                .map_err(drawing_failed)?;
            if let Some(l) = &b.label {
                s.label(l.as_str()).legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 18, y + 5)], lighten(color, 0.6).filled())
                });
            }
        }
        Ok(())
    }

    /// The horizontal reference line, the vertical separators and the impulses (pulses).
    fn guides(&mut self) -> Result<()> {
        let Self { chart, p, xr, yr } = self;
        if let Some(h) = p.hline {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(xr.start, h), (xr.end, h)],
                    BLACK.mix(0.4).stroke_width(1),
                )))
                .map_err(drawing_failed)?;
        }
        for &x in &p.separators {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x, yr.start), (x, yr.end)],
                    BLACK.mix(0.3).stroke_width(1),
                )))
                .map_err(drawing_failed)?;
        }
        chart
            .draw_series(p.impulses.iter().map(|&x| fes_figure::pulse_mark(x)))
            .map_err(drawing_failed)?;
        Ok(())
    }

    /// The lines, split at non-finite points and clamped into the ranges; a labelled line's
    /// first segment carries its legend entry.
    fn lines(&mut self) -> Result<()> {
        let Self { chart, p, xr, yr } = self;
        for l in &p.lines {
            let style = l.color.stroke_width(l.width);
            let mut first = true;
            for seg in segments(&l.points, xr, yr) {
                let anno = if l.dashed {
                    chart
                        .draw_series(DashedLineSeries::new(seg, 7, 5, style))
                        .map_err(drawing_failed)?
                } else {
                    chart
                        .draw_series(LineSeries::new(seg, style))
                        .map_err(drawing_failed)?
                };
                if first && let Some(label) = &l.label {
                    let c = l.color;
                    let dashed = l.dashed;
                    anno.label(label.as_str()).legend(move |(x, y)| {
                        if dashed {
                            PathElement::new(vec![(x, y), (x + 7, y)], c.stroke_width(2))
                        } else {
                            PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2))
                        }
                    });
                }
                first = false;
            }
        }
        Ok(())
    }

    /// The marker sets (filled circles or crosses) at their finite points.
    fn markers(&mut self) -> Result<()> {
        let Self { chart, p, .. } = self;
        for m in &p.markers {
            let (c, size, filled) = (m.color, m.size, m.filled);
            let pts: Vec<(f64, f64)> = m
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            let anno = if filled {
                chart
                    .draw_series(pts.iter().map(|&pt| Circle::new(pt, size, c.filled())))
                    .map_err(drawing_failed)?
            } else {
                chart
                    .draw_series(
                        pts.iter()
                            .map(|&pt| Cross::new(pt, size, c.stroke_width(1))),
                    )
                    .map_err(drawing_failed)?
            };
            if let Some(label) = &m.label {
                anno.label(label.as_str())
                    .legend(move |(x, y)| Circle::new((x + 9, y), size.min(5), c.filled()));
            }
        }
        Ok(())
    }
}

/// A tick label: 4 significant digits, trailing zeros dropped; scientific outside
/// 1e-4..1e5.
fn fmt_tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-4..1e5).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).clamp(0, 8) as usize;
        let s = format!("{v:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{v:.1e}")
    }
}

/// Draws a figure into a PNG or SVG (by `path`'s extension) of `size` pixels.
pub fn save(fig: &Figure, path: &Path, size: (u32, u32)) -> Result<()> {
    let draw = || -> Result<()> {
        workbench::on_figure!(path, size, |root| {
            root.fill(&WHITE).map_err(drawing_failed)?;
            let root = if fig.title.is_empty() {
                root
            } else {
                root.titled(&fig.title, ("sans-serif", 18))
                    .map_err(drawing_failed)?
            };
            let cols = root.split_evenly((1, fig.columns.len().max(1)));
            for (col, area) in fig.columns.iter().zip(cols) {
                let total: u32 = col.iter().map(|(w, _)| *w).sum::<u32>().max(1);
                let (_, h) = area.dim_in_pixel();
                let mut rest = area;
                let mut used = 0;
                for (i, (w, panel)) in col.iter().enumerate() {
                    used += w;
                    let cell = if i + 1 == col.len() {
                        rest.clone()
                    } else {
                        let cut = (h as u64 * *w as u64 / total as u64) as i32;
                        let (a, b) = rest.split_vertically(cut);
                        rest = b;
                        a
                    };
                    draw_panel(&cell, panel)?;
                }
                let _ = used;
            }
            root.present().map_err(drawing_failed)?;
            Ok(())
        })
    };
    draw().with_context(|| format!("writing {}", path.display()))
}

/// A grid of values over (x, y) drawn as coloured cells.
#[derive(Debug, Clone)]
pub struct HeatMap {
    /// Caption.
    pub title: String,
    /// Cell centres along x (increasing, evenly spaced).
    pub xs: Vec<f64>,
    /// Cell centres along y (increasing, evenly spaced).
    pub ys: Vec<f64>,
    /// `z[iy][ix]`.
    pub z: Vec<Vec<f64>>,
    /// x axis description.
    pub x_label: String,
    /// y axis description.
    pub y_label: String,
    /// Cells to mark with a ring and a text (x, y, text).
    pub marks: Vec<(f64, f64, String)>,
}

/// Diverging colour scale: `lo` blue, `mid` white, `hi` red (linear on each side).
pub fn diverging(v: f64, lo: f64, mid: f64, hi: f64) -> RGBColor {
    let (blue, white, red) = (
        (33.0, 102.0, 172.0),
        (247.0, 247.0, 247.0),
        (178.0, 24.0, 43.0),
    );
    let mix = |a: (f64, f64, f64), b: (f64, f64, f64), t: f64| {
        let t = t.clamp(0.0, 1.0);
        RGBColor(
            (a.0 + (b.0 - a.0) * t) as u8,
            (a.1 + (b.1 - a.1) * t) as u8,
            (a.2 + (b.2 - a.2) * t) as u8,
        )
    };
    if !v.is_finite() {
        return RGBColor(0, 0, 0);
    }
    if v < mid {
        mix(white, blue, (mid - v) / (mid - lo).max(1e-12))
    } else {
        mix(white, red, (v - mid) / (hi - mid).max(1e-12))
    }
}

/// How [`save_maps`] draws the grids.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapView {
    /// Flat heat maps with a colour bar; the label names the scale.
    Flat,
    /// 3-D surfaces (thesis Fig. 6.3 style); the label names the height.
    Surface,
}

/// Draws heat maps side by side, flat or as surfaces, with one shared diverging colour
/// scale `lo..mid..hi`; `label` names the value (the colour bar's or the height's).
pub fn save_maps(
    view: MapView,
    maps: &[HeatMap],
    title: &str,
    scale: (f64, f64, f64),
    label: &str,
    path: &Path,
    size: (u32, u32),
) -> Result<()> {
    let draw = || -> Result<()> {
        workbench::on_figure!(path, size, |root| {
            root.fill(&WHITE).map_err(drawing_failed)?;
            let root = root
                .titled(title, ("sans-serif", 18))
                .map_err(drawing_failed)?;
            match view {
                MapView::Flat => {
                    let (maps_area, bar_area) = root.split_horizontally(size.0 as i32 - 110);
                    let areas = maps_area.split_evenly((1, maps.len().max(1)));
                    for (m, area) in maps.iter().zip(areas) {
                        draw_heatmap(&area, m, scale)?;
                    }
                    draw_colour_bar(&bar_area, scale, label)?;
                }
                MapView::Surface => {
                    let areas = root.split_evenly((1, maps.len().max(1)));
                    for (m, area) in maps.iter().zip(areas) {
                        draw_surface(&area, m, scale, label)?;
                    }
                }
            }
            root.present().map_err(drawing_failed)?;
            Ok(())
        })
    };
    draw().with_context(|| format!("writing {}", path.display()))
}

/// One heat map in `area`: a cell per grid value on the diverging scale, the marked cells
/// ringed and labelled.
fn draw_heatmap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    m: &HeatMap,
    (lo, mid, hi): (f64, f64, f64),
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let step = |v: &[f64]| {
        if v.len() > 1 {
            (v[v.len() - 1] - v[0]) / (v.len() - 1) as f64
        } else {
            1.0
        }
    };
    let (dx, dy) = (step(&m.xs), step(&m.ys));
    let (x0, x1) = (m.xs[0] - dx / 2.0, m.xs[m.xs.len() - 1] + dx / 2.0);
    let (y0, y1) = (m.ys[0] - dy / 2.0, m.ys[m.ys.len() - 1] + dy / 2.0);
    let mut chart = ChartBuilder::on(area)
        .margin(8)
        .margin_right(14)
        .caption(&m.title, ("sans-serif", 15))
        .x_label_area_size(38)
        .y_label_area_size(48)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(drawing_failed)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(m.x_label.as_str())
        .y_desc(m.y_label.as_str())
        .y_labels(m.ys.len().min(12))
        .label_style(("sans-serif", 12))
        .axis_desc_style(("sans-serif", 13))
        .x_label_formatter(&|v| fmt_tick(*v))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()
        .map_err(drawing_failed)?;
    let cells =
        m.ys.iter()
            .enumerate()
            .flat_map(|(iy, &y)| m.xs.iter().enumerate().map(move |(ix, &x)| (ix, iy, x, y)));
    chart
        .draw_series(cells.map(|(ix, iy, x, y)| {
            let v = m.z[iy][ix];
            Rectangle::new(
                [(x - dx / 2.0, y - dy / 2.0), (x + dx / 2.0, y + dy / 2.0)],
                diverging(v, lo, mid, hi).filled(),
            )
        }))
        .map_err(drawing_failed)?;
    for (x, y, t) in &m.marks {
        chart
            .draw_series(std::iter::once(Circle::new(
                (*x, *y),
                6,
                BLACK.stroke_width(2),
            )))
            .map_err(drawing_failed)?;
        let tx = if *x > (x0 + x1) / 2.0 {
            x - 0.35 * (x1 - x0)
        } else {
            x + 2.0 * dx
        };
        chart
            .draw_series(std::iter::once(Text::new(
                t.clone(),
                (tx, *y + 0.3 * dy),
                ("sans-serif", 13),
            )))
            .map_err(drawing_failed)?;
    }
    Ok(())
}

/// The colour bar of the diverging scale `lo..mid..hi`, labelled `label`.
fn draw_colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (lo, mid, hi): (f64, f64, f64),
    label: &str,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let mut bar = ChartBuilder::on(area)
        .margin(8)
        .margin_top(40)
        .margin_bottom(46)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(drawing_failed)?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(label)
        .label_style(("sans-serif", 12))
        .axis_desc_style(("sans-serif", 13))
        .y_label_formatter(&|v| format!("{v:.2}"))
        .draw()
        .map_err(drawing_failed)?;
    let n = 100;
    bar.draw_series((0..n).map(|i| {
        let a = lo + (hi - lo) * i as f64 / n as f64;
        let b = lo + (hi - lo) * (i + 1) as f64 / n as f64;
        Rectangle::new(
            [(0.0, a), (1.0, b)],
            diverging(0.5 * (a + b), lo, mid, hi).filled(),
        )
    }))
    .map_err(drawing_failed)?;
    Ok(())
}

/// One heat map's grid in `area` as a 3-D surface coloured with the diverging scale
/// `lo..mid..hi`; `z_label` names the height.
fn draw_surface<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    m: &HeatMap,
    (lo, mid, hi): (f64, f64, f64),
    z_label: &str,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let (x0, x1) = (m.xs[0], m.xs[m.xs.len() - 1]);
    let (z0, z1) = (m.ys[0], m.ys[m.ys.len() - 1]);
    let mut chart = ChartBuilder::on(area)
        .margin(10)
        .caption(
            format!(
                "{}: {} along the front, {} to the right, {z_label} up",
                m.title, m.x_label, m.y_label
            ),
            ("sans-serif", 14),
        )
        .build_cartesian_3d(x0..x1, lo..hi, z0..z1)
        .map_err(drawing_failed)?;
    chart.with_projection(|mut pb| {
        pb.yaw = 0.6;
        pb.pitch = 0.35;
        pb.scale = 0.8;
        pb.into_matrix()
    });
    chart
        .configure_axes()
        .light_grid_style(RGBColor(230, 230, 230))
        .max_light_lines(2)
        .label_style(("sans-serif", 12))
        .x_formatter(&|v| format!("{v:.0}"))
        .z_formatter(&|v| format!("{v:.0}"))
        .y_formatter(&|v| format!("{v:.2}"))
        .draw()
        .map_err(drawing_failed)?;
    let value = |x: f64, z: f64| {
        let ix = m.xs.iter().position(|&v| v == x).unwrap_or(0);
        let iz = m.ys.iter().position(|&v| v == z).unwrap_or(0);
        m.z[iz][ix].clamp(lo, hi)
    };
    let style = |y: &f64| diverging(*y, lo, mid, hi).filled();
    chart
        .draw_series(
            SurfaceSeries::xoz(m.xs.iter().copied(), m.ys.iter().copied(), value)
                .style_func(&style),
        )
        .map_err(drawing_failed)?;
    Ok(())
}
