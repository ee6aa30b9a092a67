//! [`DriverConfig`]: the `stim-driver` configuration file (`schema = "fes-stim-driver/1"`,
//! TOML). Read once at start-up, validated, never read inside the loop.
//!
//! ```toml
//! schema = "fes-stim-driver/1"
//! prescription = "/etc/fes/prescription.toml"  # the dose (fes-prescription/1, root-owned);
//!                                # relative: to this file. Nothing below may exceed it.
//!
//! [transport]                    # optional: what carries the driver's commands
//! kind = "can"                   # "can" (default) or "sciencemode" (a RehaStim 2 on a
//!                                # serial line, docs/sciencemode.md), which then needs:
//! # device = "/dev/ttyUSB0"      # the serial device (sciencemode only)
//! # poll_ms = 150                # a liveness query this long after the last answer
//!                                # (sciencemode only), 5..=1000
//! # min_interval_ms = 20         # shortest pulse interval the device delivers; an Arm
//!                                # is refused while the generator's is shorter
//! # max_lateness_ms = 10         # a pulse waits at most this for the device's answer to
//!                                # the previous command, else it is dropped as late
//!                                # (sciencemode only), 0..=20
//!
//! [can]
//! iface = "can0"                 # required with kind "can", absent with "sciencemode";
//!                                # "hostbus:<dir>" for the host bus (docs/vcan.md)
//! host_node = 1                  # our CANopen node id (1..=127)
//! stim_node = 16                 # the stimulator's (0x10)
//! heartbeat_ms = 10              # host heartbeat period
//! tx_retry_budget_us = 200       # a full transmit queue is retried this long ...
//! tx_retry_interval_us = 50      # ... at this interval, then the frame is dropped
//! bringup_retry_ms = 500         # a bring-up step not confirmed in this starts over
//!
//! [stimulator]                   # the run's limits, sent in CONFIG (stricter than its own)
//! max_amplitude_ua = 100000      # multiple of 100 uA, <= 150 mA
//! max_width_us = 500
//! max_charge_nc = 50000          # per phase, multiple of 10 nC, <= 150 uC
//! min_ipi_ms = 1                # on arrival; <= (min_ipi_us - max_pulse_delay_us) / 1000
//! max_pulses = 100
//! rate_window_ms = 1000
//! watchdog_ms = 100              # the stimulator's heartbeat watchdog (>= 2 heartbeats)
//!
//! [interlocks]                   # the driver's own, independent of rt-core and the stimulator
//! min_ipi_us = 2000              # on grid times
//! max_pulses = 100               # in any window of rate_window_ms
//! rate_window_ms = 1000
//! max_amplitude_ua = 100000      # <= stimulator.max_amplitude_ua
//! max_width_us = 500
//! max_charge_nc = 40000          # amplitude x width per phase
//! channels = [0]
//! max_pulse_delay_us = 500       # a pulse later than this after its grid time is refused
//!
//! [watchdog]
//! tick_period_us = 1000          # rt-core's period
//! timeout_ticks = 3              # no StimTick for this many periods -> NMT stop
//! stale_after_ticks = 3          # a StimTick this old on arrival -> NMT stop
//! stimulator_timeout_ms = 100    # no STATUS for this long -> NMT stop (and no arming);
//!                                # default 100, with sciencemode 100 + 2 x poll_ms
//! arm_confirm_ms = 100           # NMT start must show in STATUS (and the supervisor be seen) within this
//! command_max_age_ms = 100       # an older Arm is refused
//! liveness_check_ms = 20         # how often the publishers' nodes are checked
//! liveness_unknown_grace_ms = 200 # a publisher's liveness unknown for longer counts as dead
//! supervisor_watch = true        # the supervisor's node dead or gone while armed -> NMT stop
//! # supervisor_unit = "fes-supervisor.service" # the DriverCommand publisher must run in it
//! # generator_unit = "fes-rt-core.service"     # the StimTick publisher must run in it
//!
//! [force]
//! max_n = 40.0                   # required: the muscle's maximal force, normalises ForceSample
//!
//! [rt]                           # the forward thread (fes_rt::rt::RtConfig)
//! priority = 79
//!
//! # [bus_rt]                     # optional: make the receive thread real-time too
//! # priority = 70
//!
//! [telemetry]
//! # hlog = "stim-driver.hlog"
//! report_period_ms = 1000
//! status_period_ms = 100
//! queue_capacity = 8192
//! trace_allocations = true       # log where the forward loop's first heap allocation came from
//!
//! [ipc]
//! prefix = "fes"
//! ```

use std::path::{Path, PathBuf};

use fes_can::{Nodes, StimLimits};
use fes_prescription::{Ceilings, Exceeded, Prescription, pulses_per_s};
use fes_rt::msg::service::ServiceError;
use fes_rt::rt::RtConfig;
use fes_rt::rt::config::{IpcConfig, RtConfigError, TelemetryConfig};
use fes_rt::rt::config_file::{self, FileError};
use serde::{Deserialize, Serialize};

use crate::forward::ForwardSettings;
use crate::interlock::{AMPLITUDE_STEP_UA, InterlockLimits, LimitsError};
use crate::tx::RetryPolicy;

/// The schema tag this version reads.
pub const SCHEMA: &str = "fes-stim-driver/1";

const MS: u64 = 1_000_000;
const US: u64 = 1_000;

/// The configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriverConfig {
    /// Must be [`SCHEMA`].
    pub schema: String,
    /// The prescription file (`fes-prescription/1`); relative paths are relative to this
    /// file. Default `/etc/fes/prescription.toml`.
    #[serde(default = "default_prescription")]
    pub prescription: PathBuf,
    /// What carries the driver's commands (absent: CAN).
    #[serde(default, skip_serializing_if = "TransportConfig::is_default")]
    pub transport: TransportConfig,
    /// The CAN side (with the ScienceMode transport: node ids, heartbeat and retry
    /// settings of the driver's frames, which the transport translates; no interface).
    #[serde(default)]
    pub can: CanConfig,
    /// Limits sent to the stimulator.
    #[serde(default)]
    pub stimulator: StimulatorConfig,
    /// The driver's own interlocks.
    #[serde(default)]
    pub interlocks: InterlockConfig,
    /// Watchdogs and timeouts.
    #[serde(default)]
    pub watchdog: WatchdogConfig,
    /// Force scaling.
    pub force: ForceConfig,
    /// Real-time settings of the forward thread.
    #[serde(default = "default_rt")]
    pub rt: RtConfig,
    /// Real-time settings of the receive thread (absent: normal priority).
    #[serde(default)]
    pub bus_rt: Option<RtConfig>,
    /// Telemetry and status.
    #[serde(default)]
    pub telemetry: TelemetryConfig<TelemetryKeys>,
    /// iceoryx2.
    #[serde(default)]
    pub ipc: IpcConfig,
}

fn default_prescription() -> PathBuf {
    PathBuf::from(fes_prescription::DEFAULT_PATH)
}

/// The forward thread's default real-time settings: [`RtConfig`]'s, at priority 79: one
/// below rt-core's loop (80) on the same core, so a StimTick is taken as soon as rt-core
/// has published it and sleeps (fes-stim-driver.service allows at most 79).
fn default_rt() -> RtConfig {
    RtConfig {
        priority: 79,
        ..RtConfig::default()
    }
}

/// `[can]`. Defaults: nodes 0x01 / 0x10, 10 ms heartbeat, 200 µs retry budget at 50 µs,
/// bring-up steps retried after 500 ms.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CanConfig {
    /// SocketCAN interface (required with the CAN transport, absent with ScienceMode).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub iface: String,
    /// The host's node id.
    #[serde(default = "default_host_node")]
    pub host_node: u8,
    /// The stimulator's node id.
    #[serde(default = "default_stim_node")]
    pub stim_node: u8,
    /// Host heartbeat period, ms (1..=1000).
    #[serde(default = "default_heartbeat_ms")]
    pub heartbeat_ms: u16,
    /// How long a full transmit queue is retried for one frame, µs (0..=1000).
    #[serde(default = "default_retry_budget_us")]
    pub tx_retry_budget_us: u32,
    /// Pause between retries, µs (10..=budget, or anything when the budget is 0).
    #[serde(default = "default_retry_interval_us")]
    pub tx_retry_interval_us: u32,
    /// A bring-up step not confirmed within this starts over, ms (50..=60000).
    #[serde(default = "default_bringup_retry_ms")]
    pub bringup_retry_ms: u32,
}

impl Default for CanConfig {
    /// No interface (required with the CAN transport), every other key's default.
    fn default() -> Self {
        Self {
            iface: String::new(),
            host_node: default_host_node(),
            stim_node: default_stim_node(),
            heartbeat_ms: default_heartbeat_ms(),
            tx_retry_budget_us: default_retry_budget_us(),
            tx_retry_interval_us: default_retry_interval_us(),
            bringup_retry_ms: default_bringup_retry_ms(),
        }
    }
}

fn default_host_node() -> u8 {
    Nodes::DEFAULT.host()
}
fn default_stim_node() -> u8 {
    Nodes::DEFAULT.stim()
}
fn default_heartbeat_ms() -> u16 {
    10
}
fn default_retry_budget_us() -> u32 {
    200
}
fn default_retry_interval_us() -> u32 {
    50
}
fn default_bringup_retry_ms() -> u32 {
    500
}

/// Which transport `[transport] kind` names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TransportKind {
    /// SocketCAN or the host bus (`[can] iface`).
    #[default]
    Can,
    /// ScienceMode 2 to a Hasomed RehaStim 2 on a serial line (`docs/sciencemode.md`).
    Sciencemode,
}

/// `[transport]`. Default: CAN.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransportConfig {
    /// `"can"` or `"sciencemode"`.
    #[serde(default)]
    pub kind: TransportKind,
    /// The serial device, e.g. `/dev/ttyUSB0` (ScienceMode only, required there).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub device: Option<PathBuf>,
    /// The liveness query (GetStimulationMode), whose answer stands for STATUS, goes this
    /// long after the last answer that did, ms (ScienceMode only; 5..=1000, default
    /// [`DEFAULT_POLL_MS`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub poll_ms: Option<u32>,
    /// How long a pulse may wait for the device's answer to the previous command before
    /// it is dropped as late (ScienceMode's stop-and-wait), ms (ScienceMode only; 0..=20,
    /// default [`DEFAULT_MAX_LATENESS_MS`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_lateness_ms: Option<u32>,
    /// The shortest interval between two pulses the transport delivers, ms: the device's
    /// answer time, which a pulse closer to the last one waits for (ScienceMode only;
    /// 1..=200, default [`DEFAULT_MIN_INTERVAL_MS`]; `stim-driver probe` measures it). The
    /// driver refuses to arm while the generator states a shorter minimum interval.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_interval_ms: Option<u32>,
}

/// Default `[watchdog] stimulator_timeout_ms` on CAN.
pub const DEFAULT_STIMULATOR_TIMEOUT_MS: u32 = 100;

/// Default `[transport] poll_ms`: 150 ms. The device answers one command at a time, so a
/// query holds the line a pulse may need; between contractions a query every 150 ms keeps
/// it busy for under a tenth of the time (answers of 10-20 ms, §2.3), and while a
/// contraction runs or is near (StimTick `FLAG_CONTRACTION_AHEAD`) queries wait for two
/// periods of silence. Measured on the bench (virtual device at `--processing-ms 10`, 60 s):
/// 5.1 % of pulses not sent with 150 ms, 4.9 % with 1000 ms (the rest is the device's slow
/// answers); 50 ms without the flag lost 6-10 %.
pub const DEFAULT_POLL_MS: u32 = 150;

/// Default `[transport] min_interval_ms`: HASOMED's "on average below 20 ms" answer time
/// (protocol §2.3); `stim-driver probe` measures a device's.
pub const DEFAULT_MIN_INTERVAL_MS: u32 = 20;

/// Default `[transport] max_lateness_ms`: the RehaStim 2 itself executes a stimulation
/// command 10-24 ms after it arrives (HASOMED), so a pulse's landing time is already
/// uncertain by 14 ms; holding it up to 10 ms for the device's answer stays inside that
/// spread, and against the document-faithful virtual device it sent 95.8-96.0 % of the
/// decided pulses where 3 ms sent 94.2-96.0 %, at the same tracking (docs/sciencemode.md).
pub const DEFAULT_MAX_LATENESS_MS: u32 = 10;

impl TransportConfig {
    fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// The liveness query period, ms (ScienceMode).
    pub fn poll_ms(&self) -> u32 {
        self.poll_ms.unwrap_or(DEFAULT_POLL_MS)
    }

    /// The lateness bound of a pulse waiting for the device, ms (ScienceMode).
    pub fn max_lateness_ms(&self) -> u32 {
        self.max_lateness_ms.unwrap_or(DEFAULT_MAX_LATENESS_MS)
    }

    /// The shortest pulse interval the transport delivers, ms (ScienceMode).
    pub fn min_interval_ms(&self) -> u32 {
        self.min_interval_ms.unwrap_or(DEFAULT_MIN_INTERVAL_MS)
    }
}

/// `[stimulator]`: the run's limits sent in CONFIG. Defaults: the protocol's
/// (`StimLimits::DEFAULT`: 100 mA, 500 µs, 1 ms, 100 pulses per 1000 ms, 100 ms watchdog,
/// 50 µC per phase).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StimulatorConfig {
    /// Amplitude ceiling, µA (a multiple of 100 µA, at most 150 mA).
    pub max_amplitude_ua: u32,
    /// Width ceiling, µs (at most 1000).
    pub max_width_us: u16,
    /// Minimum inter-pulse interval, ms (1..=1000).
    pub min_ipi_ms: u16,
    /// Most pulses in any rate window (1..=1000).
    pub max_pulses: u16,
    /// Rate window, ms (1..=60000).
    pub rate_window_ms: u16,
    /// Host heartbeat timeout, ms (20..=5000, and at least two heartbeat periods).
    pub watchdog_ms: u16,
    /// Charge-per-phase ceiling, nC (a multiple of 10 nC, at most 150 µC).
    pub max_charge_nc: u32,
}

impl Default for StimulatorConfig {
    fn default() -> Self {
        let d = StimLimits::DEFAULT;
        Self {
            max_amplitude_ua: u32::from(d.max_amplitude_100ua) * AMPLITUDE_STEP_UA,
            max_width_us: d.max_width_us,
            min_ipi_ms: d.min_ipi_ms,
            max_pulses: d.max_pulses,
            rate_window_ms: d.rate_window_ms,
            watchdog_ms: d.watchdog_ms,
            max_charge_nc: d.max_charge_nc(),
        }
    }
}

/// `[interlocks]`. Defaults: 2 ms minimum IPI, 100 pulses per 1000 ms, 100 mA, 500 µs,
/// 40 µC per phase, channel 0 only, pulses at most 500 µs late.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InterlockConfig {
    /// Minimum inter-pulse interval on grid times, µs (>= 1).
    pub min_ipi_us: u32,
    /// Most pulses in any window (1..=1000).
    pub max_pulses: u16,
    /// Rate window, ms (>= 1).
    pub rate_window_ms: u32,
    /// Amplitude ceiling, µA (>= 1).
    pub max_amplitude_ua: u32,
    /// Width ceiling, µs (1..=1000).
    pub max_width_us: u16,
    /// Charge-per-phase ceiling, nC (>= 1).
    pub max_charge_nc: u64,
    /// Channels that may be stimulated (0..=15, at least one).
    pub channels: Vec<u8>,
    /// A pulse later than this after its grid time is refused, µs (>= 1).
    pub max_pulse_delay_us: u32,
}

impl Default for InterlockConfig {
    fn default() -> Self {
        Self {
            min_ipi_us: 2000,
            max_pulses: 100,
            rate_window_ms: 1000,
            max_amplitude_ua: 100_000,
            max_width_us: 500,
            max_charge_nc: 40_000,
            channels: vec![0],
            max_pulse_delay_us: 500,
        }
    }
}

/// `[watchdog]`. Defaults: 1 ms period, 3 ticks, 3 ticks, 100 ms, 100 ms, 100 ms, 20 ms,
/// supervisor watched.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WatchdogConfig {
    /// rt-core's tick period, µs (100..=1000000).
    pub tick_period_us: u32,
    /// No valid StimTick for this many periods trips the watchdog (1..=10000).
    pub timeout_ticks: u32,
    /// A StimTick older than this many periods on arrival trips it (1..=10000).
    pub stale_after_ticks: u32,
    /// No STATUS from the stimulator for this long trips it, ms (20..=10000; absent:
    /// [`DriverConfig::stimulator_timeout_ms`]'s default for the transport).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stimulator_timeout_ms: Option<u32>,
    /// NMT start must show in STATUS, and the supervisor (with `supervisor_watch`) be seen
    /// alive, within this after an Arm, ms (20..=10000).
    pub arm_confirm_ms: u32,
    /// An Arm command older than this is refused, ms (1..=10000).
    pub command_max_age_ms: u32,
    /// Period of the publisher-liveness check, ms (1..=1000).
    pub liveness_check_ms: u32,
    /// A publisher whose liveness stays unknown (its node's state unreadable) for longer
    /// than this counts as dead, ms (1..=10000).
    pub liveness_unknown_grace_ms: u32,
    /// Watch the supervisor too: while armed, its node (the DriverCommand publisher) dead
    /// or gone trips the safe state, and an Arm is refused while it is seen dead. On by
    /// default: without the supervisor nobody watches health, records, or can stop.
    pub supervisor_watch: bool,
    /// The systemd unit the DriverCommand publisher's process must run in (its cgroup):
    /// a publisher elsewhere, a process of the same user that took the service after the
    /// supervisor died, is foreign and counts as no supervisor. Absent: not checked (a
    /// bench without systemd).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supervisor_unit: Option<String>,
    /// The same for the StimTick publisher (rt-core).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator_unit: Option<String>,
}

impl Default for WatchdogConfig {
    fn default() -> Self {
        Self {
            tick_period_us: 1000,
            timeout_ticks: 3,
            stale_after_ticks: 3,
            stimulator_timeout_ms: None,
            arm_confirm_ms: 100,
            command_max_age_ms: 100,
            liveness_check_ms: 20,
            liveness_unknown_grace_ms: 200,
            supervisor_watch: true,
            supervisor_unit: None,
            generator_unit: None,
        }
    }
}

/// `[force]` (required).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceConfig {
    /// The muscle's maximal force, N (> 0, <= 10000): `ForceSample.force = force_n / max_n`.
    pub max_n: f64,
}

/// stim-driver's own key of `[telemetry]` ([`TelemetryConfig`]). Default: a DriverStatus
/// every 100 ms (and on every state change).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TelemetryKeys {
    /// Period of DriverStatus, ms (10..=10000).
    pub status_period_ms: u64,
}

impl Default for TelemetryKeys {
    fn default() -> Self {
        Self {
            status_period_ms: 100,
        }
    }
}

fes_rt::one_own_key!(TelemetryKeys, status_period_ms);

/// The least `[telemetry] queue_capacity` stim-driver accepts, in events of the forward
/// thread.
pub const MIN_QUEUE_CAPACITY: usize = 256;

/// Invalid configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Unreadable, not TOML of this schema, wrong `schema`, or a value out of range.
    #[error(transparent)]
    File(#[from] FileError),
    /// Node ids.
    #[error("can.host_node / can.stim_node: {0}")]
    Nodes(#[from] fes_can::NodeError),
    /// The stimulator limits cannot be carried by CONFIG.
    #[error("stimulator.{0}")]
    StimLimits(#[from] fes_can::LimitsError),
    /// The interlock limits.
    #[error(transparent)]
    Interlocks(#[from] LimitsError),
    /// `[rt]` or `[bus_rt]`.
    #[error(transparent)]
    Rt(#[from] RtConfigError),
    /// The prefix.
    #[error("ipc.prefix: {0}")]
    Prefix(#[from] ServiceError),
}

impl DriverConfig {
    /// A configuration with every default, interface `iface` and maximal force `max_n`.
    pub fn with_defaults(iface: &str, max_n: f64) -> Self {
        Self {
            schema: SCHEMA.to_owned(),
            prescription: default_prescription(),
            transport: TransportConfig::default(),
            can: CanConfig {
                iface: iface.to_owned(),
                host_node: default_host_node(),
                stim_node: default_stim_node(),
                heartbeat_ms: default_heartbeat_ms(),
                tx_retry_budget_us: default_retry_budget_us(),
                tx_retry_interval_us: default_retry_interval_us(),
                bringup_retry_ms: default_bringup_retry_ms(),
            },
            stimulator: StimulatorConfig::default(),
            interlocks: InterlockConfig::default(),
            watchdog: WatchdogConfig::default(),
            force: ForceConfig { max_n },
            rt: default_rt(),
            bus_rt: None,
            telemetry: TelemetryConfig::default(),
            ipc: IpcConfig::default(),
        }
    }

    /// Reads, parses and validates a file; a relative prescription path is resolved
    /// against the file's directory.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let mut config: Self = config_file::load(path)?;
        config.validate()?;
        config_file::resolve(path, &mut config.prescription);
        Ok(config)
    }

    /// Holds the interlocks and the CONFIG limits against the prescription: none may be
    /// looser. The driver refuses to start otherwise.
    ///
    /// Amplitude, phase width, charge per phase, minimum IPI and pulses in any 1 s for the
    /// interlocks; amplitude, width, charge and pulses in any 1 s for the stimulator. The
    /// stimulator's minimum IPI is judged on arrival, where legal pulses come up to
    /// `interlocks.max_pulse_delay_us` plus one stimulator tick (1 ms) closer than on the
    /// grid, so it must be at least the prescription's minus that allowance.
    pub fn check_prescription(&self, p: &Prescription) -> Result<(), Exceeded> {
        let i = &self.interlocks;
        p.check(
            "stim-driver interlocks",
            &Ceilings {
                amplitude_ua: Some(i.max_amplitude_ua),
                width_us: Some(u32::from(i.max_width_us)),
                charge_nc: Some(u32::try_from(i.max_charge_nc).unwrap_or(u32::MAX)),
                min_ipi_us: Some(i.min_ipi_us),
                pulses_per_s: Some(pulses_per_s(u32::from(i.max_pulses), i.rate_window_ms)),
            },
        )?;
        let s = &self.stimulator;
        let arrival_allowance_us = i.max_pulse_delay_us.saturating_add(1000);
        p.check(
            "stim-driver [stimulator] (CONFIG)",
            &Ceilings {
                amplitude_ua: Some(s.max_amplitude_ua),
                width_us: Some(u32::from(s.max_width_us)),
                charge_nc: Some(s.max_charge_nc),
                min_ipi_us: None,
                pulses_per_s: Some(pulses_per_s(
                    u32::from(s.max_pulses),
                    u32::from(s.rate_window_ms),
                )),
            },
        )?;
        let stim_ipi_us = u32::from(s.min_ipi_ms) * 1000;
        let floor_us = p.min_ipi_us.saturating_sub(arrival_allowance_us);
        if stim_ipi_us < floor_us {
            return Err(Exceeded {
                layer: "stim-driver [stimulator] (CONFIG)",
                field: "minimum IPI on arrival (shorter than the prescription's minus max_pulse_delay_us + 1 ms)",
                value: u64::from(stim_ipi_us),
                limit: u64::from(floor_us),
                unit: "us",
                prescription: p.name(),
                sha256: p.sha256.clone(),
            });
        }
        Ok(())
    }

    /// Parses and validates TOML text.
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        let config: Self = config_file::parse(text)?;
        config.validate()?;
        Ok(config)
    }

    /// The node ids.
    pub fn nodes(&self) -> Result<Nodes, ConfigError> {
        Ok(Nodes::new(self.can.host_node, self.can.stim_node)?)
    }

    /// The CONFIG limits.
    pub fn stim_limits(&self) -> Result<StimLimits, ConfigError> {
        let s = &self.stimulator;
        config_file::range(
            s.max_amplitude_ua.is_multiple_of(AMPLITUDE_STEP_UA),
            "stimulator.max_amplitude_ua",
            s.max_amplitude_ua,
            "a multiple of 100 uA (the bus step)",
        )?;
        let max_amplitude_100ua =
            u16::try_from(s.max_amplitude_ua / AMPLITUDE_STEP_UA).map_err(|_| {
                FileError::Range {
                    field: "stimulator.max_amplitude_ua",
                    value: s.max_amplitude_ua.to_string(),
                    allowed: "0..=150000".into(),
                }
            })?;
        config_file::range(
            s.max_charge_nc.is_multiple_of(10),
            "stimulator.max_charge_nc",
            s.max_charge_nc,
            "a multiple of 10 nC (the bus step)",
        )?;
        let max_charge_10nc =
            u16::try_from(s.max_charge_nc / 10).map_err(|_| FileError::Range {
                field: "stimulator.max_charge_nc",
                value: s.max_charge_nc.to_string(),
                allowed: "0..=150000".into(),
            })?;
        let limits = StimLimits {
            max_amplitude_100ua,
            max_width_us: s.max_width_us,
            min_ipi_ms: s.min_ipi_ms,
            max_pulses: s.max_pulses,
            rate_window_ms: s.rate_window_ms,
            watchdog_ms: s.watchdog_ms,
            max_charge_10nc,
        };
        limits.validate()?;
        Ok(limits)
    }

    /// The interlock limits.
    pub fn interlock_limits(&self) -> Result<InterlockLimits, ConfigError> {
        let i = &self.interlocks;
        let mut allowed_channels = 0u16;
        for &c in &i.channels {
            config_file::range(c <= 15, "interlocks.channels", c, "0..=15")?;
            allowed_channels |= 1 << c;
        }
        config_file::range(
            (1..=1000).contains(&i.max_width_us),
            "interlocks.max_width_us",
            i.max_width_us,
            "1..=1000 (the bus range)",
        )?;
        // Above the stimulator's own limit the interlock guards nothing (a typo such as
        // 4000000000 uA was accepted before; found by the bad-input sweep).
        config_file::range(
            i.max_amplitude_ua <= self.stimulator.max_amplitude_ua,
            "interlocks.max_amplitude_ua",
            i.max_amplitude_ua,
            "<= stimulator.max_amplitude_ua",
        )?;
        let limits = InterlockLimits {
            min_ipi_ns: u64::from(i.min_ipi_us) * US,
            max_pulses: i.max_pulses,
            rate_window_ns: u64::from(i.rate_window_ms) * MS,
            max_amplitude_ua: i.max_amplitude_ua,
            max_width_us: i.max_width_us,
            max_charge_nc: i.max_charge_nc,
            allowed_channels,
            max_pulse_delay_ns: u64::from(i.max_pulse_delay_us) * US,
        };
        config_file::range(
            i.max_pulse_delay_us >= 1,
            "interlocks.max_pulse_delay_us",
            i.max_pulse_delay_us,
            ">= 1",
        )?;
        // The stimulator judges the minimum IPI on the pulses' arrival; two pulses let
        // through here leave at least min_ipi - max_pulse_delay apart. A stimulator minimum
        // above that refuses legal pulses that were sent a little late, and its refusal
        // trips the chain (a CI run of the kill test: 2 ms against 2000 - 500 us).
        config_file::range(
            u64::from(self.stimulator.min_ipi_ms) * 1000
                <= u64::from(i.min_ipi_us).saturating_sub(u64::from(i.max_pulse_delay_us)),
            "stimulator.min_ipi_ms",
            self.stimulator.min_ipi_ms,
            "<= (interlocks.min_ipi_us - interlocks.max_pulse_delay_us) / 1000",
        )?;
        limits.validate()?;
        Ok(limits)
    }

    /// Checks every value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config_file::check_schema(&self.schema, SCHEMA)?;
        let c = &self.can;
        self.validate_transport()?;
        self.validate_can()?;
        let limits = self.stim_limits()?;
        config_file::range(
            u32::from(limits.watchdog_ms) >= 2 * u32::from(c.heartbeat_ms),
            "stimulator.watchdog_ms",
            limits.watchdog_ms,
            ">= 2 x can.heartbeat_ms",
        )?;
        self.interlock_limits()?;
        self.validate_watchdog()?;
        config_file::range(
            self.force.max_n.is_finite() && self.force.max_n > 0.0 && self.force.max_n <= 10_000.0,
            "force.max_n",
            self.force.max_n,
            "> 0 and <= 10000 N",
        )?;
        self.rt.validate()?;
        if let Some(b) = &self.bus_rt {
            b.validate()?;
        }
        self.telemetry.validate(MIN_QUEUE_CAPACITY)?;
        let status_period_ms = self.telemetry.own.status_period_ms;
        config_file::within("telemetry.status_period_ms", status_period_ms, 10..=10_000)?;
        self.ipc.validate()?;
        Ok(())
    }

    /// `[can]`: the interface, the nodes and the bus timings.
    fn validate_can(&self) -> Result<(), ConfigError> {
        let c = &self.can;
        match fes_hostbus::bus_dir(&c.iface) {
            _ if self.transport.kind == TransportKind::Sciencemode => {}
            Some(dir) => config_file::range(
                fes_hostbus::validate_dir(dir).is_ok(),
                "can.iface",
                &c.iface,
                "hostbus:<absolute directory of at most 91 bytes> (the host bus)",
            )?,
            None => config_file::range(
                !c.iface.is_empty() && c.iface.len() < 16 && !c.iface.contains(['/', ' ']),
                "can.iface",
                &c.iface,
                "an interface name of 1..=15 characters, or hostbus:<directory>",
            )?,
        }
        self.nodes()?;
        config_file::within("can.heartbeat_ms", c.heartbeat_ms, 1..=1000)?;
        config_file::range(
            c.tx_retry_budget_us <= 1000,
            "can.tx_retry_budget_us",
            c.tx_retry_budget_us,
            "0..=1000",
        )?;
        config_file::range(
            c.tx_retry_budget_us == 0
                || (10..=c.tx_retry_budget_us).contains(&c.tx_retry_interval_us),
            "can.tx_retry_interval_us",
            c.tx_retry_interval_us,
            "10..=tx_retry_budget_us",
        )?;
        config_file::within("can.bringup_retry_ms", c.bringup_retry_ms, 50..=60_000)?;
        Ok(())
    }

    /// `[watchdog]`: the tick, stimulator, arming and command timeouts, and the
    /// publishers' liveness.
    fn validate_watchdog(&self) -> Result<(), ConfigError> {
        let w = &self.watchdog;
        config_file::within("watchdog.tick_period_us", w.tick_period_us, 100..=1_000_000)?;
        config_file::within("watchdog.timeout_ticks", w.timeout_ticks, 1..=10_000)?;
        config_file::within(
            "watchdog.stale_after_ticks",
            w.stale_after_ticks,
            1..=10_000,
        )?;
        config_file::within(
            "watchdog.stimulator_timeout_ms",
            self.stimulator_timeout_ms(),
            20..=10_000,
        )?;
        config_file::within("watchdog.arm_confirm_ms", w.arm_confirm_ms, 20..=10_000)?;
        config_file::within(
            "watchdog.command_max_age_ms",
            w.command_max_age_ms,
            1..=10_000,
        )?;
        validate_liveness(w)
    }

    /// `[transport]`: the keys of the other transport are refused, not ignored; with
    /// ScienceMode the limits must lie within the RehaStim 2's fixed ones and the
    /// stimulator timeout must cover the device's latency (`docs/sciencemode.md`).
    fn validate_transport(&self) -> Result<(), ConfigError> {
        match self.transport.kind {
            TransportKind::Can => self.validate_can_transport(),
            TransportKind::Sciencemode => self.validate_sciencemode_transport(),
        }
    }

    /// `[transport]` with kind = "can": no serial keys, an interface named.
    fn validate_can_transport(&self) -> Result<(), ConfigError> {
        let t = &self.transport;
        let device = t.device.as_deref().map(Path::display);
        absent_with_can(
            device,
            "transport.device",
            "absent with kind = \"can\" (a serial device is for kind = \"sciencemode\")",
        )?;
        absent_with_can(
            t.poll_ms,
            "transport.poll_ms",
            "absent with kind = \"can\" (the stimulator sends STATUS by itself)",
        )?;
        absent_with_can(
            t.max_lateness_ms,
            "transport.max_lateness_ms",
            "absent with kind = \"can\" (a CAN write never waits for an answer)",
        )?;
        absent_with_can(
            t.min_interval_ms,
            "transport.min_interval_ms",
            "absent with kind = \"can\" (the stimulator takes a PULSE any tick)",
        )?;
        config_file::range(
            !self.can.iface.is_empty(),
            "can.iface",
            "",
            "required with transport kind \"can\" (the default)",
        )?;
        Ok(())
    }

    /// `[transport]` with kind = "sciencemode": the device, its polling and pulse timing,
    /// and the limits and channels the RehaStim 2 has.
    fn validate_sciencemode_transport(&self) -> Result<(), ConfigError> {
        let t = &self.transport;
        let device = t.device.as_deref().unwrap_or(Path::new(""));
        config_file::range(
            device.is_absolute(),
            "transport.device",
            device.display(),
            "required with kind = \"sciencemode\": the serial device's absolute path (/dev/ttyUSB0)",
        )?;
        config_file::range(
            self.can.iface.is_empty(),
            "can.iface",
            &self.can.iface,
            "absent with transport kind \"sciencemode\" (no CAN interface is used)",
        )?;
        let poll_ms = t.poll_ms();
        config_file::within("transport.poll_ms", poll_ms, 5..=1000)?;
        let min_interval = t.min_interval_ms();
        config_file::within("transport.min_interval_ms", min_interval, 1..=200)?;
        let lateness = t.max_lateness_ms();
        config_file::range(
            lateness <= 20,
            "transport.max_lateness_ms",
            lateness,
            "0..=20",
        )?;
        config_file::range(
            self.stimulator_timeout_ms() >= crate::serial_rx::MAX_RESPONSE_MS + 2 * poll_ms,
            "watchdog.stimulator_timeout_ms",
            self.stimulator_timeout_ms(),
            ">= 100 ms (the RehaStim 2's longest answer, §2.3) + 2 x transport.poll_ms with kind = \"sciencemode\"",
        )?;
        let limits = self.stim_limits()?;
        if let Err(field) = crate::serial_rx::limits_within_device(&limits) {
            let (name, value) = match field {
                "max_amplitude_ua" => (
                    "stimulator.max_amplitude_ua",
                    self.stimulator.max_amplitude_ua,
                ),
                _ => (
                    "stimulator.max_width_us",
                    u32::from(self.stimulator.max_width_us),
                ),
            };
            config_file::range(
                false,
                name,
                value,
                "within the RehaStim 2's fixed limits (126000 uA, 500 us) with kind = \"sciencemode\"",
            )?;
        }
        for &ch in &self.interlocks.channels {
            config_file::range(
                ch < fes_sciencemode::limits::CHANNELS,
                "interlocks.channels",
                ch,
                "0..=7 (the RehaStim 2's 8 channels) with kind = \"sciencemode\"",
            )?;
        }
        Ok(())
    }

    /// `[watchdog] stimulator_timeout_ms`, or its default: 100 ms on CAN (STATUS every
    /// 10 ms), and on ScienceMode the RehaStim 2's longest answer (100 ms, §2.3) plus two
    /// liveness periods, so that a slow answer is not taken for a silent device.
    pub fn stimulator_timeout_ms(&self) -> u32 {
        self.watchdog
            .stimulator_timeout_ms
            .unwrap_or(match self.transport.kind {
                TransportKind::Can => DEFAULT_STIMULATOR_TIMEOUT_MS,
                TransportKind::Sciencemode => {
                    crate::serial_rx::MAX_RESPONSE_MS + 2 * self.transport.poll_ms()
                }
            })
    }

    /// The forward path's settings (call after [`Self::validate`]).
    pub fn forward_settings(&self) -> Result<ForwardSettings, ConfigError> {
        let w = &self.watchdog;
        let period_ns = u64::from(w.tick_period_us) * US;
        Ok(ForwardSettings {
            nodes: self.nodes()?,
            stim_limits: self.stim_limits()?,
            interlocks: self.interlock_limits()?,
            heartbeat_ns: u64::from(self.can.heartbeat_ms) * MS,
            tick_timeout_ns: u64::from(w.timeout_ticks) * period_ns,
            stale_after_ns: u64::from(w.stale_after_ticks) * period_ns,
            stimulator_timeout_ns: u64::from(self.stimulator_timeout_ms()) * MS,
            arm_confirm_ns: u64::from(w.arm_confirm_ms) * MS,
            command_max_age_ns: u64::from(w.command_max_age_ms) * MS,
            bringup_retry_ns: u64::from(self.can.bringup_retry_ms) * MS,
            max_wait_ns: period_ns,
            supervisor_watch: w.supervisor_watch,
            liveness_unknown_grace_ns: u64::from(w.liveness_unknown_grace_ms) * MS,
            pulse_lateness_ns: match self.transport.kind {
                TransportKind::Can => 0,
                TransportKind::Sciencemode => u64::from(self.transport.max_lateness_ms()) * MS,
            },
            transport_min_interval_ns: match self.transport.kind {
                TransportKind::Can => 0,
                TransportKind::Sciencemode => u64::from(self.transport.min_interval_ms()) * MS,
            },
            tick_period_ns: period_ns,
        })
    }

    /// The transmit retry policy.
    pub fn retry_policy(&self) -> RetryPolicy {
        RetryPolicy {
            budget_ns: u64::from(self.can.tx_retry_budget_us) * US,
            interval_ns: u64::from(self.can.tx_retry_interval_us) * US,
        }
    }

    /// The configuration as TOML.
    #[expect(
        clippy::expect_used,
        reason = "every field is TOML-representable, so serialisation cannot fail"
    )]
    pub fn to_toml(&self) -> String {
        // Every field is a TOML-representable value (strings, integers, finite floats,
        // tables, arrays); serialisation of this type cannot fail.
        toml::to_string_pretty(self).expect("DriverConfig serialises to TOML")
    }
}

/// A serial-transport key that kind = "can" refuses, with the value it was given.
fn absent_with_can<T: ToString>(
    value: Option<T>,
    field: &'static str,
    allowed: &'static str,
) -> Result<(), FileError> {
    let given = value.as_ref().map_or(String::new(), T::to_string);
    config_file::range(value.is_none(), field, given, allowed)
}

/// `[watchdog]`'s liveness keys: the check period, the grace of an unknown liveness, and
/// the systemd units the publishers must run in.
fn validate_liveness(w: &WatchdogConfig) -> Result<(), ConfigError> {
    config_file::within("watchdog.liveness_check_ms", w.liveness_check_ms, 1..=1000)?;
    config_file::within(
        "watchdog.liveness_unknown_grace_ms",
        w.liveness_unknown_grace_ms,
        1..=10_000,
    )?;
    for (key, unit) in [
        ("watchdog.supervisor_unit", &w.supervisor_unit),
        ("watchdog.generator_unit", &w.generator_unit),
    ] {
        if let Some(unit) = unit {
            config_file::range(
                !unit.is_empty()
                    && !unit.contains('/')
                    && unit.contains('.')
                    && unit.chars().all(|c| c.is_ascii_graphic()),
                key,
                unit,
                "a systemd unit name such as fes-supervisor.service",
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIN: &str =
        "schema = \"fes-stim-driver/1\"\n[can]\niface = \"vcan0\"\n[force]\nmax_n = 40.0\n";

    #[test]
    fn minimal_file_takes_the_documented_defaults() {
        let c = DriverConfig::parse(MIN).unwrap();
        assert_eq!(c, DriverConfig::with_defaults("vcan0", 40.0));
        let f = c.forward_settings().unwrap();
        assert_eq!(f.tick_timeout_ns, 3_000_000);
        assert_eq!(f.stale_after_ns, 3_000_000);
        assert_eq!(f.heartbeat_ns, 10_000_000);
        assert_eq!(f.stim_limits, StimLimits::DEFAULT);
        assert_eq!(f.interlocks.min_ipi_ns, 2_000_000);
        assert_eq!(f.interlocks.allowed_channels, 1);
        assert_eq!(c.rt.priority, 79);
    }

    #[test]
    fn the_shipped_rig_file_is_valid_and_states_the_defaults() {
        let rig = DriverConfig::parse(include_str!("../../deploy/etc/fes/stim-driver.toml"))
            .expect("deploy/etc/fes/stim-driver.toml");
        let mut expected = DriverConfig::with_defaults("can0", 40.0);
        expected.rt.on_missing_rights = fes_rt::rt::config::MissingRightsPolicy::Refuse;
        // The one intended difference: the limits cut to the shipped prescription's dose
        // (20 mA, 200 us, 4 uC per phase), which bounds them.
        expected.stimulator.max_amplitude_ua = 20_000;
        expected.stimulator.max_width_us = 200;
        expected.stimulator.max_charge_nc = 4000;
        expected.interlocks.max_amplitude_ua = 20_000;
        expected.interlocks.max_width_us = 200;
        expected.interlocks.max_charge_nc = 4000;
        // Stated, at the CAN default.
        expected.watchdog.stimulator_timeout_ms = Some(DEFAULT_STIMULATOR_TIMEOUT_MS);
        // On the rig the publishers' processes must run in the stack's units.
        expected.watchdog.supervisor_unit = Some("fes-supervisor.service".into());
        expected.watchdog.generator_unit = Some("fes-rt-core.service".into());
        assert_eq!(rig, expected);
        let dose = fes_prescription::Prescription::parse(include_str!(
            "../../deploy/etc/fes/prescription.toml"
        ))
        .unwrap();
        rig.check_prescription(&dose).unwrap();
    }

    #[test]
    fn the_bench_stack_file_parses() {
        // The file workbench/src/bench.rs writes (its UML timeouts).
        let text = r#"schema = "fes-stim-driver/1"

[can]
iface = "vcan0"

[stimulator]
watchdog_ms = 1000

[watchdog]
timeout_ticks = 500
stale_after_ticks = 500
stimulator_timeout_ms = 1000
arm_confirm_ms = 2000
command_max_age_ms = 2000

[force]
max_n = 40

[rt]
priority = 79
on_missing_rights = "best-effort"

[telemetry]
hlog = "/tmp/x/stim-driver.hlog"

[ipc]
prefix = "bench-1"
"#;
        let c = DriverConfig::parse(text).unwrap();
        // `max_n = {scale_n}` prints a whole number without a point: still an f64.
        assert_eq!(c.force.max_n, 40.0);
        assert_eq!(c.forward_settings().unwrap().tick_timeout_ns, 500_000_000);
        assert_eq!(c.stim_limits().unwrap().watchdog_ms, 1000);
    }

    #[test]
    fn the_printed_example_parses_back() {
        let c = DriverConfig::with_defaults("can0", 12.5);
        assert_eq!(DriverConfig::parse(&c.to_toml()).unwrap(), c);
    }

    const SM: &str = "schema = \"fes-stim-driver/1\"\n[transport]\nkind = \"sciencemode\"\ndevice = \"/dev/ttyUSB0\"\n[force]\nmax_n = 40.0\n";

    fn sm_err(extra: &str) -> String {
        err_after(SM, extra)
    }

    #[test]
    fn the_transport_is_can_by_default_and_sciencemode_needs_a_device_and_no_can_iface() {
        assert_eq!(
            DriverConfig::parse(MIN).unwrap().transport.kind,
            TransportKind::Can
        );
        let c = DriverConfig::parse(SM).unwrap();
        assert_eq!(c.transport.kind, TransportKind::Sciencemode);
        assert_eq!(c.transport.poll_ms(), DEFAULT_POLL_MS);
        assert_eq!(DriverConfig::parse(&c.to_toml()).unwrap(), c);
        // An unknown kind, a missing or relative device, CAN-only and serial-only keys.
        let e = err("[transport]\nkind = \"usb\"\n");
        assert!(e.contains("usb") && e.contains("sciencemode"), "{e}");
        let e = DriverConfig::parse(&SM.replace("device = \"/dev/ttyUSB0\"\n", ""))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("transport.device") && e.contains("required"),
            "{e}"
        );
        let e = DriverConfig::parse(&SM.replace("/dev/ttyUSB0", "ttyUSB0"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("transport.device"), "{e}");
        let e = sm_err("[can]\niface = \"can0\"\n");
        assert!(e.contains("can.iface") && e.contains("sciencemode"), "{e}");
        let e = err("[transport]\ndevice = \"/dev/ttyUSB0\"\n");
        assert!(
            e.contains("transport.device") && e.contains("\"can\""),
            "{e}"
        );
        assert!(err("[transport]\npoll_ms = 20\n").contains("transport.poll_ms"));
        let e = DriverConfig::parse("schema = \"fes-stim-driver/1\"\n[force]\nmax_n = 40.0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("can.iface") && e.contains("required"), "{e}");
        // Limits beyond the RehaStim 2's fixed ones are refused at start-up.
        let e = sm_err(
            "[stimulator]\nmax_amplitude_ua = 130000\n[interlocks]\nmax_amplitude_ua = 100000\n",
        );
        assert!(
            e.contains("stimulator.max_amplitude_ua") && e.contains("126000"),
            "{e}"
        );
        assert!(sm_err("[interlocks]\nchannels = [8]\n").contains("interlocks.channels"));
        // The stimulator timeout must cover the device's longest answer and two queries;
        // left out, it does.
        assert_eq!(c.stimulator_timeout_ms(), 100 + 2 * DEFAULT_POLL_MS);
        assert_eq!(
            DriverConfig::parse(MIN).unwrap().stimulator_timeout_ms(),
            DEFAULT_STIMULATOR_TIMEOUT_MS
        );
        let slow = SM.replace(
            "device = \"/dev/ttyUSB0\"\n",
            "device = \"/dev/ttyUSB0\"\npoll_ms = 60\n",
        );
        let e = DriverConfig::parse(&format!("{slow}[watchdog]\nstimulator_timeout_ms = 219\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("watchdog.stimulator_timeout_ms"), "{e}");
        assert!(
            DriverConfig::parse(&format!("{slow}[watchdog]\nstimulator_timeout_ms = 220\n"))
                .is_ok()
        );
        // The lateness bound: ScienceMode only, 0..=20 ms.
        assert_eq!(c.transport.max_lateness_ms(), DEFAULT_MAX_LATENESS_MS);
        assert!(err("[transport]\nmax_lateness_ms = 3\n").contains("transport.max_lateness_ms"));
        let late = SM.replace(
            "device = \"/dev/ttyUSB0\"\n",
            "device = \"/dev/ttyUSB0\"\nmax_lateness_ms = 21\n",
        );
        assert!(
            DriverConfig::parse(&late)
                .unwrap_err()
                .to_string()
                .contains("transport.max_lateness_ms")
        );
        assert!(
            DriverConfig::parse(&slow.replace("poll_ms = 60", "poll_ms = 2"))
                .unwrap_err()
                .to_string()
                .contains("transport.poll_ms")
        );
    }

    /// The error of `base` followed by `extra`.
    fn err_after(base: &str, extra: &str) -> String {
        DriverConfig::parse(&format!("{base}{extra}"))
            .unwrap_err()
            .to_string()
    }

    fn err(extra: &str) -> String {
        err_after(MIN, extra)
    }

    #[test]
    fn bad_values_name_their_key() {
        assert!(err("[watchdog]\ntimeout_ticks = 0\n").contains("watchdog.timeout_ticks"));
        assert!(
            err("[stimulator]\nmax_amplitude_ua = 20050\n").contains("stimulator.max_amplitude_ua")
        );
        assert!(err("[stimulator]\nmax_width_us = 2000\n").contains("max_width"));
        assert!(err("[stimulator]\nwatchdog_ms = 19\n").contains("watchdog"));
        assert!(err("[interlocks]\nchannels = []\n").contains("channels"));
        assert!(err("[interlocks]\nchannels = [16]\n").contains("interlocks.channels"));
        assert!(err("[interlocks]\nmax_pulses = 1001\n").contains("max_pulses"));
        // A stimulator minimum IPI the driver's legal lateness can break (2 ms on arrival
        // against 2000 us on grid times less 500 us of allowed delay).
        let e = err("[stimulator]\nmin_ipi_ms = 2\n");
        assert!(
            e.contains("stimulator.min_ipi_ms")
                && e.contains("interlocks.min_ipi_us - interlocks.max_pulse_delay_us"),
            "{e}"
        );
        assert!(
            DriverConfig::parse(&format!(
                "{MIN}[stimulator]\nmin_ipi_ms = 2\n[interlocks]\nmin_ipi_us = 2500\n"
            ))
            .is_ok()
        );
        assert!(err("[ipc]\nprefix = \"/x\"\n").contains("ipc.prefix"));
        assert!(err("[telemetry]\nqueue_capacity = 3\n").contains("queue_capacity"));
        assert!(err("[rt]\npriority = 0\n").contains("rt.priority"));
        assert!(err("[can]\n").contains("duplicate") || err("[can]\n").contains("can"));
        let e = DriverConfig::parse(
            "schema = \"fes-stim-driver/1\"\n[can]\niface = \"vcan0\"\nstim_node = 1\n[force]\nmax_n = 1.0\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("both use node id"), "{e}");
        // The host bus: an absolute directory short enough for a socket address.
        let iface = |i: &str| MIN.replace("vcan0", i);
        assert!(DriverConfig::parse(&iface("hostbus:/run/fes/bus")).is_ok());
        for bad in [
            "hostbus:relative",
            "hostbus:",
            &format!("hostbus:/{}", "d".repeat(100)),
            "can0/x",
            "sixteen_chars_xx",
        ] {
            let e = DriverConfig::parse(&iface(bad)).unwrap_err().to_string();
            assert!(e.contains("can.iface"), "{bad}: {e}");
        }
        let e = DriverConfig::parse("schema = \"fes-stim-driver/1\"\n[can]\niface = \"vcan0\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("force"), "{e}");
        let e = DriverConfig::parse(&MIN.replace("/1", "/2"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("schema"), "{e}");
        let e = DriverConfig::parse(&format!("{MIN}bogus = 1\n"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("bogus"), "{e}");
        let e = DriverConfig::parse(&MIN.replace("40.0", "-1.0"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("force.max_n"), "{e}");
    }
}
