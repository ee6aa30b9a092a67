//! Liveness of a service's publishers through iceoryx2 0.10: the StimTick publisher
//! (rt-core) and the DriverCommand publisher (the supervisor).
//!
//! iceoryx2 keeps each service's ports in its dynamic configuration
//! (`PortFactory::dynamic_config().list_publishers`, each with the `UniqueNodeId` of the
//! node that created it) and each node's liveness as a monitoring token that its process
//! holds: [`Node::state_of`] reports [`NodeState::Dead`] once the process is gone without
//! cleaning up (SIGKILL, a crash), while a clean exit removes the publisher from the list.
//! A dead node's stale resources are removed here (`DeadNodeView`'s
//! `try_remove_stale_resources`), which frees the service's single publisher slot for a
//! restarted rt-core (or supervisor).
//!
//! With several publishers, the service is alive when any publisher's node is alive, dead
//! when none is alive and one is dead.
//!
//! **Whose publisher.** Every service here admits one publisher, but once the real one is
//! gone (its process killed) a process of the same user can take the slot and publish:
//! alive, it would keep the driver armed after the supervisor's death. With a unit
//! configured ([`LivenessMonitor::in_unit`]), a publisher counts only when its node's
//! process (the pid iceoryx2's node id carries) runs in that systemd unit
//! ([`fes_rt::rt::unit`]); any publisher outside it makes the service
//! [`Liveness::Foreign`], which the forward path treats as no publisher: it trips and
//! refuses an Arm (fail closed), whatever else is alive.
//!
//! This does file-system work, so it runs on the normal-priority report thread; the
//! forward thread reads the outcome from an atomic.

use fes_rt::msg::Contract;
use fes_rt::msg::service::{ServiceError, open_pubsub};
use iceoryx2::node::NodeState;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use crate::event::Liveness;

/// Publishers looked at per check (the services here have one, DriverCommand a few).
const MAX_PUBLISHERS_CHECKED: usize = 8;

/// Checks the publishers of one service carrying `T`.
pub struct LivenessMonitor<T: Contract> {
    service: PortFactory<ipc::Service, T, ()>,
    config: iceoryx2::config::Config,
    /// The systemd unit every publisher's process must run in, if checked.
    unit: Option<String>,
}

/// What one check found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LivenessCheck {
    /// The publisher's liveness.
    pub liveness: Liveness,
    /// A dead node's resources were removed during this check.
    pub cleaned_up: bool,
}

impl<T: Contract> LivenessMonitor<T> {
    /// Opens (or creates) the `T` service under `prefix` through `node`.
    pub fn new(node: &Node<ipc::Service>, prefix: &str) -> Result<Self, ServiceError> {
        Ok(Self {
            service: open_pubsub::<T>(node, prefix)?,
            config: node.config().clone(),
            unit: None,
        })
    }

    /// Requires every publisher's process to run in systemd unit `unit` (`None`: not
    /// checked).
    pub fn in_unit(mut self, unit: Option<String>) -> Self {
        self.unit = unit;
        self
    }

    /// Looks at the publishers now (see the module documentation).
    pub fn check(&self) -> LivenessCheck {
        let mut nodes = [None; MAX_PUBLISHERS_CHECKED];
        let mut n = 0;
        self.service.dynamic_config().list_publishers(|p| {
            nodes[n] = Some(p.node_id);
            n += 1;
            if n == MAX_PUBLISHERS_CHECKED {
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
        let mut result = LivenessCheck {
            liveness: Liveness::NoPublisher,
            cleaned_up: false,
        };
        for node_id in nodes.iter().flatten() {
            if self.is_foreign(node_id) {
                return LivenessCheck {
                    liveness: Liveness::Foreign,
                    cleaned_up: result.cleaned_up,
                };
            }
            let one = self.check_node(*node_id);
            result.cleaned_up |= one.cleaned_up;
            result.liveness = match (result.liveness, one.liveness) {
                (Liveness::Alive, _) | (_, Liveness::Alive) => Liveness::Alive,
                (Liveness::Dead, _) | (_, Liveness::Dead) => Liveness::Dead,
                (_, l) => l,
            };
        }
        result
    }

    /// A publisher whose live process runs outside the configured unit. A node whose
    /// process is gone is not judged here: it is dead ([`Self::check_node`]).
    fn is_foreign(&self, node_id: &iceoryx2::identifiers::UniqueNodeId) -> bool {
        let Some(unit) = &self.unit else {
            return false;
        };
        let Ok(pid) = node_id.pid::<ipc::Service>() else {
            return true;
        };
        let Ok(pid) = u32::try_from(pid.value()) else {
            return true;
        };
        let alive = std::path::Path::new("/proc").join(pid.to_string()).exists();
        alive && !fes_rt::rt::unit::runs_in_unit(pid, unit)
    }

    fn check_node(&self, node_id: iceoryx2::identifiers::UniqueNodeId) -> LivenessCheck {
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
