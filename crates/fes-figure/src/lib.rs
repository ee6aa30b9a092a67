//! The house style of the project's figures (plotters), one place for what heat-transfer's
//! App. E figures, sim-muscle's `plot` and the workbench's (`fes`) draw alike:
//!
//! - [`TAB10`]: the line colours, matplotlib's tab10 palette.
//! - [`pulse_strip`] over [`time_panel`]: a run drawn like thesis Fig. 5.2, the pulses
//!   ([`pulse_mark`]) in a strip above the force. Both have the same left and right margins
//!   and y label area, so the strip's pulses stand over the panel's time axis.
//! - [`by_extension!`]: a figure drawn on plotters' bitmap backend for a `.png` file and on
//!   its SVG backend for a `.svg` file ([`Format`]).
//!
//! It links plotters and nothing of the project; what a figure shows, its sizes and its
//! errors stay with the crate that draws it.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

/// matplotlib's tab10 palette, in its order: blue, orange, green, red, purple, brown, pink,
/// grey, olive, cyan (distinguishable line colours).
pub const TAB10: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Left margin of a time series' strip and panel, px.
const MARGIN_LEFT: i32 = 10;
/// Right margin of a time series' strip and panel, px.
const MARGIN_RIGHT: i32 = 20;
/// Width of the y labels' area left of a time series' strip and panel, px.
const Y_LABEL_AREA: i32 = 70;

/// The builder of the strip above a time series (its pulses, [`pulse_mark`]) on `area`, to
/// build over the strip's ranges: no x label area, and the left and right edges of
/// [`time_panel`]'s plotting area.
pub fn pulse_strip<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
) -> ChartBuilder<'a, 'b, DB> {
    let mut builder = ChartBuilder::on(area);
    builder
        .margin_left(MARGIN_LEFT)
        .margin_right(MARGIN_RIGHT)
        .y_label_area_size(Y_LABEL_AREA);
    builder
}

/// The builder of a time series' panel (below its [`pulse_strip`]) on `area`, to build over
/// the panel's ranges: the strip's edges, with a 40 px x label area and a 5 px margin below.
pub fn time_panel<'a, 'b, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
) -> ChartBuilder<'a, 'b, DB> {
    let mut builder = pulse_strip(area);
    builder.margin_bottom(5).x_label_area_size(40);
    builder
}

/// One pulse at time `t`: a 1 px black stroke from 0 to 1.
pub fn pulse_mark(t: f64) -> PathElement<(f64, f64)> {
    PathElement::new(vec![(t, 0.0), (t, 1.0)], BLACK.stroke_width(1))
}

/// The formats a figure is written in, chosen by its file's extension (plotters has no PDF
/// backend).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Raster (`.png`): plotters' bitmap backend.
    Png,
    /// Vector (`.svg`): plotters' SVG backend.
    Svg,
}

impl Format {
    /// The format of `path` by its extension in any case (`.png`, `.PNG`, `.svg`); `None`
    /// for any other name.
    pub fn of(path: &Path) -> Option<Self> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Some(Self::Png),
            Some("svg") => Some(Self::Svg),
            _ => None,
        }
    }
}

/// The drawing area of a PNG figure of `size` pixels at `path`, written when it is presented.
pub fn png(path: &Path, size: (u32, u32)) -> DrawingArea<BitMapBackend<'_>, Shift> {
    BitMapBackend::new(path, size).into_drawing_area()
}

/// The drawing area of an SVG figure of `size` pixels at `path`, written when it is
/// presented.
pub fn svg(path: &Path, size: (u32, u32)) -> DrawingArea<SVGBackend<'_>, Shift> {
    SVGBackend::new(path, size).into_drawing_area()
}

/// `Some` of `$body` run with `$root` the drawing area of a `$size` figure at `$path` (a
/// `&Path`): [`png`] or [`svg`] by the path's extension ([`Format::of`]); `None`, the body
/// not run, when the path names neither. The body is compiled once per backend; a `?` in
/// it returns from the enclosing function.
#[macro_export]
macro_rules! by_extension {
    ($path:expr, $size:expr, |$root:ident| $body:block) => {{
        let path: &::std::path::Path = $path;
        match $crate::Format::of(path) {
            ::std::option::Option::Some($crate::Format::Png) => {
                let $root = $crate::png(path, $size);
                ::std::option::Option::Some($body)
            }
            ::std::option::Option::Some($crate::Format::Svg) => {
                let $root = $crate::svg(path, $size);
                ::std::option::Option::Some($body)
            }
            ::std::option::Option::None => ::std::option::Option::None,
        }
    }};
}

// The integration tests (tests/it) compile into this crate's one test binary: they use only
// the public API, through the crate's own name (docs/architecture.md, "Tests").
#[cfg(test)]
extern crate self as fes_figure;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;
