//! # fes-virtual-stimulator: the project's device emulators
//!
//! Two stimulators in software, for the tests, the bench and hosts without the hardware:
//! the virtual CAN stimulator (the stimulator side of the protocol in `crates/fes-can/dbc/fes.dbc`)
//! and the virtual Hasomed RehaStim 2 (ScienceMode 2 on a pseudo-terminal). Both drive a
//! [`Plant`] every 1 ms: sim-muscle's binary (`sim-muscle stimulator`, `sim-muscle
//! rehastim2`) puts its muscle models there, the tests the deterministic [`test_plant`].
//!
//! * [`machine`]: the protocol as a pure state machine (NMT states, heartbeat producer
//!   and consumer, CONFIG in pre-operational only, interlocks, EMCY on every rejection,
//!   watchdog), unit-tested without a socket;
//! * [`interlock`], [`watchdog`], [`outbox`]: its parts;
//! * `socket_loop`: the SocketCAN adapter on a 1 ms absolute-time loop;
//! * `clock`: the loop's only timing primitives;
//! * [`plant`]: what the devices drive ([`Plant`], [`plant::Pulse`]);
//! * [`test_plant`]: a deterministic plant for protocol tests;
//! * [`rehastim2`], [`rehastim2_pty`]: a virtual Hasomed RehaStim 2 speaking ScienceMode 2
//!   on a pseudo-terminal (`docs/sciencemode.md`), on the same plant, watchdog and clock.
//!
//! Entry points: [`run`] (what `sim-muscle stimulator` calls; SIGINT/SIGTERM stop it) and
//! [`run_until`] (the same with a caller-owned stop flag, for tests and embedding);
//! [`run_rehastim2`] and [`rehastim2_pty::run_rehastim2_until`] for the RehaStim 2.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context as _, bail};
use fes_can::{Nodes, StimLimits, parse_node_id};

mod clock;
pub mod interlock;
pub mod machine;
pub mod outbox;
pub mod pending;
pub mod plant;
mod record;
pub mod rehastim2;
pub mod rehastim2_pty;
mod socket_loop;
pub mod test_plant;
pub mod watchdog;

// The integration tests (tests/it) compile into this crate's one test binary: they use only
// the public API, through the crate's own name (docs/architecture.md, "Tests").
#[cfg(test)]
extern crate self as fes_virtual_stimulator;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;

pub use machine::{Settings, SettingsError, Stimulator, Tick, TickReport};
pub use plant::Plant;
pub use socket_loop::RunSummary;

/// Command-line options of the virtual stimulator (`sim-muscle stimulator ...`).
///
/// The limits are the stimulator's own: its boot configuration and the ceiling that no
/// CONFIG frame can loosen.
#[derive(Debug, Clone, clap::Args)]
pub struct StimulatorArgs {
    /// CAN interface (SocketCAN), or `hostbus:<absolute dir>` for the host bus (Unix
    /// datagrams carrying the same frames, for hosts without SocketCAN; docs/vcan.md).
    #[arg(long, default_value = "vcan0")]
    pub iface: String,
    /// The stimulator's CANopen node id (decimal or 0x..).
    #[arg(long, default_value = "0x10", value_parser = parse_node_id)]
    pub node_id: u8,
    /// The host's CANopen node id, whose heartbeat feeds the watchdog.
    #[arg(long, default_value = "0x01", value_parser = parse_node_id)]
    pub host_node_id: u8,
    /// Number of output channels (1..=16).
    #[arg(long, default_value_t = 1)]
    pub channels: u8,
    /// Amplitude ceiling, mA (a multiple of 0.1 mA, at most 150).
    #[arg(long, default_value_t = f64::from(StimLimits::DEFAULT.max_amplitude_100ua) / 10.0)]
    pub max_amplitude_ma: f64,
    /// Pulse width ceiling, us (at most 1000).
    #[arg(long, default_value_t = StimLimits::DEFAULT.max_width_us)]
    pub max_width_us: u16,
    /// Minimum inter-pulse interval, ms.
    #[arg(long, default_value_t = StimLimits::DEFAULT.min_ipi_ms)]
    pub min_ipi_ms: u16,
    /// Most pulses in any rate window.
    #[arg(long, default_value_t = StimLimits::DEFAULT.max_pulses)]
    pub max_pulses: u16,
    /// Rate window, ms.
    #[arg(long, default_value_t = StimLimits::DEFAULT.rate_window_ms)]
    pub rate_window_ms: u16,
    /// Watchdog: operational output stops when no host heartbeat arrives for this long, ms.
    #[arg(long, default_value_t = StimLimits::DEFAULT.watchdog_ms)]
    pub watchdog_ms: u16,
    /// Charge-per-phase ceiling (amplitude x width), uC (a multiple of 0.01 uC, at most 150).
    #[arg(long, default_value_t = f64::from(StimLimits::DEFAULT.max_charge_10nc) / 100.0)]
    pub max_charge_uc: f64,
    /// TEST ONLY, a fault to inject: apply every CONFIG with this stimulator's own amplitude
    /// ceiling instead of the requested one (and report it in CONFIG_APPLIED). The host must
    /// refuse to arm. Never use it on a rig. The environment variable
    /// FES_TEST_FAULT_LOOSE_CONFIG=1 sets it too.
    #[arg(long, hide = true)]
    pub test_fault_loose_config: bool,
    /// Period of the stimulator's heartbeat, ms.
    #[arg(long, default_value_t = 100)]
    pub heartbeat_ms: u16,
    /// Period of the host's heartbeat, ms (the watchdog must span at least two).
    #[arg(long, default_value_t = 10)]
    pub host_heartbeat_ms: u16,
    /// Write a CSV line per tick (time, lateness, state, force, applied pulse) to this file.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Stop by itself after this many seconds (default: run until SIGINT/SIGTERM).
    #[arg(long)]
    pub duration_s: Option<f64>,
}

impl StimulatorArgs {
    /// The validated settings these options describe.
    pub fn settings(&self) -> anyhow::Result<Settings> {
        let nodes =
            Nodes::new(self.host_node_id, self.node_id).context("--node-id / --host-node-id")?;
        let amplitude_100ua = (self.max_amplitude_ma * 10.0).round();
        if !self.max_amplitude_ma.is_finite()
            || (amplitude_100ua / 10.0 - self.max_amplitude_ma).abs() > 1e-9
        {
            bail!(
                "--max-amplitude-ma {} is not a multiple of 0.1 mA",
                self.max_amplitude_ma
            );
        }
        if !(0.0..=f64::from(u16::MAX)).contains(&amplitude_100ua) {
            bail!(
                "--max-amplitude-ma {} is outside 0..=150 mA",
                self.max_amplitude_ma
            );
        }
        let charge_10nc = (self.max_charge_uc * 100.0).round();
        if !self.max_charge_uc.is_finite()
            || (charge_10nc / 100.0 - self.max_charge_uc).abs() > 1e-9
            || !(0.0..=f64::from(u16::MAX)).contains(&charge_10nc)
        {
            bail!(
                "--max-charge-uc {} is not a multiple of 0.01 uC in 0..=150",
                self.max_charge_uc
            );
        }
        let ceiling = StimLimits {
            max_amplitude_100ua: amplitude_100ua as u16,
            max_width_us: self.max_width_us,
            min_ipi_ms: self.min_ipi_ms,
            max_pulses: self.max_pulses,
            rate_window_ms: self.rate_window_ms,
            watchdog_ms: self.watchdog_ms,
            max_charge_10nc: charge_10nc as u16,
        };
        // The test fault, also by environment (FES_TEST_FAULT_LOOSE_CONFIG=1) for the stack
        // tests, which start this process with fixed options.
        let test_fault_loose_config = self.test_fault_loose_config
            || std::env::var_os("FES_TEST_FAULT_LOOSE_CONFIG").is_some_and(|v| v == "1");
        let settings = Settings {
            nodes,
            ceiling,
            channels: self.channels,
            heartbeat_ms: self.heartbeat_ms,
            host_heartbeat_ms: self.host_heartbeat_ms,
            test_fault_loose_config,
        };
        if test_fault_loose_config {
            eprintln!(
                "sim-muscle stimulator: TEST FAULT --test-fault-loose-config: CONFIG amplitude \
                 ceilings are ignored"
            );
        }
        settings.validate().context("invalid stimulator options")?;
        Ok(settings)
    }

    fn max_ticks(&self) -> anyhow::Result<Option<u64>> {
        match self.duration_s {
            None => Ok(None),
            Some(d) if d.is_finite() && d > 0.0 && d < 1e7 => Ok(Some((d * 1000.0).round() as u64)),
            Some(d) => bail!("--duration-s {d} must be a positive number of seconds"),
        }
    }
}

static SIGNALLED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: nix::libc::c_int) {
    SIGNALLED.store(true, Ordering::Relaxed);
}

fn install_signal_handlers() -> anyhow::Result<()> {
    use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
    // No SA_RESTART: the loop's sleep returns EINTR and the loop sees the flag at once.
    let action = SigAction::new(
        SigHandler::Handler(on_signal),
        SaFlags::empty(),
        SigSet::empty(),
    );
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
        unsafe { sigaction(sig, &action) }
            .with_context(|| format!("installing the {sig} handler"))?;
    }
    Ok(())
}

/// Runs the virtual stimulator until SIGINT or SIGTERM (or `--duration-s`): output off,
/// a final STATUS, then `Ok`.
pub fn run(args: StimulatorArgs, plant: Box<dyn Plant>) -> anyhow::Result<()> {
    install_signal_handlers()?;
    run_until(args, plant, &SIGNALLED).map(|_| ())
}

/// Runs the virtual RehaStim 2 on a pseudo-terminal until SIGINT or SIGTERM (or
/// `--duration-s`), with `plant` as the muscle under its muscle channel.
pub fn run_rehastim2(
    args: rehastim2_pty::Rehastim2Args,
    mut plant: Box<dyn Plant>,
) -> anyhow::Result<()> {
    install_signal_handlers()?;
    fes_rt::rt::logging::init("sim-muscle");
    let summary = rehastim2_pty::run_rehastim2_until(&args, plant.as_mut(), &SIGNALLED)?;
    tracing::info!(
        "virtual RehaStim 2 stopped: {} ticks, {} packets, {} bad, {} pulses, {} answer bytes dropped, {} -8 busy and {} -3 wrong-mode answers sent, {} commands processed slowly",
        summary.ticks,
        summary.packets_rx,
        summary.bad_packets,
        summary.pulses,
        summary.tx_dropped,
        summary.busy_sent,
        summary.wrong_mode_sent,
        summary.slow_commands
    );
    Ok(())
}

/// [`run`] with a caller-owned stop flag instead of signal handlers.
pub fn run_until(
    args: StimulatorArgs,
    mut plant: Box<dyn Plant>,
    stop: &AtomicBool,
) -> anyhow::Result<RunSummary> {
    // The journal with priorities under systemd, stderr otherwise; the filter is RUST_LOG.
    // A subscriber installed already (a test's process) stays.
    fes_rt::rt::logging::init("sim-muscle");
    let settings = args.settings()?;
    let ts = plant.ts();
    if (ts - 1e-3).abs() > 1e-12 {
        bail!(
            "the muscle model samples at {ts} s; the stimulator runs a 1 ms loop and needs Ts = 0.001 s"
        );
    }
    let recorder = args
        .record
        .as_deref()
        .map(record::Recorder::create)
        .transpose()?;
    socket_loop::run_loop(
        &args.iface,
        settings,
        plant.as_mut(),
        stop,
        recorder,
        args.max_ticks()?,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: StimulatorArgs,
    }

    fn parse(extra: &[&str]) -> Result<StimulatorArgs, clap::Error> {
        let mut argv = vec!["stim"];
        argv.extend_from_slice(extra);
        Cli::try_parse_from(argv).map(|c| c.args)
    }

    #[test]
    fn defaults_are_the_protocol_defaults() {
        let s = parse(&["--iface", "vcan0"]).unwrap().settings().unwrap();
        assert_eq!(s.ceiling, StimLimits::DEFAULT);
        assert_eq!(s.nodes, Nodes::DEFAULT);
    }

    #[test]
    fn node_ids_accept_hex_and_refuse_out_of_range() {
        assert_eq!(parse(&["--node-id", "0x22"]).unwrap().node_id, 0x22);
        assert_eq!(parse(&["--node-id", "34"]).unwrap().node_id, 34);
        assert!(parse(&["--node-id", "0x80"]).is_err());
        assert!(parse(&["--node-id", "zero"]).is_err());
        let same = parse(&["--node-id", "1"]).unwrap().settings().unwrap_err();
        assert!(format!("{same:#}").contains("both use node id"), "{same:#}");
    }

    #[test]
    fn limits_are_validated_with_clear_messages() {
        let e = parse(&["--max-amplitude-ma", "20.05"])
            .unwrap()
            .settings()
            .unwrap_err();
        assert!(format!("{e:#}").contains("multiple of 0.1 mA"), "{e:#}");
        let e = parse(&["--max-width-us", "2000"])
            .unwrap()
            .settings()
            .unwrap_err();
        assert!(format!("{e:#}").contains("max_width"), "{e:#}");
        let e = parse(&["--watchdog-ms", "30", "--host-heartbeat-ms", "20"])
            .unwrap()
            .settings()
            .unwrap_err();
        assert!(
            format!("{e:#}").contains("two host heartbeat periods"),
            "{e:#}"
        );
        let e = parse(&["--duration-s=-1"])
            .unwrap()
            .max_ticks()
            .unwrap_err();
        assert!(format!("{e:#}").contains("positive"), "{e:#}");
        assert_eq!(
            parse(&["--max-amplitude-ma", "12.3"])
                .unwrap()
                .settings()
                .unwrap()
                .ceiling
                .max_amplitude_100ua,
            123
        );
    }

    #[test]
    fn a_plant_with_another_sample_time_is_refused() {
        struct Slow;
        impl Plant for Slow {
            fn ts(&self) -> f64 {
                0.005
            }
            fn step(&mut self, _: Option<crate::plant::Pulse>) -> f64 {
                0.0
            }
        }
        let stop = AtomicBool::new(false);
        let e = run_until(parse(&[]).unwrap(), Box::new(Slow), &stop).unwrap_err();
        assert!(format!("{e:#}").contains("Ts = 0.001"), "{e:#}");
    }
}
