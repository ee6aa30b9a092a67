//! `driver-latency`: the stim-driver's real forward path measured on a host without CAN,
//! for the latency regression suite (`rt-latency --driver`, docs/latency.md).
//!
//! It runs the driver's own threads — [`run_forward`] (the SCHED_FIFO forward thread:
//! iceoryx2 StimTick in, interlocks, PULSE encode, write) and [`run_report`] (its
//! HdrHistograms and `.hlog`) — with one substitution: the CAN socket is a Unix
//! `SOCK_SEQPACKET` pair ([`datagram_bus`]: one system call per frame into a kernel queue,
//! as a CAN write). At the other end, a virtual stimulator thread runs sim-muscle's
//! stimulator state machine ([`Stimulator`], with its own interlocks and watchdog) on a
//! 1 ms loop and answers with STATUS, EMCY and heartbeats, which go to the forward thread
//! through the same mapping as the driver's receive thread ([`forward_event`]). A supervisor
//! stand-in sends Arm whenever the driver is not armed (it refuses until StimTicks flow),
//! so that a trip — the driver doing its job when a tick comes stale, counted in the
//! summary with the re-arms — does not end the measurement.
//!
//! The figure of interest is the hlog tag `tick_to_can`: StimTick `t_publish_ns` → PULSE
//! write returned, per pulse — the driver's forward latency including the iceoryx2 hop.
//! Prints `ready` on stdout once its ports exist; runs until SIGINT/SIGTERM, then writes
//! the JSON summary (`--summary`).

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use anyhow::{Context as _, anyhow, bail};
use clap::Parser;
use fes_can::Nodes;
use fes_latency::DriverCounters;
use fes_rt::msg::port;
use fes_rt::msg::{DeviceState, DriverCommand, DriverCommandKind, LatencySummary};
use fes_rt::rt::alloc::CountingAllocator;
use fes_rt::rt::clock::{monotonic_ns, sleep_until};
use fes_rt::rt::hlog::HlogWriter;
use fes_rt::rt::node::create_node;
use fes_rt::rt::signals::install_stop_handler;
use fes_rt::rt::{MissingRightsPolicy, RtConfig, enter_realtime};
use fes_virtual_stimulator::machine::{Settings, Stimulator, TICK_NS, Tick};
use fes_virtual_stimulator::outbox::Outbox;
use fes_virtual_stimulator::test_plant::ChargeIntegrator;
use serde::Serialize;
use stim_driver::bus::forward_event;
use stim_driver::config::DriverConfig;
use stim_driver::report::{ReportOutcome, run_report};
use stim_driver::runner::{ForwardOutcome, Shared, run_forward};
use stim_driver::tx::{DatagramPeer, DatagramTx, datagram_bus};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// The stim-driver's forward path on a socket-pair bus with a virtual stimulator.
#[derive(Debug, Parser)]
#[command(name = "driver-latency", version)]
struct Cli {
    /// iceoryx2 service-name prefix (rt-core's `ipc.prefix`).
    #[arg(long, default_value = "fes")]
    prefix: String,
    /// SCHED_FIFO priority of the forward thread (1..=99), as the driver's `[rt] priority`.
    #[arg(long, default_value_t = 79)]
    priority: u8,
    /// Core of the forward thread.
    #[arg(long)]
    core: Option<usize>,
    /// Core of the virtual stimulator thread (SCHED_FIFO `--stim-priority`): it stands in
    /// for hardware, so keep it off the measured core.
    #[arg(long)]
    stim_core: Option<usize>,
    /// SCHED_FIFO priority of the virtual stimulator thread.
    #[arg(long, default_value_t = 10)]
    stim_priority: u8,
    /// The driver's timing as an HdrHistogram interval log (tags `tick_to_can`,
    /// `can_write`, `ipc`, `compute`, `input`, `wake`).
    #[arg(long, value_name = "FILE")]
    hlog: Option<PathBuf>,
    /// Write the JSON summary here on exit.
    #[arg(long, value_name = "FILE")]
    summary: Option<PathBuf>,
}

/// What a run did (the JSON summary).
#[derive(Debug, Serialize)]
struct Summary {
    /// The driver's counters, at the top level of the JSON as rt-latency reads them.
    #[serde(flatten)]
    counters: DriverCounters,
    /// Last fault code (0 = none).
    fault_code: u16,
    /// StimTick publish → PULSE written, ns.
    tick_to_can: Latency,
    /// The forward thread's real-time status.
    rt: String,
}

/// A [`LatencySummary`] for the JSON summary, ns.
#[derive(Debug, Serialize)]
struct Latency {
    count: u64,
    p50_ns: u64,
    p99_ns: u64,
    p999_ns: u64,
    max_ns: u64,
}

impl From<LatencySummary> for Latency {
    fn from(s: LatencySummary) -> Self {
        Self {
            count: s.count,
            p50_ns: s.p50_ns,
            p99_ns: s.p99_ns,
            p999_ns: s.p999_ns,
            max_ns: s.max_ns,
        }
    }
}

fn main() -> ExitCode {
    fes_rt::rt::logging::init("driver-latency");
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
    match run(&Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{}", fes_rt::rt::error_text::one_line(e.as_ref()));
            fes_rt::rt::exit::Exit::Failed.into()
        }
    }
}

/// Runs the driver's threads and the virtual stimulator until SIGINT/SIGTERM, then writes
/// the summary.
fn run(cli: &Cli) -> anyhow::Result<()> {
    if !(1..=99).contains(&cli.priority) || !(1..=99).contains(&cli.stim_priority) {
        bail!("--priority and --stim-priority must be in 1..=99");
    }
    let stop = install_stop_handler().context("installing signal handlers")?;
    let config = driver_config(cli)?;
    let hlog = open_hlog(cli)?;
    let settings = stimulator_settings(&config)?;
    let (tx, peer) = datagram_bus(config.retry_policy()).context("socket pair")?;
    let shared = Shared::new(&config);
    let stim = VirtualStim {
        settings,
        peer,
        rt: RtConfig {
            priority: cli.stim_priority,
            core: cli.stim_core,
            on_missing_rights: MissingRightsPolicy::BestEffort,
            ..RtConfig::default()
        },
    };
    let ended = run_threads(cli, &config, &shared, stop, tx, hlog, stim)?;
    let summary = summary(&shared, ended)?;
    log_summary(&summary);
    if let Some(path) = &cli.summary {
        std::fs::write(path, serde_json::to_vec_pretty(&summary)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if shared.failed.load(Ordering::Relaxed) {
        bail!("a driver thread failed");
    }
    Ok(())
}

/// The driver's configuration: the datagram bus, the command line's prefix, real-time
/// settings and interval log.
fn driver_config(cli: &Cli) -> anyhow::Result<DriverConfig> {
    let mut config = DriverConfig::with_defaults("datagram", 40.0);
    config.ipc.prefix = cli.prefix.clone();
    config.rt.priority = cli.priority;
    config.rt.core = cli.core;
    config.rt.on_missing_rights = MissingRightsPolicy::BestEffort;
    config.rt.cpu_dma_latency_us = None;
    config.telemetry.hlog = cli.hlog.clone();
    config.validate().context("driver configuration")?;
    Ok(config)
}

/// Creates the interval log (`--hlog`), if asked for.
fn open_hlog(cli: &Cli) -> anyhow::Result<Option<HlogWriter>> {
    Ok(match &cli.hlog {
        Some(p) => Some(
            HlogWriter::create(
                p,
                "driver-latency: stim-driver timing",
                std::time::SystemTime::now(),
            )
            .context("--hlog")?,
        ),
        None => None,
    })
}

/// The virtual stimulator's settings, matching the driver's nodes and limits.
fn stimulator_settings(config: &DriverConfig) -> anyhow::Result<Settings> {
    let nodes = config.nodes()?;
    let settings = Settings {
        nodes,
        ceiling: config.stim_limits()?,
        channels: 1,
        heartbeat_ms: 100,
        host_heartbeat_ms: config.can.heartbeat_ms,
        test_fault_loose_config: false,
    };
    settings.validate().context("virtual stimulator settings")?;
    Ok(settings)
}

/// The virtual stimulator thread's part: its settings, its end of the socket pair and
/// its real-time settings.
struct VirtualStim {
    settings: Settings,
    peer: DatagramPeer,
    rt: RtConfig,
}

/// What the driver's threads gave once they all ended.
struct Ended {
    outcome: ForwardOutcome,
    report: ReportOutcome,
    arms: u64,
}

/// Runs the virtual stimulator, the report and forward threads and (once they are ready)
/// the supervisor stand-in; prints `ready`, and joins them all when the forward thread ends.
fn run_threads(
    cli: &Cli,
    config: &DriverConfig,
    shared: &Shared,
    stop: &AtomicBool,
    tx: DatagramTx,
    hlog: Option<HlogWriter>,
    stim: VirtualStim,
) -> anyhow::Result<Ended> {
    let VirtualStim {
        settings,
        peer,
        rt: stim_rt,
    } = stim;
    std::thread::scope(|scope| -> anyhow::Result<Ended> {
        let stimulator = std::thread::Builder::new()
            .name("virtual-stim".to_owned())
            .spawn_scoped(scope, || {
                run_stimulator(settings, &peer, shared, &stim_rt)
                    .inspect_err(|_| shared.failed.store(true, Ordering::Relaxed))
            })?;
        let (report_ready_tx, report_ready_rx) = mpsc::channel();
        let report = std::thread::Builder::new()
            .name("driver-report".to_owned())
            .spawn_scoped(scope, move || {
                run_report(config, shared, hlog, None, move || {
                    let _ = report_ready_tx.send(());
                })
                .inspect_err(|_| shared.failed.store(true, Ordering::Relaxed))
            })?;
        let report_ready = report_ready_rx.recv().is_ok();
        let (fwd_ready_tx, fwd_ready_rx) = mpsc::channel();
        let forward = std::thread::Builder::new()
            .name("driver-fwd".to_owned())
            .stack_size(config.rt.thread_stack_bytes())
            .spawn_scoped(scope, move || {
                let outcome = run_forward(config, tx, shared, stop, |status| {
                    let _ = fwd_ready_tx.send(status.to_string());
                });
                shared.forward_ended.store(true, Ordering::Relaxed);
                outcome
            })?;
        let rt_status = fwd_ready_rx.recv().ok();
        let armer = if report_ready && rt_status.is_some() {
            println!("ready");
            std::io::stdout().flush()?;
            Some(
                std::thread::Builder::new()
                    .name("supervisor-stand-in".to_owned())
                    .spawn_scoped(scope, || arm_while_disarmed(&cli.prefix, shared))?,
            )
        } else {
            shared.failed.store(true, Ordering::Relaxed);
            None
        };
        let outcome = forward
            .join()
            .map_err(|_| anyhow!("the forward thread panicked"))?;
        let report = report
            .join()
            .map_err(|_| anyhow!("the report thread panicked"))?;
        stimulator
            .join()
            .map_err(|_| anyhow!("the stimulator thread panicked"))?
            .context("virtual stimulator")?;
        let arms = match armer {
            Some(a) => a
                .join()
                .map_err(|_| anyhow!("the arming thread panicked"))?
                .context("supervisor stand-in")?,
            None => 0,
        };
        Ok(Ended {
            outcome: outcome.context("forward thread")?,
            report: report.context("report thread")?,
            arms,
        })
    })
}

/// The summary of a run from the shared counters and what the threads gave.
fn summary(shared: &Shared, ended: Ended) -> anyhow::Result<Summary> {
    let Ended {
        outcome,
        report,
        arms,
    } = ended;
    let c = shared.status.load();
    Ok(Summary {
        counters: DriverCounters {
            ticks_received: c.ticks_received,
            ticks_lost: c.ticks_lost,
            ticks_refused: c.ticks_refused,
            pulses_sent: c.pulses_sent,
            pulses_rejected: c.pulses_rejected,
            pulses_not_armed: c.pulses_not_armed,
            stimulator_pulses: c.stimulator_pulses.into(),
            can_tx_errors: c.can_tx_errors,
            trips: c.trips.into(),
            watchdog_trips: c.watchdog_trips.into(),
            arms,
            hot_path_allocations: outcome
                .hot_path_allocations
                .ok_or_else(|| anyhow!("the counting allocator is not installed"))?,
        },
        fault_code: c.fault_code,
        tick_to_can: report.timing.publish.into(),
        rt: outcome.rt.to_string(),
    })
}

/// Logs the summary's counters and forward latency in one line.
fn log_summary(summary: &Summary) {
    let c = &summary.counters;
    tracing::info!(
        "{} StimTicks, {} pulses written ({} refused, {} while not armed), stimulator applied {}, {} trips, {} arms; StimTick->write p50/p99/max {:.1}/{:.1}/{:.1} us",
        c.ticks_received,
        c.pulses_sent,
        c.pulses_rejected,
        c.pulses_not_armed,
        c.stimulator_pulses,
        c.trips,
        c.arms,
        summary.tick_to_can.p50_ns as f64 / 1e3,
        summary.tick_to_can.p99_ns as f64 / 1e3,
        summary.tick_to_can.max_ns as f64 / 1e3,
    );
}

/// The virtual stimulator: a 1 ms absolute-time loop over sim-muscle's state machine, fed
/// from the socket pair, answering through the driver's bus-event mapping.
fn run_stimulator(
    settings: Settings,
    peer: &DatagramPeer,
    shared: &Shared,
    rt: &RtConfig,
) -> anyhow::Result<()> {
    enter_realtime(rt).context("virtual stimulator real-time settings")?;
    let nodes: Nodes = settings.nodes;
    let mut out = Outbox::new();
    let t0 = monotonic_ns();
    let mut stim = Stimulator::new(settings, t0, &mut out);
    let mut plant = ChargeIntegrator::new();
    let deliver = |out: &mut Outbox| {
        for frame in out.frames() {
            if let Ok(message) = nodes.decode(u32::from(frame.id), frame.payload())
                && let Some(event) = forward_event(&message)
                && shared.bus_events.push(event).is_err()
            {
                shared.bus.events_lost.fetch_add(1, Ordering::Relaxed);
            }
        }
        out.clear();
    };
    deliver(&mut out);
    let mut index = 0u64;
    while !shared.forward_ended.load(Ordering::Relaxed) && !shared.failed.load(Ordering::Relaxed) {
        index += 1;
        let nominal_ns = t0 + index * TICK_NS;
        sleep_until(nominal_ns);
        let now_ns = monotonic_ns();
        while let Some(frame) = peer.try_recv().context("reading the socket pair")? {
            stim.on_frame(now_ns, u32::from(frame.id), frame.payload(), &mut out);
        }
        // A late wake-up skips grid points; the state machine advances the plant through them.
        index = index.max((now_ns - t0) / TICK_NS);
        stim.tick(
            Tick {
                index,
                nominal_ns: t0 + index * TICK_NS,
                now_ns,
            },
            &mut plant,
            &mut out,
        );
        deliver(&mut out);
    }
    // What the driver sent last (its NMT stop) reaches the machine before it ends.
    while let Some(frame) = peer.try_recv().context("reading the socket pair")? {
        stim.on_frame(
            monotonic_ns(),
            u32::from(frame.id),
            frame.payload(),
            &mut out,
        );
    }
    Ok(())
}

/// The supervisor stand-in: an Arm every 20 ms while the driver is not armed (it refuses
/// while no StimTick flows), so that a trip (a real finding, counted in the summary) does
/// not end the measurement. Returns how many times the driver became armed.
fn arm_while_disarmed(prefix: &str, shared: &Shared) -> anyhow::Result<u64> {
    let node = create_node("driver-latency-supervisor")?;
    let commands = port::publisher::<DriverCommand>(&node, prefix)?;
    let armed = |s: u8| {
        matches!(
            DeviceState::try_from(s),
            Ok(DeviceState::Armed | DeviceState::Stimulating)
        )
    };
    let mut seq = 0;
    let mut arms = 0;
    let mut was_armed = false;
    while !shared.forward_ended.load(Ordering::Relaxed) {
        let now_armed = armed(shared.status.load().state);
        if now_armed && !was_armed {
            arms += 1;
        }
        was_armed = now_armed;
        if !now_armed {
            seq += 1;
            commands
                .send_copy(DriverCommand::new(
                    seq,
                    monotonic_ns(),
                    DriverCommandKind::Arm,
                ))
                .map_err(|e| anyhow!("sending Arm: {e:?}"))?;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(arms)
}
