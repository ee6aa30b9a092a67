//! Fig. E.1: a sketch of the heat-transfer rig, drawn with plotters as PNG and SVG.
//!
//! Air enters through a throttle valve at the fan inlet (valve angle alpha), is driven by
//! the fan through a tube, is heated by a resistor at the tube input (voltage u), and its
//! temperature is measured by a thermocouple at the outlet (y). The sketch is drawn once
//! for any plotters backend ([`draw_rig`]) and written by [`fig_e1`].

use std::path::Path;

use fes_figure::TAB10;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor;

use crate::StudyError;

/// Width and height of the sketch in pixels.
pub const SIZE: (u32, u32) = (1000, 440);

const WALL: RGBColor = RGBColor(60, 60, 60);
const AIR: RGBColor = TAB10[0];
const HOT: RGBColor = TAB10[3];
const VALVE: RGBColor = TAB10[2];
const SIGNAL: RGBColor = TAB10[4];

/// Centre line of the air path (pixels from the top).
const AXIS: i32 = 250;
/// Half the inner height of the duct and tube.
const HALF: i32 = 40;

type Res<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Where a label's `at` point lies on its text.
#[derive(Clone, Copy)]
enum Anchor {
    /// The text's top left corner.
    TopLeft,
    /// The text's centre.
    Centre,
}

fn text<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    s: &str,
    at: (i32, i32),
    size: u32,
    color: &RGBColor,
    anchor: Anchor,
) -> Res<DB> {
    let style = TextStyle::from(("sans-serif", size).into_font()).color(color);
    let style = match anchor {
        Anchor::TopLeft => style,
        Anchor::Centre => style.pos(text_anchor::Pos::new(
            text_anchor::HPos::Center,
            text_anchor::VPos::Center,
        )),
    };
    root.draw(&Text::new(s.to_string(), at, style))
}

fn path<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    points: Vec<(i32, i32)>,
    color: &RGBColor,
    width: u32,
) -> Res<DB> {
    root.draw(&PathElement::new(points, color.stroke_width(width)))
}

/// An arrow from `from` to `to` with a filled head.
fn arrow<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    from: (i32, i32),
    to: (i32, i32),
    color: &RGBColor,
) -> Res<DB> {
    path(root, vec![from, to], color, 3)?;
    let (dx, dy) = ((to.0 - from.0) as f64, (to.1 - from.1) as f64);
    let len = dx.hypot(dy).max(1.0);
    let (ux, uy) = (dx / len, dy / len);
    let back = |s: f64, side: f64| {
        (
            (to.0 as f64 - 12.0 * ux + side * s * uy).round() as i32,
            (to.1 as f64 - 12.0 * uy - side * s * ux).round() as i32,
        )
    };
    root.draw(&Polygon::new(
        vec![to, back(6.0, 1.0), back(6.0, -1.0)],
        color.filled(),
    ))
}

/// Draws the sketch on `root` (of [`SIZE`]).
pub fn draw_rig<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> Res<DB> {
    root.fill(&WHITE)?;
    text(
        root,
        "Fig. E.1: the heat-transfer process (sim-heat)",
        (500, 24),
        22,
        &BLACK,
        Anchor::Centre,
    )?;
    let (top, bottom) = (AXIS - HALF, AXIS + HALF);

    // Air in, through the inlet duct with the throttle valve.
    draw_inlet(root, top, bottom)?;

    // The fan: a housing and four blades.
    let (fx, fy, fr) = (290, AXIS, 58);
    draw_fan(root, (fx, fy), fr)?;

    // The tube, from the fan to the outlet.
    let (t0, t1) = (fx + fr - 8, 890);
    for y in [top, bottom] {
        path(root, vec![(t0, y), (t1, y)], &WALL, 4)?;
    }
    text(root, "tube", (640, bottom + 22), 17, &BLACK, Anchor::Centre)?;

    // The heating resistor at the tube input, across the air stream, fed with u.
    let rx = 405;
    draw_resistor(root, rx, top, bottom)?;

    // Air in the tube: cool before the resistor, heated after it.
    arrow(root, (t0 + 12, AXIS), (rx - 18, AXIS), &AIR)?;
    for x in [470, 590, 710] {
        arrow(root, (x, AXIS), (x + 80, AXIS), &HOT)?;
    }

    // The thermocouple at the outlet, read as y.
    draw_thermocouple(root, top)?;

    // Air out.
    arrow(root, (t1 + 5, AXIS), (975, AXIS), &HOT)?;
    text(root, "air out", (940, AXIS + 22), 16, &HOT, Anchor::Centre)?;

    // What the sketch means for the model.
    draw_notes(root)?;
    root.present()
}

/// Draws the air inlet: the duct with the throttle valve at angle alpha.
fn draw_inlet<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, top: i32, bottom: i32) -> Res<DB> {
    arrow(root, (20, AXIS), (95, AXIS), &AIR)?;
    text(root, "air in", (55, AXIS + 22), 16, &AIR, Anchor::Centre)?;
    for y in [top, bottom] {
        path(root, vec![(100, y), (230, y)], &WALL, 4)?;
    }
    // The valve plate at an angle: a thick line through the duct's centre.
    let (vx, vy) = (165, AXIS);
    let alpha_draw = 50f64.to_radians(); // drawn angle, from the duct's cross-section
    let half = (HALF - 4) as f64;
    let (sx, sy) = (half * alpha_draw.sin(), half * alpha_draw.cos());
    path(
        root,
        vec![
            ((vx as f64 - sx) as i32, (vy as f64 + sy) as i32),
            ((vx as f64 + sx) as i32, (vy as f64 - sy) as i32),
        ],
        &VALVE,
        6,
    )?;
    root.draw(&Circle::new((vx, vy), 4, VALVE.filled()))?;
    // alpha: the arc from the closed position (across the duct) to the plate.
    let arc: Vec<(i32, i32)> = (0..=20)
        .map(|k| {
            let a = alpha_draw * k as f64 / 20.0;
            (
                (vx as f64 + 26.0 * a.sin()) as i32,
                (vy as f64 - 26.0 * a.cos()) as i32,
            )
        })
        .collect();
    path(root, vec![(vx, vy), (vx, vy - 34)], &VALVE, 1)?;
    path(root, arc, &VALVE, 2)?;
    text(root, "α", (vx + 24, vy - 38), 22, &VALVE, Anchor::TopLeft)?;
    text(
        root,
        "throttle valve",
        (vx, top - 70),
        17,
        &VALVE,
        Anchor::Centre,
    )?;
    text(
        root,
        "angle α: 20° nearly closed … 120° open",
        (vx, top - 50),
        15,
        &VALVE,
        Anchor::Centre,
    )?;
    Ok(())
}

/// Draws the fan: a housing of radius `fr` around `(fx, fy)` and four blades.
fn draw_fan<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    (fx, fy): (i32, i32),
    fr: i32,
) -> Res<DB> {
    root.draw(&Circle::new((fx, fy), fr, WALL.stroke_width(4)))?;
    for k in 0..4 {
        let a = std::f64::consts::FRAC_PI_2 * k as f64 + 0.3;
        let tip = (
            (fx as f64 + 44.0 * a.cos()) as i32,
            (fy as f64 + 44.0 * a.sin()) as i32,
        );
        let side = (
            (fx as f64 + 30.0 * (a + 0.6).cos()) as i32,
            (fy as f64 + 30.0 * (a + 0.6).sin()) as i32,
        );
        root.draw(&Polygon::new(
            vec![(fx, fy), tip, side],
            RGBColor(150, 150, 150).filled(),
        ))?;
    }
    root.draw(&Circle::new((fx, fy), 7, WALL.filled()))?;
    text(root, "fan", (fx, fy + fr + 20), 17, &BLACK, Anchor::Centre)?;
    Ok(())
}

/// Draws the heating resistor at `rx` across the tube, fed with the voltage u.
fn draw_resistor<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    rx: i32,
    top: i32,
    bottom: i32,
) -> Res<DB> {
    let zig: Vec<(i32, i32)> = (0..=8)
        .map(|k| {
            let x = if k == 0 || k == 8 {
                rx
            } else if k % 2 == 1 {
                rx - 10
            } else {
                rx + 10
            };
            (x, top + 4 + k * (2 * HALF - 8) / 8)
        })
        .collect();
    path(root, zig, &HOT, 3)?;
    let (ux, uy) = (rx, 115);
    // Wires: the top end to the source, the bottom end to ground below the tube.
    path(root, vec![(rx, top + 4), (rx, uy + 20)], &HOT, 2)?;
    path(root, vec![(rx, bottom - 4), (rx, bottom + 22)], &HOT, 2)?;
    for (k, w) in [14, 9, 4].into_iter().enumerate() {
        let y = bottom + 22 + 5 * k as i32;
        path(root, vec![(rx - w, y), (rx + w, y)], &HOT, 2)?;
    }
    root.draw(&Circle::new((ux, uy), 20, HOT.stroke_width(3)))?;
    text(root, "u", (ux, uy), 22, &HOT, Anchor::Centre)?;
    text(
        root,
        "heating resistor, voltage u (0 … 10 V)",
        (ux + 30, uy - 8),
        17,
        &HOT,
        Anchor::TopLeft,
    )?;
    text(
        root,
        "heat ∝ u²",
        (ux + 30, uy + 14),
        15,
        &HOT,
        Anchor::TopLeft,
    )?;
    Ok(())
}

/// Draws the thermocouple at the outlet, read as the output y.
fn draw_thermocouple<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, top: i32) -> Res<DB> {
    let (cx, cy) = (850, AXIS);
    path(root, vec![(cx, cy), (cx, top - 6)], &SIGNAL, 3)?;
    root.draw(&Circle::new((cx, cy), 6, SIGNAL.filled()))?;
    path(root, vec![(cx, top - 6), (cx, 135)], &SIGNAL, 2)?;
    root.draw(&Rectangle::new(
        [(cx - 22, 95), (cx + 22, 135)],
        SIGNAL.stroke_width(3),
    ))?;
    text(root, "y", (cx, 115), 22, &SIGNAL, Anchor::Centre)?;
    text(
        root,
        "thermocouple: outlet temperature y",
        (cx - 60, 70),
        17,
        &SIGNAL,
        Anchor::Centre,
    )?;
    Ok(())
}

/// Writes what the sketch means for the model under it.
fn draw_notes<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>) -> Res<DB> {
    text(
        root,
        "inputs α, u; output y; sampled every 50 ms. Opening the valve moves more air: \
         lower gain u → y, shorter delay, faster response.",
        (500, 395),
        15,
        &BLACK,
        Anchor::Centre,
    )?;
    text(
        root,
        "The delay u → y is the resistor's conduction plus the air's transit to the thermocouple.",
        (500, 418),
        15,
        &BLACK,
        Anchor::Centre,
    )?;
    Ok(())
}

/// Writes Fig. E.1 as `fig-e1.png` and `fig-e1.svg` into `dir`.
pub fn fig_e1(dir: &Path) -> Result<(), StudyError> {
    let fail = |path: &Path, e: &dyn std::fmt::Display| StudyError::Figure {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let png = dir.join("fig-e1.png");
    draw_rig(&BitMapBackend::new(&png, SIZE).into_drawing_area()).map_err(|e| fail(&png, &e))?;
    let svg = dir.join("fig-e1.svg");
    draw_rig(&SVGBackend::new(&svg, SIZE).into_drawing_area()).map_err(|e| fail(&svg, &e))?;
    Ok(())
}
