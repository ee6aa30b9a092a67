//! [`enter_realtime`]: make the calling thread a real-time thread, once, at its start.
//!
//! Steps, in order: pin to the configured core (`core_affinity`),
//! `mlockall(MCL_CURRENT | MCL_FUTURE)` (still at normal priority: faulting in the whole
//! process must not hold up other real-time work on the core), SCHED_FIFO at the configured
//! priority (`thread-priority`), prefault the stack. Every step that fails is recorded as an [`RtShortfall`]; the result says in one
//! line what was achieved. With [`MissingRightsPolicy::Refuse`] any shortfall is an error
//! (and the thread's scheduling is put back to normal); with
//! [`MissingRightsPolicy::BestEffort`] the thread carries on with what it got.

use core::fmt;
use std::hint::black_box;

use thread_priority::{
    RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
};

use super::config::{MissingRightsPolicy, RtConfig, RtConfigError};

/// One real-time guarantee that could not be had.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RtShortfall {
    /// SCHED_FIFO was refused (EPERM: the process needs CAP_SYS_NICE or an RLIMIT_RTPRIO of
    /// at least the priority, e.g. `LimitRTPRIO=` in its systemd unit).
    SchedFifoDenied {
        /// Requested priority.
        priority: u8,
        /// errno of `pthread_setschedparam`.
        errno: i32,
    },
    /// The requested core is not among the cores this process may run on.
    CoreMissing {
        /// Requested core.
        core: usize,
        /// Number of cores available to the process.
        available: usize,
    },
    /// Pinning to an existing core failed.
    AffinityFailed {
        /// Requested core.
        core: usize,
    },
    /// `mlockall` failed (EPERM/ENOMEM: needs CAP_IPC_LOCK or a large enough
    /// RLIMIT_MEMLOCK, e.g. `LimitMEMLOCK=infinity`).
    MemoryLockFailed {
        /// errno of `mlockall`.
        errno: i32,
    },
    /// The CPU wake-up latency limit could not be set (no `/dev/cpu_dma_latency`, or no
    /// permission to open it: root or a udev rule is needed).
    WakeLatencyLimitFailed {
        /// Requested limit, µs.
        limit_us: u32,
        /// errno of `open`/`write`.
        errno: i32,
    },
}

impl fmt::Display for RtShortfall {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::SchedFifoDenied { priority, errno } => write!(
                f,
                "no SCHED_FIFO {priority} ({}: needs CAP_SYS_NICE or RLIMIT_RTPRIO >= {priority})",
                errno_name(errno)
            ),
            Self::CoreMissing { core, available } => write!(
                f,
                "core {core} does not exist here ({available} core(s) available: 0..{})",
                available.saturating_sub(1)
            ),
            Self::AffinityFailed { core } => write!(f, "pinning to core {core} failed"),
            Self::MemoryLockFailed { errno } => write!(
                f,
                "memory not locked (mlockall: {}: needs CAP_IPC_LOCK or RLIMIT_MEMLOCK=unlimited)",
                errno_name(errno)
            ),
            Self::WakeLatencyLimitFailed { limit_us, errno } => write!(
                f,
                "CPU wake-up latency not limited to {limit_us} us (/dev/cpu_dma_latency: {})",
                errno_name(errno)
            ),
        }
    }
}

fn errno_name(errno: i32) -> String {
    match errno {
        libc::EPERM => "EPERM".to_owned(),
        libc::ENOMEM => "ENOMEM".to_owned(),
        libc::EINVAL => "EINVAL".to_owned(),
        libc::EAGAIN => "EAGAIN".to_owned(),
        libc::ENOENT => "ENOENT".to_owned(),
        libc::EACCES => "EACCES".to_owned(),
        other => format!("errno {other}"),
    }
}

/// What [`enter_realtime`] achieved.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RtStatus {
    /// SCHED_FIFO priority in effect, if any.
    pub fifo_priority: Option<u8>,
    /// Core the thread is pinned to, if any.
    pub core: Option<usize>,
    /// Whether all current and future memory is locked.
    pub memory_locked: bool,
    /// Bytes of stack prefaulted.
    pub stack_prefaulted_bytes: usize,
    /// CPU wake-up latency limit in force for the process, µs.
    pub cpu_dma_latency_us: Option<u32>,
    /// Guarantees that could not be had (empty: fully real-time).
    pub shortfalls: Vec<RtShortfall>,
    /// The policy that applied.
    pub policy: MissingRightsPolicy,
}

impl RtStatus {
    /// True when at least one guarantee is missing.
    pub fn is_degraded(&self) -> bool {
        !self.shortfalls.is_empty()
    }
}

impl fmt::Display for RtStatus {
    /// One line, e.g. `real-time: SCHED_FIFO 80, core 1, memory locked, 256 KiB stack
    /// prefaulted` or `real-time DEGRADED (best-effort): no SCHED_FIFO 80 (...); running
    /// SCHED_OTHER, ...`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_degraded() {
            let how = match self.policy {
                MissingRightsPolicy::Refuse => "REFUSED (on_missing_rights = refuse)",
                MissingRightsPolicy::BestEffort => "DEGRADED (best-effort)",
            };
            write!(f, "real-time {how}: ")?;
            for (i, s) in self.shortfalls.iter().enumerate() {
                if i > 0 {
                    f.write_str("; ")?;
                }
                write!(f, "{s}")?;
            }
            f.write_str("; got: ")?;
        } else {
            f.write_str("real-time: ")?;
        }
        match self.fifo_priority {
            Some(p) => write!(f, "SCHED_FIFO {p}")?,
            None => f.write_str("SCHED_OTHER")?,
        }
        match self.core {
            Some(c) => write!(f, ", core {c}")?,
            None => f.write_str(", not pinned")?,
        }
        f.write_str(if self.memory_locked {
            ", memory locked"
        } else {
            ", memory not locked"
        })?;
        write!(
            f,
            ", {} KiB stack prefaulted",
            self.stack_prefaulted_bytes / 1024
        )?;
        match self.cpu_dma_latency_us {
            Some(us) => write!(f, ", CPU wake-up latency <= {us} us"),
            None => Ok(()),
        }
    }
}

/// [`enter_realtime`] failed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RtError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] RtConfigError),
    /// A guarantee is missing and the policy is to refuse.
    #[error("{0}")]
    Refused(RtStatus),
}

/// Makes the calling thread real-time as configured (see the module documentation). Call it
/// once, first thing in the thread that runs the loop.
pub fn enter_realtime(config: &RtConfig) -> Result<RtStatus, RtError> {
    config.validate()?;
    let mut shortfalls = Vec::new();

    let core = match config.core {
        None => None,
        Some(core) => pin_to_core(core).map_err(|s| shortfalls.push(s)).ok(),
    };

    let memory_locked = if config.lock_memory {
        match lock_memory() {
            Ok(()) => true,
            Err(s) => {
                shortfalls.push(s);
                false
            }
        }
    } else {
        false
    };

    let fifo_priority = match set_fifo(config.priority) {
        Ok(()) => Some(config.priority),
        Err(s) => {
            shortfalls.push(s);
            None
        }
    };

    prefault_stack(config.prefault_stack_bytes);

    let cpu_dma_latency_us = match config.cpu_dma_latency_us {
        None => None,
        Some(limit_us) => match limit_wake_latency(limit_us) {
            Ok(()) => Some(limit_us),
            Err(s) => {
                shortfalls.push(s);
                None
            }
        },
    };

    let status = RtStatus {
        fifo_priority,
        core,
        memory_locked,
        stack_prefaulted_bytes: config.prefault_stack_bytes,
        cpu_dma_latency_us,
        shortfalls,
        policy: config.on_missing_rights,
    };
    if status.is_degraded() && config.on_missing_rights == MissingRightsPolicy::Refuse {
        if status.fifo_priority.is_some() {
            // Do not leave a refused thread at real-time priority; failure to undo is harmless
            // because the caller is about to stop.
            let _ = thread_priority::set_thread_priority_and_policy(
                thread_priority::thread_native_id(),
                ThreadPriority::Min,
                ThreadSchedulePolicy::Normal(thread_priority::NormalThreadSchedulePolicy::Other),
            );
        }
        return Err(RtError::Refused(RtStatus {
            fifo_priority: None,
            ..status
        }));
    }
    Ok(status)
}

fn pin_to_core(core: usize) -> Result<usize, RtShortfall> {
    let available = core_affinity::get_core_ids().unwrap_or_default();
    if !available.iter().any(|c| c.id == core) {
        return Err(RtShortfall::CoreMissing {
            core,
            available: available.len(),
        });
    }
    if core_affinity::set_for_current(core_affinity::CoreId { id: core }) {
        Ok(core)
    } else {
        Err(RtShortfall::AffinityFailed { core })
    }
}

fn set_fifo(priority: u8) -> Result<(), RtShortfall> {
    let denied = |errno| RtShortfall::SchedFifoDenied { priority, errno };
    let value = ThreadPriorityValue::try_from(priority).map_err(|_| denied(libc::EINVAL))?;
    thread_priority::set_thread_priority_and_policy(
        thread_priority::thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| match e {
        thread_priority::Error::OS(errno) => denied(errno),
        _ => denied(libc::EINVAL),
    })
}

fn lock_memory() -> Result<(), RtShortfall> {
    use nix::sys::mman::{MlockAllFlags, mlockall};
    mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE)
        .map_err(|e| RtShortfall::MemoryLockFailed { errno: e as i32 })
}

/// The open `/dev/cpu_dma_latency` request: the limit holds while the file stays open, so it
/// is kept for the life of the process (the kernel drops it when the process exits).
static WAKE_LATENCY_REQUEST: std::sync::Mutex<Option<(std::fs::File, u32)>> =
    std::sync::Mutex::new(None);

/// Requests a CPU wake-up latency of at most `limit_us` µs (PM QoS) for the life of the
/// process. A second call with a different limit replaces the first.
fn limit_wake_latency(limit_us: u32) -> Result<(), RtShortfall> {
    use std::io::Write;
    let fail = |e: std::io::Error| RtShortfall::WakeLatencyLimitFailed {
        limit_us,
        errno: e.raw_os_error().unwrap_or(libc::EIO),
    };
    let mut held = WAKE_LATENCY_REQUEST
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if matches!(&*held, Some((_, l)) if *l == limit_us) {
        return Ok(());
    }
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/cpu_dma_latency")
        .map_err(fail)?;
    // The interface takes a native-endian 32-bit value.
    file.write_all(&(limit_us as i32).to_ne_bytes())
        .map_err(fail)?;
    *held = Some((file, limit_us));
    Ok(())
}

/// Touches `bytes` of stack below the caller so that the pages are resident (and, after
/// `mlockall`, locked) before the loop runs.
pub fn prefault_stack(bytes: usize) {
    const CHUNK: usize = 4096;
    #[inline(never)]
    fn touch(remaining: usize) -> u8 {
        let mut page = [0u8; CHUNK];
        // Writes through black_box cannot be elided, so every page is really touched.
        black_box(&mut page)[0] = 1;
        let below = if remaining > CHUNK {
            touch(remaining - CHUNK)
        } else {
            0
        };
        // Using the page after the recursive call keeps the frame (no tail call).
        black_box(&page)[0].wrapping_add(below)
    }
    if bytes > 0 {
        black_box(touch(bytes));
    }
}
