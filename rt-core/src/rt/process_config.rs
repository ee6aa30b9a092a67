//! [`RtCoreConfig`]: the configuration file of the `rt-core` process
//! (`schema = "fes-rt-core/1"`, TOML). Read once at start-up and validated; never read inside
//! the loop.
//!
//! ```toml
//! schema = "fes-rt-core/1"
//! period_us = 1000                 # tick period, 100..=1000000 us
//! prescription = "/etc/fes/prescription.toml"  # optional: [pulse] may not exceed it
//!
//! [source]                         # what runs every tick (required)
//! kind = "test-pattern"            # bench source without a model ...
//! ipi_ticks = 20                   # ... firing every 20 ticks while the reference is > 0
//!
//! [rt]                             # see RtConfig
//! priority = 80
//! core = 1                       # omit: not pinned
//! on_missing_rights = "refuse"     # or "best-effort"
//! lock_memory = true
//! prefault_stack_bytes = 262144
//!
//! [reference]
//! stale_after_ms = 100             # older references are stale ...
//! stale_ramp_per_s = 2.0           # ... and the target ramps to 0 at this rate
//!
//! [feedback]
//! enabled = false                  # pass measured force (ForceSample) to the generator
//! max_age_ms = 5
//!
//! [pulse]
//! channel = 0
//! amplitude_ua = 20000
//! width_us = 200
//!
//! [telemetry]
//! hlog = "rt-core.hlog"            # optional interval log
//! report_period_ms = 1000          # TimingReport and hlog interval period
//! queue_capacity = 8192            # tick records buffered for the telemetry thread
//! trace_allocations = true         # log where the loop's first heap allocation came from
//!
//! [ipc]
//! prefix = "fes"                   # iceoryx2 service-name prefix
//! notify = true                    # notify the stim-tick event after each publish
//! ```

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::generator::PulseSettings;
use super::reference::ReferencePolicy;
use fes_rt::msg::StimTick;
use fes_rt::msg::service::ServiceError;
use fes_rt::rt::clock::{MAX_PERIOD, MIN_PERIOD};
use fes_rt::rt::config::{IpcConfig, RtConfig, RtConfigError, TelemetryConfig};
use fes_rt::rt::config_file::{self, FileError};

/// The schema tag this version reads.
pub const SCHEMA: &str = "fes-rt-core/1";

/// The `rt-core` configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RtCoreConfig {
    /// Must be [`SCHEMA`].
    pub schema: String,
    /// Tick period, µs. Default 1000 (1 ms, the thesis's Ts).
    #[serde(default = "default_period_us")]
    pub period_us: u64,
    /// The prescription file (`fes-prescription/1`) the pulse is held against at start:
    /// amplitude, phase width and charge per phase may not exceed it.
    /// Relative: to this file. None: not checked here (stim-driver still enforces it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prescription: Option<PathBuf>,
    /// What runs every tick.
    pub source: SourceConfig,
    /// Real-time settings of the loop thread.
    #[serde(default)]
    pub rt: RtConfig,
    /// Reference staleness.
    #[serde(default)]
    pub reference: ReferenceConfig,
    /// Feedback mode.
    #[serde(default)]
    pub feedback: FeedbackConfig,
    /// Pulse parameters.
    #[serde(default)]
    pub pulse: PulseConfig,
    /// Telemetry.
    #[serde(default)]
    pub telemetry: TelemetryConfig,
    /// iceoryx2.
    #[serde(default)]
    pub ipc: IpcConfig<IpcKeys>,
}

fn default_period_us() -> u64 {
    1000
}

/// The tick source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum SourceConfig {
    /// The thesis's pattern generator from a controller file (schema "fes-lcn/1").
    Controller {
        /// Controller file; relative paths are relative to the configuration file.
        path: PathBuf,
    },
    /// [`super::source::TestPattern`]: fires every `ipi_ticks` ticks while the reference is
    /// above zero (bench and tests; no muscle model).
    TestPattern {
        /// Inter-pulse interval in ticks, >= 2.
        ipi_ticks: u32,
    },
}

/// Reference staleness. Defaults: stale after 100 ms, ramp to zero at 2.0 per second.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReferenceConfig {
    /// A reference older than this is stale, ms (1..=10000).
    pub stale_after_ms: u64,
    /// Ramp-to-zero rate of a stale reference, normalised force per second (0 = at once;
    /// 0..=1000).
    pub stale_ramp_per_s: f64,
}

impl Default for ReferenceConfig {
    fn default() -> Self {
        Self {
            stale_after_ms: 100,
            stale_ramp_per_s: 2.0,
        }
    }
}

/// Feedback mode. Default off; samples up to 5 ms old are used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeedbackConfig {
    /// Subscribe to ForceSample and pass the measured force to the generator.
    pub enabled: bool,
    /// Oldest sample used, ms (1..=1000).
    pub max_age_ms: u64,
}

impl Default for FeedbackConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            max_age_ms: 5,
        }
    }
}

/// Pulse parameters. Defaults: channel 0, 20 mA, 200 µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PulseConfig {
    /// Stimulator channel, 0..=15.
    pub channel: u8,
    /// Amplitude, µA, 1..=250000.
    pub amplitude_ua: u32,
    /// Width, µs, >= 1.
    pub width_us: u16,
}

impl Default for PulseConfig {
    fn default() -> Self {
        Self {
            channel: 0,
            amplitude_ua: 20_000,
            width_us: 200,
        }
    }
}

/// rt-core's own key of `[ipc]` ([`IpcConfig`]). Default: notify on.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IpcKeys {
    /// Notify the stim-tick event service after each StimTick, so receivers can sleep on a
    /// listener instead of polling.
    pub notify: bool,
}

impl Default for IpcKeys {
    fn default() -> Self {
        Self { notify: true }
    }
}

fes_rt::one_own_key!(IpcKeys, notify);

/// The least `[telemetry] queue_capacity` rt-core accepts, in tick records.
pub const MIN_QUEUE_CAPACITY: usize = 16;

/// Invalid configuration file.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Unreadable, not TOML of this schema, wrong `schema`, or a value out of range.
    #[error(transparent)]
    File(#[from] FileError),
    /// The `[rt]` table is invalid.
    #[error(transparent)]
    Rt(#[from] RtConfigError),
    /// The service-name prefix is invalid.
    #[error("ipc.prefix: {0}")]
    Prefix(#[from] ServiceError),
    /// The prescription cannot be read or is invalid.
    #[error(transparent)]
    Prescription(#[from] fes_prescription::PrescriptionError),
    /// The pulse exceeds the prescription.
    #[error("[pulse] refused: {0}")]
    AbovePrescription(#[from] fes_prescription::Exceeded),
}

impl RtCoreConfig {
    /// A configuration with all defaults and the given source.
    pub fn with_source(source: SourceConfig) -> Self {
        Self {
            schema: SCHEMA.to_owned(),
            period_us: default_period_us(),
            prescription: None,
            source,
            rt: RtConfig::default(),
            reference: ReferenceConfig::default(),
            feedback: FeedbackConfig::default(),
            pulse: PulseConfig::default(),
            telemetry: TelemetryConfig::default(),
            ipc: IpcConfig::default(),
        }
    }

    /// Reads, parses and validates a file; a relative controller path is resolved against
    /// the file's directory.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let mut config: Self = config_file::load(path)?;
        config.validate()?;
        // Absolute, so that the configuration can be written elsewhere and still point at
        // the same files.
        if let SourceConfig::Controller { path: controller } = &mut config.source {
            config_file::resolve(path, controller);
        }
        if let Some(p) = &mut config.prescription {
            config_file::resolve(path, p);
        }
        Ok(config)
    }

    /// Reads the prescription, if one is configured, and holds the pulse against it:
    /// amplitude, phase width and charge per phase (amplitude x width) may not exceed it.
    /// rt-core refuses to start otherwise, so a slip in `[pulse]` (e.g. 100 mA for 20 mA)
    /// emits no tick at all. Returns the prescription read.
    pub fn check_prescription(
        &self,
    ) -> Result<Option<fes_prescription::Prescription>, ConfigError> {
        let Some(path) = &self.prescription else {
            return Ok(None);
        };
        let p = fes_prescription::Prescription::load(path)?;
        p.check_pulse(
            "rt-core [pulse]",
            self.pulse.amplitude_ua,
            u32::from(self.pulse.width_us),
        )?;
        Ok(Some(p))
    }

    /// Parses and validates TOML text.
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        let config: Self = config_file::parse(text)?;
        config.validate()?;
        Ok(config)
    }

    /// Checks every value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config_file::check_schema(&self.schema, SCHEMA)?;
        let period = Duration::from_micros(self.period_us);
        config_file::range(
            (MIN_PERIOD..=MAX_PERIOD).contains(&period),
            "period_us",
            self.period_us,
            "100..=1000000",
        )?;
        if let SourceConfig::TestPattern { ipi_ticks } = self.source {
            config_file::range(ipi_ticks >= 2, "source.ipi_ticks", ipi_ticks, ">= 2")?;
        }
        self.rt.validate()?;
        let r = &self.reference;
        config_file::within("reference.stale_after_ms", r.stale_after_ms, 1..=10_000)?;
        config_file::range(
            (0.0..=1000.0).contains(&r.stale_ramp_per_s),
            "reference.stale_ramp_per_s",
            r.stale_ramp_per_s,
            "0..=1000, finite",
        )?;
        config_file::within("feedback.max_age_ms", self.feedback.max_age_ms, 1..=1000)?;
        let p = &self.pulse;
        config_file::range(
            p.channel <= StimTick::MAX_CHANNEL,
            "pulse.channel",
            p.channel,
            "0..=15",
        )?;
        config_file::range(
            (1..=StimTick::MAX_AMPLITUDE_UA).contains(&p.amplitude_ua),
            "pulse.amplitude_ua",
            p.amplitude_ua,
            "1..=250000",
        )?;
        config_file::range(p.width_us >= 1, "pulse.width_us", p.width_us, ">= 1")?;
        self.telemetry.validate(MIN_QUEUE_CAPACITY)?;
        self.ipc.validate()?;
        Ok(())
    }

    /// The tick period.
    pub fn period(&self) -> Duration {
        Duration::from_micros(self.period_us)
    }

    /// The reference policy of the loop.
    pub fn reference_policy(&self) -> ReferencePolicy {
        ReferencePolicy {
            stale_after_ns: self.reference.stale_after_ms * 1_000_000,
            stale_ramp_per_s: self.reference.stale_ramp_per_s,
            tick_ns: self.period_us * 1_000,
        }
    }

    /// The pulse settings of the loop.
    pub fn pulse_settings(&self) -> PulseSettings {
        PulseSettings {
            channel: self.pulse.channel,
            amplitude_ua: self.pulse.amplitude_ua,
            width_us: self.pulse.width_us,
        }
    }

    /// Feedback sample age limit, ns, when feedback is on.
    pub fn feedback_max_age_ns(&self) -> Option<u64> {
        self.feedback
            .enabled
            .then_some(self.feedback.max_age_ms * 1_000_000)
    }

    /// The configuration as TOML.
    #[expect(
        clippy::expect_used,
        reason = "every field is TOML-representable, so serialisation cannot fail"
    )]
    pub fn to_toml(&self) -> String {
        // Every field is a TOML-representable value (strings, integers, finite floats,
        // tables); serialisation of this type cannot fail.
        toml::to_string_pretty(self).expect("RtCoreConfig serialises to TOML")
    }
}
