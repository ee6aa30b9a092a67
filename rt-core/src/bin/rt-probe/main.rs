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
use std::path::PathBuf;
use std::process::ExitCode;

use rt_core::rt::exit::Exit;
use std::sync::atomic::Ordering;
use std::time::{Duration, SystemTime};

use anyhow::Context;
use clap::Parser;
use rt_core::msg::port;
use rt_core::msg::{Contract, StimTick, TimingReport, TimingSource};
use rt_core::rt::clock::{NS_PER_S, monotonic_ns};
use rt_core::rt::histogram::LatencyHistogram;
use rt_core::rt::hlog::HlogWriter;
use rt_core::rt::probe::{ProbeSummary, RECORD_HEADER, RtCoreTiming, TickRecord};
use rt_core::rt::runner::create_node;
use rt_core::rt::signals::install_stop_handler;
use rt_core::rt::telemetry::{TAG_IPC, TAG_RECEIVE};
use rt_core::rt::{MissingRightsPolicy, RtConfig, enter_realtime};

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
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .init();
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
    match run(&Cli::parse()) {
        Ok(true) => Exit::Done.into(),
        Ok(false) => {
            tracing::warn!("ended without rt-core's final tick");
            Exit::Failed.into()
        }
        Err(e) => {
            tracing::error!("{}", rt_core::rt::error_text::one_line(e.as_ref()));
            Exit::Failed.into()
        }
    }
}

/// Runs the probe; true when rt-core's final tick was received.
fn run(cli: &Cli) -> anyhow::Result<bool> {
    let stop = install_stop_handler().context("installing signal handlers")?;
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
    let mut hlog = match &cli.hlog {
        Some(p) => Some(HlogWriter::create(
            p,
            "rt-probe: StimTick publish-to-receive latency",
            SystemTime::now(),
        )?),
        None => None,
    };
    let mut records: Vec<TickRecord> = if cli.record.is_some() {
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

    let mut ipc = LatencyHistogram::new();
    let mut interval = LatencyHistogram::new();
    // Receive cost alone: from the listener's wake-up to the sample in hand.
    let mut receive_interval = LatencyHistogram::new();
    let start_ns = monotonic_ns();
    let mut interval_start_ns = start_ns;
    let mut last_activity_ns = start_ns;
    let mut summary = ProbeSummary {
        received: 0,
        invalid: 0,
        lost: 0,
        first_seq: 0,
        last_seq: 0,
        pulses: 0,
        final_seen: false,
        ipc_ns: Default::default(),
        rt_core: None,
        rt_core_final: false,
    };
    let mut final_seen_ns = None;
    let idle_ns = cli.idle_timeout_ms * 1_000_000;

    while !stop.load(Ordering::Relaxed) {
        listener
            .timed_wait(|_| {}, Duration::from_millis(50))
            .map_err(|e| anyhow::anyhow!("stim-tick listener: {e:?}"))?;
        let t_woke_ns = monotonic_ns();
        while let Some(sample) = ticks
            .receive()
            .map_err(|e| anyhow::anyhow!("StimTick receive: {e:?}"))?
        {
            let t_recv_ns = monotonic_ns();
            let tick = *sample.payload();
            drop(sample);
            last_activity_ns = t_recv_ns;
            summary.received += 1;
            if tick.validate().is_err() {
                summary.invalid += 1;
                continue;
            }
            let latency = t_recv_ns.saturating_sub(tick.t_publish_ns);
            ipc.record(latency);
            interval.record(latency);
            receive_interval.record(t_recv_ns.saturating_sub(t_woke_ns.max(tick.t_publish_ns)));
            if summary.first_seq == 0 {
                summary.first_seq = tick.seq;
            } else if tick.seq > summary.last_seq + 1 {
                summary.lost += tick.seq - summary.last_seq - 1;
            }
            summary.last_seq = summary.last_seq.max(tick.seq);
            summary.pulses += u64::from(tick.fires());
            if tick.has(StimTick::FLAG_FINAL) {
                summary.final_seen = true;
                final_seen_ns = Some(t_recv_ns);
            }
            if cli.record.is_some() && records.len() < records.capacity() {
                records.push(TickRecord { tick, t_recv_ns });
            }
        }
        while let Some(sample) = reports
            .receive()
            .map_err(|e| anyhow::anyhow!("TimingReport receive: {e:?}"))?
        {
            let report = *sample.payload();
            drop(sample);
            if report.validate().is_ok() && report.source() == Ok(TimingSource::RtCore) {
                summary.rt_core = Some(RtCoreTiming::from(&report));
                summary.rt_core_final = report.flags & TimingReport::FLAG_FINAL != 0;
            }
        }
        let now = monotonic_ns();
        if let Some(log) = &mut hlog
            && now - interval_start_ns >= NS_PER_S
        {
            write_interval(
                log,
                &mut interval,
                TAG_IPC,
                start_ns,
                interval_start_ns,
                now,
            )?;
            write_interval(
                log,
                &mut receive_interval,
                TAG_RECEIVE,
                start_ns,
                interval_start_ns,
                now,
            )?;
            interval_start_ns = now;
        }
        let final_done = final_seen_ns
            .is_some_and(|t| summary.rt_core_final || now.saturating_sub(t) > NS_PER_S);
        if final_done || now.saturating_sub(last_activity_ns) > idle_ns {
            break;
        }
    }

    if let Some(log) = &mut hlog {
        let now = monotonic_ns();
        write_interval(
            log,
            &mut interval,
            TAG_IPC,
            start_ns,
            interval_start_ns,
            now,
        )?;
        write_interval(
            log,
            &mut receive_interval,
            TAG_RECEIVE,
            start_ns,
            interval_start_ns,
            now,
        )?;
    }
    summary.ipc_ns = ipc.summary().into();
    if let Some(path) = &cli.record {
        let file = File::create(path).with_context(|| format!("{}", path.display()))?;
        let mut out = BufWriter::new(file);
        writeln!(out, "{RECORD_HEADER}")?;
        for r in &records {
            r.write_csv(&mut out)?;
        }
        out.flush()?;
    }
    if let Some(path) = &cli.summary {
        std::fs::write(path, serde_json::to_string_pretty(&summary)?)
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
