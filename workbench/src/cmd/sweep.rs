//! `fes sweep`: every network size of one structure, the table and bar plot of thesis
//! Figs. 5.13-5.21, and the size with the lowest test MSSE (the thesis's rule).

use super::identify::{FitArgs, load_delivered, stamp_undelivered};
use super::{Feedback, fmt_err};
use anyhow::{Context, Result, bail};
use fes_ident::ident::sweep::{Sweep, SweepRow, sweep};
use fes_model::model::file;
use plotters::prelude::*;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

const AFTER_HELP: &str = "\
Fits --units sizes one after the other (each as `fes identify` would), prints the
table (train MSPE for ARX structures, train MSSE, test MSSE; eq. B.8 at 1 ms) and marks
with * the size with the lowest test MSSE: the thesis's rule for the network size (5.4).
With --out DIR also writes sweep.md, sweep.json, sweep.png (bars like Figs. 5.13-5.21,
log scale) and one model file per size (units_<M>.lmn.json).

EXAMPLE
  fes sweep --data data/fast --structure ss-eig-common --units 1..10 --out sweep-fast";

/// `fes sweep` arguments.
#[derive(Debug, clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    #[command(flatten)]
    pub fit: FitArgs,
    /// Sizes: `A..B` (inclusive, as the thesis writes 1..10), `A..=B`, or one number.
    #[arg(long, default_value = "1..10", value_parser = parse_units)]
    pub units: RangeInclusive<usize>,
    /// Output directory for the table, plot and models (created if needed).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Format of the figures: png (raster) or svg (vector, for papers).
    #[arg(long, value_enum, default_value_t = workbench::plots::FigureFormat::Png)]
    pub format: workbench::plots::FigureFormat,
}

/// A `--units` value that is not a range of network sizes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UnitsError {
    /// A bound is not a whole number.
    #[error("`{0}` is not a whole number of units")]
    NotANumber(String),
    /// The bounds are out of order or outside 1..=MAX_UNITS.
    #[error("unit range {from}..{to}: need 1 <= A <= B <= {max}")]
    OutOfRange {
        /// A.
        from: usize,
        /// B.
        to: usize,
        /// The largest network size.
        max: usize,
    },
}

/// Parses `A..B`, `A..=B` (both inclusive) or `A`, each in 1..=16.
pub fn parse_units(s: &str) -> Result<RangeInclusive<usize>, UnitsError> {
    let num = |t: &str| {
        t.trim()
            .parse::<usize>()
            .map_err(|_| UnitsError::NotANumber(t.to_string()))
    };
    let (a, b) = match s.split_once("..") {
        Some((a, b)) => (num(a)?, num(b.trim_start_matches('='))?),
        None => {
            let a = num(s)?;
            (a, a)
        }
    };
    let max = fes_model::model::validity::MAX_UNITS;
    if a == 0 || b > max || a > b {
        return Err(UnitsError::OutOfRange {
            from: a,
            to: b,
            max,
        });
    }
    Ok(a..=b)
}

/// The Markdown table of a sweep (best size marked with *).
pub fn table(sw: &Sweep) -> String {
    let mut s = String::from(
        "| units | train MSPE | train MSSE | test MSSE | test fit (%) | iterations | time (s) | stable |\n|---:|---:|---:|---:|---:|---:|---:|:---:|\n",
    );
    for (i, r) in sw.rows.iter().enumerate() {
        let mark = if sw.best == Some(i) { " *" } else { "" };
        s.push_str(&format!(
            "| {}{mark} | {} | {} | {} | {} | {} | {:.1} | {} |\n",
            r.units,
            fmt_err(r.train_mspe),
            fmt_diverging(r.train_msse),
            fmt_diverging(r.test_msse),
            r.test_fit_percent
                .map_or_else(|| "-".to_owned(), |v| format!("{v:.1}")),
            r.iterations,
            r.seconds,
            if r.stable { "yes" } else { "no" }
        ));
    }
    s
}

fn fmt_diverging(v: Option<f64>) -> String {
    v.map_or_else(|| "diverges".into(), |x| format!("{x:.3e}"))
}

/// Grouped bars per size (train MSPE where defined, train MSSE, test MSSE) on a log scale,
/// the best size marked with *; a diverging fit is drawn as a pale full-height bar.
pub fn plot(rows: &[SweepRow], best: Option<usize>, title: &str, out: &Path) -> Result<()> {
    workbench::on_figure!(out, (900, 500), |root| {
        draw(&root, rows, best, title)
            .map_err(|m| anyhow::anyhow!("{}: drawing failed: {m}", out.display()))
    })
}

/// The log axis's range: a third of the smallest positive error to five times the largest
/// (1e-6..1 when there is none).
fn mse_axis(rows: &[SweepRow]) -> (f64, f64) {
    let vals: Vec<f64> = rows
        .iter()
        .flat_map(|r| [r.train_mspe, r.train_msse, r.test_msse])
        .flatten()
        .filter(|v| *v > 0.0)
        .collect();
    let lo = vals.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = vals.iter().copied().fold(0.0, f64::max);
    if vals.is_empty() {
        (1e-6, 1.0)
    } else {
        (lo / 3.0, hi * 5.0)
    }
}

/// (units, value) of bar series `s` (0 train MSPE, 1 train MSSE, 2 test MSSE) for every
/// size where it is defined; None: the fit diverges.
fn bar_values(rows: &[SweepRow], s: usize) -> Vec<(usize, Option<f64>)> {
    rows.iter()
        .filter_map(|r| {
            let v = [r.train_mspe, r.train_msse, r.test_msse][s];
            let defined = s > 0 || r.train_mspe.is_some();
            defined.then_some((r.units, v))
        })
        .collect()
}

/// The left edge of bar `k` (of 3) in the group of a size.
fn bar_x(units: usize, k: f64) -> f64 {
    units as f64 - 0.4 + 0.8 * k / 3.0
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    rows: &[SweepRow],
    best: Option<usize>,
    title: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (lo, hi) = mse_axis(rows);
    root.fill(&WHITE)?;
    // Groups centred on the unit counts.
    let (u0, u1) = match (rows.first(), rows.last()) {
        (Some(a), Some(b)) => (a.units as f64, b.units as f64),
        _ => (1.0, 1.0),
    };
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d((u0 - 0.5)..(u1 + 0.5), (lo..hi).log_scale())?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(rows.len() + 1)
        .x_label_formatter(&|x| {
            if (x - x.round()).abs() < 1e-6 {
                format!("{x:.0}")
            } else {
                String::new()
            }
        })
        .x_desc("number of units")
        .y_desc("MSE (normalised force)")
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .draw()?;
    let colours = [
        RGBColor(60, 60, 60),
        RGBColor(70, 130, 200),
        RGBColor(230, 140, 40),
    ];
    let names = ["train MSPE", "train MSSE", "test MSSE"];
    let with_mspe = rows.iter().any(|r| r.train_mspe.is_some());
    for (s, (&colour, name)) in colours.iter().zip(names).enumerate() {
        if s == 0 && !with_mspe {
            continue;
        }
        chart
            .draw_series(bar_values(rows, s).iter().map(|&(u, v)| {
                // A diverging fit: a pale bar to the top of the axis.
                let (top, style) = match v {
                    Some(v) => (v, colour.filled()),
                    None => (hi, colour.mix(0.25).filled()),
                };
                Rectangle::new(
                    [(bar_x(u, s as f64), lo), (bar_x(u, s as f64 + 1.0), top)],
                    style,
                )
            }))?
            .label(name)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], colour.filled()));
    }
    if let Some(b) = best
        && let Some(t) = rows[b].test_msse
    {
        let u = rows[b].units;
        chart.draw_series(std::iter::once(Text::new(
            "*",
            (bar_x(u, 2.2), t * 1.6),
            ("sans-serif", 28),
        )))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    root.present()?;
    Ok(())
}

/// Runs `fes sweep`.
pub fn run(args: Args) -> Result<()> {
    let (records, undelivered) = load_delivered(&args.fit)?;
    let opts = args.fit.options(*args.units.start(), records.ts)?;
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let mut fb = Feedback::new("", args.fit.verbose);
    let structure = opts.structure;
    let sw = {
        let cur = std::cell::Cell::new(*args.units.start());
        fb.set_prefix(format!("{structure} "));
        let r = fb.with_hooks(|h| {
            sweep(&records, &opts, args.units.clone(), h, &mut |m, r| {
                cur.set(m + 1);
                eprintln!(
                    "{structure} {m} units: test MSSE {} ({:.1} s)",
                    fmt_err(Some(r.metrics.test_msse)),
                    r.seconds
                );
            })
        });
        fb.finish();
        r.context("sweep failed")?
    };
    let text = table(&sw);
    print!("{text}");
    match sw.best {
        Some(b) => println!(
            "best size: {} units (lowest test MSSE, {})",
            sw.rows[b].units,
            fmt_err(sw.rows[b].test_msse)
        ),
        None => println!("every fit diverges on the test data"),
    }
    if let Some(dir) = &args.out {
        for (r, m) in sw.rows.iter().zip(&sw.models) {
            let p = dir.join(format!("units_{}.lmn.json", r.units));
            let mut m = m.clone();
            super::stamp_tool(&mut m, "sweep");
            stamp_undelivered(&mut m, undelivered);
            file::save(&m, &p).with_context(|| format!("cannot write {}", p.display()))?;
        }
        let md = dir.join("sweep.md");
        std::fs::write(
            &md,
            format!("# {structure} on {}\n\n{text}", args.fit.data.display()),
        )
        .with_context(|| format!("cannot write {}", md.display()))?;
        let js = dir.join("sweep.json");
        let json = serde_json::json!({
            "data_set": args.fit.data.display().to_string(),
            "structure": structure.name(),
            "options": opts.to_json(),
            "rows": sw.rows,
            "best_units": sw.best.map(|b| sw.rows[b].units),
        });
        std::fs::write(&js, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("cannot write {}", js.display()))?;
        let png = args.format.file(dir, "sweep");
        plot(
            &sw.rows,
            sw.best,
            &format!("{structure}, {}", args.fit.data.display()),
            &png,
        )?;
        println!("wrote {}", dir.display());
    }
    if sw.best.is_none() {
        bail!("no size gave a finite test MSSE");
    }
    Ok(())
}
