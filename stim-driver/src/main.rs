//! `stim-driver`: StimTicks from iceoryx2 to PULSE frames on SocketCAN, with independent
//! interlocks, arming and a watchdog (the library [`stim_driver`] holds the logic).
//!
//! Threads of `run`: the receive thread (bus frames → forward thread, ForceSample), the
//! report thread (logs, DriverStatus, TimingReport, hlog, publisher liveness), the systemd
//! notifier (READY=1, WATCHDOG=1 only while the forward loop makes progress), and ONE
//! real-time forward thread. SIGINT/SIGTERM: NMT stop on the bus, final DriverStatus and
//! TimingReport, exit 0.

use std::path::PathBuf;
use std::process::ExitCode;

use fes_rt::rt::exit::Exit;
use std::sync::atomic::Ordering;
use std::sync::mpsc;
use std::time::SystemTime;

use anyhow::{Context, anyhow};
use clap::{Parser, Subcommand};
use fes_can::Nodes;
use fes_rt::rt::alloc::CountingAllocator;
use fes_rt::rt::hlog::HlogWriter;
use fes_rt::rt::node::RunError;
use fes_rt::rt::notify::{NotifierSettings, ServiceManager, run_progress_notifier};
use fes_rt::rt::realtime::{RtError, enter_realtime};
use fes_rt::rt::signals::install_stop_handler;
use stim_driver::bus::{BusSettings, run_bus};
use stim_driver::config::{DriverConfig, TransportKind};
use stim_driver::report::{ReportOutcome, run_report};
use stim_driver::runner::{ForwardOutcome, Shared, run_forward};
use stim_driver::safe_stop::safe_stop;
use stim_driver::serial_rx::{SerialRxSettings, run_serial_rx};
use stim_driver::serial_tx::{ScienceModeTx, ftdi_latency_timer_ms, open_serial};
use stim_driver::tx::BusTx;
use stim_driver::txstamp::{self, TxStampReader};
use tracing::{error, info, warn};

/// Counts the forward thread's heap allocations (reported as `hot_path_allocations`).
#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

const AFTER_HELP: &str = "\
SUBCOMMANDS
  run --config FILE        drive the stimulator (the service; see below)
  safe-stop --iface IFACE  send NMT stop (to the stimulator's node and to all nodes) and
                           exit; systemd's ExecStopPost runs it whenever the driver stops
  example-config           print a configuration with every default
  probe --device PATH      time a RehaStim 2's answers and print the [transport]
                           min_interval_ms to use (the driver stopped)

WHAT `run` DOES: brings the stimulator up (NMT pre-operational, CONFIG with the run's
limits from [stimulator], waits until STATUS shows them), sends the host heartbeat, and
starts DISARMED: nothing is forwarded until the supervisor sends an Arm DriverCommand
(iceoryx2 <prefix>/driver_command). Armed, each StimTick with a pulse that passes the
driver's own [interlocks] becomes one PULSE frame; a refused pulse is not sent, never
altered, and is logged and counted. No StimTick for timeout_ticks periods, a stale
StimTick, the publisher's node dead or gone, the stimulator silent, an EMCY, bus-off or
the link going down: NMT stop, SAFE STATE, and nothing until an explicit re-arm.

CONFIGURATION (TOML, schema \"fes-stim-driver/1\"; `example-config` prints every key; only
[can] iface and [force] max_n are required; docs/stim-driver.md documents each key):
  [transport]   kind = \"can\" (default) or \"sciencemode\" (a RehaStim 2 on a serial line:
                device = \"/dev/ttyUSB0\", poll_ms; no [can] iface; docs/sciencemode.md)
  [can]         iface, host_node, stim_node, heartbeat_ms, tx_retry_budget_us, ...
  [stimulator]  the limits sent in CONFIG: max_amplitude_ua, max_width_us, min_ipi_ms,
                max_pulses, rate_window_ms, watchdog_ms
  [interlocks]  the driver's own: min_ipi_us, max_pulses, rate_window_ms,
                max_amplitude_ua, max_width_us, max_charge_nc, channels, max_pulse_delay_us
  [watchdog]    tick_period_us, timeout_ticks, stale_after_ticks, stimulator_timeout_ms,
                arm_confirm_ms, command_max_age_ms, liveness_check_ms, supervisor_watch
  [force]       max_n (normalises ForceSample)
  [rt]          the forward thread: priority, core, on_missing_rights, lock_memory, ...
  [bus_rt]      optional: the receive thread real-time too
  [telemetry]   hlog, report_period_ms, status_period_ms, queue_capacity
  [ipc]         prefix

UNDER SYSTEMD (Type=notify): READY=1 once the forward loop runs; WATCHDOG=1 from a normal
thread only while the loop makes progress; logs go to the journal. RUST_LOG filters the
log (default info).

EXIT STATUS: 0 stopped by SIGINT/SIGTERM (after NMT stop) or safe-stop sent;
1 bad configuration or usage; 2 refused to start (real time missing with
on_missing_rights = \"refuse\"); 3 run-time failure (CAN interface, iceoryx2, a thread
failed; NMT stop was attempted).";

/// The stimulator driver: iceoryx2 StimTicks to SocketCAN PULSE frames, with independent
/// interlocks, arming and a watchdog.
#[derive(Debug, Parser)]
#[command(name = "stim-driver", version, after_help = AFTER_HELP)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Drive the stimulator (the service).
    Run {
        /// Configuration file (TOML, schema "fes-stim-driver/1").
        #[arg(long, value_name = "FILE")]
        config: PathBuf,
        /// Use this CAN interface instead of the file's [can] iface (under systemd,
        /// FES_CAN_IFACE from can.env: the interface safe-stop uses too).
        #[arg(long, value_name = "IFACE")]
        iface: Option<String>,
        /// Validate the configuration, print a summary, and exit.
        #[arg(long)]
        check: bool,
    },
    /// Send NMT stop to the stimulator (its node and all nodes) and exit.
    SafeStop {
        /// CAN interface.
        #[arg(long, value_name = "IFACE")]
        iface: String,
        /// The stimulator's node id (decimal or 0x..).
        #[arg(long, default_value = "0x10", value_parser = fes_can::parse_node_id)]
        stim_node: u8,
    },
    /// Print a configuration with every default (interface vcan0, max_n 40 N).
    ExampleConfig,
    /// Time a RehaStim 2's answers (ScienceMode 2) and print the `[transport]
    /// min_interval_ms` to configure. Sends GetStimulationMode (and with
    /// --zero-current-pulses SinglePulse of 0 mA, 0 us) one at a time, each after the
    /// answer to the last, as the driver does; starts no stimulation. Stop the driver
    /// first: the port must be the probe's alone.
    Probe {
        /// The serial device (e.g. /dev/rehastim2).
        #[arg(long, value_name = "PATH")]
        device: PathBuf,
        /// Commands to time.
        #[arg(long, default_value_t = 200)]
        commands: u32,
        /// Every other command a SinglePulse of 0 mA and 0 us (no charge): the answer path
        /// of a pulse, which may be slower than a query's.
        #[arg(long)]
        zero_current_pulses: bool,
    },
}

/// The environment variable (set by systemd from can.env) that overrides `[can] iface`.
const ENV_CAN_IFACE: &str = "FES_CAN_IFACE";

/// Why the process did not end cleanly.
enum Failure {
    /// Bad configuration: exit 1 (`Exit::Failed`).
    Config(anyhow::Error),
    /// Real time refused: exit 1 (`Exit::Failed`).
    Refused(String),
    /// A run-time failure: exit 4 (`Exit::Fault`; systemd restarts it).
    Run(anyhow::Error),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // safe-stop (ExecStopPost=) lives for milliseconds: its lines go through its stderr
    // stream so journald attributes them to the unit (fes_rt::rt::logging).
    if matches!(cli.command, Command::SafeStop { .. }) {
        fes_rt::rt::logging::init_stream();
    } else {
        fes_rt::rt::logging::init("stim-driver");
    }
    fes_rt::rt::panic::install("stim-driver");
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
    let result = match cli.command {
        Command::Run {
            config,
            iface,
            check,
        } => run(&config, iface, check),
        Command::SafeStop { iface, stim_node } => stop_now(&iface, stim_node),
        Command::ExampleConfig => {
            print!("{}", DriverConfig::with_defaults("vcan0", 40.0).to_toml());
            Ok(())
        }
        Command::Probe {
            device,
            commands,
            zero_current_pulses,
        } => run_probe(&device, commands, zero_current_pulses),
    };
    let line = |e: &anyhow::Error| fes_rt::rt::error_text::one_line(e.as_ref());
    match result {
        Ok(()) => Exit::Done.into(),
        Err(Failure::Config(e)) => {
            error!("{}", line(&e));
            Exit::Failed.into()
        }
        Err(Failure::Refused(text)) => {
            error!("{text}");
            Exit::Failed.into()
        }
        Err(Failure::Run(e)) => {
            error!("{}", line(&e));
            Exit::Fault.into()
        }
    }
}

/// `stim-driver probe`: the device's answer times and the minimum interval they ask for.
fn run_probe(device: &std::path::Path, commands: u32, zero_pulses: bool) -> Result<(), Failure> {
    use stim_driver::probe::{ProbeSettings, probe};
    if commands == 0 {
        return Err(Failure::Config(anyhow!("--commands 0: nothing to time")));
    }
    if let Some(ms) = ftdi_latency_timer_ms(std::path::Path::new("/sys"), device)
        && ms > 1
    {
        warn!(
            "the USB adapter's latency timer is {ms} ms (protocol §2.1 asks for 1): every answer waits up to that long in the adapter; docs/deployment.md sets it with a udev rule"
        );
    }
    let settings = ProbeSettings {
        commands,
        zero_pulses,
        ..ProbeSettings::default()
    };
    let r = probe(device, &settings, |k| {
        if k % 50 == 0 {
            eprintln!("{k} of {commands} commands timed");
        }
    })
    .map_err(|e| Failure::Config(e.into()))?;
    let q = |p: f64| {
        r.quantile_ms(p)
            .map_or("-".to_owned(), |v| format!("{v:.1}"))
    };
    println!(
        "{} of {commands} commands answered: median {} ms, p90 {} ms, p99 {} ms, longest {} ms; {} answered -8 busy, {} with another error {:?}, {} unanswered within {} ms; {} MOTOmed packets skipped",
        r.answer_ms.len(),
        q(0.5),
        q(0.9),
        q(0.99),
        q(1.0),
        r.busy,
        r.errors.len(),
        r.errors,
        r.lost,
        stim_driver::serial_rx::ANSWER_TIMEOUT_MS,
        r.information
    );
    match r.min_interval_ms() {
        Some(ms) => {
            println!(
                "[transport]\nmin_interval_ms = {ms}    # the 90th percentile of the answers, rounded up"
            );
            println!(
                "design the controller with `fes design ... --min-interval-ms {ms}` (or more)"
            );
            Ok(())
        }
        None => Err(Failure::Run(anyhow!(
            "no command was answered: nothing to suggest"
        ))),
    }
}

fn stop_now(iface: &str, stim_node: u8) -> Result<(), Failure> {
    let host = if stim_node == Nodes::DEFAULT.host() {
        Nodes::DEFAULT.stim()
    } else {
        Nodes::DEFAULT.host()
    };
    let nodes =
        Nodes::new(host, stim_node).map_err(|e| Failure::Config(anyhow!("--stim-node: {e}")))?;
    let written = safe_stop(iface, &nodes).map_err(|e| Failure::Run(e.into()))?;
    info!("safe-stop: NMT stop written on {iface} ({written} of 2 frames)");
    Ok(())
}

fn run(path: &std::path::Path, iface: Option<String>, check: bool) -> Result<(), Failure> {
    let (config, prescription) = load_config(path, iface)?;
    if check {
        println!("{}: ok", path.display());
        return Ok(());
    }
    // A panicking thread: NMT stop on the bus before the process aborts (the stimulator's
    // own watchdog would stop it too, later). On ScienceMode nothing to do: a pulse is a
    // command, and a process that sends none delivers none.
    if config.transport.kind == TransportKind::Can
        && let Ok(nodes) = config.nodes()
    {
        let iface = config.can.iface.clone();
        fes_rt::rt::panic::set_safe_move(move || match safe_stop(&iface, &nodes) {
            Ok(n) => eprintln!("stim-driver: NMT stop written on {iface} ({n} of 2 frames)"),
            Err(e) => eprintln!("stim-driver: NMT stop on {iface} failed: {e}"),
        });
    }
    let manager = ServiceManager::from_env()
        .context("systemd notification")
        .map_err(Failure::Config)?;
    let stop = install_stop_handler()
        .context("installing SIGINT/SIGTERM handlers")
        .map_err(Failure::Run)?;
    let shared = Shared::new(&config);
    let _ = shared.prescription.set(prescription);
    let (outputs, rx_port) = Outputs::open(&config, &shared)?;
    let nodes = config
        .nodes()
        .context("configuration")
        .map_err(Failure::Config)?;
    let receive = match rx_port {
        None => Receive::Can(BusSettings {
            iface: config.can.iface.clone(),
            nodes,
            max_force_n: config.force.max_n,
            prefix: config.ipc.prefix.clone(),
        }),
        Some(port) => Receive::Serial(
            port,
            SerialRxSettings {
                limits: config
                    .stim_limits()
                    .context("configuration")
                    .map_err(Failure::Config)?,
            },
        ),
    };
    std::thread::scope(|scope| {
        run_threads(scope, &config, &shared, &manager, stop, outputs, receive)
    })
}

/// What the receive thread reads: the CAN bus, or the ScienceMode serial port.
enum Receive {
    Can(BusSettings),
    Serial(std::fs::File, SerialRxSettings),
}

/// Loads and validates the configuration; `iface` (`--iface`, or `FES_CAN_IFACE` from the
/// unit's can.env, which ExecStopPost's safe-stop also uses) overrides `[can] iface`.
/// The configuration, checked against the prescription, and the prescription's
/// fingerprint (what the TimingReports carry).
fn load_config(
    path: &std::path::Path,
    iface: Option<String>,
) -> Result<(DriverConfig, [u8; 6]), Failure> {
    let mut config = DriverConfig::load(path)
        .context("configuration")
        .map_err(Failure::Config)?;
    let iface = if config.transport.kind == TransportKind::Sciencemode {
        if let Some(iface) = iface {
            return Err(Failure::Config(anyhow!(
                "--iface {iface}: no CAN interface with transport kind \"sciencemode\""
            )));
        }
        None
    } else {
        iface.or_else(|| std::env::var(ENV_CAN_IFACE).ok().filter(|s| !s.is_empty()))
    };
    if let Some(iface) = iface
        && iface != config.can.iface
    {
        info!(
            "CAN interface {iface:?} (--iface or FES_CAN_IFACE) instead of the file's {:?}",
            config.can.iface
        );
        config.can.iface = iface;
        config
            .validate()
            .context("--iface")
            .map_err(Failure::Config)?;
    }
    // The prescription: read-only to this service, separate from its configuration. Nothing
    // this driver would let through or send in CONFIG may exceed it.
    let prescription = fes_prescription::Prescription::load(&config.prescription)
        .context("configuration: prescription")
        .map_err(Failure::Config)?;
    config
        .check_prescription(&prescription)
        .context("configuration refused by the prescription")
        .map_err(Failure::Config)?;
    info!("{}", prescription.summary());
    let c = &config;
    info!(
        "config {}: {} (stimulator node {:#04x}), tick {} us, watchdog {} ticks, \
         interlocks min IPI {} us / {} pulses per {} ms / {} uA / {} us, prefix {:?}",
        path.display(),
        match (&c.transport.kind, &c.transport.device) {
            (TransportKind::Sciencemode, Some(d)) => format!("ScienceMode 2 on {}", d.display()),
            _ => c.can.iface.clone(),
        },
        c.can.stim_node,
        c.watchdog.tick_period_us,
        c.watchdog.timeout_ticks,
        c.interlocks.min_ipi_us,
        c.interlocks.max_pulses,
        c.interlocks.rate_window_ms,
        c.interlocks.max_amplitude_ua,
        c.interlocks.max_width_us,
        c.ipc.prefix
    );
    Ok((config, prescription.fingerprint()))
}

/// What the driver writes to: the bus, the kernel's transmit timestamps of CAN frames
/// (when the socket gives them), the timing log.
struct Outputs {
    tx: BusTx,
    stamps: Option<TxStampReader>,
    hlog: Option<HlogWriter>,
}

impl Outputs {
    /// Opens the outputs; with ScienceMode also the serial port's read side for the
    /// receive thread.
    fn open(
        config: &DriverConfig,
        shared: &Shared,
    ) -> Result<(Self, Option<std::fs::File>), Failure> {
        let hlog = match &config.telemetry.hlog {
            Some(p) => Some(
                HlogWriter::create(p, "stim-driver timing", SystemTime::now())
                    .context("telemetry.hlog")
                    .map_err(Failure::Config)?,
            ),
            None => None,
        };
        if let (TransportKind::Sciencemode, Some(device)) =
            (config.transport.kind, &config.transport.device)
        {
            let port = open_serial(device)
                .with_context(|| format!("serial device {}", device.display()))
                .map_err(Failure::Run)?;
            let rx = port
                .try_clone()
                .with_context(|| format!("serial device {}", device.display()))
                .map_err(Failure::Run)?;
            let nodes = config
                .nodes()
                .context("configuration")
                .map_err(Failure::Config)?;
            let tx = ScienceModeTx::with_link(
                port,
                nodes,
                config.retry_policy(),
                shared.serial_link.clone(),
                u64::from(config.transport.poll_ms()) * 1_000_000,
            );
            info!(
                "ScienceMode 2 on {} (a Hasomed RehaStim 2; docs/sciencemode.md)",
                device.display()
            );
            // §2.1 of the protocol description: the adapter's latency timer at 1 ms.
            if let Some(ms) = ftdi_latency_timer_ms(std::path::Path::new("/sys"), device)
                && ms > 1
            {
                warn!(
                    "{}: FTDI latency timer {ms} ms, the protocol description asks for 1 ms \
                     (§2.1): the device's answers wait up to {ms} ms in the adapter \
                     (docs/deployment.md, the udev rule's latency_timer)",
                    device.display()
                );
            }
            let outputs = Self {
                tx: BusTx::Serial(tx),
                stamps: None,
                hlog,
            };
            return Ok((outputs, Some(rx)));
        }
        let tx = BusTx::open(&config.can.iface, config.retry_policy())
            .with_context(|| format!("CAN interface {:?}", config.can.iface))
            .map_err(Failure::Run)?;
        let stamps = match &tx {
            BusTx::Can(tx) => {
                match txstamp::enable(tx.socket()).and_then(|()| TxStampReader::new(tx.raw_fd())) {
                    Ok(r) => Some(r),
                    Err(e) => {
                        warn!("no kernel transmit timestamps: {e}");
                        None
                    }
                }
            }
            BusTx::Serial(_) => None,
            BusTx::Host(_) => {
                warn!(
                    "{}: the host bus (Unix datagrams, no CAN): for tests and benches on hosts without SocketCAN",
                    config.can.iface
                );
                None
            }
        };
        Ok((Self { tx, stamps, hlog }, None))
    }
}

type Handle<'scope> = std::thread::ScopedJoinHandle<'scope, anyhow::Result<()>>;

/// Marks the driver failed (the forward loop then stops) and passes the error on.
fn failed(shared: &Shared, e: anyhow::Error) -> anyhow::Error {
    shared.failed.store(true, Ordering::Relaxed);
    e
}

/// Starts the receive thread (bus frames to the forward thread, ForceSample) and waits
/// until its ports are open.
fn spawn_bus<'scope>(
    scope: &'scope std::thread::Scope<'scope, '_>,
    config: &'scope DriverConfig,
    shared: &'scope Shared,
    receive: Receive,
) -> Result<Handle<'scope>, Failure> {
    let (ready_tx, ready_rx) = mpsc::channel();
    let thread = std::thread::Builder::new()
        .name("stim-driver-bus".to_owned())
        .spawn_scoped(scope, move || -> anyhow::Result<()> {
            if let Some(rt) = &config.bus_rt {
                let status = enter_realtime(rt).context("[bus_rt]")?;
                info!("receive thread: {status}");
            }
            let ready = move || {
                let _ = ready_tx.send(());
            };
            match receive {
                Receive::Can(settings) => run_bus(
                    &settings,
                    &shared.bus_events,
                    &shared.status,
                    &shared.bus,
                    &shared.sent_log,
                    &shared.forward_ended,
                    ready,
                )
                .map_err(|e| failed(shared, e.into())),
                Receive::Serial(port, settings) => run_serial_rx(
                    &settings,
                    port,
                    &shared.serial_link,
                    &shared.bus_events,
                    &shared.bus,
                    &shared.forward_ended,
                    ready,
                )
                .map_err(|e| failed(shared, anyhow::Error::from(e).context("serial port"))),
            }
        })
        .context("spawning the receive thread")
        .map_err(Failure::Run)?;
    if ready_rx.recv().is_err() {
        shared.forward_ended.store(true, Ordering::Relaxed);
        let e = match thread.join() {
            Ok(Err(e)) => e,
            _ => anyhow!("the receive thread stopped early"),
        };
        return Err(Failure::Run(e.context("receive thread")));
    }
    Ok(thread)
}

/// Starts the report thread (logs, DriverStatus, TimingReport, hlog, publisher liveness)
/// and waits until its ports are open. On failure the other threads see `forward_ended`
/// and stop; the scope joins them.
fn spawn_report<'scope>(
    scope: &'scope std::thread::Scope<'scope, '_>,
    config: &'scope DriverConfig,
    shared: &'scope Shared,
    hlog: Option<HlogWriter>,
    stamps: Option<TxStampReader>,
) -> Result<std::thread::ScopedJoinHandle<'scope, Result<ReportOutcome, anyhow::Error>>, Failure> {
    let (ready_tx, ready_rx) = mpsc::channel();
    let thread = std::thread::Builder::new()
        .name("stim-driver-report".to_owned())
        .spawn_scoped(scope, move || {
            run_report(config, shared, hlog, stamps, move || {
                let _ = ready_tx.send(());
            })
            .map_err(|e| failed(shared, e.into()))
        })
        .context("spawning the report thread");
    let thread = match thread {
        Ok(t) => t,
        Err(e) => {
            shared.forward_ended.store(true, Ordering::Relaxed);
            return Err(Failure::Run(e));
        }
    };
    if ready_rx.recv().is_err() {
        shared.forward_ended.store(true, Ordering::Relaxed);
        let e = match thread.join() {
            Ok(Err(e)) => e,
            _ => anyhow!("the report thread stopped early"),
        };
        return Err(Failure::Run(e.context("report thread")));
    }
    Ok(thread)
}

/// Runs the driver's threads: receive, report, the systemd notifier (READY=1, then
/// WATCHDOG=1 only while the forward loop wakes up) and the real-time forward thread, until
/// the forward thread ends; then joins them and logs the final account.
fn run_threads<'scope>(
    scope: &'scope std::thread::Scope<'scope, '_>,
    config: &'scope DriverConfig,
    shared: &'scope Shared,
    manager: &'scope ServiceManager,
    stop: &'static std::sync::atomic::AtomicBool,
    outputs: Outputs,
    receive: Receive,
) -> Result<(), Failure> {
    let Outputs { tx, stamps, hlog } = outputs;
    let bus_thread = spawn_bus(scope, config, shared, receive)?;
    let report_thread = spawn_report(scope, config, shared, hlog, stamps)?;
    let notifier = std::thread::Builder::new()
        .name("stim-driver-notify".to_owned())
        .spawn_scoped(scope, move || {
            let settings = NotifierSettings::for_watchdog(manager.watchdog());
            run_progress_notifier(
                manager,
                &settings,
                shared.status.wakeups(),
                &[&shared.forward_ended],
                |wakeups| {
                    let c = shared.status.load();
                    format!(
                        "{}; {} StimTicks, {} pulses sent, {} refused, {wakeups} wake-ups",
                        device_state_name(c.state),
                        c.ticks_received,
                        c.pulses_sent,
                        c.pulses_rejected
                    )
                },
            )
        });
    let forward = std::thread::Builder::new()
        .name("stim-driver-fwd".to_owned())
        .stack_size(config.rt.thread_stack_bytes())
        .spawn_scoped(scope, move || {
            run_forward(config, tx, shared, stop, |status| {
                if status.is_degraded() {
                    warn!("forward thread: {status}");
                } else {
                    info!("forward thread: {status}");
                }
                info!("running, DISARMED until an Arm command; SIGINT or SIGTERM stops");
            })
        });
    let outcome = match forward {
        Ok(t) => t.join(),
        Err(e) => {
            shared.forward_ended.store(true, Ordering::Relaxed);
            let _ = bus_thread.join();
            let _ = report_thread.join();
            return Err(Failure::Run(
                anyhow::Error::from(e).context("spawning the forward thread"),
            ));
        }
    };
    shared.forward_ended.store(true, Ordering::Relaxed);
    if let Ok(n) = notifier
        && let Ok(n) = n.join()
        && manager.is_present()
        && n.send_errors > 0
    {
        warn!("{} systemd notifications could not be sent", n.send_errors);
    }
    let bus = bus_thread
        .join()
        .unwrap_or_else(|_| Err(anyhow!("the receive thread panicked")));
    let report = report_thread
        .join()
        .unwrap_or_else(|_| Err(anyhow!("the report thread panicked")));
    let outcome = outcome.map_err(|_| Failure::Run(anyhow!("the forward thread panicked")))?;
    let outcome = match outcome {
        Ok(o) => o,
        Err(RunError::Realtime(RtError::Refused(status))) => {
            return Err(Failure::Refused(format!("refused to start: {status}")));
        }
        Err(e) => {
            return Err(Failure::Run(
                anyhow::Error::from(e).context("forward thread"),
            ));
        }
    };
    if let Ok(r) = &report {
        log_final(shared, r, &outcome);
    }
    if let Some(trace) = fes_rt::rt::alloc::take_first_heap_allocation() {
        warn!("{trace}");
    }
    if !outcome.stop_sent {
        warn!("the final NMT stop could not be written (the stimulator's watchdog stops it)");
    }
    bus.map_err(|e| Failure::Run(e.context("receive thread")))?;
    report.map_err(|e| Failure::Run(e.context("report thread")))?;
    if shared.failed.load(Ordering::Relaxed) {
        return Err(Failure::Run(anyhow!("a driver thread failed")));
    }
    info!("stopped");
    Ok(())
}

/// The final account of a run: StimTicks, pulses, refusals, trips, the forward path's
/// latency and the hot path's allocations.
fn log_final(shared: &Shared, r: &ReportOutcome, outcome: &ForwardOutcome) {
    let t = &r.timing;
    let us = |ns: u64| ns as f64 / 1000.0;
    let c = shared.status.load();
    info!(
        "final: {} StimTicks ({} missing, {} refused), {} pulses sent ({} of them accounted \
         applied by the stimulator and {} not, the rest still open; its last STATUS: {} \
         applied since its reset), {} refused by the interlocks, {} \
         while not armed, {} written late and {} dropped late (transport busy), {} busy \
         answers ({} pulses), {} CAN write errors, {} trips ({} \
         watchdog); StimTick->CAN write p50/p99/max {:.1}/{:.1}/{:.1} us; {} TX \
         stamps; hot-path heap allocations {}",
        c.ticks_received,
        c.ticks_lost,
        c.ticks_refused,
        c.pulses_sent,
        c.pulses_applied,
        c.pulses_not_applied,
        c.stimulator_pulses,
        c.pulses_rejected,
        c.pulses_not_armed,
        c.pulses_late,
        c.pulses_dropped_late,
        c.device_busy,
        c.pulses_busy,
        c.can_tx_errors,
        c.trips,
        c.watchdog_trips,
        us(t.publish.p50_ns),
        us(t.publish.p99_ns),
        us(t.publish.max_ns),
        r.tx_stamps,
        outcome
            .hot_path_allocations
            .map_or("not counted".to_owned(), |n| n.to_string()),
    );
}

fn device_state_name(state: u8) -> &'static str {
    use fes_rt::msg::DeviceState;
    match DeviceState::try_from(state) {
        Ok(DeviceState::Boot) => "starting",
        Ok(DeviceState::PreOperational) => "disarmed",
        Ok(DeviceState::Armed | DeviceState::Stimulating) => "ARMED",
        Ok(DeviceState::Fault) => "SAFE STATE / fault",
        Ok(DeviceState::Stopped) => "stopped",
        Ok(DeviceState::Unknown) | Err(_) => "unknown",
    }
}
