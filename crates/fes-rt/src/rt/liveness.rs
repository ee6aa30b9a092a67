//! Liveness of a service's publishers through iceoryx2 0.10, for the processes that must
//! know whether whoever publishes a service still runs: stim-driver watches the StimTick
//! publisher (rt-core) and the DriverCommand publisher (the supervisor) with
//! [`LivenessMonitor::check`]; the supervisor learns which nodes publish StimTick and
//! DriverStatus ([`LivenessMonitor::publisher_ids`]) and follows those nodes in the listing
//! of every node ([`list_nodes`]).
//!
//! iceoryx2 keeps each service's ports in its dynamic configuration
//! (`PortFactory::dynamic_config().list_publishers`, each with the `UniqueNodeId` of the
//! node that created it) and each node's liveness as a monitoring token that its process
//! holds: [`Node::state_of`] reports [`NodeState::Dead`] once the process is gone without
//! cleaning up (SIGKILL, a crash), while a clean exit removes the publisher from the list.
//! A check removes a dead node's stale resources (`DeadNodeView`'s
//! `try_remove_stale_resources`), which frees the service's single publisher slot for a
//! restarted rt-core (or supervisor); the listing leaves them, so the supervisor sees the
//! node dead until someone does.
//!
//! With several publishers, the service is alive when any publisher's node is alive, dead
//! when none is alive and one is dead.
//!
//! **Whose publisher.** Every service here admits one publisher, but once the real one is
//! gone (its process killed) a process of the same user can take the slot and publish:
//! alive, it would keep the driver armed after the supervisor's death. With a unit
//! configured ([`LivenessMonitor::in_unit`]), a publisher counts only when its node's
//! process (the pid iceoryx2's node id carries) runs in that systemd unit
//! ([`crate::rt::unit`]); any publisher outside it makes the service
//! [`Liveness::Foreign`], which stim-driver treats as no publisher: it trips and refuses an
//! Arm (fail closed), whatever else is alive.
//!
//! This does file-system work: it runs on a normal-priority thread, never a real-time loop.

use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::node::{NodeState, NodeView as _};
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use crate::code_enum::code_enum;
use crate::msg::Contract;
use crate::msg::service::{ServiceError, open_pubsub};

code_enum! {
    /// Liveness of a service's publisher, as a check found it.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Liveness {
        /// Not checked yet, or its node's state could not be read.
        Unknown = 0,
        /// A publisher exists and its node's process is alive.
        Alive = 1,
        /// The publisher's node is dead (its process died without cleaning up).
        Dead = 2,
        /// The service has no publisher.
        NoPublisher = 3,
        /// Its publisher's process runs outside the systemd unit the monitor requires
        /// ([`LivenessMonitor::in_unit`]): a squatter, never the real one.
        Foreign = 4,
    }
}

impl Liveness {
    /// Decodes a liveness stored as its `u8` (an atomic that one thread writes and another
    /// reads); an unknown value is [`Liveness::Unknown`].
    pub const fn from_u8(v: u8) -> Self {
        match Self::from_code(v) {
            Some(l) => l,
            None => Liveness::Unknown,
        }
    }
}

/// What one check found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LivenessCheck {
    /// The publisher's liveness.
    pub liveness: Liveness,
    /// A dead node's resources were removed during this check.
    pub cleaned_up: bool,
}

/// Publishers looked at per check (the services here have one, DriverCommand a few).
const MAX_PUBLISHERS_CHECKED: usize = 8;

/// Watches the publishers of one service carrying `T`.
pub struct LivenessMonitor<T: Contract> {
    service: PortFactory<ipc::Service, T, ()>,
    config: iceoryx2::config::Config,
    /// The systemd unit every publisher's process must run in, if checked.
    unit: Option<String>,
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

    /// The node ids of the service's publishers now (as [`NodeObservation::id`]), dead ones
    /// included until their resources are removed.
    pub fn publisher_ids(&self) -> Vec<u128> {
        let mut ids = Vec::new();
        self.for_each_publisher(|id| {
            ids.push(id.value());
            CallbackProgression::Continue
        });
        ids
    }

    /// Looks at the publishers now, the first 8 of them, without allocating (see the
    /// module documentation).
    pub fn check(&self) -> LivenessCheck {
        let mut nodes = [None; MAX_PUBLISHERS_CHECKED];
        let mut n = 0;
        self.for_each_publisher(|id| {
            nodes[n] = Some(id);
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

    /// Calls `f` with the node id of each publisher of the service until it says stop.
    fn for_each_publisher(&self, mut f: impl FnMut(UniqueNodeId) -> CallbackProgression) {
        self.service
            .dynamic_config()
            .list_publishers(|p| f(p.node_id));
    }

    /// A publisher whose live process runs outside the configured unit. A node whose
    /// process is gone is not judged here: it is dead ([`Self::check_node`]).
    fn is_foreign(&self, node_id: &UniqueNodeId) -> bool {
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
        alive && !crate::rt::unit::runs_in_unit(pid, unit)
    }

    fn check_node(&self, node_id: UniqueNodeId) -> LivenessCheck {
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

/// An iceoryx2 node seen in a node listing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeObservation {
    /// Node name (`rt-core`, `stim-driver`, ...).
    pub name: String,
    /// Owner process id.
    pub pid: u32,
    /// iceoryx2's unique node id (as [`LivenessMonitor::publisher_ids`] gives it).
    pub id: u128,
    /// iceoryx2 reports the node dead (its process is gone without cleaning up).
    pub dead: bool,
}

/// Lists the iceoryx2 nodes of this machine that are alive or dead and name themselves;
/// nodes whose state cannot be read are left out.
pub fn list_nodes() -> Vec<NodeObservation> {
    let config = iceoryx2::config::Config::default();
    let mut out = Vec::new();
    let _ = Node::<ipc::Service>::list(&config, |state| {
        let (dead, details, id) = match &state {
            NodeState::Alive(v) => (false, v.details().clone(), v.id().value()),
            NodeState::Dead(v) => (true, v.details().clone(), v.id().value()),
            _ => return CallbackProgression::Continue,
        };
        if let Some(d) = details {
            out.push(NodeObservation {
                name: d.name().as_str().to_string(),
                pid: d.process_id().value() as u32,
                id,
                dead,
            });
        }
        CallbackProgression::Continue
    });
    out
}

#[cfg(test)]
mod tests {
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};

    use super::*;
    use crate::msg::{DriverCommand, StimTick, port};
    use crate::rt::node::create_node;

    /// Set in the child run of [`a_killed_publisher_is_dead_until_a_check_removes_it`]:
    /// the prefix to publish under and the file to create once publishing.
    const CHILD_PREFIX: &str = "FES_RT_LIVENESS_CHILD_PREFIX";
    const CHILD_READY: &str = "FES_RT_LIVENESS_CHILD_READY";

    /// Held by each test that makes nodes: creating a node removes every dead node, so
    /// these tests run one at a time.
    static NODES: std::sync::Mutex<()> = std::sync::Mutex::new(());

    fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
        NODES
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The liveness of `T`'s publishers as a monitor requiring `unit` sees it.
    fn liveness<T: Contract>(
        watcher: &Node<ipc::Service>,
        prefix: &str,
        unit: Option<&str>,
    ) -> Liveness {
        LivenessMonitor::<T>::new(watcher, prefix)
            .expect("monitor")
            .in_unit(unit.map(str::to_owned))
            .check()
            .liveness
    }

    /// What both daemons rely on while the publisher lives: stim-driver's check finds it
    /// alive, the supervisor finds its node among the publishers and, by that id, alive in
    /// the listing with its name and pid; once it is dropped, neither finds a publisher.
    #[test]
    fn a_live_publisher_is_alive_in_both_views_and_gone_once_dropped() {
        let _one = one_at_a_time();
        let prefix = format!("fesrt-live{}", std::process::id());
        let watcher = create_node("fesrt-live-watch").expect("node");
        let monitor = LivenessMonitor::<StimTick>::new(&watcher, &prefix).expect("monitor");
        assert_eq!(monitor.check().liveness, Liveness::NoPublisher);
        assert!(monitor.publisher_ids().is_empty());

        let node = create_node("fesrt-live-pub").expect("node");
        let publisher = port::publisher::<StimTick>(&node, &prefix).expect("publisher");
        let check = monitor.check();
        assert_eq!(
            check,
            LivenessCheck {
                liveness: Liveness::Alive,
                cleaned_up: false
            }
        );
        let ids = monitor.publisher_ids();
        assert_eq!(ids, vec![node.id().value()]);
        let listed = list_nodes();
        let seen = listed.iter().find(|n| n.id == ids[0]).expect("listed");
        assert_eq!(
            (seen.name.as_str(), seen.pid, seen.dead),
            ("fesrt-live-pub", std::process::id(), false)
        );

        drop(publisher);
        assert_eq!(monitor.check().liveness, Liveness::NoPublisher);
        assert!(monitor.publisher_ids().is_empty());
    }

    /// The child's part: a node publishing StimTick under `prefix`, then the ready file,
    /// then nothing until it is killed.
    fn child(prefix: &str, ready: &str) -> ! {
        let node = create_node("fesrt-live-dying").expect("node");
        let _publisher = port::publisher::<StimTick>(&node, prefix).expect("publisher");
        std::fs::write(ready, b"publishing\n").expect("ready file");
        loop {
            std::thread::sleep(Duration::from_secs(1));
        }
    }

    /// A publisher killed (SIGKILL: no clean-up): the supervisor sees its node dead in the
    /// listing and still among the publishers; stim-driver's check finds it dead and removes
    /// its stale resources, after which the service has no publisher and its one slot takes
    /// a restarted publisher.
    #[test]
    fn a_killed_publisher_is_dead_until_a_check_removes_it() {
        if let (Ok(prefix), Ok(ready)) = (std::env::var(CHILD_PREFIX), std::env::var(CHILD_READY)) {
            child(&prefix, &ready);
        }
        let _one = one_at_a_time();
        let dir = fes_testkit::Scratch::new("rt-liveness");
        // iceoryx2 removes dead nodes whenever any process creates a node: one created by
        // another process (another test binary, another stack) between the kill and the
        // look leaves nothing to see. That attempt does not count; another is made.
        for attempt in 0..5 {
            let prefix = format!("fesrt-dead{}-{attempt}", std::process::id());
            let watcher = create_node("fesrt-dead-watch").expect("node");
            let monitor = LivenessMonitor::<StimTick>::new(&watcher, &prefix).expect("monitor");
            let child_pid = kill_a_publisher(&prefix, &dir.join(format!("ready-{attempt}")));
            let ids = monitor.publisher_ids();
            let listed = list_nodes();
            let Some(seen) = ids
                .first()
                .and_then(|id| listed.iter().find(|n| n.id == *id))
            else {
                continue;
            };
            assert_eq!(
                (ids.len(), seen.pid, seen.dead),
                (1, child_pid, true),
                "{seen:?}"
            );
            let check = monitor.check();
            let removed_by_another = || list_nodes().iter().all(|n| n.id != seen.id);
            if check.liveness == Liveness::NoPublisher
                || (check.liveness == Liveness::Dead && !check.cleaned_up && removed_by_another())
            {
                continue;
            }
            assert_eq!(
                check,
                LivenessCheck {
                    liveness: Liveness::Dead,
                    cleaned_up: true
                }
            );
            assert_eq!(monitor.check().liveness, Liveness::NoPublisher);
            assert!(monitor.publisher_ids().is_empty());
            assert!(list_nodes().iter().all(|n| n.id != seen.id), "still listed");
            let restarted = create_node("fesrt-dead-restart").expect("node");
            let _again =
                port::publisher::<StimTick>(&restarted, &prefix).expect("the slot is free again");
            assert_eq!(monitor.check().liveness, Liveness::Alive);
            return;
        }
        panic!("5 times, another node's creation removed the dead node before it was seen");
    }

    /// Runs a child process that publishes StimTick under `prefix`, waits until it does,
    /// kills it (SIGKILL) and returns its pid.
    fn kill_a_publisher(prefix: &str, ready: &std::path::Path) -> u32 {
        let mut c = Command::new(std::env::current_exe().unwrap())
            .args([
                "rt::liveness::tests::a_killed_publisher_is_dead_until_a_check_removes_it",
                "--exact",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_PREFIX, prefix)
            .env(CHILD_READY, ready)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .unwrap();
        let start = Instant::now();
        while !ready.exists() {
            if let Some(status) = c.try_wait().unwrap() {
                panic!("the child ended before publishing: {status:?}");
            }
            if start.elapsed() > Duration::from_secs(30) {
                let _ = c.kill();
                let _ = c.wait();
                panic!("the child never published");
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let pid = c.id();
        c.kill().unwrap();
        c.wait().unwrap();
        pid
    }

    /// Whose publisher: the test process publishes DriverCommand and StimTick; it runs in
    /// no unit named `fes-supervisor.service` (nor any other fes unit), so a monitor
    /// requiring those units calls both publishers foreign. Without a unit (a bench) the
    /// same publishers are alive, and so they are in the unit the process does run in (its
    /// own cgroup's last component, when it has one).
    #[test]
    fn a_publisher_outside_the_configured_unit_is_foreign() {
        let _one = one_at_a_time();
        let prefix = format!("sdt-ident{}", std::process::id());
        let node = create_node("sdt-ident").expect("node");
        let _commands = port::publisher::<DriverCommand>(&node, &prefix).expect("publisher");
        let _ticks = port::publisher::<StimTick>(&node, &prefix).expect("publisher");
        let watcher = create_node("sdt-ident-watch").expect("node");
        let supervisor = |unit| liveness::<DriverCommand>(&watcher, &prefix, unit);
        let generator = |unit| liveness::<StimTick>(&watcher, &prefix, unit);
        assert_eq!(supervisor(None), Liveness::Alive, "no unit configured");
        assert_eq!(generator(None), Liveness::Alive, "no unit configured");
        assert_eq!(
            supervisor(Some("fes-supervisor.service")),
            Liveness::Foreign
        );
        assert_eq!(generator(Some("fes-rt-core.service")), Liveness::Foreign);
        let own = crate::rt::unit::cgroup_of(std::process::id()).expect("own cgroup");
        let own_unit = own.rsplit('/').next().unwrap_or_default();
        if own_unit.contains('.') {
            assert_eq!(supervisor(Some(own_unit)), Liveness::Alive, "{own}");
        } else {
            eprintln!(
                "this process's cgroup {own:?} names no unit: the positive case is the boot test's"
            );
        }
    }

    #[test]
    fn a_stored_liveness_decodes_to_itself() {
        for l in [
            Liveness::Unknown,
            Liveness::Alive,
            Liveness::Dead,
            Liveness::NoPublisher,
            Liveness::Foreign,
        ] {
            assert_eq!(Liveness::from_u8(l as u8), l);
        }
        assert_eq!(Liveness::from_u8(200), Liveness::Unknown);
    }
}
