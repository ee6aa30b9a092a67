//! The daemon's configuration file (`schema = "fes-supervisor/1"`, TOML), read once at
//! start-up and validated; every key has a documented default
//! (`deploy/etc/fes/supervisor.toml` is the complete file, `supervisor run
//! --print-example-config` prints it).

use std::path::{Path, PathBuf};

use fes_rt::rt::config::IpcConfig;
use serde::{Deserialize, Serialize};

use crate::contraction::ContractionSettings;
use crate::health::HealthSettings;
use crate::limits::ReferenceLimits;
use crate::outer_loop::OuterLoopSettings;
use crate::range::RangeError;

/// The schema tag this version reads.
pub const SCHEMA: &str = "fes-supervisor/1";

/// The complete, documented rig configuration (`deploy/etc/fes/supervisor.toml`): the
/// defaults, plus `control.group = "fes"`.
pub const EXAMPLE: &str = include_str!("../../deploy/etc/fes/supervisor.toml");

/// The supervisor configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupervisorConfig {
    /// Must be [`SCHEMA`].
    pub schema: String,
    /// iceoryx2: the service-name prefix (as rt-core's and stim-driver's) and the node name.
    #[serde(default)]
    pub ipc: IpcConfig<IpcKeys>,
    /// Reference publication and limits.
    #[serde(default)]
    pub reference: ReferenceConfig,
    /// Operator control socket.
    #[serde(default)]
    pub control: ControlConfig,
    /// Outer loop.
    #[serde(default)]
    pub outer_loop: OuterLoopSettings,
    /// Contraction estimate of each beat.
    #[serde(default)]
    pub contraction: ContractionSettings,
    /// Health monitoring.
    #[serde(default)]
    pub health: HealthSettings,
    /// Recording.
    #[serde(default)]
    pub recording: RecordingConfig,
}

/// The supervisor's own key of `[ipc]` ([`IpcConfig`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IpcKeys {
    /// iceoryx2 node name of the supervisor (1..=64 characters). Default "supervisor".
    pub node_name: String,
}

impl Default for IpcKeys {
    fn default() -> Self {
        Self {
            node_name: "supervisor".into(),
        }
    }
}

fes_rt::one_own_key!(IpcKeys, node_name);

/// Reference publication.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReferenceConfig {
    /// A reference is published at least this often, ms (keep-alive for rt-core's
    /// staleness watchdog; profile edges are published when they happen). 1..=50,
    /// default 10.
    pub period_ms: u64,
    /// Highest reference the operator may ask for, in (0, 1]. Default 1.
    pub max_force: f64,
    /// Fastest change of the reference, normalised force per second, in (0, 1000];
    /// faster requests are refused. Default 50.
    pub max_rate_per_s: f64,
    /// Rate of a `set` without `--rate`, in (0, max_rate_per_s]. Default 5.
    pub default_rate_per_s: f64,
}

impl Default for ReferenceConfig {
    fn default() -> Self {
        let l = ReferenceLimits::default();
        Self {
            period_ms: 10,
            max_force: l.max_force,
            max_rate_per_s: l.max_rate_per_s,
            default_rate_per_s: l.default_rate_per_s,
        }
    }
}

impl ReferenceConfig {
    /// The limits part.
    pub fn limits(&self) -> ReferenceLimits {
        ReferenceLimits {
            max_force: self.max_force,
            max_rate_per_s: self.max_rate_per_s,
            default_rate_per_s: self.default_rate_per_s,
        }
    }
}

/// Operator control socket.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControlConfig {
    /// Socket path. Default /run/fes/supervisor.sock.
    pub socket: PathBuf,
    /// Socket file mode; must grant nothing to others. Default 0o660.
    pub mode: u32,
    /// A user whose processes may connect (besides the daemon's own user). Default none.
    pub user: Option<String>,
    /// A group whose members (primary or supplementary) may connect. Default none.
    pub group: Option<String>,
    /// A group whose members may only stop: admitted on the stop socket (which is then
    /// owned by this group), refused on the control socket. Default none (the stop socket
    /// has `group`'s policy and ownership). An operator who may also arm is a member of
    /// both.
    pub stop_group: Option<String>,
    /// Whether root may connect. Default true.
    pub allow_root: bool,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self {
            socket: PathBuf::from("/run/fes/supervisor.sock"),
            mode: 0o660,
            user: None,
            group: None,
            stop_group: None,
            allow_root: true,
        }
    }
}

/// Recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordingConfig {
    /// Record stimulation runs. Default true.
    pub enabled: bool,
    /// Directory that receives one sub-directory per run (created 0750). Default
    /// /var/lib/fes/recordings.
    pub dir: PathBuf,
    /// Files are flushed (and `dataset.json` rewritten) at least this often, ms;
    /// 100..=1000, default 1000.
    pub flush_period_ms: u64,
    /// Longest data-set record, ms (records also end at each beat). 100..=60000,
    /// default 1000 (so a crash loses at most the record being written).
    pub max_record_ms: u64,
    /// Newtons per unit of normalised force, for `dataset.json`, when the force stream
    /// cannot tell (no force variation yet). Default 1.
    pub scale_n: f64,
    /// Offset removed from the force, N, likewise. Default 0.
    pub offset_n: f64,
    /// Free text naming the rig in `dataset.json` `source`. Default "fes-supervisor".
    pub source: String,
    /// The prescription file (`fes-prescription/1`) whose SHA-256 goes into every
    /// recording's `dataset.json` (`prescription_sha256`); relative: to this file. With
    /// recording enabled the daemon refuses to start when it cannot read it. Default
    /// /etc/fes/prescription.toml.
    pub prescription: PathBuf,
}

impl Default for RecordingConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            dir: PathBuf::from("/var/lib/fes/recordings"),
            flush_period_ms: 1000,
            max_record_ms: 1000,
            scale_n: 1.0,
            offset_n: 0.0,
            source: "fes-supervisor".into(),
            prescription: PathBuf::from(fes_prescription::DEFAULT_PATH),
        }
    }
}

/// A configuration error, naming the file and the key.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Not valid TOML or not the expected shape.
    #[error("{path}: {source}")]
    Parse {
        /// File.
        path: PathBuf,
        /// toml's error (its message names the key and line).
        #[source]
        source: toml::de::Error,
    },
    /// A value out of range.
    #[error("{path}: {key}: {problem}")]
    Invalid {
        /// File.
        path: PathBuf,
        /// Key.
        key: String,
        /// What is wrong.
        problem: String,
    },
}

impl SupervisorConfig {
    /// A configuration with every default.
    pub fn defaults() -> Self {
        Self {
            schema: SCHEMA.into(),
            ipc: IpcConfig::default(),
            reference: ReferenceConfig::default(),
            control: ControlConfig::default(),
            outer_loop: OuterLoopSettings::default(),
            contraction: ContractionSettings::default(),
            health: HealthSettings::default(),
            recording: RecordingConfig::default(),
        }
    }

    /// Reads and validates `path`; relative paths in it are made relative to its
    /// directory.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut cfg = Self::from_toml(&text, path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        for p in [
            &mut cfg.control.socket,
            &mut cfg.recording.dir,
            &mut cfg.recording.prescription,
        ] {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        }
        Ok(cfg)
    }

    /// Parses and validates TOML text (`path` only names the file in errors).
    pub fn from_toml(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let parse = |source| ConfigError::Parse {
            path: path.to_path_buf(),
            source,
        };
        // Schema first, so a wrong file says so rather than complaining about a key.
        let value: toml::Table = toml::from_str(text).map_err(parse)?;
        match value.get("schema").and_then(|v| v.as_str()) {
            Some(SCHEMA) => {}
            Some(other) => {
                return Err(ConfigError::Invalid {
                    path: path.to_path_buf(),
                    key: "schema".into(),
                    problem: format!("`{other}` is not `{SCHEMA}`"),
                });
            }
            None => {
                return Err(ConfigError::Invalid {
                    path: path.to_path_buf(),
                    key: "schema".into(),
                    problem: format!("missing; the first line must be schema = \"{SCHEMA}\""),
                });
            }
        }
        let cfg: Self = toml::from_str(text).map_err(parse)?;
        cfg.validate()
            .map_err(|(key, problem)| ConfigError::Invalid {
                path: path.to_path_buf(),
                key,
                problem,
            })?;
        Ok(cfg)
    }

    /// Checks every value; the error is (key, problem).
    pub fn validate(&self) -> Result<(), (String, String)> {
        let key = |section: &str, e: RangeError| (format!("{section}.{}", e.key), e.problem());
        self.ipc
            .validate()
            .map_err(|e| ("ipc.prefix".to_string(), e.to_string()))?;
        let node_name = &self.ipc.own.node_name;
        if node_name.is_empty() || node_name.len() > 64 {
            return Err(("ipc.node_name".into(), "must be 1..=64 characters".into()));
        }
        if !(1..=50).contains(&self.reference.period_ms) {
            return Err((
                "reference.period_ms".into(),
                format!("{} must be in [1, 50]", self.reference.period_ms),
            ));
        }
        self.reference
            .limits()
            .validate()
            .map_err(|e| (format!("reference.{}", e.field), e.problem))?;
        if self.control.mode & !0o777 != 0 || self.control.mode & 0o007 != 0 {
            return Err((
                "control.mode".into(),
                format!(
                    "0o{:o} must be a permission mode granting nothing to others (e.g. 0o660)",
                    self.control.mode
                ),
            ));
        }
        if self.control.mode & 0o600 != 0o600 {
            return Err((
                "control.mode".into(),
                format!(
                    "0o{:o} must let the owner read and write",
                    self.control.mode
                ),
            ));
        }
        if self.control.socket.as_os_str().is_empty() {
            return Err(("control.socket".into(), "must not be empty".into()));
        }
        self.outer_loop
            .validate()
            .map_err(|e| key("outer_loop", e))?;
        self.contraction
            .validate()
            .map_err(|e| key("contraction", e))?;
        self.health.validate().map_err(|e| key("health", e))?;
        if !self.health.test_configuration {
            for (k, on) in [
                ("watch_rt_core", self.health.watch_rt_core),
                ("watch_stim_driver", self.health.watch_stim_driver),
                ("watch_stimulator", self.health.watch_stimulator),
            ] {
                if !on {
                    return Err((
                        format!("health.{k}"),
                        "false turns a safety watch off (no fault when that process stalls \
                         or dies, no acknowledged stop); only a test configuration may \
                         (health.test_configuration = true)"
                            .into(),
                    ));
                }
            }
        }
        let r = &self.recording;
        if !(100..=1000).contains(&r.flush_period_ms) {
            return Err((
                "recording.flush_period_ms".into(),
                format!("{} must be in [100, 1000]", r.flush_period_ms),
            ));
        }
        if !(100..=60_000).contains(&r.max_record_ms) {
            return Err((
                "recording.max_record_ms".into(),
                format!("{} must be in [100, 60000]", r.max_record_ms),
            ));
        }
        if !(r.scale_n.is_finite() && r.scale_n > 0.0) {
            return Err((
                "recording.scale_n".into(),
                format!("{} must be > 0", r.scale_n),
            ));
        }
        if !r.offset_n.is_finite() {
            return Err(("recording.offset_n".into(), "must be finite".into()));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_example_is_the_defaults_but_the_operator_group() {
        let cfg = SupervisorConfig::from_toml(EXAMPLE, Path::new("supervisor.toml")).unwrap();
        let mut expected = SupervisorConfig::defaults();
        expected.control.group = Some("fes".into());
        assert_eq!(cfg, expected);
    }

    #[test]
    fn errors_name_the_key() {
        let p = Path::new("s.toml");
        let e = SupervisorConfig::from_toml("schema = \"x\"", p).unwrap_err();
        assert_eq!(
            e.to_string(),
            "s.toml: schema: `x` is not `fes-supervisor/1`"
        );
        let e = SupervisorConfig::from_toml(
            "schema = \"fes-supervisor/1\"\n[control]\nmode = 0o666\n",
            p,
        )
        .unwrap_err();
        assert!(e.to_string().contains("control.mode"), "{e}");
        let e = SupervisorConfig::from_toml(
            "schema = \"fes-supervisor/1\"\n[outer_loop]\ngain = 2.0\n",
            p,
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "s.toml: outer_loop.gain: 2 must be in (0, 1]"
        );
        let e = SupervisorConfig::from_toml(
            "schema = \"fes-supervisor/1\"\n[reference]\nmax_rate_per_s = 0.0\n",
            p,
        )
        .unwrap_err();
        assert!(e.to_string().contains("reference.max_rate_per_s"), "{e}");
        let e =
            SupervisorConfig::from_toml("schema = \"fes-supervisor/1\"\n[health]\nbogus = 1\n", p)
                .unwrap_err();
        assert!(e.to_string().contains("unknown field `bogus`"), "{e}");
    }
}
