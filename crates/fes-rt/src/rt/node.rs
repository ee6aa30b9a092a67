//! The iceoryx2 node of a real-time process and the failures of its real-time thread,
//! shared by rt-core's loop and stim-driver's forward path.

use iceoryx2::prelude::*;

use super::clock::PeriodError;
use super::hlog::HlogError;
use super::realtime::RtError;
use crate::msg::port::PortError;
use crate::msg::service::ServiceError;

/// Failure of the real-time loop thread before or while it runs.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Real time could not be entered (refused, or invalid settings).
    #[error("refused to start: {0}")]
    Realtime(#[from] RtError),
    /// A service could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// A port could not be created.
    #[error(transparent)]
    Port(#[from] PortError),
    /// A port could not connect to its peers.
    #[error("cannot connect the {port}: {detail}")]
    Connect {
        /// Which port.
        port: &'static str,
        /// iceoryx2's reason.
        detail: String,
    },
    /// The period is invalid.
    #[error(transparent)]
    Period(#[from] PeriodError),
    /// The iceoryx2 node could not be created.
    #[error("cannot create the iceoryx2 node: {0}")]
    Node(String),
    /// The interval log could not be written.
    #[error(transparent)]
    Hlog(#[from] HlogError),
}

/// A map from an iceoryx2 connection error to [`RunError::Connect`] naming the port.
pub fn connect_err(port: &'static str) -> impl Fn(&dyn std::fmt::Debug) -> RunError {
    move |e| RunError::Connect {
        port,
        detail: format!("{e:?}"),
    }
}

/// Creates an iceoryx2 node named `name` with iceoryx2's own signal handling disabled (the
/// process installs [`super::signals::install_stop_handler`]).
pub fn create_node(name: &str) -> Result<Node<ipc::Service>, RunError> {
    let node_name = NodeName::new(name).map_err(|e| RunError::Node(format!("{e:?}")))?;
    // An explicit default configuration: iceoryx2's defaults, without its warning that no
    // global configuration file was found.
    let config = iceoryx2::config::Config::default();
    NodeBuilder::new()
        .config(&config)
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| RunError::Node(format!("{e:?}")))
}
