//! `fes analyse`: what a model does away from its training data (thesis 2.4, 5.4.3):
//! static analysis over phi (Fig. 5.27-5.28), the force-frequency curve (Fig. 5.26) with the
//! extrapolated range marked, the stability report (2.4.1, Fig. D.4) and, with a data set,
//! simulated against measured test records (Fig. 5.24). Writes PNG plots, CSV tables and
//! `report.md` into `--out`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fes_ident::analysis::force_frequency::{ForceFrequencyPoint, force_frequency};
use fes_ident::analysis::static_analysis::{StaticReport, analyse};
use fes_ident::analysis::trace::phi_range;
use fes_ident::analysis::validation::{RecordFit, fit_record, msse};
use fes_ident::ident::validation::{
    RESID_LAGS, Trace, Validation as FieldValidation, fit_and_rrse, resid,
};
use fes_model::model::lmn::UnitStability;
use fes_model::model::{Lmn, Network, Scheduler};
use sim_muscle::pattern::constant_train;

use super::inputs::{
    Data, OpenedModel, Series, md_table, open_data, open_model, out_dir, sci, write_csv,
};
use super::plots::{self, Band, Figure, Line, Panel, color};

/// Arguments of `fes analyse`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (fes-lmn/1); unstable models are opened and flagged.
    #[arg(long)]
    pub model: PathBuf,
    /// A data set (fes-dataset/1): its training records give the phi range the model was
    /// identified on; its test records are simulated and scored.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Output directory (created if needed).
    #[arg(long)]
    pub out: PathBuf,
    /// Points of the static analysis over the valid phi range.
    #[arg(long, default_value_t = 201)]
    pub grid: usize,
    /// Highest frequency of the force-frequency curve, Hz (1 Hz steps from 1 Hz).
    #[arg(long, default_value_t = 150)]
    pub max_hz: u32,
    /// Length of each constant train, ms (thesis: 1000).
    #[arg(long, default_value_t = 1000)]
    pub train_ms: u32,
    /// The mean force is taken from this time to the end of the train, ms ("after the
    /// initial rising portion").
    #[arg(long, default_value_t = 500)]
    pub average_from_ms: u32,
    /// Test records drawn in validation.png (all are scored).
    #[arg(long, default_value_t = 4)]
    pub plot_records: usize,
    /// Format of the figures: png (raster) or svg (vector, for papers).
    #[arg(long, value_enum, default_value_t = workbench::plots::FigureFormat::Png)]
    pub format: workbench::plots::FigureFormat,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if args.grid < 2 {
        bail!("--grid {}: need at least 2 points", args.grid);
    }
    if args.max_hz == 0 {
        bail!("--max-hz must be at least 1");
    }
    if args.average_from_ms >= args.train_ms {
        bail!(
            "--average-from-ms {} must be shorter than --train-ms {}",
            args.average_from_ms,
            args.train_ms
        );
    }
    let model = open_model(&args.model)?;
    let data = args
        .data
        .as_deref()
        .map(|d| open_data(d, model.lmn.ts))
        .transpose()?;
    out_dir(&args.out)?;
    let net = model.lmn.network().context("building the model network")?;
    let report = analyse(&model.lmn, args.grid).context("static analysis")?;

    let train_phi = match &data {
        Some(d) => phi_range(&net, d.train.iter().map(|s| s.u.as_slice()))
            .context("scheduling variable over the training records")?,
        None => None,
    };

    let mut md = String::new();
    let _ = writeln!(md, "# Analysis of `{}`\n", args.model.display());
    stability_section(&mut md, &model, &report);
    static_section(
        &mut md,
        &args.out,
        args.format,
        &model.lmn,
        &report,
        train_phi,
    )?;
    ff_section(&mut md, &args, &net, train_phi)?;
    if let Some(d) = &data {
        validation_section(&mut md, &args, &net, d)?;
    } else {
        let _ = writeln!(
            md,
            "## Validation\n\nNo data set given (`--data`): no test records simulated, and the \
             extrapolated phi range is not marked.\n"
        );
    }
    let path = args.out.join("report.md");
    std::fs::write(&path, md).with_context(|| format!("writing {}", path.display()))?;
    println!("report written to {}", path.display());
    Ok(())
}

fn stability_section(md: &mut String, model: &OpenedModel, rep: &StaticReport) {
    let lmn = &model.lmn;
    let bad = model.unstable_units();
    if !bad.is_empty() {
        let _ = writeln!(
            md,
            "> **WARNING: UNSTABLE MODEL.** The local models of units {bad:?} are unstable \
             (|1 + Ts p| >= 1). The model was opened with the stability check disabled; \
             long stimulation in the region these units dominate drives the output away \
             without bound (thesis 5.4.3, Fig. 5.32). Repair: `fes modify --stabilise`.\n"
        );
    }
    let _ = writeln!(
        md,
        "Structure `{}`, {} units, Ts = {} ms, delay {} samples, scheduling {}, offsets {}.\n",
        lmn.structure(),
        lmn.units(),
        lmn.ts * 1e3,
        lmn.delay,
        match Scheduler::new(&lmn.scheduling, lmn.ts) {
            Ok(Scheduler::Output) => "output (phi = y[k-1], eq. 5.1)",
            _ => "input (pre-filtered pulse train, eq. 5.2-5.4)",
        },
        if lmn.zero_offsets {
            "fixed at zero"
        } else {
            "free"
        }
    );
    let _ = writeln!(md, "## Stability of the local models\n");
    let _ = writeln!(
        md,
        "Delta-domain stability region: a pole p is stable when |1 + Ts p| < 1 (the circle of \
         radius 1/Ts = {:.0} /s centred at -1/Ts, Fig. D.4); for real poles -2/Ts < p < 0.\n",
        1.0 / lmn.ts
    );
    let rows: Vec<Vec<String>> = model.stability.iter().map(stability_row).collect();
    md.push_str(&md_table(
        &["unit", "poles (1/s)", "max abs(1 + Ts p)", "verdict"],
        &rows,
    ));
    md.push('\n');
    eigenvector_note(md, rep);
}

/// One unit's row of the stability table: its poles, max |1 + Ts p| and verdict.
fn stability_row(s: &UnitStability) -> Vec<String> {
    vec![
        s.unit.to_string(),
        s.poles
            .iter()
            .map(|p| {
                if p.im == 0.0 {
                    format!("{:.2}", p.re)
                } else {
                    format!("{:.2}{:+.2}i", p.re, p.im)
                }
            })
            .collect::<Vec<_>>()
            .join(", "),
        format!("{:.6}", s.radius),
        if s.stable { "stable" } else { "**UNSTABLE**" }.into(),
    ]
}

/// Whether the eigenvectors are common (then stability by construction, 2.4.1) or local
/// (the LPV caveat).
fn eigenvector_note(md: &mut String, rep: &StaticReport) {
    match rep.common_eigenvectors {
        Some(a) => {
            let _ = writeln!(
                md,
                "The local models share real eigenvectors (angles {:.4} and {:.4} rad). {}\n",
                a[0],
                a[1],
                if rep.network_stable_by_construction {
                    "With every local model stable, the network is stable for any scheduling \
                     sequence (thesis 2.4.1)."
                } else {
                    "But some local model is unstable, so the network is not stable."
                }
            );
        }
        None => {
            let _ = writeln!(
                md,
                "**The eigenvectors are local** (not common to all units). Caveat (thesis \
                 2.4.1): the network is a linear parameter-varying system, and stability of \
                 every local model does **not** imply stability of the network; only common \
                 eigenvectors with all local models stable guarantee it. The frozen-phi \
                 figures below describe the interpolated model at each fixed phi, not the \
                 network's behaviour while phi varies (2.4.2).\n"
            );
        }
    }
}

/// Contiguous x intervals where `flag` holds, from sorted (x, flag) pairs.
fn runs(points: &[(f64, bool)], half_step: f64) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    let mut open: Option<f64> = None;
    for (i, &(x, f)) in points.iter().enumerate() {
        match (f, open) {
            (true, None) => open = Some(x - half_step),
            (false, Some(s)) => {
                out.push((s, points[i - 1].0 + half_step));
                open = None;
            }
            _ => {}
        }
    }
    if let (Some(s), Some(last)) = (open, points.last()) {
        out.push((s, last.0 + half_step));
    }
    out
}

fn extrapolation_bands(range: (f64, f64), train_phi: Option<(f64, f64)>) -> Vec<Band> {
    let Some((lo, hi)) = train_phi else {
        return Vec::new();
    };
    let mut bands = Vec::new();
    let label = Some("extrapolation (phi not in training data)".to_string());
    if lo > range.0 {
        bands.push(Band {
            x0: range.0,
            x1: lo,
            color: plots::EXTRAPOLATION_BAND,
            label: label.clone(),
        });
    }
    if hi < range.1 {
        bands.push(Band {
            x0: hi,
            x1: range.1,
            color: plots::EXTRAPOLATION_BAND,
            label: if bands.is_empty() { label } else { None },
        });
    }
    bands
}

/// What the static analysis shows beyond its points: where the frozen model is unstable
/// and how far the gain ranges.
struct StaticFindings {
    /// The phi grid's extent.
    range: (f64, f64),
    /// phi intervals where the frozen model is unstable (half a grid step beyond the points).
    unstable: Vec<(f64, f64)>,
    /// Smallest and largest gain over phi.
    gain_span: (f64, f64),
    /// Grid points where the frozen model is unstable.
    unstable_points: usize,
}

fn static_findings(rep: &StaticReport) -> StaticFindings {
    let phis: Vec<f64> = rep.points.iter().map(|p| p.phi).collect();
    let range = (phis[0], phis[phis.len() - 1]);
    let step = if phis.len() > 1 {
        0.5 * (phis[1] - phis[0])
    } else {
        0.0
    };
    let unstable: Vec<(f64, bool)> = rep.points.iter().map(|p| (p.phi, !p.stable)).collect();
    let gain_span = rep
        .points
        .iter()
        .filter_map(|p| p.gain)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), g| {
            (a.min(g), b.max(g))
        });
    StaticFindings {
        range,
        unstable: runs(&unstable, step),
        gain_span,
        unstable_points: rep.points.iter().filter(|p| !p.stable).count(),
    }
}

/// `static.png`, `static.csv` and the report's section.
fn static_section(
    md: &mut String,
    out: &Path,
    format: workbench::plots::FigureFormat,
    lmn: &Lmn,
    rep: &StaticReport,
    train_phi: Option<(f64, f64)>,
) -> Result<()> {
    let found = static_findings(rep);
    let mut bands = extrapolation_bands(found.range, train_phi);
    bands.extend(found.unstable.iter().enumerate().map(|(i, &(a, b))| Band {
        x0: a,
        x1: b,
        color: plots::UNSTABLE_BAND,
        label: (i == 0).then(|| "frozen model unstable".to_string()),
    }));
    plots::save(
        &static_figure(lmn, rep, bands),
        &format.file(out, "static"),
        (900, 900),
    )?;
    write_static_csv(&out.join("static.csv"), lmn.units(), rep)?;
    static_markdown(md, &found, rep.points.len(), train_phi);
    Ok(())
}

/// Fig. 5.27: activations, gain and poles over phi, `bands` shaded in each.
fn static_figure(lmn: &Lmn, rep: &StaticReport, bands: Vec<Band>) -> Figure {
    let m = lmn.units();
    let act = Panel {
        title: Some("activations rho_i(phi)".into()),
        x_label: "phi".into(),
        y_label: "rho_i".into(),
        y: Some((0.0, 1.05)),
        lines: (0..m)
            .map(|i| {
                Line::new(
                    Some(format!("unit {i}")),
                    rep.points
                        .iter()
                        .map(|p| (p.phi, p.activations[i]))
                        .collect(),
                    color(i),
                )
            })
            .collect(),
        bands: bands.clone(),
        legend: true,
        ..Panel::default()
    };
    let gain = Panel {
        title: Some("steady-state gain G = -c'A^-1 b (eq. A.18) = FTI per pulse / Ts".into()),
        x_label: "phi".into(),
        y_label: "G".into(),
        lines: vec![Line::new(
            None,
            rep.points
                .iter()
                .map(|p| (p.phi, p.gain.unwrap_or(f64::NAN)))
                .collect(),
            color(0),
        )],
        hline: Some(0.0),
        y: gain_range(rep),
        bands: bands.clone(),
        ..Panel::default()
    };
    Figure {
        title: format!(
            "static analysis over phi ({} units, {})",
            m,
            lmn.structure()
        ),
        columns: vec![vec![(1, act), (1, gain), (1, pole_panel(rep, bands))]],
    }
}

/// The real parts of both poles over phi (and the imaginary part of the first when some
/// pole is complex).
fn pole_panel(rep: &StaticReport, bands: Vec<Band>) -> Panel {
    let pole = |j: usize, im: bool| -> Vec<(f64, f64)> {
        rep.points
            .iter()
            .map(|p| {
                let z = p.poles.get(j).copied().unwrap_or_default();
                (p.phi, if im { z.im } else { z.re })
            })
            .collect()
    };
    let any_complex = rep
        .points
        .iter()
        .any(|p| p.poles.iter().any(|z| z.im != 0.0));
    let mut pole_lines = vec![
        Line::new(Some("Re p1".to_string()), pole(0, false), color(0)),
        Line::new(Some("Re p2".to_string()), pole(1, false), color(1)),
    ];
    if any_complex {
        pole_lines.push(Line::new(Some("Im p1".to_string()), pole(0, true), color(2)).dashed());
    }
    Panel {
        title: Some("poles of the interpolated model (delta domain)".into()),
        x_label: "phi".into(),
        y_label: "p (1/s)".into(),
        lines: pole_lines,
        hline: Some(0.0),
        bands,
        legend: true,
        ..Panel::default()
    }
}

/// One row per grid point: phi, activations, gain, output offset, poles, stability.
fn write_static_csv(path: &Path, m: usize, rep: &StaticReport) -> Result<()> {
    let mut header: Vec<String> = vec!["phi".into()];
    header.extend((0..m).map(|i| format!("rho_{i}")));
    header.extend(
        [
            "gain",
            "offset_output",
            "p1_re",
            "p1_im",
            "p2_re",
            "p2_im",
            "radius",
            "stable",
        ]
        .map(String::from),
    );
    let rows: Vec<Vec<String>> = rep
        .points
        .iter()
        .map(|p| {
            let mut r = vec![format!("{}", p.phi)];
            r.extend(p.activations.iter().map(|a| format!("{a}")));
            let opt = |v: Option<f64>| v.map_or("".into(), |v| format!("{v}"));
            r.push(opt(p.gain));
            r.push(opt(p.offset_output));
            for j in 0..2 {
                let z = p.poles.get(j).copied().unwrap_or_default();
                r.push(format!("{}", z.re));
                r.push(format!("{}", z.im));
            }
            r.push(format!("{}", p.stability_radius));
            r.push(p.stable.to_string());
            r
        })
        .collect();
    let h: Vec<&str> = header.iter().map(String::as_str).collect();
    write_csv(path, &h, &rows)
}

fn static_markdown(
    md: &mut String,
    found: &StaticFindings,
    points: usize,
    train_phi: Option<(f64, f64)>,
) {
    let _ = writeln!(md, "## Static analysis over phi (Fig. 5.27)\n");
    let _ = writeln!(md, "![static analysis](static.png)\n");
    let (gmin, gmax) = found.gain_span;
    let _ = writeln!(
        md,
        "Gain range over phi: {gmin:.4} .. {gmax:.4}{}. Frozen model unstable at {} of {} grid points. Table: `static.csv`.\n",
        if gmin < 0.0 {
            " (**negative somewhere**: the LCN design refuses negative local gains, thesis 6.5.3)"
        } else {
            ""
        },
        found.unstable_points,
        points
    );
    if let Some((lo, hi)) = train_phi {
        let _ = writeln!(
            md,
            "The training records drive phi over [{lo:.3}, {hi:.3}] (the model's own scheduler); the shaded range outside it is extrapolation.\n"
        );
    }
}

/// The gain axis from the 5th to the 95th percentile of the gain (widened by half its span
/// and including 0): where an eigenvalue crosses zero A is nearly singular and the gain
/// spikes; those values run along the border.
fn gain_range(rep: &StaticReport) -> Option<(f64, f64)> {
    let mut g: Vec<f64> = rep
        .points
        .iter()
        .filter_map(|p| p.gain)
        .filter(|g| g.is_finite())
        .collect();
    if g.is_empty() {
        return None;
    }
    g.sort_by(f64::total_cmp);
    let q = |f: f64| g[((g.len() - 1) as f64 * f).round() as usize];
    let (lo, hi) = (q(0.05).min(0.0), q(0.95).max(0.0));
    let span = (hi - lo).max(1e-9);
    Some((lo - 0.5 * span, hi + 0.5 * span))
}

/// The force-frequency curve and what the report says of it.
struct ForceFrequency {
    points: Vec<ForceFrequencyPoint>,
    /// Per point: its train drives phi outside the training data's range (false without a
    /// data set).
    extrapolated: Vec<bool>,
    /// Frequencies at which the curve is lower than at the frequency before.
    drops: Vec<f64>,
}

impl ForceFrequency {
    /// The lowest frequency whose train drives phi outside the training data's range.
    fn first_extrapolated(&self) -> Option<f64> {
        self.points
            .iter()
            .zip(&self.extrapolated)
            .find(|(_, e)| **e)
            .map(|(p, _)| p.frequency_hz)
    }
}

/// Constant trains at 1..`--max-hz` Hz from rest (Fig. 5.26), each point judged against
/// the training data's phi range.
fn force_frequency_curve(
    args: &Args,
    net: &Network<f64>,
    train_phi: Option<(f64, f64)>,
) -> Result<ForceFrequency> {
    let ts = net.ts();
    let samples = (args.train_ms as f64 * 1e-3 / ts).round() as usize;
    let from = (args.average_from_ms as f64 * 1e-3 / ts).round() as usize;
    let trains = (1..=args.max_hz)
        .map(|f| {
            let f = f as f64;
            constant_train(f, 0, samples, ts)
                .map(|p| (f, p))
                .with_context(|| format!("{f} Hz train"))
        })
        .collect::<Result<Vec<_>>>()?;
    let points = force_frequency(net, &trains, samples, from).context("force-frequency curve")?;
    let extrapolated = points
        .iter()
        .map(|p| train_phi.is_some_and(|(lo, hi)| p.phi_max > hi + 1e-9 || p.phi_max < lo - 1e-9))
        .collect();
    let drops = points
        .windows(2)
        .filter(|w| w[1].mean_output < w[0].mean_output)
        .map(|w| w[1].frequency_hz)
        .collect();
    Ok(ForceFrequency {
        points,
        extrapolated,
        drops,
    })
}

/// `force_frequency.png`, `force_frequency.csv` and the report's section.
fn ff_section(
    md: &mut String,
    args: &Args,
    net: &Network<f64>,
    train_phi: Option<(f64, f64)>,
) -> Result<()> {
    let ff = force_frequency_curve(args, net, train_phi)?;
    plots::save(
        &ff_figure(args, &ff, train_phi),
        &args.format.file(&args.out, "force_frequency"),
        (900, 650),
    )?;
    write_ff_csv(
        &args.out.join("force_frequency.csv"),
        &ff,
        train_phi.is_some(),
    )?;
    ff_markdown(md, args, &ff);
    Ok(())
}

/// The curve above, the mean and largest phi of each train below; extrapolated
/// frequencies shaded.
fn ff_figure(args: &Args, ff: &ForceFrequency, train_phi: Option<(f64, f64)>) -> Figure {
    let pts = &ff.points;
    let flags: Vec<(f64, bool)> = pts
        .iter()
        .zip(&ff.extrapolated)
        .map(|(p, &e)| (p.frequency_hz, e))
        .collect();
    let bands: Vec<Band> = runs(&flags, 0.5)
        .into_iter()
        .enumerate()
        .map(|(i, (a, b))| Band {
            x0: a,
            x1: b,
            color: plots::EXTRAPOLATION_BAND,
            label: (i == 0).then(|| "extrapolation (phi above the training data's)".to_string()),
        })
        .collect();
    let x = Some((0.0, args.max_hz as f64 + 1.0));
    let curve = Panel {
        x_label: "stimulation frequency (Hz)".into(),
        y_label: "mean output (normalised force)".into(),
        x,
        lines: vec![Line::new(
            None,
            pts.iter()
                .map(|p| (p.frequency_hz, p.mean_output))
                .collect(),
            color(0),
        )],
        bands: bands.clone(),
        hline: Some(0.0),
        legend: true,
        ..Panel::default()
    };
    let phi = Panel {
        x_label: "stimulation frequency (Hz)".into(),
        y_label: "phi".into(),
        x,
        lines: vec![
            Line::new(
                Some("mean phi".to_string()),
                pts.iter().map(|p| (p.frequency_hz, p.phi_mean)).collect(),
                color(1),
            ),
            Line::new(
                Some("max phi".to_string()),
                pts.iter().map(|p| (p.frequency_hz, p.phi_max)).collect(),
                color(2),
            )
            .dashed(),
        ],
        hline: train_phi.map(|r| r.1),
        bands,
        legend: true,
        ..Panel::default()
    };
    Figure {
        title: format!(
            "force-frequency curve: mean model output over {}..{} ms of {} ms constant trains",
            args.average_from_ms, args.train_ms, args.train_ms
        ),
        columns: vec![vec![(3, curve), (2, phi)]],
    }
}

/// One row per frequency; `extrapolated` is empty without a data set (`judged` false).
fn write_ff_csv(path: &Path, ff: &ForceFrequency, judged: bool) -> Result<()> {
    let rows: Vec<Vec<String>> = ff
        .points
        .iter()
        .zip(&ff.extrapolated)
        .map(|(p, e)| {
            vec![
                format!("{}", p.frequency_hz),
                format!("{}", p.mean_output),
                format!("{}", p.phi_mean),
                format!("{}", p.phi_max),
                if judged { e.to_string() } else { "".into() },
            ]
        })
        .collect();
    write_csv(
        path,
        &[
            "frequency_hz",
            "mean_output",
            "phi_mean",
            "phi_max",
            "extrapolated",
        ],
        &rows,
    )
}

fn ff_markdown(md: &mut String, args: &Args, ff: &ForceFrequency) {
    let _ = writeln!(md, "## Force-frequency curve (Fig. 5.26)\n");
    let _ = writeln!(md, "![force-frequency curve](force_frequency.png)\n");
    let _ = writeln!(
        md,
        "Constant trains of {} ms at 1..{} Hz from rest (pulses at the nearest sample); the \
         force is the mean model output over {}..{} ms. Table: `force_frequency.csv`.",
        args.train_ms, args.max_hz, args.average_from_ms, args.train_ms
    );
    if let Some(first) = ff.first_extrapolated() {
        let _ = write!(
            md,
            " From {first} Hz on, the trains drive phi above the training data's maximum: the curve is extrapolated there."
        );
    }
    if !ff.drops.is_empty() {
        let _ = write!(
            md,
            " The curve falls at {} of {} steps (first at {} Hz): a force that drops as the frequency rises is not a property of muscle (thesis 5.4.3: the 30-40 Hz bump of an unstable local model).",
            ff.drops.len(),
            ff.points.len() - 1,
            ff.drops[0]
        );
    }
    md.push_str("\n\n");
}

/// The model against the data set's records (Fig. 5.24), with the field's figures.
struct Validation {
    /// Each test record simulated from rest, in the data set's order.
    fits: Vec<RecordFit>,
    /// MSSE over all training / test samples (eq. B.8).
    train: f64,
    test: f64,
    /// NRMSE fit, RRSE and residual tests, as `identify` reports them.
    field: FieldValidation,
}

/// Simulates every record from rest and scores it: MSSE (eq. B.8), NRMSE fit and RRSE,
/// and the residual tests of the test records (`fes_ident::ident::validation`).
fn validate(net: &Network<f64>, d: &Data) -> Result<Validation> {
    let simulate = |records: &[Series]| {
        records
            .iter()
            .map(|s| fit_record(net, &s.u, &s.y).with_context(|| format!("simulating {}", s.name)))
            .collect::<Result<Vec<_>>>()
    };
    let fits = simulate(&d.test)?;
    let train_fits = simulate(&d.train)?;
    let traces = |records: &[Series], fits: &[RecordFit]| -> Vec<Trace> {
        records
            .iter()
            .zip(fits)
            .map(|(s, f)| Trace {
                measured: s.y.clone(),
                simulated: f.simulated.clone(),
            })
            .collect()
    };
    let train_traces = traces(&d.train, &train_fits);
    let test_traces = traces(&d.test, &fits);
    let (train_fit_percent, _) = fit_and_rrse(&train_traces);
    let (test_fit_percent, test_rrse) = fit_and_rrse(&test_traces);
    let residuals: Vec<(Vec<f64>, &[f64])> = d
        .test
        .iter()
        .zip(&test_traces)
        .map(|(s, t)| {
            let e = t.measured.iter().zip(&t.simulated).map(|(y, yh)| y - yh);
            (e.collect(), s.u.as_slice())
        })
        .collect();
    let pairs: Vec<(&[f64], &[f64])> = residuals.iter().map(|(e, u)| (e.as_slice(), *u)).collect();
    let field = FieldValidation {
        train_fit_percent,
        test_fit_percent,
        test_rrse,
        resid: resid(&pairs, RESID_LAGS),
        train: train_traces,
        test: test_traces,
    };
    let train = msse(net, d.train_pairs()).context("training MSSE")?;
    let test = msse(net, d.test_pairs()).context("test MSSE")?;
    Ok(Validation {
        fits,
        train,
        test,
        field,
    })
}

/// `validation.png`, `validation.csv`, the field's validation files and the report's
/// section.
fn validation_section(md: &mut String, args: &Args, net: &Network<f64>, d: &Data) -> Result<()> {
    let v = validate(net, d)?;
    let shown = d.test.len().min(args.plot_records.max(1));
    let traces = concatenate(d, &v.fits, shown, net.ts() * 1e3);
    plots::save(
        &validation_figure(traces, shown, d.test.len()),
        &args.format.file(&args.out, "validation"),
        (1100, 600),
    )?;
    let per_record: Vec<(Option<f64>, Option<f64>)> = v
        .field
        .test
        .iter()
        .map(|t| fit_and_rrse(std::slice::from_ref(t)))
        .collect();
    let opt = |x: Option<f64>, digits: usize| x.map_or(String::new(), |v| format!("{v:.digits$}"));
    // One row per test record: its name and kind, then its MSSE, fit and RRSE as `cells`
    // writes them (the CSV in full, the report rounded).
    let table = |cells: &dyn Fn(f64, Option<f64>, Option<f64>) -> [String; 3]| {
        let rows = d.test.iter().zip(&v.fits).zip(&per_record);
        rows.map(|((s, f), (fit, rrse))| {
            let [msse, fit, rrse] = cells(f.msse, *fit, *rrse);
            vec![s.name.clone(), s.kind.clone(), msse, fit, rrse]
        })
        .collect::<Vec<Vec<String>>>()
    };
    let full = |x: Option<f64>| x.map_or(String::new(), |v| v.to_string());
    let rows = table(&|msse, fit, rrse| [format!("{msse}"), full(fit), full(rrse)]);
    write_csv(
        &args.out.join("validation.csv"),
        &["record", "kind", "msse", "fit_percent", "rrse"],
        &rows,
    )?;
    let name = args.model.file_name().map_or_else(
        || args.model.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    super::validation::write(&args.out, &v.field, net.ts(), &name, args.format)?;
    let _ = writeln!(md, "## Validation on the test records (Fig. 5.24)\n");
    let _ = writeln!(
        md,
        "Data set `{}`: training MSSE {}, test MSSE {} (eq. B.8, every record simulated from rest).\n",
        d.dir.display(),
        sci(v.train),
        sci(v.test)
    );
    let pct = |x: Option<f64>| x.map_or("-".to_owned(), |v| format!("{v:.1} %"));
    let _ = writeln!(
        md,
        "As the field reports it (MATLAB `compare`, sysidentpy): NRMSE fit {} on the training \
         records, {} on the test records; test RRSE {}.\n",
        pct(v.field.train_fit_percent),
        pct(v.field.test_fit_percent),
        v.field
            .test_rrse
            .map_or("-".to_owned(), |x| format!("{x:.4}"))
    );
    if let Some(r) = &v.field.resid {
        let _ = writeln!(
            md,
            "Residual tests (MATLAB `resid`, {} samples, 99 % band ±{:.4}): {} of {RESID_LAGS} \
             autocorrelation lags and {} of {} input cross-correlation lags outside the band \
             (`resid.csv`); the traces are in `traces_train.csv` and `traces_test.csv`.\n\n\
             ![resid](resid.{ext})\n",
            r.samples,
            r.band,
            r.autocorr_outside,
            r.xcorr_outside,
            2 * RESID_LAGS + 1,
            ext = args.format.ext()
        );
    }
    let _ = writeln!(md, "![validation](validation.{})\n", args.format.ext());
    let md_rows = table(&|msse, fit, rrse| [sci(msse), opt(fit, 1), opt(rrse, 4)]);
    md.push_str(&md_table(
        &["test record", "kind", "MSSE", "fit %", "RRSE"],
        &md_rows,
    ));
    md.push('\n');
    Ok(())
}

/// The first test records laid end to end on one time axis (ms), for the figure.
struct Concatenated {
    /// End of the last record.
    t_end: f64,
    /// Pulse times.
    pulses: Vec<f64>,
    /// Measured and simulated force, broken (NaN) between records.
    measured: Vec<(f64, f64)>,
    simulated: Vec<(f64, f64)>,
    /// Where one record ends and the next begins.
    separators: Vec<f64>,
    /// Each record's kind and MSSE, above its start.
    texts: Vec<(f64, f64, String)>,
    /// The force axis's top before its margin.
    top: f64,
}

fn concatenate(d: &Data, fits: &[RecordFit], shown: usize, ts_ms: f64) -> Concatenated {
    let mut c = Concatenated {
        t_end: 0.0,
        pulses: Vec::new(),
        measured: Vec::new(),
        simulated: Vec::new(),
        separators: Vec::new(),
        texts: Vec::new(),
        top: 0.1,
    };
    for (s, f) in d.test.iter().zip(fits).take(shown) {
        let t0 = c.t_end;
        if t0 > 0.0 {
            c.separators.push(t0);
            c.measured.push((f64::NAN, f64::NAN));
            c.simulated.push((f64::NAN, f64::NAN));
        }
        for k in 0..s.u.len() {
            let t = t0 + k as f64 * ts_ms;
            if s.u[k] > 0.5 {
                c.pulses.push(t);
            }
            c.measured.push((t, s.y[k]));
            c.simulated.push((t, f.simulated[k]));
            c.top = c.top.max(s.y[k]).max(f.simulated[k].min(1.5));
        }
        c.texts.push((
            t0 + 8.0 * ts_ms,
            0.0,
            format!("{}: MSSE {}", s.kind, sci(f.msse)),
        ));
        c.t_end += s.u.len() as f64 * ts_ms;
    }
    for t in &mut c.texts {
        t.1 = 1.2 * c.top;
    }
    c
}

/// Fig. 5.24: pulses above, measured (dashed) and simulated (solid) force below.
fn validation_figure(c: Concatenated, shown: usize, records: usize) -> Figure {
    let (t0, hi) = (c.t_end, c.top);
    Figure {
        title: format!(
            "test records: measured (dashed) and simulated from rest (solid); first {shown} of {records}"
        ),
        columns: vec![vec![
            (
                1,
                Panel {
                    y_label: "pulse".into(),
                    x: Some((0.0, t0)),
                    y: Some((0.0, 1.1)),
                    y_ticks: Some(2),
                    compact: true,
                    impulses: c.pulses,
                    separators: c.separators.clone(),
                    ..Panel::default()
                },
            ),
            (
                4,
                Panel {
                    x_label: "time (ms), records concatenated, each simulated from rest".into(),
                    y_label: "force (normalised)".into(),
                    x: Some((0.0, t0)),
                    y: Some((-0.1 * hi, 1.25 * hi)),
                    lines: vec![
                        Line::new(Some("measured".to_string()), c.measured, color(7)).dashed(),
                        Line::new(Some("model".to_string()), c.simulated, color(0)),
                    ],
                    separators: c.separators,
                    texts: c.texts,
                    legend: true,
                    ..Panel::default()
                },
            ),
        ]],
    }
}
