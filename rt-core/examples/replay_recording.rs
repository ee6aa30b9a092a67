//! Replays a process-bench recording through rt-core's tick logic ([`PatternLoop`] around
//! the controller's [`ControllerSource`]) and compares every decision with the recorded
//! one: the References and previews the supervisor published are offered at the recorded
//! wake-ups, with the recorded skipped periods, and planning runs on its step budget alone
//! (no clock), so a beat the run planned oddly can be looked at again, tick by tick.
//! docs/bench.md, "The slow muscle at 0.5 on the process bench", found a grid-timing fault
//! this way.
//!
//! `cargo run --release -p rt-core --example replay_recording -- RUN_DIR CONFIG
//! [FROM_NS TO_NS]`: RUN_DIR is a recording's `run-*` directory (`ticks.csv`,
//! `references.csv`, `previews.csv`), CONFIG the `rt-core.toml` the run used (its
//! controller, period, reference policy and pulse; `fes bench --out DIR` writes it to
//! DIR). Model-mode controllers only: the measured force is not replayed. Prints
//! every tick whose pulse differs from the recording, the tick's pulse and the plan in
//! force (pulse times in ticks from the next tick) for ticks whose grid time lies in
//! `[FROM_NS, TO_NS)`, and the planner's counters. Exit 1 when a decision differs.
#![allow(clippy::unwrap_used, clippy::expect_used)] // a tool: a failed step ends it with its message

use std::path::Path;

use fes_rt::msg::{PreviewEdge, Reference, ReferencePreview};
use fes_rt::rt::clock::Wakeup;
use rt_core::rt::process_config::{RtCoreConfig, SourceConfig};
use rt_core::rt::{ControllerSource, PatternLoop};

/// A CSV file of the recording as rows of named fields.
struct Table {
    head: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    fn read(path: &Path) -> Table {
        let (head, rows) = fes_testkit::table::read_csv(path);
        Table { head, rows }
    }

    /// Field `name` of `row`, parsed.
    fn get<T: std::str::FromStr>(&self, row: &[String], name: &str) -> T {
        let i = self
            .head
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name}"));
        row[i]
            .parse()
            .unwrap_or_else(|_| panic!("column {name}: {:?}", row[i]))
    }
}

fn references(t: &Table) -> Vec<Reference> {
    t.rows
        .iter()
        .map(|r| Reference {
            seq: t.get(r, "seq"),
            t_ns: t.get(r, "t_ns"),
            force: t.get(r, "force"),
            max_rate_per_s: t.get(r, "max_rate_per_s"),
            flags: t.get(r, "flags"),
            reserved: [0; 4],
        })
        .collect()
}

fn previews(t: &Table) -> Vec<ReferencePreview> {
    t.rows
        .iter()
        .map(|r| {
            let n: usize = t.get(r, "len");
            let edges: Vec<PreviewEdge> = (0..n)
                .map(|i| PreviewEdge {
                    t_ns: t.get(r, &format!("t_ns_{i}")),
                    force: t.get(r, &format!("force_{i}")),
                    max_rate_per_s: t.get(r, &format!("max_rate_per_s_{i}")),
                })
                .collect();
            ReferencePreview::new(
                t.get(r, "seq"),
                t.get(r, "t_ns"),
                t.get(r, "ref_seq"),
                &edges,
            )
        })
        .collect()
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [dir, config, window @ ..] = args.as_slice() else {
        eprintln!("usage: replay_recording RUN_DIR CONFIG [FROM_NS TO_NS]");
        std::process::exit(2);
    };
    let (from, to): (u64, u64) = match window {
        [a, b] => (a.parse().expect("FROM_NS"), b.parse().expect("TO_NS")),
        _ => (0, 0),
    };
    let dir = Path::new(dir);
    let refs = references(&Table::read(&dir.join("references.csv")));
    let pvs = previews(&Table::read(&dir.join("previews.csv")));
    let ticks = Table::read(&dir.join("ticks.csv"));
    let config = RtCoreConfig::load(Path::new(config)).expect("rt-core configuration");
    let SourceConfig::Controller { path } = &config.source else {
        panic!("the run's source is not a controller file");
    };
    assert!(
        config.feedback_max_age_ns().is_none(),
        "a measured-force run: its force samples are not replayed"
    );
    let source = ControllerSource::load(path, config.period())
        .expect("controller")
        .without_plan_clock();
    let mut pl = PatternLoop::new(
        source,
        config.reference_policy(),
        None,
        config.pulse_settings(),
        false,
    );
    let (mut ri, mut pi, mut differ) = (0, 0, 0usize);
    let mut plan = [0i64; 64];
    for row in &ticks.rows {
        let grid_ns: u64 = ticks.get(row, "t_ns");
        let wake_ns: u64 = ticks.get(row, "t_wake_ns");
        let missed_periods: u32 = ticks.get(row, "missed_periods");
        let recorded: u8 = ticks.get(row, "pulse");
        while ri < refs.len() && refs[ri].t_ns <= wake_ns {
            let _ = pl.offer_reference(&refs[ri], wake_ns);
            ri += 1;
        }
        while pi < pvs.len() && pvs[pi].t_ns <= wake_ns {
            let _ = pl.offer_preview(&pvs[pi], wake_ns);
            pi += 1;
        }
        let wake = Wakeup {
            deadline_ns: grid_ns,
            grid_ns,
            wake_ns,
            lateness_ns: wake_ns.saturating_sub(grid_ns),
            missed_periods,
        };
        let (tick, _) = pl.step(&wake);
        if tick.pulse != recorded {
            differ += 1;
            println!("{grid_ns}: pulse {} (recorded {recorded})", tick.pulse);
        }
        if (from..to).contains(&grid_ns) {
            let planner = pl.source().generator().planner();
            let shown = planner.and_then(|p| p.plan_now(&mut plan));
            let plan = shown.map(|(n, j)| format!("{:?} J {j:.4}", &plan[..n]));
            println!(
                "{grid_ns}: woke +{} us, missed {missed_periods}, target {:.4}, pulse {}, plan {}",
                (wake_ns - grid_ns) / 1000,
                tick.reference,
                tick.pulse,
                plan.as_deref().unwrap_or("none")
            );
        }
    }
    println!("{} ticks, {differ} decisions differ", ticks.rows.len());
    println!("{:?}", pl.source().planner_stats());
    if differ > 0 {
        std::process::exit(1);
    }
}
