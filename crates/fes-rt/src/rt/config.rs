//! The sections the daemons' configuration files share, each defined once with its
//! defaults and its range checks: `[rt]` ([`RtConfig`]: how a thread asks to become
//! real-time), `[ipc]` ([`IpcConfig`]) and `[telemetry]` ([`TelemetryConfig`]).
//!
//! A process that has keys of its own in a shared section (rt-core's `[ipc] notify`, the
//! supervisor's `[ipc] node_name`, stim-driver's `[telemetry] status_period_ms`) keeps them
//! in a type of its own ([`OwnKeys`]), read from the same table: every file keeps its
//! format, and a key the process does not have is refused as unknown, with serde's message
//! for a struct that denies unknown fields, as before the sections were shared.

mod section;

use std::path::PathBuf;

use serde::de::{IgnoredAny, MapAccess, SeqAccess};
use serde::{Deserialize, Deserializer, Serialize};

use super::config_file::{self, FileError};
use crate::msg::service::{DEFAULT_PREFIX, ServiceError, validate_prefix};

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

/// Keys one process adds to a shared section ([`IpcConfig`], [`TelemetryConfig`]), read from
/// the same TOML table as the shared keys. Its [`Default`] is the keys' defaults; its
/// `Serialize` writes the keys (the section flattens it); the process checks their values.
pub trait OwnKeys: Default {
    /// The keys, in their order in the section.
    const KEYS: &'static [&'static str];

    /// Reads the value of `key`, one of [`Self::KEYS`], from `map`.
    fn read_value<'de, A: MapAccess<'de>>(
        &mut self,
        key: &'static str,
        map: &mut A,
    ) -> Result<(), A::Error>;

    /// Reads the keys' values in their order from a section written as an array (the
    /// positional form serde's derive accepts for any struct, and so the sections accepted
    /// before they were shared); `false` once the array has ended.
    fn read_elements<'de, A: SeqAccess<'de>>(&mut self, seq: &mut A) -> Result<bool, A::Error>;
}

/// No keys beyond the shared ones: the section as a process without keys of its own has it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct NoOwnKeys {}

impl OwnKeys for NoOwnKeys {
    const KEYS: &'static [&'static str] = &[];

    fn read_value<'de, A: MapAccess<'de>>(
        &mut self,
        _key: &'static str,
        map: &mut A,
    ) -> Result<(), A::Error> {
        // Not called: no key is ours.
        map.next_value::<IgnoredAny>().map(drop)
    }

    fn read_elements<'de, A: SeqAccess<'de>>(&mut self, _seq: &mut A) -> Result<bool, A::Error> {
        Ok(true)
    }
}

/// Implements [`OwnKeys`] for a struct whose one own key is its field `$field`, named as the
/// field (rt-core's `[ipc] notify`, the supervisor's `[ipc] node_name`, stim-driver's
/// `[telemetry] status_period_ms`). The struct implements `Default` (the key's default);
/// the crate using the macro depends on serde.
#[macro_export]
macro_rules! one_own_key {
    ($ty:ty, $field:ident) => {
        impl $crate::rt::config::OwnKeys for $ty {
            const KEYS: &'static [&'static str] = &[stringify!($field)];

            fn read_value<'de, A: ::serde::de::MapAccess<'de>>(
                &mut self,
                _key: &'static str,
                map: &mut A,
            ) -> Result<(), A::Error> {
                self.$field = map.next_value()?;
                Ok(())
            }

            fn read_elements<'de, A: ::serde::de::SeqAccess<'de>>(
                &mut self,
                seq: &mut A,
            ) -> Result<bool, A::Error> {
                Ok(seq.next_element()?.map(|v| self.$field = v).is_some())
            }
        }
    };
}

/// Implements `Deserialize` and `section::Section` for the shared section `$ty<K>`, whose
/// shared keys are its fields `$field`, in their order, with the process's own keys after
/// the first `$own_at`: the list of keys and the reading of each stand once.
macro_rules! shared_section {
    ($ty:ident, own keys after $own_at:literal: $($field:ident),+) => {
        impl<'de, K: OwnKeys> Deserialize<'de> for $ty<K> {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                section::deserialize(d)
            }
        }

        impl<K: OwnKeys> section::Section for $ty<K> {
            const NAME: &'static str = stringify!($ty);
            const SHARED: &'static [&'static str] = &[$(stringify!($field)),+];
            const OWN_AT: usize = $own_at;
            type Own = K;

            fn own_mut(&mut self) -> &mut K {
                &mut self.own
            }

            fn read_shared<'de, A: MapAccess<'de>>(
                &mut self,
                i: usize,
                map: &mut A,
            ) -> Result<(), A::Error> {
                $(if Self::SHARED[i] == stringify!($field) {
                    self.$field = map.next_value()?;
                })+
                Ok(())
            }

            fn read_shared_element<'de, A: SeqAccess<'de>>(
                &mut self,
                i: usize,
                seq: &mut A,
            ) -> Result<bool, A::Error> {
                $(if Self::SHARED[i] == stringify!($field) {
                    return Ok(seq.next_element()?.map(|v| self.$field = v).is_some());
                })+
                Ok(false)
            }
        }
    };
}

/// `[ipc]`: where the processes of one stack meet on iceoryx2. Default prefix "fes". `K`:
/// the keys the process adds, after `prefix` (rt-core's `notify`, the supervisor's
/// `node_name`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IpcConfig<K = NoOwnKeys> {
    /// Service-name prefix: the same in every process of a stack, another one for a second
    /// stack (a bench, a test) on the same machine.
    pub prefix: String,
    /// The process's own keys.
    #[serde(flatten)]
    pub own: K,
}

impl<K: Default> Default for IpcConfig<K> {
    fn default() -> Self {
        Self {
            prefix: DEFAULT_PREFIX.to_owned(),
            own: K::default(),
        }
    }
}

impl<K> IpcConfig<K> {
    /// Checks the prefix (the process checks its own keys).
    pub fn validate(&self) -> Result<(), ServiceError> {
        validate_prefix(&self.prefix)
    }
}

shared_section! { IpcConfig, own keys after 1: prefix }

/// `[telemetry]` of a process with a real-time thread: what it measures and reports, and
/// the queue its real-time thread hands its records to the telemetry thread through.
/// Defaults: no hlog, a TimingReport every 1000 ms, 8192 queued records, allocations traced.
/// `K`: the keys the process adds, after `report_period_ms` (stim-driver's
/// `status_period_ms`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TelemetryConfig<K = NoOwnKeys> {
    /// HdrHistogram interval log to write; relative paths are relative to the working
    /// directory.
    pub hlog: Option<PathBuf>,
    /// Period of TimingReports and hlog intervals, ms (10..=60000).
    pub report_period_ms: u64,
    /// The process's own keys.
    #[serde(flatten)]
    pub own: K,
    /// Records the queue from the real-time thread to the telemetry thread holds (rt-core's
    /// tick records, stim-driver's events), at most
    /// [`TelemetryConfig::MAX_QUEUE_CAPACITY`]; the least is the process's
    /// ([`TelemetryConfig::validate`]).
    pub queue_capacity: usize,
    /// Keep the backtrace of the real-time loop's first heap allocation, if one happens, and
    /// log it at exit ([`crate::rt::alloc::trace_first_heap_allocation`]; costs nothing until
    /// then). Default true.
    pub trace_allocations: bool,
}

impl<K: Default> Default for TelemetryConfig<K> {
    fn default() -> Self {
        Self {
            hlog: None,
            report_period_ms: 1000,
            own: K::default(),
            queue_capacity: 8192,
            trace_allocations: true,
        }
    }
}

impl<K> TelemetryConfig<K> {
    /// Most records a telemetry queue may hold.
    pub const MAX_QUEUE_CAPACITY: usize = 1 << 20;

    /// Checks the shared keys (the process checks its own): the report period, and a queue
    /// of at least `min_queue_capacity` records, a floor each process sets for its records
    /// (rt-core 16 tick records, stim-driver 256 events).
    pub fn validate(&self, min_queue_capacity: usize) -> Result<(), FileError> {
        config_file::within(
            "telemetry.report_period_ms",
            self.report_period_ms,
            10..=60_000,
        )?;
        config_file::within(
            "telemetry.queue_capacity",
            self.queue_capacity,
            min_queue_capacity..=Self::MAX_QUEUE_CAPACITY,
        )
    }
}

shared_section! {
    TelemetryConfig, own keys after 2: hlog, report_period_ms, queue_capacity, trace_allocations
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A process's own `[ipc]` key, as rt-core's `notify`.
    #[derive(Debug, Clone, PartialEq, Eq, Serialize)]
    struct Notify {
        notify: bool,
    }

    impl Default for Notify {
        fn default() -> Self {
            Self { notify: true }
        }
    }

    crate::one_own_key!(Notify, notify);

    /// A process's own `[telemetry]` key, as stim-driver's `status_period_ms`.
    #[derive(Debug, Clone, PartialEq, Eq, Serialize)]
    struct StatusPeriod {
        status_period_ms: u64,
    }

    impl Default for StatusPeriod {
        fn default() -> Self {
            Self {
                status_period_ms: 100,
            }
        }
    }

    crate::one_own_key!(StatusPeriod, status_period_ms);

    /// A file with the shared sections, `I` and `T` their own keys.
    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(deny_unknown_fields, bound(deserialize = "I: OwnKeys, T: OwnKeys"))]
    struct Shared<I: OwnKeys, T: OwnKeys> {
        #[serde(default)]
        ipc: IpcConfig<I>,
        #[serde(default)]
        telemetry: TelemetryConfig<T>,
    }

    /// The sections as each process derived them before they were shared: what the shared
    /// ones must read, refuse and write alike. `plain`: without own keys; `own`: with the
    /// test's own keys.
    mod derived {
        use serde::{Deserialize, Serialize};

        #[derive(Debug, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct File<I, T> {
            #[serde(default)]
            pub ipc: I,
            #[serde(default)]
            pub telemetry: T,
        }

        pub mod plain {
            use std::path::PathBuf;

            use serde::{Deserialize, Serialize};

            #[derive(Debug, PartialEq, Serialize, Deserialize)]
            #[serde(deny_unknown_fields, default)]
            pub struct IpcConfig {
                pub prefix: String,
            }

            impl Default for IpcConfig {
                fn default() -> Self {
                    Self {
                        prefix: "fes".into(),
                    }
                }
            }

            #[derive(Debug, PartialEq, Serialize, Deserialize)]
            #[serde(deny_unknown_fields, default)]
            pub struct TelemetryConfig {
                pub hlog: Option<PathBuf>,
                pub report_period_ms: u64,
                pub queue_capacity: usize,
                pub trace_allocations: bool,
            }

            impl Default for TelemetryConfig {
                fn default() -> Self {
                    Self {
                        hlog: None,
                        report_period_ms: 1000,
                        queue_capacity: 8192,
                        trace_allocations: true,
                    }
                }
            }
        }

        pub mod own {
            use std::path::PathBuf;

            use serde::{Deserialize, Serialize};

            #[derive(Debug, PartialEq, Serialize, Deserialize)]
            #[serde(deny_unknown_fields, default)]
            pub struct IpcConfig {
                pub prefix: String,
                pub notify: bool,
            }

            impl Default for IpcConfig {
                fn default() -> Self {
                    Self {
                        prefix: "fes".into(),
                        notify: true,
                    }
                }
            }

            #[derive(Debug, PartialEq, Serialize, Deserialize)]
            #[serde(deny_unknown_fields, default)]
            pub struct TelemetryConfig {
                pub hlog: Option<PathBuf>,
                pub report_period_ms: u64,
                pub status_period_ms: u64,
                pub queue_capacity: usize,
                pub trace_allocations: bool,
            }

            impl Default for TelemetryConfig {
                fn default() -> Self {
                    Self {
                        hlog: None,
                        report_period_ms: 1000,
                        status_period_ms: 100,
                        queue_capacity: 8192,
                        trace_allocations: true,
                    }
                }
            }
        }
    }

    /// Texts that exercise reading: defaults, every key, own keys in the wrong process,
    /// unknown keys, wrong types, inline tables and the positional (array) form.
    const TEXTS: &[&str] = &[
        "",
        "[ipc]\n[telemetry]\n",
        "[ipc]\nprefix = \"bench-1\"\n",
        "[ipc]\nprefix = 3\n",
        "[ipc]\nnotify = false\n",
        "[ipc]\nnotify = \"yes\"\n",
        "[ipc]\nnode_name = \"x\"\n",
        "[ipc]\nprefix = \"p\"\nnotify = false\nbogus = 1\n",
        "ipc = 3\n",
        "ipc = [\"x\"]\n",
        "ipc = [\"x\", false]\n",
        "ipc = { prefix = \"q\", notify = false }\n",
        "[telemetry]\nhlog = \"/tmp/x.hlog\"\nreport_period_ms = 500\nqueue_capacity = 300\ntrace_allocations = false\n",
        "[telemetry]\nstatus_period_ms = 50\n",
        "[telemetry]\nhlog = 3\n",
        "[telemetry]\nqueue_capacity = -1\n",
        "[telemetry]\nbogus = 1\n",
        "telemetry = [\"x\", 20, 30, 40, false]\n",
        "telemetry = [\"x\", 20]\n",
    ];

    /// Parses `text` with the shared sections and with the derived ones; the outcomes (the
    /// values written back, or the error with its place) must be the same.
    fn same<I, T, DI, DT>(text: &str)
    where
        I: OwnKeys + Serialize,
        T: OwnKeys + Serialize,
        DI: Default + Serialize + serde::de::DeserializeOwned,
        DT: Default + Serialize + serde::de::DeserializeOwned,
    {
        let shared = toml::from_str::<Shared<I, T>>(text)
            .map(|s| toml::to_string(&s).unwrap())
            .map_err(|e| e.to_string());
        let derived = toml::from_str::<derived::File<DI, DT>>(text)
            .map(|s| toml::to_string(&s).unwrap())
            .map_err(|e| e.to_string());
        assert_eq!(shared, derived, "{text:?}");
    }

    #[test]
    fn shared_sections_read_refuse_and_write_as_the_derived_ones_did() {
        for text in TEXTS {
            same::<NoOwnKeys, NoOwnKeys, derived::plain::IpcConfig, derived::plain::TelemetryConfig>(
                text,
            );
            same::<Notify, StatusPeriod, derived::own::IpcConfig, derived::own::TelemetryConfig>(
                text,
            );
        }
        // Spot checks of what that comparison covers.
        let e = toml::from_str::<Shared<Notify, NoOwnKeys>>("[ipc]\nbogus = 1\n").unwrap_err();
        assert!(
            e.to_string()
                .contains("unknown field `bogus`, expected `prefix` or `notify`"),
            "{e}"
        );
        let e = toml::from_str::<Shared<NoOwnKeys, StatusPeriod>>("[telemetry]\nx = 1\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "expected one of `hlog`, `report_period_ms`, `status_period_ms`, \
                 `queue_capacity`, `trace_allocations`"
            ),
            "{e}"
        );
        let e = toml::from_str::<Shared<NoOwnKeys, NoOwnKeys>>("[ipc]\nnotify = true\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown field `notify`, expected `prefix`"),
            "{e}"
        );
        let s: Shared<Notify, StatusPeriod> =
            toml::from_str("[ipc]\nnotify = false\n[telemetry]\nstatus_period_ms = 50\n").unwrap();
        assert_eq!(
            (s.ipc.prefix.as_str(), s.ipc.own.notify),
            (DEFAULT_PREFIX, false)
        );
        assert_eq!(s.telemetry.own.status_period_ms, 50);
        assert_eq!(
            s.telemetry,
            TelemetryConfig {
                own: StatusPeriod {
                    status_period_ms: 50
                },
                ..TelemetryConfig::default()
            }
        );
        // Written back in the order of the file: the own key after report_period_ms.
        let text = toml::to_string(&s).unwrap();
        assert!(
            text.contains(
                "report_period_ms = 1000\nstatus_period_ms = 50\nqueue_capacity = 8192\n"
            ),
            "{text}"
        );
    }

    #[test]
    fn shared_sections_check_their_ranges_and_the_process_sets_the_queue_floor() {
        let t = TelemetryConfig::<NoOwnKeys>::default();
        assert!(t.validate(16).is_ok());
        let range = |t: &TelemetryConfig, min| match t.validate(min) {
            Err(FileError::Range { field, allowed, .. }) => (field, allowed.into_owned()),
            other => panic!("{other:?}"),
        };
        for (period, ok) in [(9, false), (10, true), (60_000, true), (60_001, false)] {
            let t: TelemetryConfig = TelemetryConfig {
                report_period_ms: period,
                ..TelemetryConfig::default()
            };
            assert_eq!(t.validate(16).is_ok(), ok, "{period}");
        }
        let small: TelemetryConfig = TelemetryConfig {
            queue_capacity: 255,
            ..TelemetryConfig::default()
        };
        assert!(small.validate(16).is_ok());
        assert_eq!(
            range(&small, 256),
            ("telemetry.queue_capacity", "256..=1048576".to_owned())
        );
        let big: TelemetryConfig = TelemetryConfig {
            queue_capacity: (1 << 20) + 1,
            ..TelemetryConfig::default()
        };
        assert_eq!(
            range(&big, 16),
            ("telemetry.queue_capacity", "16..=1048576".to_owned())
        );
        assert_eq!(
            small.validate(256).unwrap_err().to_string(),
            "telemetry.queue_capacity = 255 is out of range (256..=1048576)"
        );

        assert!(IpcConfig::<NoOwnKeys>::default().validate().is_ok());
        let bad = IpcConfig::<NoOwnKeys> {
            prefix: "a b".into(),
            own: NoOwnKeys {},
        };
        assert_eq!(bad.validate(), Err(ServiceError::InvalidPrefix));
    }
}
