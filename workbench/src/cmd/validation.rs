//! The field's validation outputs of a model (`fes identify --validation DIR`): the
//! measured and simulated traces per record and the residual tests of MATLAB's `resid`,
//! as CSV and as a figure ([`fes_ident::ident::validation`]).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use fes_ident::ident::validation::{RESID_LAGS, Resid, Trace, Validation};

use super::plots::{self, Figure, Line, Markers, Panel};

/// `record,t_ms,measured,simulated`: every record's traces at the data's period `ts_s`.
pub fn traces_csv(traces: &[Trace], ts_s: f64) -> String {
    let mut s = String::from("record,t_ms,measured,simulated\n");
    for (i, t) in traces.iter().enumerate() {
        for (k, (m, y)) in t.measured.iter().zip(&t.simulated).enumerate() {
            let _ = writeln!(s, "{i},{},{m},{y}", k as f64 * ts_s * 1e3);
        }
    }
    s
}

/// `lag,autocorr,xcorr,band_99`: r_ee(k) for k >= 0 (empty below), r_ue(k), the band.
pub fn resid_csv(r: &Resid) -> String {
    let k = RESID_LAGS as isize;
    let mut s = String::from("lag,autocorr,xcorr,band_99\n");
    for (i, x) in r.xcorr.iter().enumerate() {
        let lag = i as isize - k;
        let ac = usize::try_from(lag)
            .ok()
            .and_then(|l| r.autocorr.get(l))
            .map_or(String::new(), |v| v.to_string());
        let _ = writeln!(s, "{lag},{ac},{x},{}", r.band);
    }
    s
}

/// The two panels of `resid`: the residuals' autocorrelation and their cross-correlation
/// with the input, each with the 99 % band.
fn resid_figure(r: &Resid, title: &str) -> Figure {
    let k = RESID_LAGS as f64;
    let panel = |title: &str, y_label: &str, points: Vec<(f64, f64)>, x0: f64| {
        let band = |sign: f64| {
            Line::new(
                (sign > 0.0).then(|| "99 % band".to_owned()),
                vec![(x0, sign * r.band), (k, sign * r.band)],
                plots::color(3),
            )
            .dashed()
        };
        Panel {
            title: Some(title.to_owned()),
            x_label: "lag (samples)".into(),
            y_label: y_label.into(),
            x: Some((x0 - 0.5, k + 0.5)),
            y: Some((-1.05, 1.05)),
            lines: vec![band(1.0), band(-1.0)],
            markers: vec![Markers {
                label: None,
                points,
                color: plots::color(0),
                size: 3,
                filled: true,
            }],
            hline: Some(0.0),
            legend: true,
            ..Panel::default()
        }
    };
    let ac = r
        .autocorr
        .iter()
        .enumerate()
        .map(|(i, v)| (i as f64, *v))
        .collect();
    let xc = r
        .xcorr
        .iter()
        .enumerate()
        .map(|(i, v)| (i as f64 - k, *v))
        .collect();
    Figure {
        title: title.to_owned(),
        columns: vec![vec![
            (
                1,
                panel(
                    &format!(
                        "autocorrelation of the residuals ({} of {RESID_LAGS} lags outside)",
                        r.autocorr_outside
                    ),
                    "r_ee(k)",
                    ac,
                    0.0,
                ),
            ),
            (
                1,
                panel(
                    &format!(
                        "cross-correlation input -> residuals ({} of {} lags outside)",
                        r.xcorr_outside,
                        2 * RESID_LAGS + 1
                    ),
                    "r_ue(k)",
                    xc,
                    -k,
                ),
            ),
        ]],
    }
}

/// Writes `traces_train.csv`, `traces_test.csv`, `resid.csv` and `resid.png` (or `.svg`)
/// into `dir`.
pub fn write(
    dir: &Path,
    v: &Validation,
    ts_s: f64,
    model: &str,
    format: workbench::plots::FigureFormat,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let put = |name: &str, text: String| {
        let p = dir.join(name);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))
    };
    put("traces_train.csv", traces_csv(&v.train, ts_s))?;
    put("traces_test.csv", traces_csv(&v.test, ts_s))?;
    if let Some(r) = &v.resid {
        put("resid.csv", resid_csv(r))?;
        let fig = resid_figure(r, &format!("residual tests of {model} on the test records"));
        plots::save(&fig, &format.file(dir, "resid"), (900, 700))?;
    }
    Ok(())
}
