//! Service names and quality of service for every topic, in one place.
//!
//! A full service name is `<prefix>/<topic>`; the prefix defaults to [`DEFAULT_PREFIX`] and is
//! configurable in every process so that tests (and two benches on one machine) run in
//! isolation. Every process opens a topic through [`open_pubsub`] (or
//! [`open_stim_tick_event`]), which applies the topic's [`PubSubQos`]: whichever process comes
//! first creates the service with exactly these settings, and the others find them compatible.
//! Ports are made from them only through [`super::port`].
//!
//! All topics use safe overflow: a full subscriber buffer drops its *oldest* sample, so a
//! publisher never blocks and never fails because a receiver is slow (the real-time rule "never
//! a blocking back-pressure strategy on the hot path"). A slow receiver sees a gap in `seq`.

use core::fmt::Debug;

use iceoryx2::port::backpressure_strategy::BackpressureStrategy;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::port_factory::{event, publish_subscribe};

use super::ValidationError;

/// Default service-name prefix.
pub const DEFAULT_PREFIX: &str = "fes";

/// Topic of [`super::Reference`]: supervisor -> rt-core.
pub const TOPIC_REFERENCE: &str = "reference";
/// Topic of [`super::ReferencePreview`]: supervisor -> rt-core (the setpoints scheduled
/// ahead).
pub const TOPIC_REFERENCE_PREVIEW: &str = "reference_preview";
/// Topic of [`super::StimTick`]: rt-core -> stim-driver (and recorders), every tick.
pub const TOPIC_STIM_TICK: &str = "stim_tick";
/// Event service notified by rt-core right after each [`super::StimTick`] is published, so a
/// receiver can sleep on a listener instead of polling.
pub const TOPIC_STIM_TICK_EVENT: &str = "stim_tick_event";
/// Topic of [`super::ForceSample`]: stim-driver -> supervisor, rt-core (feedback mode).
pub const TOPIC_FORCE_SAMPLE: &str = "force_sample";
/// Topic of [`super::DriverStatus`]: stim-driver -> supervisor.
pub const TOPIC_DRIVER_STATUS: &str = "driver_status";
/// Topic of [`super::TimingReport`]: rt-core, stim-driver, probes -> supervisor.
pub const TOPIC_TIMING: &str = "timing";
/// Topic of [`super::DriverCommand`]: supervisor -> stim-driver (arm, disarm, safe stop).
pub const TOPIC_DRIVER_COMMAND: &str = "driver_command";
/// Topic of [`super::PulseOutcome`]: stim-driver -> supervisor (what became of each pulse).
pub const TOPIC_PULSE_OUTCOME: &str = "pulse_outcome";

/// Longest accepted prefix (iceoryx2 service names are bounded; the topic is appended).
pub const MAX_PREFIX_LEN: usize = 64;

/// Quality of service of one publish-subscribe topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PubSubQos {
    /// Publishers the service admits.
    pub max_publishers: usize,
    /// Subscribers the service admits.
    pub max_subscribers: usize,
    /// Samples a subscriber buffers before the oldest is overwritten.
    pub subscriber_buffer: usize,
    /// Samples a late-joining subscriber receives on connection (0 = none).
    pub history: usize,
    /// Samples a publisher may hold loaned at once (iceoryx2's default is 2); it sizes the
    /// publisher's shared-memory segment.
    pub max_loaned_samples: usize,
}

impl PubSubQos {
    /// The QoS of a status or report topic ([`super::DriverStatus`], [`super::TimingReport`]):
    /// a periodic snapshot of which subscribers act on the newest sample, from up to
    /// `max_publishers` senders.
    ///
    /// - `history: 1`: a subscriber that connects late (a restarted supervisor) gets the last
    ///   snapshot at once instead of waiting up to a period for the next;
    /// - `subscriber_buffer: 16`: a reader that falls behind for a while (a second and more
    ///   of DriverStatus at its 100 ms period) still finds the recent snapshots; beyond that
    ///   the oldest is overwritten, and the publisher never waits;
    /// - `max_loaned_samples: 2`: iceoryx2's default; the publishers are reporting threads,
    ///   not the 1 ms loop, so their shared-memory segment is not trimmed to one loan;
    /// - `max_subscribers: 8`, as on most topics.
    pub const fn status_report(max_publishers: usize) -> Self {
        Self {
            max_publishers,
            max_subscribers: 8,
            subscriber_buffer: 16,
            history: 1,
            max_loaned_samples: 2,
        }
    }
}

/// A message type together with its topic, its quality of service and its validation.
pub trait Contract: Copy + Debug + ZeroCopySend + 'static {
    /// Topic name (appended to the prefix).
    const TOPIC: &'static str;
    /// Quality of service every process uses for this topic.
    const QOS: PubSubQos;
    /// Checks everything a receiver relies on: finite floats, ranges, known flags and enums,
    /// timestamp order. Call it on every received sample before use.
    fn validate(&self) -> Result<(), ValidationError>;
}

/// Failure to name or open a service.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ServiceError {
    /// The prefix is empty, too long, or contains characters other than ASCII letters, digits,
    /// `_`, `-`, `.` and `/` (no leading or trailing `/`).
    #[error(
        "invalid service-name prefix (1..=64 characters of [A-Za-z0-9_./-], no leading/trailing '/')"
    )]
    InvalidPrefix,
    /// iceoryx2 rejected the composed service name.
    #[error("iceoryx2 rejected the service name: {0:?}")]
    InvalidName(iceoryx2::service::service_name::ServiceNameError),
    /// The publish-subscribe service could not be opened or created (an incompatible existing
    /// service with the same name, e.g. from an older build: remove it or change the prefix).
    #[error("cannot open or create publish-subscribe service {topic}: {error}")]
    PubSub {
        /// Topic that failed.
        topic: &'static str,
        /// iceoryx2's reason.
        error: PublishSubscribeOpenOrCreateError,
    },
    /// The service exists with another publisher limit or without safe overflow: it was
    /// not created by this stack (iceoryx2 opens a service whose limit is larger than
    /// asked without complaint, so a process that created it first with room for more
    /// publishers could add a second commander beside ours).
    #[error(
        "publish-subscribe service {topic} exists with max_publishers {found} and safe \
         overflow {safe_overflow}; this stack creates it with max_publishers {expected} \
         and safe overflow: another process created it (remove its files under \
         /dev/shm and /tmp/iceoryx2, or use another prefix)"
    )]
    Foreign {
        /// Topic that failed.
        topic: &'static str,
        /// The existing service's publisher limit.
        found: usize,
        /// This stack's.
        expected: usize,
        /// Whether the existing service has safe overflow.
        safe_overflow: bool,
    },
    /// The event service exists with another notifier limit (see [`Self::Foreign`]).
    #[error(
        "event service {topic} exists with max_notifiers {found}; this stack creates it \
         with {expected}: another process created it"
    )]
    ForeignEvent {
        /// Topic that failed.
        topic: &'static str,
        /// The existing service's notifier limit.
        found: usize,
        /// This stack's.
        expected: usize,
    },
    /// The event service could not be opened or created.
    #[error("cannot open or create event service {topic}: {error}")]
    Event {
        /// Topic that failed.
        topic: &'static str,
        /// iceoryx2's reason.
        error: EventOpenOrCreateError,
    },
}

/// Checks a service-name prefix (see [`ServiceError::InvalidPrefix`]).
pub fn validate_prefix(prefix: &str) -> Result<(), ServiceError> {
    let ok_chars = prefix
        .bytes()
        .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'_' | b'-' | b'.' | b'/'));
    if prefix.is_empty()
        || prefix.len() > MAX_PREFIX_LEN
        || !ok_chars
        || prefix.starts_with('/')
        || prefix.ends_with('/')
    {
        return Err(ServiceError::InvalidPrefix);
    }
    Ok(())
}

/// `<prefix>/<topic>` as an iceoryx2 service name.
pub fn service_name(prefix: &str, topic: &str) -> Result<ServiceName, ServiceError> {
    validate_prefix(prefix)?;
    let full = format!("{prefix}/{topic}");
    ServiceName::new(&full).map_err(ServiceError::InvalidName)
}

/// Opens (or creates) the publish-subscribe service of contract `M` under `prefix` with the
/// contract's [`PubSubQos`] and safe overflow, and checks that the service admits exactly
/// the contract's publishers ([`ServiceError::Foreign`] otherwise).
pub fn open_pubsub<M: Contract>(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<publish_subscribe::PortFactory<ipc::Service, M, ()>, ServiceError> {
    let name = service_name(prefix, M::TOPIC)?;
    let factory = node
        .service_builder(&name)
        .publish_subscribe::<M>()
        .enable_safe_overflow(true)
        .max_publishers(M::QOS.max_publishers)
        .max_subscribers(M::QOS.max_subscribers)
        .subscriber_max_buffer_size(M::QOS.subscriber_buffer)
        .history_size(M::QOS.history)
        .subscriber_max_borrowed_samples(2)
        .open_or_create()
        .map_err(|error| ServiceError::PubSub {
            topic: M::TOPIC,
            error,
        })?;
    // iceoryx2 treats the limits asked on open as minimums: read back what the service
    // really admits.
    let config = factory.static_config();
    if config.max_publishers() != M::QOS.max_publishers || !config.has_safe_overflow() {
        return Err(ServiceError::Foreign {
            topic: M::TOPIC,
            found: config.max_publishers(),
            expected: M::QOS.max_publishers,
            safe_overflow: config.has_safe_overflow(),
        });
    }
    Ok(factory)
}

/// Opens (or creates) the event service that rt-core notifies after each StimTick.
pub fn open_stim_tick_event(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<event::PortFactory<ipc::Service>, ServiceError> {
    let name = service_name(prefix, TOPIC_STIM_TICK_EVENT)?;
    let factory = node
        .service_builder(&name)
        .event()
        .max_notifiers(STIM_TICK_EVENT_NOTIFIERS)
        .max_listeners(8)
        .open_or_create()
        .map_err(|error| ServiceError::Event {
            topic: TOPIC_STIM_TICK_EVENT,
            error,
        })?;
    let found = factory.static_config().max_notifiers();
    if found != STIM_TICK_EVENT_NOTIFIERS {
        return Err(ServiceError::ForeignEvent {
            topic: TOPIC_STIM_TICK_EVENT,
            found,
            expected: STIM_TICK_EVENT_NOTIFIERS,
        });
    }
    Ok(factory)
}

/// Notifiers the StimTick event service admits (rt-core, and a restarted rt-core while
/// the old one's port is reclaimed).
const STIM_TICK_EVENT_NOTIFIERS: usize = 2;

/// Back-pressure strategy every publisher uses. With safe overflow it is never consulted;
/// it is set anyway so that a service created elsewhere without safe overflow still cannot
/// make a publisher wait.
pub const BACKPRESSURE: BackpressureStrategy = BackpressureStrategy::DiscardData;
