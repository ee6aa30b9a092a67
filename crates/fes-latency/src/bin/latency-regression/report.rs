//! The printed table, the printed gate, and `report.md`.

use std::fmt::Write as _;
use std::path::Path;

use crate::check_line;
use crate::gate::Check;
use fes_latency::Percentiles;

use crate::summary::{Condition, ConditionSummary, Summary, Unconfirmed};

/// The rows of one condition's table.
fn rows(s: &ConditionSummary) -> Vec<(&'static str, Option<Percentiles>)> {
    vec![
        ("wake-up lateness", Some(s.wake_us)),
        ("input (receive references)", Some(s.input_us)),
        ("compute (tick source)", Some(s.compute_us)),
        ("publish (+notify)", Some(s.publish_us)),
        ("IPC publish -> receive", Some(s.ipc_us)),
        ("driver forward path", s.driver_forward_us),
        ("cyclictest", s.cyclictest_us),
    ]
}

fn ratio(r: Option<f64>) -> String {
    r.map_or("-".to_owned(), |r| format!("{r:.2}"))
}

/// Prints every condition's table and ratios.
pub fn print_table(summary: &Summary) {
    for (c, s) in &summary.conditions {
        println!(
            "-- {} ({} s, {} rounds, load: {})",
            c.key(),
            s.seconds,
            s.rounds,
            s.load.as_deref().unwrap_or("none")
        );
        Percentiles::print_header();
        for (name, p) in rows(s) {
            match p {
                Some(p) => p.print_row(name),
                None => println!("{name:<28} {:>9}", "absent"),
            }
        }
        println!(
            "ticks {}, missed periods {}, late wake-ups {} (cyclictest {} of {}); ratio p99 {}, p99.9 {}",
            s.ticks,
            s.misses,
            s.overruns,
            s.cyclictest_over_period,
            s.cyclictest_samples,
            ratio(s.ratio_p99),
            ratio(s.ratio_p999)
        );
        println!(
            "median over rounds of the per-round p99 ratio: {}",
            ratio(s.ratio_p99_round_median)
        );
        if let Some(d) = &s.driver {
            println!("driver: {}", driver_line(d));
        }
    }
    if let Some(note) = &summary.driver_forward_note {
        println!("driver forward path: {note}");
    }
    for u in &summary.unconfirmed {
        println!("{}", unconfirmed_line(u));
    }
}

/// A measurement measured again, in one line.
fn unconfirmed_line(u: &Unconfirmed) -> String {
    format!(
        "{} attempt {} failed {} and was measured again (kept in {})",
        u.condition.key(),
        u.attempt,
        u.failed.join(", "),
        u.dir
    )
}

/// The driver's counters in one line.
fn driver_line(d: &serde_json::Value) -> String {
    let n = |k: &str| d[k].as_u64().map_or("?".to_owned(), |v| v.to_string());
    format!(
        "{} StimTicks ({} lost, {} refused), {} PULSE written, {} refused by its interlocks, \
         {} while not armed, {} applied by the stimulator, {} write errors, {} trips ({} arms), \
         {} hot-path heap allocations",
        n("ticks_received"),
        n("ticks_lost"),
        n("ticks_refused"),
        n("pulses_sent"),
        n("pulses_rejected"),
        n("pulses_not_armed"),
        n("stimulator_pulses"),
        n("can_tx_errors"),
        n("trips"),
        n("arms"),
        n("hot_path_allocations"),
    )
}

/// Prints the gate; returns whether every check passed.
pub fn print_checks(checks: &[Check], baseline: &Path) -> bool {
    println!("gate against {}:", baseline.display());
    println!(
        "{:<8} {:<22} {:>10} {:>10}",
        "cond.", "check", "value", "limit"
    );
    for c in checks {
        println!("{}", check_line(c));
    }
    let failed: Vec<String> = checks
        .iter()
        .filter(|c| !c.passed)
        .map(|c| format!("{}.{}", c.condition.key(), c.key))
        .collect();
    if failed.is_empty() {
        println!("PASS: no regression");
        true
    } else {
        println!("FAIL: regressed: {}", failed.join(", "));
        false
    }
}

/// `report.md`.
pub fn markdown(summary: &Summary, checks: Option<&[Check]>, baseline: &Path) -> String {
    let mut md = String::new();
    write_header(&mut md, summary);
    for (c, s) in &summary.conditions {
        write_condition(&mut md, *c, s);
    }
    write_driver_and_logs(&mut md, summary);
    match checks {
        Some(checks) => write_gate(&mut md, summary, checks, baseline),
        None => {
            let _ = writeln!(md, "No baseline comparison (`--no-baseline`).");
        }
    }
    md
}

/// The report's title, the run's circumstances and the test-slowdown warning.
fn write_header(md: &mut String, summary: &Summary) {
    let _ = writeln!(md, "# Latency regression report\n");
    let _ = writeln!(
        md,
        "Started {} on kernel {}; load average before `{}`, after `{}`.\n\nCommand: `{}`\n",
        summary.started,
        summary.kernel,
        summary.load_average[0],
        summary.load_average[1],
        summary.command
    );
    if let Some(us) = summary.test_slowdown_us {
        let _ = writeln!(
            md,
            "**TEST SLOWDOWN ON: every tick busy-waited {us} µs (`FES_TEST_TICK_BUSY_US`).**\n"
        );
    }
}

/// One condition's section: its table, counters and ratios.
fn write_condition(md: &mut String, c: Condition, s: &ConditionSummary) {
    let _ = writeln!(
        md,
        "## {}\n\n{} s of rt-core and {} s of cyclictest in {} alternating rounds; load: {}.\n",
        c.key(),
        s.seconds,
        s.seconds,
        s.rounds,
        s.load.as_deref().unwrap_or("none")
    );
    let _ = writeln!(md, "| latency (µs) | p50 | p99 | p99.9 | max |");
    let _ = writeln!(md, "|---|---|---|---|---|");
    for (name, p) in rows(s) {
        match p {
            Some(p) => {
                let _ = writeln!(
                    md,
                    "| {name} | {:.1} | {:.1} | {:.1} | {:.1} |",
                    p.p50, p.p99, p.p999, p.max
                );
            }
            None => {
                let _ = writeln!(md, "| {name} | absent | | | |");
            }
        }
    }
    let _ = writeln!(
        md,
        "\n{} ticks, {} missed periods in {} late wake-ups; cyclictest {} of {} samples at \
         or above one period; hot-path heap allocations {}; probe lost {}. \
         Ratio of wake-up lateness to cyclictest's: **p99 {}, p99.9 {}** (median over the \
         rounds of the per-round p99 ratio: {}).\n\n\
         cyclictest: `{}`\n",
        s.ticks,
        s.misses,
        s.overruns,
        s.cyclictest_over_period,
        s.cyclictest_samples,
        s.hot_path_allocations,
        s.probe_lost,
        ratio(s.ratio_p99),
        ratio(s.ratio_p999),
        ratio(s.ratio_p99_round_median),
        s.cyclictest_command.as_deref().unwrap_or("not run")
    );
}

/// The driver's method note and counters, the plot and the list of interval logs.
fn write_driver_and_logs(md: &mut String, summary: &Summary) {
    if let Some(note) = &summary.driver_forward_note {
        let _ = writeln!(md, "Driver forward path: {note}.\n");
    }
    for (c, s) in &summary.conditions {
        if let Some(d) = &s.driver {
            let _ = writeln!(md, "Driver, {}: {}.\n", c.key(), driver_line(d));
        }
    }
    let _ = writeln!(md, "![latency by percentile](percentiles.png)\n");
    let _ = writeln!(
        md,
        "Interval logs (HdrHistogram `.hlog`, ns): `<condition>/rt-core-N.hlog` (tags wake, \
         input, compute, publish), `<condition>/rt-probe-N.hlog` (ipc, receive), \
         `<condition>/cyclictest.hlog`, `<condition>/driver-N.hlog` (tick_to_can, can_write, \
         and the driver's own ipc, compute, input, wake).\n"
    );
}

/// The gate's section: the measurements measured again and the checks' table.
fn write_gate(md: &mut String, summary: &Summary, checks: &[Check], baseline: &Path) {
    let _ = writeln!(md, "## Gate against `{}`\n", baseline.display());
    if !summary.unconfirmed.is_empty() {
        let _ = writeln!(
            md,
            "The figures above are each condition's last measurement. Measured \
             again after failing the gate (`--confirm`):\n"
        );
        for u in &summary.unconfirmed {
            let _ = writeln!(md, "- {}", unconfirmed_line(u));
        }
        let _ = writeln!(md);
    }
    let _ = writeln!(md, "| condition | check | value | limit | result |");
    let _ = writeln!(md, "|---|---|---|---|---|");
    for c in checks {
        let _ = writeln!(
            md,
            "| {} | {} | {:.3} | {:.3} | {} |",
            c.condition.key(),
            c.key,
            c.value,
            c.limit,
            if c.passed {
                crate::verdict(c)
            } else {
                "**REGRESSED**"
            }
        );
    }
}
