//! `rt-core`: the 1 ms real-time pattern generator process.
//!
//! A thin shell around [`rt_core::rt::runner`]: it reads and validates the configuration and
//! the controller, creates the iceoryx2 node, starts the telemetry thread and ONE real-time
//! thread, and on SIGINT/SIGTERM stops them cleanly (final StimTick, histograms flushed,
//! iceoryx2 resources released, exit 0). Under systemd it logs to the journal and reports
//! READY=1 / WATCHDOG=1 through [`fes_rt::rt::notify`] while the loop makes progress.

mod slowdown;
mod source;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{OnceLock, mpsc};
use std::thread::{Scope, ScopedJoinHandle};
use std::time::SystemTime;

use anyhow::{Context, anyhow};
use clap::Parser;
use fes_rt::msg::{LatencySummary, TimingReport};
use fes_rt::rt::RtStatus;
use fes_rt::rt::alloc::CountingAllocator;
use fes_rt::rt::exit::Exit;
use fes_rt::rt::hlog::HlogWriter;
use fes_rt::rt::node::{RunError, create_node};
use fes_rt::rt::notify::{
    NotifierOutcome, NotifierSettings, ServiceManager, run_progress_notifier,
};
use fes_rt::rt::realtime::RtError;
use fes_rt::rt::signals::install_stop_handler;
use fes_rt::rt::telemetry::TelemetryChannel;
use iceoryx2::prelude::{Node, ipc};
use rt_core::rt::process_config::{RtCoreConfig, SourceConfig};
use rt_core::rt::runner::{LoopOutcome, TelemetrySettings, run_pattern_loop, run_telemetry};
use tracing::{error, info, warn};

use source::Source;

/// Counts the real-time thread's allocations (reported as `hot_path_allocations`).
#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

const AFTER_HELP: &str = "\
CONFIGURATION FILE (TOML, schema \"fes-rt-core/1\"; `--print-example-config` prints one):
  schema = \"fes-rt-core/1\"   required
  period_us = 1000            tick period in us (100..=1000000)
  [source]                    required: what runs every tick
    kind = \"controller\"       the thesis's pattern generator (LCN -> shaper -> LMN)
    path = \"ctrl.json\"        controller file (schema fes-lcn/1), relative to this file
    -- or --
    kind = \"test-pattern\"     bench source without a model:
    ipi_ticks = 20            fires every 20 ticks while the reference is > 0
  [rt]                        real-time settings of the loop thread
    priority = 80             SCHED_FIFO priority 1..=99
    core = 1                  CPU core to pin to (default: not pinned)
    on_missing_rights = \"best-effort\"   or \"refuse\" (rig): without SCHED_FIFO rights,
                              a missing core, unlockable memory or wake-up latency
                              limit, refuse to start
    lock_memory = true        mlockall(MCL_CURRENT|MCL_FUTURE)
    prefault_stack_bytes = 262144
    cpu_dma_latency_us = 0    PM QoS wake-up latency limit (/dev/cpu_dma_latency);
                              omit to leave the system's setting
  [reference]
    stale_after_ms = 100      a Reference older than this is stale ...
    stale_ramp_per_s = 2.0    ... and the target ramps to 0 at this rate (per second)
  [feedback]
    enabled = false           pass measured force (ForceSample) to the generator
    max_age_ms = 5            oldest sample used
  prescription = \"/etc/fes/prescription.toml\"
                              optional (top level): [pulse] may not exceed this
                              prescription (amplitude, phase width, charge); refuse to
                              start otherwise
  [pulse]
    channel = 0               stimulator channel 0..=15
    amplitude_ua = 20000      pulse amplitude (uA)
    width_us = 200            pulse width (us)
  [telemetry]
    hlog = \"rt-core.hlog\"     HdrHistogram interval log (optional)
    report_period_ms = 1000   TimingReport / hlog interval period
    queue_capacity = 8192     tick records buffered for the telemetry thread
  [ipc]
    prefix = \"fes\"            iceoryx2 service-name prefix (<prefix>/stim_tick, ...)
    notify = true             notify <prefix>/stim_tick_event after each StimTick

UNDER SYSTEMD (Type=notify): READY=1 once the loop has ticked; with WatchdogSec= set,
WATCHDOG=1 from a normal thread only while the tick count advances; logs go to the
journal when stderr is connected to it (JOURNAL_STREAM), else to stderr. RUST_LOG
filters the log (default info).

EXIT STATUS: 0 stopped cleanly by SIGINT/SIGTERM; 1 bad configuration or run-time error;
2 refused to start (real-time guarantee missing with on_missing_rights = \"refuse\").";

/// The 1 ms real-time pattern generator: publishes a StimTick every period on iceoryx2.
#[derive(Debug, Parser)]
#[command(name = "rt-core", version, after_help = AFTER_HELP)]
struct Cli {
    /// Configuration file (TOML, schema "fes-rt-core/1"; described below).
    #[arg(
        long,
        value_name = "FILE",
        required_unless_present = "print_example_config"
    )]
    config: Option<PathBuf>,
    /// Validate the configuration and the controller file, print a summary, and exit.
    #[arg(long)]
    check: bool,
    /// Print an example configuration (every default, a test-pattern source) and exit.
    #[arg(long, conflicts_with_all = ["config", "check"])]
    print_example_config: bool,
}

/// Why the process did not run to a clean stop.
enum Failure {
    /// Real time refused: exit 1 (`Exit::Failed`).
    Refused(String),
    /// Anything else: exit 1.
    Other(anyhow::Error),
}

impl From<anyhow::Error> for Failure {
    fn from(e: anyhow::Error) -> Self {
        Failure::Other(e)
    }
}

fn main() -> ExitCode {
    fes_rt::rt::logging::init("rt-core");
    // A panicking thread aborts the process: the driver's StimTick watchdog and its
    // liveness check of this node stop the stimulator (a final tick cannot be sent from
    // another thread: the StimTick service has one publisher, the loop's).
    fes_rt::rt::panic::install("rt-core");
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
    let cli = Cli::parse();
    match run(&cli) {
        Ok(()) => Exit::Done.into(),
        Err(Failure::Refused(line)) => {
            error!("{line}");
            Exit::Failed.into()
        }
        Err(Failure::Other(e)) => {
            error!("{}", fes_rt::rt::error_text::one_line(e.as_ref()));
            Exit::Failed.into()
        }
    }
}

/// Runs the process: configuration, outputs, threads; the final report is logged when the
/// threads end.
fn run(cli: &Cli) -> Result<(), Failure> {
    if cli.print_example_config {
        print_example_config();
        return Ok(());
    }
    let path = cli
        .config
        .as_deref()
        .ok_or_else(|| anyhow!("--config is required"))?;
    let (config, source, prescription) = load_configuration(path)?;
    if cli.check {
        println!("{}: ok", path.display());
        return Ok(());
    }
    let outputs = Outputs::open(&config)?;
    run_threads(&config, source, prescription, outputs)
}

/// Prints an example configuration: every default, a test-pattern source, an hlog file.
fn print_example_config() {
    let mut example = RtCoreConfig::with_source(SourceConfig::TestPattern { ipi_ticks: 20 });
    example.telemetry.hlog = Some(PathBuf::from("rt-core.hlog"));
    print!("{}", example.to_toml());
}

/// Configuration phase: reads and validates the configuration file and the source it
/// names (a controller file is read and checked here), and logs what will run.
fn load_configuration(path: &Path) -> anyhow::Result<(RtCoreConfig, Source, [u8; 6])> {
    let config = RtCoreConfig::load(path).context("configuration")?;
    let prescription = match config.check_prescription().context("configuration")? {
        Some(p) => {
            info!("{}", p.summary());
            p.fingerprint()
        }
        None => {
            info!("no prescription configured: [pulse] is checked by stim-driver only");
            [0; 6]
        }
    };
    let source = Source::load(&config.source, config.period(), config.feedback.enabled)?;
    info!(
        "config {}: period {} us, source {}, prefix {:?}",
        path.display(),
        config.period_us,
        source.describe(),
        config.ipc.prefix
    );
    Ok((config, source, prescription))
}

/// What the process opens before any thread starts (may allocate, may fail).
struct Outputs {
    /// systemd's notification socket (none outside systemd).
    manager: ServiceManager,
    /// The test hook's busy-wait per tick, µs (never on a rig).
    slowdown: Option<u64>,
    /// Set by SIGINT/SIGTERM.
    stop: &'static AtomicBool,
    /// The HdrHistogram interval log, if configured.
    hlog: Option<HlogWriter>,
    /// The real-time thread's iceoryx2 node.
    node: Node<ipc::Service>,
}

impl Outputs {
    /// Outputs phase, in this order: the systemd notification socket, the test slowdown
    /// hook (warned about), the SIGINT/SIGTERM handlers, the hlog file, the iceoryx2 node.
    fn open(config: &RtCoreConfig) -> anyhow::Result<Self> {
        let manager = ServiceManager::from_env().context("systemd notification")?;
        let slowdown = slowdown::from_env()?;
        if let Some(us) = slowdown {
            warn!(
                "TEST HOOK {}={us}: every tick busy-waits {us} us (never on a rig)",
                slowdown::ENV_TICK_BUSY_US
            );
        }
        let stop = install_stop_handler().context("installing SIGINT/SIGTERM handlers")?;
        let hlog = match &config.telemetry.hlog {
            Some(p) => Some(
                HlogWriter::create(p, "rt-core timing", SystemTime::now())
                    .context("telemetry.hlog")?,
            ),
            None => None,
        };
        let node = create_node("rt-core")?;
        Ok(Self {
            manager,
            slowdown,
            stop,
            hlog,
            node,
        })
    }
}

/// What the threads share (made before they start).
struct Shared {
    /// The loop's timing records and counters, drained by the telemetry thread.
    telemetry: TelemetryChannel,
    /// Stops the telemetry thread (once the loop has ended).
    telemetry_stop: AtomicBool,
    /// The real-time status line, once the loop thread has entered real time.
    rt_status: OnceLock<String>,
    /// Set when the real-time thread has ended (stops the notification thread).
    loop_ended: AtomicBool,
}

/// The telemetry thread's handle: its final TimingReport, or why it failed.
type TelemetryThread<'scope> = ScopedJoinHandle<'scope, Result<TimingReport, RunError>>;

/// Threads phase: the telemetry thread (waited for until its port exists), the systemd
/// notification thread and ONE real-time thread; when the loop ends, the notification
/// thread and then the telemetry thread are stopped, and the outcome reported.
fn run_threads(
    config: &RtCoreConfig,
    source: Source,
    prescription: [u8; 6],
    outputs: Outputs,
) -> Result<(), Failure> {
    let Outputs {
        manager,
        slowdown,
        stop,
        hlog,
        node,
    } = outputs;
    let shared = Shared {
        telemetry: TelemetryChannel::new(config.telemetry.queue_capacity),
        telemetry_stop: AtomicBool::new(false),
        rt_status: OnceLock::new(),
        loop_ended: AtomicBool::new(false),
    };
    let telemetry_settings = TelemetrySettings {
        prescription,
        ..TelemetrySettings::for_rt_core(config)
    };
    std::thread::scope(|scope| -> Result<(), Failure> {
        let telemetry_thread = start_telemetry(scope, &shared, &telemetry_settings, hlog)?;
        let notifier = spawn_notifier(scope, &shared, &manager, stop, slowdown.is_some())?;
        let rt_thread = match spawn_loop(scope, &shared, config, source, node, stop, slowdown) {
            Ok(t) => t,
            Err(e) => {
                shared.loop_ended.store(true, Ordering::Relaxed);
                return Err(e.into());
            }
        };
        let outcome = rt_thread.join();
        shared.loop_ended.store(true, Ordering::Relaxed);
        let notified = notifier
            .join()
            .map_err(|_| anyhow!("the systemd notification thread panicked"))?;
        if manager.is_present() && notified.send_errors > 0 {
            warn!(
                "{} systemd notifications could not be sent",
                notified.send_errors
            );
        }
        let outcome = outcome.map_err(|_| anyhow!("the real-time thread panicked"))?;
        let telemetry_result = stop_telemetry(telemetry_thread, &shared);
        report_outcome(outcome, telemetry_result)
    })
}

/// Spawns the telemetry thread (normal priority) and waits until its port exists; if it
/// fails before that, stops it and returns why.
fn start_telemetry<'scope>(
    scope: &'scope Scope<'scope, '_>,
    shared: &'scope Shared,
    settings: &'scope TelemetrySettings,
    hlog: Option<HlogWriter>,
) -> Result<TelemetryThread<'scope>, Failure> {
    let (ready_tx, ready_rx) = mpsc::channel();
    let thread = std::thread::Builder::new()
        .name("rt-core-telemetry".to_owned())
        .spawn_scoped(scope, move || {
            run_telemetry(
                settings,
                hlog,
                &shared.telemetry,
                &shared.telemetry_stop,
                move || {
                    let _ = ready_tx.send(());
                },
            )
        })
        .context("spawning the telemetry thread")?;
    if ready_rx.recv().is_err() {
        // The sender was dropped without signalling: the thread failed; report why.
        return Err(stop_telemetry(thread, shared)
            .err()
            .unwrap_or_else(|| anyhow!("the telemetry thread stopped early"))
            .into());
    }
    Ok(thread)
}

/// Spawns the systemd notification thread (normal priority): READY=1 and WATCHDOG=1
/// while the tick count advances, until `stop` or the loop's end.
fn spawn_notifier<'scope>(
    scope: &'scope Scope<'scope, '_>,
    shared: &'scope Shared,
    manager: &'scope ServiceManager,
    stop: &'static AtomicBool,
    slowed: bool,
) -> anyhow::Result<ScopedJoinHandle<'scope, NotifierOutcome>> {
    std::thread::Builder::new()
        .name("rt-core-notify".to_owned())
        .spawn_scoped(scope, move || {
            let settings = NotifierSettings::for_watchdog(manager.watchdog());
            let counters = &shared.telemetry.counters;
            run_progress_notifier(
                manager,
                &settings,
                &counters.ticks,
                &[stop, &shared.loop_ended],
                |ticks| {
                    format!(
                        "{}{}; {ticks} ticks, {} missed periods",
                        if slowed { "TEST SLOWDOWN; " } else { "" },
                        shared.rt_status.get().map_or("starting", String::as_str),
                        counters.misses.load(Ordering::Relaxed)
                    )
                },
            )
        })
        .context("spawning the systemd notification thread")
}

/// Spawns the ONE real-time thread running the pattern loop on `node` (the source slowed
/// down by the test hook when `slowdown` is set).
fn spawn_loop<'scope>(
    scope: &'scope Scope<'scope, '_>,
    shared: &'scope Shared,
    config: &'scope RtCoreConfig,
    source: Source,
    node: Node<ipc::Service>,
    stop: &'static AtomicBool,
    slowdown: Option<u64>,
) -> anyhow::Result<ScopedJoinHandle<'scope, Result<LoopOutcome, RunError>>> {
    std::thread::Builder::new()
        .name("rt-core-loop".to_owned())
        .stack_size(config.rt.thread_stack_bytes())
        .spawn_scoped(scope, move || {
            let telemetry = &shared.telemetry;
            let on_ready = |status: &RtStatus| announce_realtime(status, &shared.rt_status);
            match slowdown {
                None => run_pattern_loop(&node, config, source, telemetry, stop, on_ready),
                Some(us) => run_pattern_loop(
                    &node,
                    config,
                    slowdown::Slowed::new(source, us),
                    telemetry,
                    stop,
                    on_ready,
                ),
            }
        })
        .context("spawning the real-time thread")
}

/// Logs what real time the loop achieved (a warning when degraded), keeps it for the
/// systemd status, and says the loop is running.
fn announce_realtime(status: &RtStatus, rt_status: &OnceLock<String>) {
    if status.is_degraded() {
        warn!("{status}");
    } else {
        info!("{status}");
    }
    let _ = rt_status.set(status.to_string());
    info!("running; SIGINT or SIGTERM stops");
}

/// Stops the telemetry thread, waits for its final report and logs it, with the trace of
/// the loop's first heap allocation if there was one.
fn stop_telemetry(thread: TelemetryThread<'_>, shared: &Shared) -> anyhow::Result<()> {
    shared.telemetry_stop.store(true, Ordering::Relaxed);
    let report = thread
        .join()
        .map_err(|_| anyhow!("the telemetry thread panicked"))??;
    log_final_timing(
        &report,
        shared.telemetry.counters.snapshot().connection_allocations,
    );
    if let Some(trace) = fes_rt::rt::alloc::take_first_heap_allocation() {
        warn!("{trace}");
    }
    Ok(())
}

/// Final report: the loop's counts and its latency percentiles in one line.
fn log_final_timing(report: &TimingReport, connection_allocations: u64) {
    info!(
        "final timing: {} ticks, {} missed periods, {} hot-path heap allocations \
         ({} while connecting late peers), {} queue overflows; p50/p99/p99.9/max us: wake-up {}, \
         input {}, compute {}, publish {}",
        report.ticks,
        report.misses,
        report.hot_path_allocations,
        connection_allocations,
        report.queue_overflows,
        percentiles_us(&report.wake),
        percentiles_us(&report.input),
        percentiles_us(&report.compute),
        percentiles_us(&report.publish),
    );
}

/// `p50/p99/p99.9/max` in µs with one decimal.
fn percentiles_us(s: &LatencySummary) -> String {
    let us = |ns: u64| ns as f64 / 1000.0;
    format!(
        "{:.1}/{:.1}/{:.1}/{:.1}",
        us(s.p50_ns),
        us(s.p99_ns),
        us(s.p999_ns),
        us(s.max_ns)
    )
}

/// How the run ended: the loop's outcome first (a refusal is its own failure), then the
/// telemetry thread's.
fn report_outcome(
    outcome: Result<LoopOutcome, RunError>,
    telemetry_result: anyhow::Result<()>,
) -> Result<(), Failure> {
    match outcome {
        Ok(outcome) => {
            if let Some(summary) = &outcome.source_summary {
                info!("{summary}");
            }
            info!(
                "stopped: final tick seq {} published{}",
                outcome.final_seq,
                if outcome.allocations_counted {
                    ""
                } else {
                    " (allocations not counted)"
                }
            );
            telemetry_result.map_err(Failure::Other)
        }
        Err(RunError::Realtime(RtError::Refused(status))) => {
            Err(Failure::Refused(format!("refused to start: {status}")))
        }
        Err(e) => Err(Failure::Other(e.into())),
    }
}
