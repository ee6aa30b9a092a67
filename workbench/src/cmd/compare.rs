//! `fes compare`: the thesis's Tables 5.1 and 5.2 on one data set.

use super::identify::load_records;
use super::{Feedback, fmt_err};
use anyhow::{Context, Result};
use fes_ident::ident::sweep::{COMPARE_UNITS, CompareRow, QUICK_UNITS, compare, setups};
use std::path::PathBuf;

const AFTER_HELP: &str = "\
Rows: Table 5.1 (single linear models; output and input scheduling; shift parameters at the
linear models' best period of Ts = 1, 5, 10 ms and delta parameters at 1 ms; prediction mode
with local learning and simulation mode), then Table 5.2 (state space, real eigensystems,
local and common eigenvectors) and the common-eigenvector network with offsets fixed at
zero (6.5.3). Each network row sweeps its size and keeps the lowest test MSSE (5.4).

Sizes swept: prediction-mode rows 1..12, simulation-mode rows 1..8 (--quick: 1..3 with at
most 30 LM iterations, for tests). Expect a few minutes on 2 cores without --quick.

EXAMPLE
  fes compare --data data/fast --out compare-fast";

/// `fes compare` arguments.
#[derive(Debug, clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// Data-set directory (fes-dataset/1).
    #[arg(long)]
    pub data: PathBuf,
    /// Output directory for compare.md and compare.json (created if needed).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Small sweeps (1..3 units, 30 iterations): a smoke run.
    #[arg(long)]
    pub quick: bool,
    /// Seed of the perturbed starts.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print every stage and accepted step on stderr.
    #[arg(long, short)]
    pub verbose: bool,
    /// Compare on a recording whose delivered pulses differ from the decided ones
    /// (refused by default, as `fes identify`).
    #[arg(long)]
    pub allow_undelivered: bool,
}

fn e3(v: Option<f64>) -> String {
    v.map_or_else(|| "diverges".into(), |x| format!("{:.3}", x * 1e3))
}

/// The Markdown table (errors x 1e-3, as the thesis prints them). `stable` says whether
/// every local model of the chosen network is stable (an unstable one is a model to
/// repair with `modify --stabilise`, not one to design a controller from).
pub fn table(rows: &[CompareRow]) -> String {
    let mut s = String::from(
        "| scheduling | parameter domain | estimation | Ts (ms) | # units | train MSSE (x1e-3) | test MSSE (x1e-3) | train MSPE (x1e-3) | test fit (%) | stable | sizes tried | time (s) |\n|---|---|---|---:|---:|---:|---:|---:|---:|---|---|---:|\n",
    );
    for r in rows {
        let (units, train, test, mspe, fit, stable) = match &r.best {
            Some(b) => (
                b.units.to_string(),
                e3(b.train_msse),
                e3(b.test_msse),
                b.train_mspe
                    .map_or("-".into(), |v| format!("{:.4}", v * 1e3)),
                b.test_fit_percent.map_or("-".into(), |v| format!("{v:.1}")),
                if b.stable { "yes" } else { "NO" },
            ),
            None => (
                "-".into(),
                "diverges".into(),
                "diverges".into(),
                "-".into(),
                "-".into(),
                "-",
            ),
        };
        s.push_str(&format!(
            "| {} | {} | {} | {} | {units} | {train} | {test} | {mspe} | {fit} | {stable} | {}..{} | {:.0} |\n",
            r.scheduling, r.domain, r.mode, r.ts_ms, r.units_tried.0, r.units_tried.1, r.seconds
        ));
    }
    s
}

/// Runs `fes compare`.
pub fn run(args: Args) -> Result<()> {
    let records = load_records(&args.data)?;
    records
        .check_deliveries(args.allow_undelivered)
        .with_context(|| format!("cannot use data set {}", args.data.display()))?;
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let list = setups(args.quick, args.seed);
    let mut fb = Feedback::new("", args.verbose);
    fb.set_prefix("compare ");
    let rows = fb.with_hooks(|h| {
        compare(&records, &list, h, &mut |s, f, m, r| {
            eprintln!(
                "{} / {} / {:?} / Ts {} / {m} units: test MSSE {} ({:.1} s)",
                s.scheduling,
                s.domain,
                s.mode,
                f as f64 * records.ts * 1e3,
                fmt_err(Some(r.metrics.test_msse)),
                r.seconds
            )
        })
    });
    fb.finish();
    let rows = rows.context("comparison failed")?;
    let text = table(&rows);
    print!("{text}");
    if let Some(dir) = &args.out {
        let md = dir.join("compare.md");
        let (p, s) = if args.quick {
            (QUICK_UNITS, QUICK_UNITS)
        } else {
            COMPARE_UNITS
        };
        std::fs::write(
            &md,
            format!(
                "# Tables 5.1 / 5.2 on {}\n\nBest size per row by test MSSE; prediction rows swept 1..{p}, simulation rows 1..{s}.\n\n{text}",
                args.data.display()
            ),
        )
        .with_context(|| format!("cannot write {}", md.display()))?;
        let js = dir.join("compare.json");
        let json = serde_json::json!({
            "data_set": args.data.display().to_string(),
            "quick": args.quick,
            "seed": args.seed,
            "rows": rows,
        });
        std::fs::write(&js, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("cannot write {}", js.display()))?;
        println!("wrote {}", dir.display());
    }
    Ok(())
}
