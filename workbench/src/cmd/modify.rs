//! `fes modify --stabilise`: the thesis's model modification (5.4.3): every unstable
//! local eigenvalue is replaced by a slow stable one and that unit's offsets are
//! re-estimated on the training data (`fes_ident::analysis::stabilise`). Prints Table 5.4
//! (training/test MSSE before and after), writes the model, and draws the long-train
//! response before and after (Fig. 5.32(a)) next to it.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fes_ident::analysis::stabilise::{DEFAULT_EIGENVALUE, Stabilised, stabilise};
use fes_ident::analysis::trace::{Trace, simulate_trace};
use fes_ident::analysis::validation::msse;
use fes_model::model::{Lmn, file};
use sim_muscle::pattern::constant_train;

use super::inputs::{Data, md_table, open_data, open_model, sci};
use super::plots::{self, Figure, Line, Panel, color};

/// Arguments of `fes modify`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (fes-lmn/1); opened even when unstable.
    #[arg(long)]
    pub model: PathBuf,
    /// Replace unstable local eigenvalues and re-estimate the units' offsets (5.4.3).
    #[arg(long)]
    pub stabilise: bool,
    /// The replacement eigenvalue, 1/s, in (-1/Ts, 0) (thesis: -1).
    #[arg(long, default_value_t = DEFAULT_EIGENVALUE, allow_negative_numbers = true)]
    pub eigenvalue: f64,
    /// The data set whose training records re-estimate the offsets (its test records give
    /// the test MSSE).
    #[arg(long)]
    pub data: PathBuf,
    /// The modified model file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Frequency of the long constant train drawn before/after, Hz (thesis Fig. 5.32: 37).
    #[arg(long, default_value_t = 37.0)]
    pub long_train_hz: f64,
    /// Length of that train, ms.
    #[arg(long, default_value_t = 3000)]
    pub long_train_ms: u32,
    /// Format of the figures: png (raster) or svg (vector, for papers).
    #[arg(long, value_enum, default_value_t = workbench::plots::FigureFormat::Png)]
    pub format: workbench::plots::FigureFormat,
}

/// Where the plot and the report go: next to `--out`, named after it.
fn side_file(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().trim_end_matches(".lmn").to_string())
        .unwrap_or_else(|| "model".into());
    out.with_file_name(format!("{stem}{suffix}"))
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if !args.stabilise {
        bail!("nothing to do: give --stabilise (the only modification offered)");
    }
    if !(args.long_train_hz.is_finite() && args.long_train_hz > 0.0) {
        bail!(
            "--long-train-hz {}: must be a finite number > 0",
            args.long_train_hz
        );
    }
    if args.out.extension().is_none_or(|e| e != "json") {
        bail!(
            "--out {}: the model file must end in .json",
            args.out.display()
        );
    }
    let model = open_model(&args.model)?;
    let data = open_data(&args.data, model.lmn.ts)?;
    let train = data.train_pairs();
    let result = stabilise(&model.lmn, args.eigenvalue, &train)
        .with_context(|| format!("stabilising {}", args.model.display()))?;
    let before = errors(&model.lmn, &data)?;
    let after = errors(&result.model, &data)?;

    let mut fixed = result.model.clone();
    fixed.provenance.train_mspe = None;
    fixed.provenance.train_msse = Some(after.0);
    fixed.provenance.test_msse = Some(after.1);
    fixed.provenance.extra.insert(
        "modified".into(),
        serde_json::json!({
            "tool": format!("fes modify {}", env!("CARGO_PKG_VERSION")),
            "from": args.model.display().to_string(),
            "data_set": data.dir.display().to_string(),
            "eigenvalues_replaced": result.changes.iter().map(|c| serde_json::json!({
                "unit": c.unit, "index": c.index, "old": c.old, "new": c.new })).collect::<Vec<_>>(),
            "offsets_reestimated": result.offsets.iter().map(|o| o.unit).collect::<Vec<_>>(),
        }),
    );
    file::save(&fixed, &args.out).with_context(|| format!("writing {}", args.out.display()))?;
    // The result must pass the strict loader (every local model stable).
    file::load(&args.out).with_context(|| {
        format!(
            "{} does not pass the strict model check",
            args.out.display()
        )
    })?;

    let png = side_file(&args.out, &format!("-long-train.{}", args.format.ext()));
    let long = long_train(&args, &model.lmn, &fixed, &result, &png)?;
    let md = report(&args, &result, before, after, &png, long);
    let md_path = side_file(&args.out, "-modify.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    println!("{md}");
    println!(
        "modified model written to {} (report {}, plot {})",
        args.out.display(),
        md_path.display(),
        png.display()
    );
    Ok(())
}

/// Training and test MSSE (eq. B.8).
fn errors(lmn: &Lmn, data: &Data) -> Result<(f64, f64)> {
    let net = lmn.network().context("building the network")?;
    Ok((
        msse(&net, data.train_pairs()).context("training MSSE")?,
        msse(&net, data.test_pairs()).context("test MSSE")?,
    ))
}

/// Summary of the long train: (max |y| original, max |y| modified, final y modified).
type LongTrain = (f64, f64, f64);

fn long_train(
    args: &Args,
    original: &Lmn,
    fixed: &Lmn,
    result: &Stabilised,
    png: &Path,
) -> Result<LongTrain> {
    let ts = fixed.ts;
    let n = (args.long_train_ms as f64 * 1e-3 / ts).round() as usize;
    let pulses = constant_train(args.long_train_hz, 0, n, ts)
        .with_context(|| format!("--long-train-hz {}", args.long_train_hz))?;
    let mut u = vec![0.0; n];
    for k in pulses {
        u[k] = 1.0;
    }
    let t0 = simulate_trace(&original.network()?, &u).context("original model")?;
    let t1 = simulate_trace(&fixed.network()?, &u).context("modified model")?;
    let ts_ms = ts * 1e3;
    let fig = Figure {
        title: format!(
            "{} Hz constant train: original (unstable) and modified model (Fig. 5.32(a))",
            args.long_train_hz
        ),
        columns: vec![
            vec![
                (3, output_panel(&t0, &t1, ts_ms)),
                (1, activation_panel(fixed, result, &t1, ts_ms)?),
            ],
            vec![(1, phase_plane(&t0, &t1, ts_ms))],
        ],
    };
    plots::save(&fig, png, (1300, 600))?;
    Ok((
        max_abs(&t0.y),
        max_abs(&t1.y),
        t1.y.last().copied().unwrap_or(0.0),
    ))
}

/// The largest |y| of a trace, infinite when any sample is not finite.
fn max_abs(y: &[f64]) -> f64 {
    y.iter().fold(0.0f64, |a, v| {
        if v.is_finite() {
            a.max(v.abs())
        } else {
            f64::INFINITY
        }
    })
}

/// A trace as (ms, value) points.
fn trace_points(y: &[f64], ts_ms: f64) -> Vec<(f64, f64)> {
    y.iter()
        .enumerate()
        .map(|(k, &v)| (k as f64 * ts_ms, v))
        .collect()
}

/// Both models' outputs (Fig. 5.32(a)), axes from the modified model's, with a note where
/// the original leaves them.
fn output_panel(t0: &Trace, t1: &Trace, ts_ms: f64) -> Panel {
    let finite = || t1.y.iter().copied().filter(|v| v.is_finite());
    let hi = finite().fold(0.0, f64::max);
    let lo = finite().fold(0.0, f64::min);
    let span = (hi - lo).max(0.1);
    let (ylo, yhi) = (lo - 0.5 * span, hi + 0.5 * span);
    let leaves =
        t0.y.iter()
            .position(|v| !(v.is_finite() && (ylo..=yhi).contains(v)))
            .map(|k| k as f64 * ts_ms);
    let peak = max_abs(&t0.y);
    let peak = if peak < 1e4 {
        format!("{peak:.2}")
    } else if peak.is_finite() {
        format!("{peak:.3e}")
    } else {
        "infinite".into()
    };
    Panel {
        x_label: "time (ms)".into(),
        y_label: "model output (normalised force)".into(),
        y: Some((ylo, yhi)),
        lines: vec![
            Line::new(
                Some("original".to_string()),
                trace_points(&t0.y, ts_ms),
                color(3),
            )
            .dashed(),
            Line::new(
                Some("modified".to_string()),
                trace_points(&t1.y, ts_ms),
                color(0),
            ),
        ],
        hline: Some(0.0),
        texts: leaves
            .map(|t| {
                vec![(
                    t + 20.0,
                    hi + 0.35 * span,
                    format!("original leaves the plot at {t:.0} ms (max |y| {peak})"),
                )]
            })
            .unwrap_or_default(),
        legend: true,
        ..Panel::default()
    }
}

/// The activations of the units the modification changed, along the modified model's run.
fn activation_panel(fixed: &Lmn, result: &Stabilised, t1: &Trace, ts_ms: f64) -> Result<Panel> {
    let net = fixed.network()?;
    let mut lines = Vec::new();
    let mut seen = Vec::new();
    let units =
        (result.offsets.iter().map(|o| o.unit)).chain(result.changes.iter().map(|c| c.unit));
    for i in units {
        if seen.contains(&i) {
            continue;
        }
        seen.push(i);
        let rho: Vec<(f64, f64)> = t1
            .phi
            .iter()
            .enumerate()
            .map(|(k, &phi)| (k as f64 * ts_ms, net.validity().eval(phi).get(i)))
            .collect();
        lines.push(Line::new(
            Some(format!("rho_{i} (modified unit)")),
            rho,
            color(2 + seen.len()),
        ));
    }
    Ok(Panel {
        x_label: "time (ms)".into(),
        y_label: "activation".into(),
        y: Some((0.0, 1.05)),
        lines,
        legend: true,
        ..Panel::default()
    })
}

/// State trajectories of both models over the first 300 ms (Fig. 5.32(b)), axes from the
/// modified model's trajectory.
fn phase_plane(t0: &Trace, t1: &Trace, ts_ms: f64) -> Panel {
    let n = ((300.0 / ts_ms) as usize).min(t1.x.len());
    let traj = |t: &Trace| -> Vec<(f64, f64)> {
        t.x[..n.min(t.x.len())]
            .iter()
            .map(|x| (x[0], x[1]))
            .collect()
    };
    let m = traj(t1);
    let ext = |f: &dyn Fn(&(f64, f64)) -> f64| {
        let (lo, hi) = m
            .iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        let span = (hi - lo).max(1e-9);
        (lo - 0.3 * span, hi + 0.3 * span)
    };
    Panel {
        title: Some("state trajectories, 0-300 ms (Fig. 5.32(b))".into()),
        x_label: "x_1".into(),
        y_label: "x_2".into(),
        x: Some(ext(&|p| p.0)),
        y: Some(ext(&|p| p.1)),
        lines: vec![
            Line::new(Some("original".to_string()), traj(t0), color(3)).dashed(),
            Line::new(Some("modified".to_string()), m, color(0)),
        ],
        legend: true,
        ..Panel::default()
    }
}

fn report(
    args: &Args,
    r: &Stabilised,
    before: (f64, f64),
    after: (f64, f64),
    png: &Path,
    long: LongTrain,
) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Modification of `{}` (thesis 5.4.3)\n",
        args.model.display()
    );
    if r.changes.is_empty() {
        let _ = writeln!(
            md,
            "Every local model is already stable: nothing was changed.\n"
        );
    } else {
        let rows: Vec<Vec<String>> = r
            .changes
            .iter()
            .map(|c| {
                vec![
                    c.unit.to_string(),
                    c.index.to_string(),
                    format!("{:.4}", c.old),
                    format!("{:.4}", c.new),
                ]
            })
            .collect();
        md.push_str("Replaced eigenvalues (1/s):\n\n");
        md.push_str(&md_table(
            &["unit", "eigenvalue #", "before", "after"],
            &rows,
        ));
        md.push('\n');
    }
    if !r.offsets.is_empty() {
        let f = |v: [f64; 3]| format!("{:.6}, {:.6}, {:.6}", v[0], v[1], v[2]);
        let rows: Vec<Vec<String>> = r
            .offsets
            .iter()
            .map(|o| vec![o.unit.to_string(), f(o.before), f(o.after)])
            .collect();
        let _ = writeln!(
            md,
            "Re-estimated offsets (d^x_0, d^x_1, d^y) on the training records (exact linear least squares on Dual sensitivities, {} step(s)):\n",
            r.iterations
        );
        md.push_str(&md_table(&["unit", "before", "after"], &rows));
        md.push('\n');
    } else if !r.changes.is_empty() {
        md.push_str(
            "The model has its offsets fixed at zero: only the eigenvalues were replaced.\n\n",
        );
    }
    md.push_str("Mean squared simulation errors (Table 5.4):\n\n");
    md.push_str(&md_table(
        &["LMN", "training MSSE", "test MSSE"],
        &[
            vec!["original".into(), sci(before.0), sci(before.1)],
            vec![
                "eigenvalue replaced only".into(),
                sci(r.msse_replaced),
                "".into(),
            ],
            vec!["modified".into(), sci(after.0), sci(after.1)],
        ],
    ));
    let _ = writeln!(
        md,
        "\n{} Hz, {} ms constant train: max |output| original {}, modified {:.4} (final value {:.4}).\n",
        args.long_train_hz,
        args.long_train_ms,
        if long.0.is_finite() {
            format!("{:.4}", long.0)
        } else {
            "diverges".into()
        },
        long.1,
        long.2
    );
    let _ = writeln!(
        md,
        "![long train]({})\n",
        png.file_name()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default()
    );
    md
}
