//! The one way every process makes its iceoryx2 ports: the service opened with the topic's
//! [`PubSubQos`] ([`super::service::open_pubsub`]), then the port with the settings the
//! contract implies, so that no process builds a port by hand and gets one of them wrong.
//!
//! - a publisher never blocks ([`BACKPRESSURE`], safe overflow on the service) and loans at
//!   most [`PubSubQos::max_loaned_samples`] samples (the pattern generator's 1: one tick in
//!   flight);
//! - a subscriber buffers [`PubSubQos::subscriber_buffer`] samples and asks for the topic's
//!   history ([`PubSubQos::history`]: the last Reference, DriverStatus, TimingReport);
//! - the stim-tick event has one notifier (rt-core) and listeners (the driver, probes).
//!
//! Errors keep iceoryx2's error as their source ([`PortError`]).

use iceoryx2::port::listener::{Listener, ListenerCreateError};
use iceoryx2::port::notifier::{Notifier, NotifierCreateError};
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;

use super::service::{
    BACKPRESSURE, Contract, PubSubQos, ServiceError, TOPIC_STIM_TICK_EVENT, open_pubsub,
    open_stim_tick_event,
};

/// A port that could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    /// The service behind it could not be opened or created.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The publisher could not be created.
    #[error("cannot create the {topic} publisher: {source}")]
    Publisher {
        /// The topic.
        topic: &'static str,
        /// iceoryx2's reason.
        #[source]
        source: PublisherCreateError,
    },
    /// The subscriber could not be created.
    #[error("cannot create the {topic} subscriber: {source}")]
    Subscriber {
        /// The topic.
        topic: &'static str,
        /// iceoryx2's reason.
        #[source]
        source: SubscriberCreateError,
    },
    /// The event notifier could not be created.
    #[error("cannot create the {topic} notifier: {source}")]
    Notifier {
        /// The event topic.
        topic: &'static str,
        /// iceoryx2's reason.
        #[source]
        source: NotifierCreateError,
    },
    /// The event listener could not be created.
    #[error("cannot create the {topic} listener: {source}")]
    Listener {
        /// The event topic.
        topic: &'static str,
        /// iceoryx2's reason.
        #[source]
        source: ListenerCreateError,
    },
}

/// The publisher of contract `M` under `prefix`.
pub fn publisher<M: Contract>(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<Publisher<ipc::Service, M, ()>, PortError> {
    open_pubsub::<M>(node, prefix)?
        .publisher_builder()
        .backpressure_strategy(BACKPRESSURE)
        .max_loaned_samples(M::QOS.max_loaned_samples)
        .create()
        .map_err(|source| PortError::Publisher {
            topic: M::TOPIC,
            source,
        })
}

/// A subscriber of contract `M` under `prefix`.
pub fn subscriber<M: Contract>(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<Subscriber<ipc::Service, M, ()>, PortError> {
    let q: PubSubQos = M::QOS;
    open_pubsub::<M>(node, prefix)?
        .subscriber_builder()
        .buffer_size(q.subscriber_buffer)
        .history_request(q.history)
        .create()
        .map_err(|source| PortError::Subscriber {
            topic: M::TOPIC,
            source,
        })
}

/// The notifier of the stim-tick event (rt-core, after each StimTick).
pub fn stim_tick_notifier(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<Notifier<ipc::Service>, PortError> {
    open_stim_tick_event(node, prefix)?
        .notifier_builder()
        .create()
        .map_err(|source| PortError::Notifier {
            topic: TOPIC_STIM_TICK_EVENT,
            source,
        })
}

/// A listener of the stim-tick event (the driver, probes).
pub fn stim_tick_listener(
    node: &Node<ipc::Service>,
    prefix: &str,
) -> Result<Listener<ipc::Service>, PortError> {
    open_stim_tick_event(node, prefix)?
        .listener_builder()
        .create()
        .map_err(|source| PortError::Listener {
            topic: TOPIC_STIM_TICK_EVENT,
            source,
        })
}
