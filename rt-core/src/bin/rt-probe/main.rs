//! `rt-probe`: a subscriber process that measures StimTick publish-to-receive latency.
//!
//! It sleeps on the stim-tick event listener (rt-core notifies it after every publish), takes
//! every waiting StimTick, and records `receive time - t_publish_ns` into a bounded
//! HdrHistogram (hlog tag `ipc`, one interval per second), and separately the receive cost
//! alone, from its wake-up to the sample in hand (tag `receive`). It also checks every tick
//! (validation, `seq` gaps), optionally records them all to CSV, keeps rt-core's last
//! TimingReport, and exits after rt-core's final tick (or on SIGINT/SIGTERM, or when no tick
//! came for the idle timeout), writing its JSON summary.
//!
//! Prints `ready` on stdout once subscribed, so a harness can start rt-core after it.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime};

use anyhow::Context;
use clap::Parser;
use fes_rt::msg::port;
use fes_rt::msg::{Contract, StimTick, TimingReport, TimingSource};
use fes_rt::rt::clock::{NS_PER_S, monotonic_ns};
use fes_rt::rt::exit::Exit;
use fes_rt::rt::histogram::LatencyHistogram;
use fes_rt::rt::hlog::HlogWriter;
use fes_rt::rt::node::create_node;
use fes_rt::rt::probe::{ProbeSummary, RECORD_HEADER, TickRecord};
use fes_rt::rt::signals::install_stop_handler;
use fes_rt::rt::telemetry::{TAG_IPC, TAG_RECEIVE};
use fes_rt::rt::{MissingRightsPolicy, RtConfig, enter_realtime};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{Node, ipc};

/// Measures StimTick publish-to-receive latency and checks the tick stream.
#[derive(Debug, Parser)]
#[command(name = "rt-probe", version)]
struct Cli {
    /// iceoryx2 service-name prefix (as rt-core's `ipc.prefix`).
    #[arg(long, default_value = "fes")]
    prefix: String,
    /// Write publish-to-receive latency as an HdrHistogram interval log (tag "ipc").
    #[arg(long, value_name = "FILE")]
    hlog: Option<PathBuf>,
    /// Write every received tick as CSV.
    #[arg(long, value_name = "FILE")]
    record: Option<PathBuf>,
    /// Write a JSON summary on exit.
    #[arg(long, value_name = "FILE")]
    summary: Option<PathBuf>,
    /// SCHED_FIFO priority (1..=99); 0 = normal scheduling.
    #[arg(long, default_value_t = 0)]
    priority: u8,
    /// CPU core to pin to.
    #[arg(long)]
    core: Option<usize>,
    /// Most ticks kept for --record (memory is reserved at start).
    #[arg(long, default_value_t = 120_000)]
    max_ticks: usize,
    /// Exit when no tick arrived for this long, ms.
    #[arg(long, default_value_t = 10_000)]
    idle_timeout_ms: u64,
}

fn main() -> ExitCode {
    fes_rt::rt::logging::init("rt-probe");
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
    match run(&Cli::parse()) {
        Ok(true) => Exit::Done.into(),
        Ok(false) => {
            tracing::warn!("ended without rt-core's final tick");
            Exit::Failed.into()
        }
        Err(e) => {
            tracing::error!("{}", fes_rt::rt::error_text::one_line(e.as_ref()));
            Exit::Failed.into()
        }
    }
}

/// Runs the probe; true when rt-core's final tick was received.
fn run(cli: &Cli) -> anyhow::Result<bool> {
    let stop = install_stop_handler().context("installing signal handlers")?;
    enter_realtime_if_asked(cli)?;
    let mut probe = Probe::open(cli)?;
    probe.run(stop)?;
    probe.finish(cli)
}

/// With `--priority` > 0: SCHED_FIFO at that priority (best effort), pinned to `--core`,
/// memory locked; logs what was achieved.
fn enter_realtime_if_asked(cli: &Cli) -> anyhow::Result<()> {
    if cli.priority > 0 {
        let status = enter_realtime(&RtConfig {
            priority: cli.priority,
            core: cli.core,
            on_missing_rights: MissingRightsPolicy::BestEffort,
            lock_memory: true,
            prefault_stack_bytes: 64 * 1024,
            cpu_dma_latency_us: None,
        })
        .context("real-time settings")?;
        tracing::info!("{status}");
    }
    Ok(())
}

/// The probe's state: its ports, histograms, records and running summary.
struct Probe {
    /// rt-core's ticks.
    ticks: Subscriber<ipc::Service, StimTick, ()>,
    /// Every process's TimingReports (rt-core's are kept).
    reports: Subscriber<ipc::Service, TimingReport, ()>,
    /// The stim-tick event, slept on.
    listener: Listener<ipc::Service>,
    /// The node of the ports (dropped after them).
    _node: Node<ipc::Service>,
    /// The interval log and the histograms of its current interval.
    intervals: Intervals,
    /// Publish-to-receive latency over the whole run.
    ipc: LatencyHistogram,
    /// Every received tick, when `--record` is given (capacity reserved at start).
    records: Vec<TickRecord>,
    /// Whether ticks are recorded (`--record`).
    record: bool,
    /// Counts so far.
    summary: ProbeSummary,
    /// When a tick last arrived (or the start), ns.
    last_activity_ns: u64,
    /// When rt-core's final tick arrived, ns.
    final_seen_ns: Option<u64>,
    /// Exit after no tick for this long, ns.
    idle_ns: u64,
}

/// The hlog file (if any) and the per-interval histograms written to it once a second.
struct Intervals {
    /// The interval log (`--hlog`).
    hlog: Option<HlogWriter>,
    /// Publish-to-receive latency in the current interval (tag `ipc`).
    ipc: LatencyHistogram,
    /// Receive cost alone, from the listener's wake-up to the sample in hand (tag
    /// `receive`).
    receive: LatencyHistogram,
    /// The probe's start, ns.
    start_ns: u64,
    /// Start of the current interval, ns.
    interval_start_ns: u64,
}

impl Probe {
    /// Creates the hlog file, reserves the records, subscribes, and prints `ready`.
    fn open(cli: &Cli) -> anyhow::Result<Self> {
        let hlog = match &cli.hlog {
            Some(p) => Some(HlogWriter::create(
                p,
                "rt-probe: StimTick publish-to-receive latency",
                SystemTime::now(),
            )?),
            None => None,
        };
        let records: Vec<TickRecord> = if cli.record.is_some() {
            Vec::with_capacity(cli.max_ticks)
        } else {
            Vec::new()
        };
        let node = create_node("rt-probe")?;
        let ticks = port::subscriber::<StimTick>(&node, &cli.prefix)?;
        let reports = port::subscriber::<TimingReport>(&node, &cli.prefix)?;
        let listener = port::stim_tick_listener(&node, &cli.prefix)?;
        println!("ready");
        std::io::stdout().flush()?;

        let ipc = LatencyHistogram::new();
        let interval = LatencyHistogram::new();
        let receive_interval = LatencyHistogram::new();
        let start_ns = monotonic_ns();
        Ok(Self {
            ticks,
            reports,
            listener,
            _node: node,
            intervals: Intervals {
                hlog,
                ipc: interval,
                receive: receive_interval,
                start_ns,
                interval_start_ns: start_ns,
            },
            ipc,
            records,
            record: cli.record.is_some(),
            summary: ProbeSummary::default(),
            last_activity_ns: start_ns,
            final_seen_ns: None,
            idle_ns: cli.idle_timeout_ms * 1_000_000,
        })
    }

    /// Sleeps on the stim-tick event and takes every waiting tick and report, until
    /// `stop`, rt-core's final tick (and its final report, or a second), or the idle
    /// timeout.
    fn run(&mut self, stop: &AtomicBool) -> anyhow::Result<()> {
        while !stop.load(Ordering::Relaxed) {
            self.listener
                .timed_wait(|_| {}, Duration::from_millis(50))
                .map_err(|e| anyhow::anyhow!("stim-tick listener: {e:?}"))?;
            let t_woke_ns = monotonic_ns();
            while let Some(sample) = self
                .ticks
                .receive()
                .map_err(|e| anyhow::anyhow!("StimTick receive: {e:?}"))?
            {
                let t_recv_ns = monotonic_ns();
                let tick = *sample.payload();
                drop(sample);
                self.on_tick(tick, t_recv_ns, t_woke_ns);
            }
            self.receive_reports()?;
            let now = monotonic_ns();
            self.intervals.write_if_due(now)?;
            if self.done(now) {
                break;
            }
        }
        Ok(())
    }

    /// Checks and counts one tick received at `t_recv_ns` (the listener woke at
    /// `t_woke_ns`), records its latencies, and keeps it for `--record`.
    fn on_tick(&mut self, tick: StimTick, t_recv_ns: u64, t_woke_ns: u64) {
        let summary = &mut self.summary;
        self.last_activity_ns = t_recv_ns;
        summary.received += 1;
        if tick.validate().is_err() {
            summary.invalid += 1;
            return;
        }
        let latency = t_recv_ns.saturating_sub(tick.t_publish_ns);
        self.ipc.record(latency);
        self.intervals.ipc.record(latency);
        self.intervals
            .receive
            .record(t_recv_ns.saturating_sub(t_woke_ns.max(tick.t_publish_ns)));
        if summary.first_seq == 0 {
            summary.first_seq = tick.seq;
        } else if tick.seq > summary.last_seq + 1 {
            summary.lost += tick.seq - summary.last_seq - 1;
        }
        summary.last_seq = summary.last_seq.max(tick.seq);
        summary.pulses += u64::from(tick.fires());
        if tick.has(StimTick::FLAG_FINAL) {
            summary.final_seen = true;
            self.final_seen_ns = Some(t_recv_ns);
        }
        if self.record && self.records.len() < self.records.capacity() {
            self.records.push(TickRecord { tick, t_recv_ns });
        }
    }

    /// Takes every waiting TimingReport and keeps rt-core's last valid one.
    fn receive_reports(&mut self) -> anyhow::Result<()> {
        while let Some(sample) = self
            .reports
            .receive()
            .map_err(|e| anyhow::anyhow!("TimingReport receive: {e:?}"))?
        {
            let report = *sample.payload();
            drop(sample);
            if report.validate().is_ok() && report.source() == Ok(TimingSource::RtCore) {
                self.summary.rt_core = Some(report);
                self.summary.rt_core_final = report.flags & TimingReport::FLAG_FINAL != 0;
            }
        }
        Ok(())
    }

    /// True when the run is over at `now`: rt-core's final tick came and either its final
    /// report or a second passed since, or no tick came for the idle timeout.
    fn done(&self, now: u64) -> bool {
        let final_done = self
            .final_seen_ns
            .is_some_and(|t| self.summary.rt_core_final || now.saturating_sub(t) > NS_PER_S);
        final_done || now.saturating_sub(self.last_activity_ns) > self.idle_ns
    }

    /// Writes the last hlog interval, the `--record` CSV and the `--summary` JSON, logs
    /// the counts; true when rt-core's final tick was received.
    fn finish(mut self, cli: &Cli) -> anyhow::Result<bool> {
        self.intervals.write_last(monotonic_ns())?;
        self.summary.ipc_ns = self.ipc.summary().into();
        if let Some(path) = &cli.record {
            write_records(path, &self.records)?;
        }
        let summary = &self.summary;
        if let Some(path) = &cli.summary {
            std::fs::write(path, serde_json::to_string_pretty(summary)?)
                .with_context(|| format!("{}", path.display()))?;
        }
        tracing::info!(
            "received {} ticks ({} lost, {} invalid), ipc p50/p99/p99.9/max = {}/{}/{}/{} ns",
            summary.received,
            summary.lost,
            summary.invalid,
            summary.ipc_ns.p50,
            summary.ipc_ns.p99,
            summary.ipc_ns.p999,
            summary.ipc_ns.max
        );
        Ok(summary.final_seen)
    }
}

impl Intervals {
    /// With an hlog, once the current interval is a second long: writes it (`ipc`, then
    /// `receive`) ending at `now` and starts the next.
    fn write_if_due(&mut self, now: u64) -> anyhow::Result<()> {
        if self.hlog.is_some() && now - self.interval_start_ns >= NS_PER_S {
            self.write_last(now)?;
            self.interval_start_ns = now;
        }
        Ok(())
    }

    /// With an hlog: writes the current interval (`ipc`, then `receive`) ending at `now`.
    fn write_last(&mut self, now: u64) -> anyhow::Result<()> {
        if let Some(log) = &mut self.hlog {
            let (start, from) = (self.start_ns, self.interval_start_ns);
            write_interval(log, &mut self.ipc, TAG_IPC, start, from, now)?;
            write_interval(log, &mut self.receive, TAG_RECEIVE, start, from, now)?;
        }
        Ok(())
    }
}

/// Writes the `--record` CSV: the header, then one line per tick.
fn write_records(path: &Path, records: &[TickRecord]) -> anyhow::Result<()> {
    let file = File::create(path).with_context(|| format!("{}", path.display()))?;
    let mut out = BufWriter::new(file);
    writeln!(out, "{RECORD_HEADER}")?;
    for r in records {
        r.write_csv(&mut out)?;
    }
    out.flush()?;
    Ok(())
}

fn write_interval(
    log: &mut HlogWriter,
    interval: &mut LatencyHistogram,
    tag: &str,
    start_ns: u64,
    from_ns: u64,
    to_ns: u64,
) -> anyhow::Result<()> {
    log.write(
        interval,
        tag,
        Duration::from_nanos(from_ns - start_ns),
        Duration::from_nanos(to_ns - from_ns),
    )?;
    log.flush()?;
    interval.reset();
    Ok(())
}
