//! A time series' pulse strip and panel: the strip's pulses stand over the panel's time
//! axis.

use plotters::element::PointCollection;
use plotters::prelude::*;

use fes_figure::{pulse_mark, pulse_strip, time_panel};

#[test]
fn strip_and_panel_share_the_time_axis() {
    let (w, h) = (900u32, 500u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
    let (upper, lower) = root.split_vertically(90);
    let strip = pulse_strip(&upper)
        .build_cartesian_2d(0.0..4.0, 0.0..1.2)
        .unwrap();
    let panel = time_panel(&lower)
        .build_cartesian_2d(0.0..4.0, -0.05..1.1)
        .unwrap();
    let (sx, sy) = strip.plotting_area().get_pixel_range();
    let (px, py) = panel.plotting_area().get_pixel_range();
    assert_eq!(sx, px, "the strip's and the panel's x pixels");
    // 10 px left margin and a 70 px y label area; 20 px right margin.
    assert_eq!((px.start, px.end), (80, w as i32 - 20));
    // The strip has no x label area: its plot reaches the bottom of its area.
    assert_eq!(sy.end, 90);
    // The panel leaves a 40 px x label area and a 5 px margin below its plot.
    assert_eq!(py.end, h as i32 - 45);
    // The same time lands on the same column in both.
    assert_eq!(
        strip.backend_coord(&(2.5, 0.0)).0,
        panel.backend_coord(&(2.5, 0.0)).0
    );
}

#[test]
fn a_pulse_is_a_stroke_from_0_to_1() {
    let mark = pulse_mark(2.5);
    let points: Vec<(f64, f64)> = (&mark).point_iter().to_vec();
    assert_eq!(points, [(2.5, 0.0), (2.5, 1.0)]);
}
