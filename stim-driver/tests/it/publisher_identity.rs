//! Whose publisher: with a systemd unit configured, a live publisher whose process runs
//! outside it is foreign ([`Liveness::Foreign`]), and the forward path treats that as no
//! supervisor: it trips while armed and refuses an Arm. Without a unit (a bench) the same
//! publisher is simply alive.

use fes_rt::msg::{Contract, DriverCommand, StimTick, port};
use fes_rt::rt::node::create_node;
use stim_driver::event::Liveness;
use stim_driver::liveness::LivenessMonitor;

/// The test process publishes DriverCommand and StimTick; it runs in no unit named
/// `fes-supervisor.service` (nor any other fes unit), so a driver configured with those
/// units calls both publishers foreign. The unit the process does run in (its own cgroup's
/// last component, when it has one) makes them alive again.
#[test]
fn a_publisher_outside_the_configured_unit_is_foreign() {
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
    let own = fes_rt::rt::unit::cgroup_of(std::process::id()).expect("own cgroup");
    let own_unit = own.rsplit('/').next().unwrap_or_default();
    if own_unit.contains('.') {
        assert_eq!(supervisor(Some(own_unit)), Liveness::Alive, "{own}");
    } else {
        eprintln!(
            "this process's cgroup {own:?} names no unit: the positive case is the boot test's"
        );
    }
}

/// The liveness of `T`'s publishers as a monitor requiring `unit` sees it.
fn liveness<T: Contract>(
    watcher: &iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    prefix: &str,
    unit: Option<&str>,
) -> Liveness {
    LivenessMonitor::<T>::new(watcher, prefix)
        .expect("monitor")
        .in_unit(unit.map(str::to_owned))
        .check()
        .liveness
}
