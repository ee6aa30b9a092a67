//! [`RtConfig`]: how a thread asks to become real-time (TOML, serde, validated).

use serde::{Deserialize, Serialize};

/// What to do when a real-time guarantee cannot be had (no rights for SCHED_FIFO, the core
/// does not exist, memory cannot be locked).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MissingRightsPolicy {
    /// Refuse to run (the stimulation rig's setting).
    Refuse,
    /// Say so in one line and run as well as possible (a bench, laptop or CI setting).
    BestEffort,
}

/// Real-time settings of one thread. Defaults (bench): SCHED_FIFO priority 80, not pinned,
/// best-effort, memory locked, 256 KiB of stack prefaulted, CPU wake-up latency limited to
/// 0 µs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RtConfig {
    /// SCHED_FIFO priority, 1..=99 (cyclictest's `-p`). Default 80.
    pub priority: u8,
    /// CPU core to pin the thread to (cyclictest's `-a`); absent = not pinned (the default:
    /// which core is isolated for real time is a deployment decision).
    pub core: Option<usize>,
    /// Refuse or run best-effort when a guarantee is missing. Default best-effort.
    pub on_missing_rights: MissingRightsPolicy,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`. Default true.
    pub lock_memory: bool,
    /// Bytes of stack to touch at start so the loop never page-faults on it. Default 256 KiB;
    /// at most [`RtConfig::MAX_PREFAULT_STACK_BYTES`].
    pub prefault_stack_bytes: usize,
    /// PM QoS limit on CPU wake-up (exit) latency for the life of the process, µs, written to
    /// `/dev/cpu_dma_latency` (as cyclictest does): 0 keeps the CPUs out of deep idle states
    /// so a timer wake-up is not delayed by leaving them. Absent = leave the system's setting.
    /// Default 0.
    pub cpu_dma_latency_us: Option<u32>,
}

impl Default for RtConfig {
    fn default() -> Self {
        Self {
            priority: 80,
            core: None,
            on_missing_rights: MissingRightsPolicy::BestEffort,
            lock_memory: true,
            prefault_stack_bytes: 256 * 1024,
            cpu_dma_latency_us: Some(0),
        }
    }
}

/// Invalid [`RtConfig`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RtConfigError {
    /// Priority outside 1..=99.
    #[error("rt.priority = {0} is outside 1..=99 (SCHED_FIFO priorities)")]
    Priority(u8),
    /// Core index absurdly large.
    #[error("rt.core = {0} is larger than {max}", max = RtConfig::MAX_CORE)]
    Core(usize),
    /// Stack prefault too large.
    #[error("rt.prefault_stack_bytes = {0} exceeds {max}", max = RtConfig::MAX_PREFAULT_STACK_BYTES)]
    PrefaultStack(usize),
}

impl RtConfig {
    /// Largest stack prefault accepted (the real-time thread is spawned with a stack of at
    /// least this plus 1 MiB).
    pub const MAX_PREFAULT_STACK_BYTES: usize = 8 * 1024 * 1024;
    /// Largest core index accepted by validation (whether it exists is checked at run time).
    pub const MAX_CORE: usize = 4095;

    /// Checks the ranges; whether the core exists is only known when entering real time.
    pub fn validate(&self) -> Result<(), RtConfigError> {
        if !(1..=99).contains(&self.priority) {
            return Err(RtConfigError::Priority(self.priority));
        }
        if let Some(core) = self.core
            && core > Self::MAX_CORE
        {
            return Err(RtConfigError::Core(core));
        }
        if self.prefault_stack_bytes > Self::MAX_PREFAULT_STACK_BYTES {
            return Err(RtConfigError::PrefaultStack(self.prefault_stack_bytes));
        }
        Ok(())
    }

    /// Stack size the real-time thread should be spawned with: the prefaulted part plus
    /// [`RtConfig::THREAD_STACK_HEADROOM_BYTES`].
    pub fn thread_stack_bytes(&self) -> usize {
        self.prefault_stack_bytes + Self::THREAD_STACK_HEADROOM_BYTES
    }

    /// Stack beyond the prefaulted part, as much as a default main thread has (8 MiB). The
    /// loop thread creates its iceoryx2 ports itself (before the hot path), and iceoryx2's
    /// set-up keeps large fixed-capacity containers on the stack; with 1 MiB the loop
    /// thread overflowed in debug builds while other iceoryx2 processes were running.
    pub const THREAD_STACK_HEADROOM_BYTES: usize = 8 * 1024 * 1024;
}
