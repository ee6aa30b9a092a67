//! `latency-regression`: the latency regression suite (`scripts/latency-regression` builds
//! the release binaries and runs this).
//!
//! For each load condition (none, then `stress-ng --cpu 1` on the other core) it runs
//! `rt-latency` (the real rt-core loop with a subscriber process, alternating with
//! cyclictest on the same core), then writes into `--out-dir`:
//! `report.md` (tables, ratios, the gate), `percentiles.png` (latency by percentile),
//! `summary.json` (also `--json FILE`) and, per condition, rt-latency's `.hlog` files.
//! It compares the ratios with the stored baseline and exits 1 when one regressed
//! beyond the baseline's tolerance (`gate.rs` states the rules), 2 when it could not
//! measure or judge, 0 otherwise. `--compare SUMMARY` judges a stored summary again.

mod gate;
mod plot;
mod report;
mod summary;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use fes_rt::rt::exit::Exit;

use anyhow::{Context, bail};
use clap::Parser;
use fes_rt::rt::histogram::LatencyHistogram;
use fes_rt::rt::hlog::{merge_by_tag, read_intervals};

use gate::{Baseline, Check};
use summary::{
    Condition, ConditionSummary, DRIVER_FORWARD_METHOD, SUMMARY_SCHEMA, Summary, Unconfirmed,
};

/// The latency regression suite: rt-core's loop against cyclictest, with and without
/// load, compared with a stored baseline.
#[derive(Debug, Parser)]
#[command(name = "latency-regression", version)]
struct Cli {
    /// Seconds of rt-core per condition (and as many of cyclictest, alternating): 5 is
    /// the CI short form (about 20 s of measurement for both conditions), 300 the long
    /// form (10 minutes per condition).
    #[arg(long, default_value_t = 5)]
    seconds: u64,
    /// Only the loaded condition.
    #[arg(long, conflicts_with = "no_load")]
    load: bool,
    /// Only the unloaded condition.
    #[arg(long)]
    no_load: bool,
    /// Alternating rounds per condition (default: 1 s rounds up to 20 s, else 10 s).
    #[arg(long)]
    rounds: Option<u64>,
    /// Core of the real-time loop and cyclictest.
    #[arg(long, default_value_t = 1)]
    core: usize,
    /// Core of the subscriber process (default: the loop's core, one priority below it,
    /// as the driver sits; a loop that hogs its core then starves it).
    #[arg(long)]
    probe_core: Option<usize>,
    /// rt-core configuration to measure (default: rt-latency's test-pattern source).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Report directory.
    #[arg(long, value_name = "DIR", default_value = "latency-report")]
    out_dir: PathBuf,
    /// Also write the summary here.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Baseline to compare with.
    #[arg(
        long,
        value_name = "FILE",
        default_value = "crates/fes-latency/latency-baseline.json"
    )]
    baseline: PathBuf,
    /// Measure and report without comparing.
    #[arg(long, conflicts_with = "baseline")]
    no_baseline: bool,
    /// Directory holding rt-latency, rt-core and rt-probe (default: this program's).
    #[arg(long, value_name = "DIR")]
    bin_dir: Option<PathBuf>,
    /// Re-measurements of a condition that fails the gate. A regression is reported only
    /// when every measurement of the condition fails: a slower loop fails them all, a host
    /// stall that falls into a 5 s run fails the one it fell into (the failed ones are kept
    /// as `<condition>-attempt-N/` and listed in the report). 0 judges the first alone.
    #[arg(long, default_value_t = 1, value_name = "N")]
    confirm: u32,
    /// Do not measure: judge this summary (written earlier) against the baseline.
    #[arg(long, value_name = "SUMMARY", conflicts_with_all = ["load", "no_load", "no_baseline"])]
    compare: Option<PathBuf>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(&cli) {
        Ok(true) => Exit::Done.into(),
        // A regression and an error both fail (the exit-code convention); the error says
        // `latency-regression: error:`, a regression names the measures over their limits.
        Ok(false) => Exit::Failed.into(),
        Err(e) => {
            eprintln!("latency-regression: error: {e:#}");
            Exit::Failed.into()
        }
    }
}

/// Runs the suite; `Ok(false)` when the gate failed.
fn run(cli: &Cli) -> anyhow::Result<bool> {
    if let Some(path) = &cli.compare {
        return compare_stored(cli, path);
    }
    if cli.seconds == 0 {
        bail!("--seconds must be at least 1");
    }
    // Read the baseline first: a broken one should not cost a measurement.
    let baseline = if cli.no_baseline {
        None
    } else {
        Some(Baseline::load(&cli.baseline)?)
    };
    let rt_latency = locate_rt_latency(cli)?;
    let conditions = conditions(cli);
    let rounds = rounds(cli);
    let slowdown = test_slowdown()?;
    std::fs::create_dir_all(&cli.out_dir)
        .with_context(|| format!("creating {}", cli.out_dir.display()))?;
    let load_before = read_trim("/proc/loadavg");
    let started = utc_now();

    let mut measured = BTreeMap::new();
    let mut panels = Vec::new();
    let mut unconfirmed = Vec::new();
    for &condition in &conditions {
        let (s, panel) = measure_confirmed(
            cli,
            &rt_latency,
            condition,
            rounds,
            baseline.as_ref(),
            &mut unconfirmed,
        )?;
        panels.push(panel);
        measured.insert(condition, s);
    }

    let summary = Summary {
        schema: SUMMARY_SCHEMA.to_owned(),
        ratio_p99: Summary::worst(&measured, |c| c.ratio_p99),
        ratio_p999: Summary::worst(&measured, |c| c.ratio_p999),
        conditions: measured,
        driver_forward_note: Some(DRIVER_FORWARD_METHOD.to_owned()),
        unconfirmed,
        test_slowdown_us: slowdown,
        kernel: read_trim("/proc/sys/kernel/osrelease"),
        load_average: [load_before, read_trim("/proc/loadavg")],
        started,
        command: std::env::args().collect::<Vec<_>>().join(" "),
    };
    let checks = match &baseline {
        Some(b) => Some(gate::compare(&summary.conditions, b)?),
        None => None,
    };
    write_report(cli, &summary, checks.as_deref(), &panels)?;

    report::print_table(&summary);
    println!("report: {}/report.md", cli.out_dir.display());
    Ok(match &checks {
        Some(checks) => report::print_checks(checks, &cli.baseline),
        None => {
            println!("no baseline comparison (--no-baseline)");
            true
        }
    })
}

/// `--compare`: judges a stored summary against the baseline and prints the gate.
fn compare_stored(cli: &Cli, path: &Path) -> anyhow::Result<bool> {
    let s = Summary::load(path)?;
    let baseline = Baseline::load(&cli.baseline)?;
    let checks = gate::compare(&s.conditions, &baseline)?;
    Ok(report::print_checks(&checks, &cli.baseline))
}

/// The `rt-latency` binary in `--bin-dir` (default: this program's directory).
fn locate_rt_latency(cli: &Cli) -> anyhow::Result<PathBuf> {
    let bin_dir = match &cli.bin_dir {
        Some(d) => d.clone(),
        None => std::env::current_exe()
            .context("locating latency-regression")?
            .parent()
            .context("latency-regression has no directory")?
            .to_path_buf(),
    };
    let rt_latency = bin_dir.join("rt-latency");
    if !rt_latency.is_file() {
        bail!(
            "{} not found (build it: cargo build --release -p rt-core --bins)",
            rt_latency.display()
        );
    }
    Ok(rt_latency)
}

/// The load conditions to measure (`--load`, `--no-load`, default both).
fn conditions(cli: &Cli) -> Vec<Condition> {
    match (cli.load, cli.no_load) {
        (true, _) => vec![Condition::Load],
        (_, true) => vec![Condition::NoLoad],
        _ => vec![Condition::NoLoad, Condition::Load],
    }
}

/// The rounds per condition (`--rounds`, else by the run's length).
fn rounds(cli: &Cli) -> u64 {
    // 1 s rounds in a short run (as many alternations as possible, so that both sides
    // see the same hypervisor stalls), 10 s rounds in a long one.
    cli.rounds
        .unwrap_or(if cli.seconds <= 20 {
            cli.seconds
        } else {
            cli.seconds.div_ceil(10)
        })
        .clamp(1, cli.seconds)
}

/// Measures a condition, and again (up to `--confirm` times) while it fails the gate;
/// the failed measurements are set aside and added to `unconfirmed`. Returns the last.
fn measure_confirmed(
    cli: &Cli,
    rt_latency: &Path,
    condition: Condition,
    rounds: u64,
    baseline: Option<&Baseline>,
    unconfirmed: &mut Vec<Unconfirmed>,
) -> anyhow::Result<(ConditionSummary, plot::Panel)> {
    let dir = cli.out_dir.join(condition.key());
    let mut attempt = 1;
    loop {
        let (s, panel) = measure(cli, rt_latency, condition, &dir, rounds)?;
        let Some(b) = baseline else {
            return Ok((s, panel));
        };
        let alone = BTreeMap::from([(condition, s.clone())]);
        let failed: Vec<String> = gate::compare(&alone, b)?
            .into_iter()
            .filter(|c| !c.passed)
            .map(|c| c.key)
            .collect();
        if failed.is_empty() || attempt > cli.confirm {
            return Ok((s, panel));
        }
        // Keep the failed measurement for inspection and measure again: a regression
        // of the code fails every measurement, a host stall the one it fell into.
        let kept = set_aside(cli, condition, &dir, attempt)?;
        println!(
            "== {}: attempt {attempt} failed {}; measuring again to confirm ({} of {})",
            condition.key(),
            failed.join(", "),
            attempt,
            cli.confirm
        );
        unconfirmed.push(Unconfirmed {
            condition,
            attempt,
            failed,
            dir: kept.display().to_string(),
        });
        attempt += 1;
    }
}

/// Moves a failed measurement's `dir` to `<condition>-attempt-N/`, replacing an old one.
fn set_aside(cli: &Cli, condition: Condition, dir: &Path, attempt: u32) -> anyhow::Result<PathBuf> {
    let kept = cli
        .out_dir
        .join(format!("{}-attempt-{attempt}", condition.key()));
    if kept.exists() {
        std::fs::remove_dir_all(&kept).with_context(|| format!("removing {}", kept.display()))?;
    }
    std::fs::rename(dir, &kept).with_context(|| format!("moving {} aside", dir.display()))?;
    Ok(kept)
}

/// Writes `summary.json` (and `--json`), `percentiles.png` and `report.md`.
fn write_report(
    cli: &Cli,
    summary: &Summary,
    checks: Option<&[Check]>,
    panels: &[plot::Panel],
) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(summary)?;
    for path in std::iter::once(cli.out_dir.join("summary.json")).chain(cli.json.clone()) {
        std::fs::write(&path, &text).with_context(|| format!("writing {}", path.display()))?;
    }
    plot::draw(panels, &cli.out_dir.join("percentiles.png"))?;
    let md = report::markdown(summary, checks, &cli.baseline);
    std::fs::write(cli.out_dir.join("report.md"), md)
        .with_context(|| format!("writing {}/report.md", cli.out_dir.display()))?;
    Ok(())
}

/// One `rt-latency` run of a condition into `dir`: its summary and its percentile panel.
fn measure(
    cli: &Cli,
    rt_latency: &Path,
    condition: Condition,
    dir: &Path,
    rounds: u64,
) -> anyhow::Result<(ConditionSummary, plot::Panel)> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let json = dir.join("rt-latency.json");
    let mut cmd = Command::new(rt_latency);
    cmd.arg("--seconds")
        .arg(cli.seconds.to_string())
        .arg("--rounds")
        .arg(rounds.to_string())
        .arg("--core")
        .arg(cli.core.to_string())
        .arg("--out-dir")
        .arg(dir)
        .arg("--json")
        .arg(&json)
        .arg("--driver");
    if condition == Condition::Load {
        cmd.arg("--load");
    }
    if let Some(core) = cli.probe_core {
        cmd.arg("--probe-core").arg(core.to_string());
    }
    if let Some(config) = &cli.config {
        cmd.arg("--config").arg(config);
    }
    println!("== {}: {}", condition.key(), command_text(&cmd));
    let status = cmd
        .status()
        .with_context(|| format!("running {}", rt_latency.display()))?;
    if !status.success() {
        bail!("rt-latency ({}) failed: {status}", condition.key());
    }
    let mut s = ConditionSummary::from_rt_latency_json(&json)?;
    s.ratio_p99_round_median = round_median_ratio_p99(dir, s.rounds)?;
    let panel = plot::Panel {
        title: match condition {
            Condition::NoLoad => "no load".to_owned(),
            Condition::Load => format!("load: {}", s.load.as_deref().unwrap_or("?")),
        },
        curves: curves(dir, s.rounds)?,
    };
    Ok((s, panel))
}

/// The test-only slowdown rt-core will apply (it reads the same variable and validates it;
/// here it is only recorded in the summary).
fn test_slowdown() -> anyhow::Result<Option<u64>> {
    match std::env::var("FES_TEST_TICK_BUSY_US") {
        Ok(v) => {
            let us = v
                .trim()
                .parse()
                .with_context(|| format!("FES_TEST_TICK_BUSY_US={v:?}: not a number of µs"))?;
            println!("TEST SLOWDOWN: every tick busy-waits {us} µs (FES_TEST_TICK_BUSY_US)");
            Ok(Some(us))
        }
        Err(std::env::VarError::NotPresent) => Ok(None),
        Err(e) => bail!("FES_TEST_TICK_BUSY_US: {e}"),
    }
}

/// The median over the rounds of wake-up p99 / cyclictest p99, each pair from one round
/// (`rt-core-N.hlog` and interval N of `cyclictest.hlog`, whose values are already the
/// middles of cyclictest's microsecond buckets); `None` without cyclictest.
fn round_median_ratio_p99(dir: &Path, rounds: u64) -> anyhow::Result<Option<f64>> {
    let path = dir.join("cyclictest.hlog");
    if !path.is_file() {
        return Ok(None);
    }
    let cyclic: Vec<_> = read_intervals(&path)?
        .into_iter()
        .filter(|i| i.tag == "cyclictest")
        .collect();
    if cyclic.len() as u64 != rounds {
        bail!(
            "{}: {} cyclictest intervals for {rounds} rounds",
            path.display(),
            cyclic.len()
        );
    }
    let mut ratios = Vec::new();
    for (round, interval) in cyclic.iter().enumerate() {
        let file = dir.join(format!("rt-core-{round}.hlog"));
        let wake = merge_by_tag(&file)?
            .remove("wake")
            .with_context(|| format!("{}: no 'wake' intervals", file.display()))?;
        let mut theirs = LatencyHistogram::new();
        theirs.add_raw(&interval.histogram);
        let theirs = theirs.quantile_ns(0.99);
        if wake.count() > 0 && theirs > 0 {
            ratios.push(wake.quantile_ns(0.99) as f64 / theirs as f64);
        }
    }
    if ratios.is_empty() {
        return Ok(None);
    }
    ratios.sort_by(f64::total_cmp);
    let n = ratios.len();
    Ok(Some(if n % 2 == 1 {
        ratios[n / 2]
    } else {
        (ratios[n / 2 - 1] + ratios[n / 2]) / 2.0
    }))
}

/// The percentile curves of one condition, from rt-latency's interval logs.
fn curves(dir: &Path, rounds: u64) -> anyhow::Result<Vec<plot::Curve>> {
    let mut by_tag: BTreeMap<String, LatencyHistogram> = BTreeMap::new();
    let mut files: Vec<PathBuf> = (0..rounds)
        .flat_map(|r| {
            [
                dir.join(format!("rt-core-{r}.hlog")),
                dir.join(format!("rt-probe-{r}.hlog")),
            ]
        })
        .collect();
    files.push(dir.join("cyclictest.hlog"));
    for file in files {
        for (tag, h) in merge_by_tag(&file)? {
            by_tag.entry(tag).or_default().add(&h);
        }
    }
    let mut curves = Vec::new();
    for (tag, name) in [
        ("wake", "rt-core wake-up lateness"),
        ("ipc", "IPC publish -> receive"),
        ("compute", "compute (tick source)"),
        ("cyclictest", "cyclictest"),
    ] {
        let histogram = by_tag
            .remove(tag)
            .with_context(|| format!("{}: no '{tag}' interval log", dir.display()))?;
        curves.push(plot::Curve {
            name: name.to_owned(),
            histogram,
        });
    }
    // The driver's own log also has `ipc` and `compute` tags (its view): only its forward
    // latency is plotted.
    let mut forward = LatencyHistogram::new();
    for r in 0..rounds {
        let file = dir.join(format!("driver-{r}.hlog"));
        if file.is_file()
            && let Some(h) = merge_by_tag(&file)?.remove("tick_to_can")
        {
            forward.add(&h);
        }
    }
    if forward.count() > 0 {
        curves.push(plot::Curve {
            name: "driver StimTick -> PULSE written".to_owned(),
            histogram: forward,
        });
    }
    Ok(curves)
}

fn command_text(cmd: &Command) -> String {
    std::iter::once(cmd.get_program())
        .chain(cmd.get_args())
        .map(|a| a.to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join(" ")
}

fn read_trim(path: &str) -> String {
    std::fs::read_to_string(path)
        .map(|s| s.trim().to_owned())
        .unwrap_or_else(|_| "unknown".to_owned())
}

fn utc_now() -> String {
    Command::new("date")
        .args(["-u", "+%Y-%m-%dT%H:%M:%SZ"])
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_owned())
        .unwrap_or_else(|| "unknown".to_owned())
}

/// A check as one line of text.
fn check_line(c: &Check) -> String {
    format!(
        "{:<8} {:<22} {:>10.3} {:>10.3}  {}",
        c.condition.key(),
        c.key,
        c.value,
        c.limit,
        verdict(c)
    )
}

/// A check's verdict in words.
fn verdict(c: &Check) -> &'static str {
    match (c.judged, c.passed) {
        (false, _) => "not judged (too few tail samples)",
        (true, true) => "ok",
        (true, false) => "REGRESSED",
    }
}
