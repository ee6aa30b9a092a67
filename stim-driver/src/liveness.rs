//! Liveness of the StimTick publisher through iceoryx2 0.10.
//!
//! iceoryx2 keeps each service's ports in its dynamic configuration
//! (`PortFactory::dynamic_config().list_publishers`, each with the `UniqueNodeId` of the
//! node that created it) and each node's liveness as a monitoring token that its process
//! holds: [`Node::state_of`] reports [`NodeState::Dead`] once the process is gone without
//! cleaning up (SIGKILL, a crash), while a clean exit removes the publisher from the list.
//! A dead node's stale resources are removed here (`DeadNodeView`'s
//! `try_remove_stale_resources`), which frees the service's single publisher slot for a
//! restarted rt-core.
//!
//! This does file-system work, so it runs on the normal-priority report thread; the
//! forward thread reads the outcome from an atomic.

use iceoryx2::node::NodeState;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use rt_core::msg::StimTick;
use rt_core::msg::service::{ServiceError, open_pubsub};

use crate::event::Liveness;

/// Checks the StimTick publisher of one service.
pub struct LivenessMonitor {
    service: PortFactory<ipc::Service, StimTick, ()>,
    config: iceoryx2::config::Config,
}

/// What one check found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LivenessCheck {
    /// The publisher's liveness.
    pub liveness: Liveness,
    /// A dead node's resources were removed during this check.
    pub cleaned_up: bool,
}

impl LivenessMonitor {
    /// Opens (or creates) the StimTick service under `prefix` through `node`.
    pub fn new(node: &Node<ipc::Service>, prefix: &str) -> Result<Self, ServiceError> {
        Ok(Self {
            service: open_pubsub::<StimTick>(node, prefix)?,
            config: node.config().clone(),
        })
    }

    /// Looks at the publisher now.
    pub fn check(&self) -> LivenessCheck {
        let mut publisher_node = None;
        self.service.dynamic_config().list_publishers(|p| {
            publisher_node = Some(p.node_id);
            CallbackProgression::Stop
        });
        let Some(node_id) = publisher_node else {
            return LivenessCheck {
                liveness: Liveness::NoPublisher,
                cleaned_up: false,
            };
        };
        match Node::<ipc::Service>::state_of(&self.config, node_id) {
            Ok(Some(NodeState::Alive(_))) => LivenessCheck {
                liveness: Liveness::Alive,
                cleaned_up: false,
            },
            Ok(Some(NodeState::Dead(view))) => LivenessCheck {
                liveness: Liveness::Dead,
                cleaned_up: view.try_remove_stale_resources().is_ok(),
            },
            // The publisher is registered but its node is gone: dead.
            Ok(None) => LivenessCheck {
                liveness: Liveness::Dead,
                cleaned_up: false,
            },
            Ok(Some(NodeState::Inaccessible(_) | NodeState::Undefined(_))) | Err(_) => {
                LivenessCheck {
                    liveness: Liveness::Unknown,
                    cleaned_up: false,
                }
            }
        }
    }
}
