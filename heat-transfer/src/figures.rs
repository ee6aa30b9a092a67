//! The thesis's App. E figures redrawn (PNG), from the same study the tables come from:
//!
//! - `fig-e1.png`, `fig-e1.svg`: the rig's sketch ([`crate::rig`]).
//! - `fig-e2-e3-<experiment>.png`: one record of each E.2 experiment (alpha, u, y).
//! - `fig-e4.png`: responses to the 4 V step at the five test angles, (a) 15 s, (b) the
//!   first second (the delays of Table E.1).
//! - `fig-e5.png`: responses to steps of the valve angle.
//! - `fig-e6.png`: the state-space networks' eigenvector directions per unit.
//! - `fig-e7-5.png`, `fig-e7-10.png`: the networks frozen over phi: activations, G_u and
//!   G_alpha, the pole.
//! - `fig-e8a.png`, `fig-e8b.png`, `fig-e8-process.png`: the LCN and the linear controller
//!   at alpha = 0.1, 0.5, 0.9 on the design model, the E.4.4 model and the process.

use std::collections::BTreeMap;
use std::path::Path;

use fes_figure::TAB10;
use fes_ident::ident::miso;
use fes_model::control::io_design::PolyLcn;
use fes_model::model::miso::MisoArx;
use plotters::prelude::*;
use sim_heat::experiment::{Experiment, Normalisation, all_records};
use sim_heat::plant::{HeatParams, HeatPlant, TEST_ANGLES_DEG};

use crate::control::{ControlStudy, PlantModel, RISE_LINEAR_S, scheduled_rise, step_response};
use crate::{SsRow, StudyError};

/// One line of a panel.
struct Series {
    label: String,
    points: Vec<(f64, f64)>,
    color: RGBColor,
    dashed: bool,
}

/// One panel: axis labels and its lines.
struct Panel {
    y_label: String,
    x_label: String,
    series: Vec<Series>,
}

/// The lines' colours, in the order the figures number them: tab10's blue, red, green,
/// purple, orange and cyan.
const COLORS: [RGBColor; 6] = [TAB10[0], TAB10[3], TAB10[2], TAB10[4], TAB10[1], TAB10[9]];

fn draw_error(path: &Path, e: impl std::fmt::Display) -> StudyError {
    StudyError::Figure {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// Panels stacked vertically into a PNG file.
fn draw(path: &Path, title: &str, panels: &[Panel]) -> Result<(), StudyError> {
    let height = 60 + 260 * panels.len() as u32;
    let root = BitMapBackend::new(path, (900, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_error(path, e))?;
    let root = root
        .titled(title, ("sans-serif", 22))
        .map_err(|e| draw_error(path, e))?;
    let areas = root.split_evenly((panels.len(), 1));
    for (area, panel) in areas.iter().zip(panels) {
        let all = panel.series.iter().flat_map(|s| s.points.iter());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, y) in all {
            if x.is_finite() && y.is_finite() {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
        if x0 >= x1 {
            (x0, x1) = (0.0, 1.0);
        }
        let pad = ((y1 - y0) * 0.08).max(1e-3);
        let (y0, y1) = if y0 <= y1 {
            (y0 - pad, y1 + pad)
        } else {
            (0.0, 1.0)
        };
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| draw_error(path, e))?;
        chart
            .configure_mesh()
            .max_light_lines(0)
            .x_desc(panel.x_label.as_str())
            .y_desc(panel.y_label.as_str())
            .draw()
            .map_err(|e| draw_error(path, e))?;
        for s in &panel.series {
            let style = ShapeStyle::from(&s.color).stroke_width(2);
            let drawn = if s.dashed {
                chart.draw_series(DashedLineSeries::new(s.points.iter().copied(), 6, 4, style))
            } else {
                chart.draw_series(LineSeries::new(s.points.iter().copied(), style))
            }
            .map_err(|e| draw_error(path, e))?;
            if !s.label.is_empty() {
                let c = s.color;
                drawn
                    .label(s.label.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c));
            }
        }
        if panel.series.iter().any(|s| !s.label.is_empty()) {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| draw_error(path, e))?;
        }
    }
    root.present().map_err(|e| draw_error(path, e))
}

fn line(label: impl Into<String>, points: Vec<(f64, f64)>, i: usize, dashed: bool) -> Series {
    Series {
        label: label.into(),
        points,
        color: COLORS[i % COLORS.len()],
        dashed,
    }
}

fn timed(v: &[f64], ts: f64) -> Vec<(f64, f64)> {
    v.iter()
        .enumerate()
        .map(|(k, y)| (k as f64 * ts, *y))
        .collect()
}

/// Draws every figure into `dir` (created if needed).
pub fn draw_all(
    dir: &Path,
    p: &HeatParams,
    seed: u64,
    sims: &BTreeMap<(usize, &str), MisoArx>,
    e44: &MisoArx,
    cs: &ControlStudy,
    state_space: &[SsRow],
) -> Result<(), StudyError> {
    std::fs::create_dir_all(dir).map_err(|e| draw_error(dir, e))?;
    crate::rig::fig_e1(dir)?;
    fig_e2_e3(dir, p, seed)?;
    // Figs. E.4-E.5: noise-free, normalised.
    let norm = Normalisation::of(p);
    let clean = HeatParams {
        noise_std_k: 0.0,
        ..*p
    };
    fig_e4(dir, clean, &norm)?;
    fig_e5(dir, clean, &norm)?;
    fig_e6(dir, state_space)?;
    fig_e7(dir, sims)?;
    fig_e8(dir, p, e44, cs)
}

/// Draws Figs. E.2-E.3: the first record of each E.2 experiment (alpha, u, y).
fn fig_e2_e3(dir: &Path, p: &HeatParams, seed: u64) -> Result<(), StudyError> {
    let ts = p.ts_s;
    let recs = all_records(p, seed)?;
    for e in Experiment::ALL {
        if let Some(r) = recs.iter().find(|r| r.experiment == e) {
            let panel = |name: &str, v: &[f64], i| Panel {
                y_label: format!("{name} (normalised)"),
                x_label: "t (s)".into(),
                series: vec![line("", timed(v, ts), i, false)],
            };
            draw(
                &dir.join(format!("fig-e2-e3-{}.png", e.name())),
                &format!("Figs. E.2-E.3: {} ({})", e.name(), r.name),
                &[
                    panel("valve angle alpha", &r.alpha, 0),
                    panel("voltage u", &r.u, 1),
                    panel("temperature y", &r.y, 2),
                ],
            )?;
        }
    }
    Ok(())
}

/// Draws Fig. E.4: the responses to a 3 -> 7 V step at each test angle (15 s and 1 s).
fn fig_e4(dir: &Path, clean: HeatParams, norm: &Normalisation) -> Result<(), StudyError> {
    let ts = clean.ts_s;
    let mut long = Vec::new();
    let mut short = Vec::new();
    for (i, &deg) in TEST_ANGLES_DEG.iter().enumerate() {
        let mut plant = HeatPlant::new(clean, 0, deg)?;
        plant.settle(deg, 3.0);
        let y: Vec<f64> = (0..300).map(|_| norm.y(plant.step(deg, 7.0))).collect();
        long.push(line(format!("{deg} deg"), timed(&y, ts), i, false));
        short.push(line(format!("{deg} deg"), timed(&y[..21], ts), i, false));
    }
    draw(
        &dir.join("fig-e4.png"),
        "Fig. E.4: response to a 4 V step (3 -> 7 V at t = 0)",
        &[
            Panel {
                y_label: "y (normalised)".into(),
                x_label: "t (s)".into(),
                series: long,
            },
            Panel {
                y_label: "y (normalised)".into(),
                x_label: "t (s), first second".into(),
                series: short,
            },
        ],
    )?;
    Ok(())
}

/// Draws Fig. E.5: the responses to steps of the valve angle at 6 V.
fn fig_e5(dir: &Path, clean: HeatParams, norm: &Normalisation) -> Result<(), StudyError> {
    let ts = clean.ts_s;
    let mut steps = Vec::new();
    for (i, (from, to)) in [(60.0, 90.0), (90.0, 40.0)].into_iter().enumerate() {
        let mut plant = HeatPlant::new(clean, 0, from)?;
        plant.settle(from, 6.0);
        let y: Vec<f64> = (0..160).map(|_| norm.y(plant.step(to, 6.0))).collect();
        steps.push(line(
            format!("{from} -> {to} deg at t = 0"),
            timed(&y, ts),
            i,
            false,
        ));
    }
    draw(
        &dir.join("fig-e5.png"),
        "Fig. E.5: responses to steps of the valve angle (6 V)",
        &[Panel {
            y_label: "y (normalised)".into(),
            x_label: "t (s)".into(),
            series: steps,
        }],
    )?;
    Ok(())
}

/// Draws Fig. E.6: the state-space networks' eigenvector directions per unit.
fn fig_e6(dir: &Path, state_space: &[SsRow]) -> Result<(), StudyError> {
    let panels: Vec<Panel> = state_space
        .iter()
        .map(|row| Panel {
            y_label: format!("{} model", row.model),
            x_label: "x_1".into(),
            series: row
                .angles_rad
                .iter()
                .enumerate()
                .flat_map(|(i, a)| {
                    let seg = |t: f64| vec![(-t.cos(), -t.sin()), (t.cos(), t.sin())];
                    [
                        line(format!("unit {i}"), seg(a[0]), i, false),
                        line("", seg(a[1]), i, true),
                    ]
                })
                .collect(),
        })
        .collect();
    draw(
        &dir.join("fig-e6.png"),
        "Fig. E.6: eigenvector directions (first eigenvector solid, second dashed)",
        &panels,
    )?;
    Ok(())
}

/// Draws Fig. E.7: the 5- and 10-unit global networks frozen over phi.
fn fig_e7(dir: &Path, sims: &BTreeMap<(usize, &str), MisoArx>) -> Result<(), StudyError> {
    for units in [5, 10] {
        let Some(m) = sims.get(&(units, "global")) else {
            continue;
        };
        let pts = miso::static_analysis(m, 101);
        let rho = (0..units)
            .map(|i| {
                line(
                    "",
                    pts.iter().map(|q| (q.phi, q.rho[i])).collect(),
                    i,
                    false,
                )
            })
            .collect();
        let curve = |f: &dyn Fn(&miso::FrozenPoint) -> f64| -> Vec<(f64, f64)> {
            pts.iter().map(|q| (q.phi, f(q))).collect()
        };
        draw(
            &dir.join(format!("fig-e7-{units}.png")),
            &format!("Fig. E.7: the {units}-unit network frozen over phi"),
            &[
                Panel {
                    y_label: "rho_i".into(),
                    x_label: "phi (normalised valve angle)".into(),
                    series: rho,
                },
                Panel {
                    y_label: "steady-state gain".into(),
                    x_label: "phi".into(),
                    series: vec![
                        line("G_u", curve(&|q| q.gains[1]), 0, false),
                        line("G_alpha", curve(&|q| q.gains[0]), 1, true),
                    ],
                },
                Panel {
                    y_label: "pole".into(),
                    x_label: "phi".into(),
                    series: vec![line("", curve(&|q| q.poles[0].re), 2, false)],
                },
            ],
        )?;
    }
    Ok(())
}

/// Draws Fig. E.8: the LCN and the linear controller at alpha = 0.1, 0.5, 0.9 on each plant.
fn fig_e8(dir: &Path, p: &HeatParams, e44: &MisoArx, cs: &ControlStudy) -> Result<(), StudyError> {
    let ts = p.ts_s;
    for (file, title, plant) in [
        (
            "fig-e8a.png",
            "Fig. E.8(a): control of the design model",
            PlantModel::Design(&cs.model),
        ),
        (
            "fig-e8b.png",
            "Fig. E.8(b): control of the E.4.4 model",
            PlantModel::WithAlpha(e44),
        ),
        (
            "fig-e8-process.png",
            "LCN and linear controller on the simulated process",
            PlantModel::Process(p),
        ),
    ] {
        let mut panels = Vec::new();
        for (i, a) in [0.1, 0.5, 0.9].into_iter().enumerate() {
            let mut l = PolyLcn::new(cs.model.validity, cs.lcn.clone(), (0.0, 1.0))?;
            let mut s = PolyLcn::single(cs.linear.clone(), (0.0, 1.0))?;
            let (_, yl, _) = step_response(plant, &mut l, a, scheduled_rise(a))?;
            let (_, ys, _) = step_response(plant, &mut s, a, RISE_LINEAR_S)?;
            let n = (10.0 / ts) as usize;
            panels.push(Panel {
                y_label: format!("y, alpha = {a}"),
                x_label: "t (s)".into(),
                series: vec![
                    line("LCN", timed(&yl[..n], ts), i, false),
                    line("linear (alpha = 0.5)", timed(&ys[..n], ts), 5, true),
                ],
            });
        }
        draw(&dir.join(file), title, &panels)?;
    }
    Ok(())
}
