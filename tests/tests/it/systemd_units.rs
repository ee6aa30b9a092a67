//! The systemd units and the installer, checked without booting systemd:
//!
//! - `systemd-analyze verify` accepts every rendered unit of both variants (rig, bench),
//!   with no output at all, and rejects a unit with a typo (the check can fail);
//! - the unit graph starts the stack in order (CAN -> stimulator -> driver -> rt-core ->
//!   supervisor) and stops what depends on a stopped unit (driver -> rt-core, stimulator);
//! - the real-time settings of the units agree with the shipped configuration files;
//! - the safety, iceoryx2 and hardening settings are there;
//! - the private bus: the CAN interface lives in a network namespace of its own that only
//!   the driver (and the bench's virtual stimulator) joins;
//! - the installer keeps the operator's configuration and rejects bad options;
//! - `notify`: the real rt-core binary against a fake service manager (READY, watchdog
//!   feeding only while the loop ticks, STOPPING), in one test binary with the above;
//! - `boot` (minutes; its own phase of `scripts/test`): the units booted by a real systemd
//!   in a UML guest.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod boot;
mod notify;
use crate::systemd_support;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

use systemd_support::{Scratch, UnitFile, cpu_set, scratch, stack_binaries, stage, workspace_root};

const UNIT_DIR: &str = "etc/systemd/system";
const SERVICES: [&str; 5] = [
    "fes-can.service",
    "fes-sim-muscle.service",
    "fes-stim-driver.service",
    "fes-rt-core.service",
    "fes-supervisor.service",
];
/// The private bus's network namespace.
const NETNS: &str = "fes-can-netns.service";
/// Processes that share iceoryx2 services.
const ICEORYX2_USERS: [&str; 3] = [
    "fes-stim-driver.service",
    "fes-rt-core.service",
    "fes-supervisor.service",
];

/// A staged bench (or rig) install with deterministic CPU placement.
fn staged(mode: &str) -> (Scratch, BTreeMap<String, UnitFile>) {
    let bins = stack_binaries();
    let scratch = scratch(&format!("units{}", mode.trim_start_matches('-')));
    stage(
        mode,
        scratch.path(),
        &bins,
        &["--rt-cpus", "1", "--housekeeping-cpus", "0"],
    );
    let units = read_units(&scratch.path().join(UNIT_DIR));
    (scratch, units)
}

fn read_units(dir: &Path) -> BTreeMap<String, UnitFile> {
    let mut units = BTreeMap::new();
    for entry in std::fs::read_dir(dir).expect("unit directory") {
        let path = entry.expect("dir entry").path();
        if path.is_file() {
            let u = UnitFile::load(&path);
            units.insert(u.name.clone(), u);
        }
    }
    units
}

/// Runs `systemd-analyze verify` on every unit in `dir` (the unit search path starts
/// there); returns (exit status ok, all output).
pub(crate) fn analyze_verify(dir: &Path) -> (bool, String) {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .expect("unit directory")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    let out = Command::new("systemd-analyze")
        .arg("verify")
        .args(&files)
        .env("SYSTEMD_UNIT_PATH", format!("{}:", dir.display()))
        .env("SYSTEMD_LOG_COLOR", "0")
        .output()
        .expect("systemd-analyze (package systemd; scripts/setup installs it)");
    let mut text = String::from_utf8_lossy(&out.stdout).into_owned();
    text.push_str(&String::from_utf8_lossy(&out.stderr));
    (out.status.success(), text)
}

/// Copies the staged units to `dir`, pointing their executables at the staged binaries
/// (the units name /usr/local/bin/..., which exists only on the installed machine;
/// `systemd-analyze verify` checks that every command is executable).
fn units_for_verify(staged_root: &Path, dir: &Path) {
    std::fs::create_dir_all(dir).expect("verify dir");
    let bindir = staged_root.join("usr/local/bin");
    for entry in std::fs::read_dir(staged_root.join(UNIT_DIR)).expect("units") {
        let path = entry.expect("entry").path();
        if !path.is_file() {
            continue;
        }
        let text = std::fs::read_to_string(&path).expect("unit text");
        let text = text.replace("/usr/local/bin/", &format!("{}/", bindir.display()));
        std::fs::write(dir.join(path.file_name().expect("name")), text).expect("write");
    }
}

#[test]
fn systemd_analyze_verify_accepts_every_unit_silently() {
    for mode in ["--rig", "--bench"] {
        let (scratch, units) = staged(mode);
        let expected: BTreeSet<&str> = if mode == "--bench" {
            SERVICES
                .iter()
                .copied()
                .chain(["fes.target", NETNS])
                .collect()
        } else {
            SERVICES
                .iter()
                .copied()
                .filter(|u| *u != "fes-sim-muscle.service")
                .chain(["fes.target", NETNS])
                .collect()
        };
        let got: BTreeSet<&str> = units.keys().map(String::as_str).collect();
        assert_eq!(got, expected, "{mode}: installed units");
        let dir = scratch.path().join("verify");
        units_for_verify(scratch.path(), &dir);
        let (ok, text) = analyze_verify(&dir);
        println!("{mode}: systemd-analyze verify: ok={ok} output={text:?}");
        assert!(
            ok && text.trim().is_empty(),
            "{mode}: systemd-analyze verify must pass without any output:\n{text}"
        );
    }
}

/// The verification above can fail: an unknown key, or a command that does not exist.
#[test]
fn systemd_analyze_verify_rejects_broken_units() {
    let (scratch, _) = staged("--bench");
    let dir = scratch.path().join("verify");
    units_for_verify(scratch.path(), &dir);
    let unit = dir.join("fes-rt-core.service");
    let good = std::fs::read_to_string(&unit).expect("unit");
    for (what, broken) in [
        (
            "typo in a key",
            good.replace("NoNewPrivileges=yes", "NoNewPrivilege=yes"),
        ),
        (
            "missing executable",
            good.replace("/bin/rt-core ", "/bin/rt-core-missing "),
        ),
    ] {
        assert_ne!(broken, good, "{what}: the edit applies");
        std::fs::write(&unit, &broken).expect("write");
        let (ok, text) = analyze_verify(&dir);
        assert!(
            !(ok && text.trim().is_empty()),
            "{what}: verify did not complain"
        );
        println!("{what}: {}", text.trim());
    }
}

/// Start order implied by After=/Before= among the stack's units (Kahn's algorithm; a
/// cycle is a failure).
fn start_order(units: &BTreeMap<String, UnitFile>) -> Vec<String> {
    let names: BTreeSet<&String> = units.keys().collect();
    let mut after: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
    for (name, u) in units {
        after.entry(name).or_default();
        for dep in u.words("Unit", "After") {
            if let Some(d) = names.get(&dep) {
                after.entry(name).or_default().insert(d);
            }
        }
        for dep in u.words("Unit", "Before") {
            if let Some(d) = names.get(&dep) {
                after.entry(d).or_default().insert(name);
            }
        }
    }
    let mut order = Vec::new();
    while !after.is_empty() {
        let ready: Vec<&str> = after
            .iter()
            .filter(|(_, deps)| deps.is_empty())
            .map(|(n, _)| *n)
            .collect();
        assert!(!ready.is_empty(), "ordering cycle among {after:?}");
        for n in ready {
            after.remove(n);
            for deps in after.values_mut() {
                deps.remove(n);
            }
            order.push(n.to_owned());
        }
    }
    order
}

/// Units stopped when `unit` stops: those that BindsTo= or PartOf= it (or Requires= it,
/// which propagates an explicit stop), transitively.
fn stopped_with(units: &BTreeMap<String, UnitFile>, unit: &str) -> BTreeSet<String> {
    let mut stopped = BTreeSet::from([unit.to_owned()]);
    loop {
        let before = stopped.len();
        for (name, u) in units {
            let bound = ["BindsTo", "PartOf", "Requires"]
                .iter()
                .flat_map(|k| u.words("Unit", k))
                .any(|d| stopped.contains(&d));
            if bound {
                stopped.insert(name.clone());
            }
        }
        if stopped.len() == before {
            return stopped;
        }
    }
}

#[test]
fn unit_graph_orders_and_binds_the_stack() {
    let (_scratch, units) = staged("--bench");
    let order = start_order(&units);
    println!("start order: {order:?}");
    let pos = |u: &str| {
        order
            .iter()
            .position(|n| n == u)
            .unwrap_or_else(|| panic!("{u} not ordered"))
    };
    for pair in SERVICES.windows(2) {
        assert!(
            pos(pair[0]) < pos(pair[1]),
            "{} must start before {}",
            pair[0],
            pair[1]
        );
    }
    let u = |n: &str| &units[n];
    // rt-core needs the driver READY first (Type=notify + After=) and goes with it.
    assert!(u("fes-rt-core.service").has_word("Unit", "BindsTo", "fes-stim-driver.service"));
    assert!(u("fes-rt-core.service").has_word("Unit", "After", "fes-stim-driver.service"));
    // The stimulator is stopped (or restarted) when the driver is.
    assert_eq!(
        stopped_with(&units, "fes-stim-driver.service"),
        BTreeSet::from([
            "fes-stim-driver.service".to_owned(),
            "fes-rt-core.service".to_owned(),
            "fes-sim-muscle.service".to_owned(),
        ]),
        "stopping the driver stops rt-core and the stimulator, nothing else"
    );
    // The interface going away stops everything that talks over it.
    let can = stopped_with(&units, "fes-can.service");
    for s in [
        "fes-stim-driver.service",
        "fes-rt-core.service",
        "fes-sim-muscle.service",
    ] {
        assert!(can.contains(s), "{s} must stop with the CAN interface");
    }
    // The supervisor survives an rt-core or driver stop (it reports it) ...
    assert!(!stopped_with(&units, "fes-rt-core.service").contains("fes-supervisor.service"));
    // ... and the target stops everything.
    let all = stopped_with(&units, "fes.target");
    for s in SERVICES {
        assert!(
            all.contains(s),
            "{s} must be PartOf=fes.target (or bound to a part)"
        );
    }
    // The target pulls the core stack in; the installer enables each unit into it.
    let target = u("fes.target");
    for s in [
        "fes-can.service",
        "fes-stim-driver.service",
        "fes-rt-core.service",
        "fes-supervisor.service",
    ] {
        assert!(target.has_word("Unit", "Wants", s), "fes.target Wants={s}");
    }
    for s in SERVICES {
        assert!(u(s).has_word("Install", "WantedBy", "fes.target"), "{s}");
    }
    assert!(target.has_word("Install", "WantedBy", "multi-user.target"));
}

/// The private bus: on both variants the CAN interface exists only in
/// the network namespace /run/netns/fes, made before it and removed after it; the driver's
/// unit and the bench's virtual stimulator join it, nothing else does; the units'
/// sandboxing does not fight it (no PrivateNetwork=, AF_CAN allowed, RestrictNamespaces=
/// applies to the process, systemd joins the namespace for it).
#[test]
fn private_bus_only_the_driver_and_the_stimulator_join_the_can_namespace() {
    for mode in ["--rig", "--bench"] {
        let (_scratch, units) = staged(mode);
        let u = |n: &str| {
            units
                .get(n)
                .unwrap_or_else(|| panic!("{mode}: {n} not installed"))
        };
        let netns = u(NETNS);
        let start = netns.values("Service", "ExecStart").join(" ; ");
        assert!(
            start.contains("ip netns add fes"),
            "{mode}: {NETNS} makes /run/netns/fes: {start}"
        );
        assert!(
            netns
                .values("Service", "ExecStop")
                .join(" ")
                .contains("ip netns delete fes"),
            "{mode}: {NETNS} removes it on stop"
        );
        assert!(netns.is("Service", "RemainAfterExit", "yes"), "{mode}");
        assert!(netns.has_word("Unit", "PartOf", "fes.target"), "{mode}");
        assert!(
            netns.has_word("Install", "WantedBy", "fes.target"),
            "{mode}"
        );
        assert!(u("fes.target").has_word("Unit", "Wants", NETNS), "{mode}");

        // The interface is put in the namespace (rig: moved; bench: created there) and
        // configured only there.
        let can = u("fes-can.service");
        assert!(can.has_word("Unit", "BindsTo", NETNS), "{mode}");
        assert!(can.has_word("Unit", "After", NETNS), "{mode}");
        let can_start = can.values("Service", "ExecStart");
        if mode == "--rig" {
            let moved = can_start
                .iter()
                .position(|c| c.contains("link set dev ${FES_CAN_IFACE} netns fes"))
                .unwrap_or_else(|| panic!("rig: the interface is moved: {can_start:?}"));
            for c in &can_start[moved + 1..] {
                assert!(
                    c.contains("ip -n fes "),
                    "rig: {c:?} runs outside the namespace"
                );
            }
            assert!(
                can_start[moved + 1..].iter().any(|c| c.ends_with(" up")),
                "rig: brought up in the namespace: {can_start:?}"
            );
            assert!(
                !can.has_word("Unit", "BindsTo", "sys-subsystem-net-devices-can0.device"),
                "rig: BindsTo= the device unit would stop the interface once it is moved"
            );
        } else {
            assert!(
                can_start
                    .iter()
                    .any(|c| c.contains("ip -n fes link add dev ${FES_CAN_IFACE} type vcan")),
                "bench: vcan made in the namespace: {can_start:?}"
            );
            assert!(
                can_start.iter().all(|c| c.contains("ip -n fes ")),
                "bench: every interface command in the namespace: {can_start:?}"
            );
        }

        // Who joins it.
        let joiners: Vec<&str> = if mode == "--bench" {
            vec!["fes-stim-driver.service", "fes-sim-muscle.service"]
        } else {
            vec!["fes-stim-driver.service"]
        };
        for (name, unit) in &units {
            let joins = unit.get("Service", "NetworkNamespacePath");
            if joiners.contains(&name.as_str()) {
                assert_eq!(
                    joins.as_deref(),
                    Some("/run/netns/fes"),
                    "{mode}: {name} must join the private bus"
                );
                assert!(unit.has_word("Unit", "Requires", NETNS), "{mode}: {name}");
                assert!(unit.has_word("Unit", "After", NETNS), "{mode}: {name}");
                assert!(
                    !unit.is("Service", "PrivateNetwork", "yes"),
                    "{mode}: {name}: PrivateNetwork= would replace the namespace"
                );
                for af in ["AF_CAN", "AF_UNIX", "AF_NETLINK"] {
                    assert!(
                        unit.has_word("Service", "RestrictAddressFamilies", af),
                        "{mode}: {name}: {af}"
                    );
                }
                // RestrictNamespaces= stops the process from making or entering namespaces;
                // the namespace systemd joins for it is set up before.
                assert!(
                    unit.is("Service", "RestrictNamespaces", "yes"),
                    "{mode}: {name}"
                );
            } else {
                assert_eq!(
                    joins, None,
                    "{mode}: {name} does not need the bus and must not join it"
                );
            }
        }

        // Order and binding: namespace, interface, then its users; stopping the namespace
        // stops everything on the bus.
        let order = start_order(&units);
        let pos = |n: &str| order.iter().position(|o| o == n).unwrap();
        assert!(pos(NETNS) < pos("fes-can.service"), "{mode}: {order:?}");
        for j in &joiners {
            assert!(pos("fes-can.service") < pos(j), "{mode}: {order:?}");
        }
        let gone = stopped_with(&units, NETNS);
        for s in joiners
            .iter()
            .chain(&["fes-can.service", "fes-rt-core.service"])
        {
            assert!(
                gone.contains(*s),
                "{mode}: {s} must stop with the namespace"
            );
        }
        assert!(
            !gone.contains("fes-supervisor.service"),
            "{mode}: the supervisor survives it (and reports)"
        );
    }
}

/// Reads a TOML file shipped in deploy/.
fn shipped_toml(rel: &str) -> Option<toml::Table> {
    let path = workspace_root().join("deploy").join(rel);
    let text = std::fs::read_to_string(&path).ok()?;
    Some(
        text.parse::<toml::Table>()
            .unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
}

/// `[table] key` as an integer.
fn toml_int(t: &toml::Table, table: &str, key: &str) -> Option<i64> {
    t.get(table)?.as_table()?.get(key)?.as_integer()
}

#[test]
fn real_time_settings_agree_with_the_configuration() {
    let (_scratch, units) = staged("--bench");
    let rt_core = &units["fes-rt-core.service"];
    let driver = &units["fes-stim-driver.service"];
    let limit = |u: &UnitFile| -> i64 {
        u.get("Service", "LimitRTPRIO")
            .unwrap_or_else(|| panic!("{} sets LimitRTPRIO", u.name))
            .parse()
            .expect("LimitRTPRIO is a number")
    };
    let rt_cpus = cpu_set(&rt_core.get("Service", "CPUAffinity").expect("CPUAffinity"));
    assert_eq!(rt_cpus, [1]);
    for u in [rt_core, driver] {
        assert!(u.is("Service", "CPUSchedulingPolicy", "fifo"), "{}", u.name);
        assert!(
            u.is("Service", "CPUSchedulingResetOnFork", "yes"),
            "{}",
            u.name
        );
        assert!(u.is("Service", "LimitMEMLOCK", "infinity"), "{}", u.name);
        let main_prio: i64 = u
            .get("Service", "CPUSchedulingPriority")
            .expect("CPUSchedulingPriority")
            .parse()
            .expect("number");
        assert!((1..=limit(u)).contains(&main_prio), "{}", u.name);
        assert!(
            !u.is("Service", "RestrictRealtime", "yes"),
            "{}: RestrictRealtime=yes forbids SCHED_FIFO",
            u.name
        );
        // The forward path shares the real-time CPU with rt-core (docs/realtime.md).
        assert_eq!(
            cpu_set(&u.get("Service", "CPUAffinity").expect("CPUAffinity")),
            rt_cpus,
            "{}",
            u.name
        );
    }
    assert!(
        limit(driver) < limit(rt_core),
        "the driver's forward path runs below rt-core's loop"
    );
    for s in ["fes-supervisor.service", "fes-sim-muscle.service"] {
        let cpus = cpu_set(&units[s].get("Service", "CPUAffinity").expect("CPUAffinity"));
        assert!(
            cpus.iter().all(|c| !rt_cpus.contains(c)),
            "{s} stays off the real-time CPU"
        );
        assert_eq!(limit(&units[s]), 0, "{s} has no real-time priority");
    }
    // rt-core.toml, rig and bench: the loop's priority is within the unit's limit, and a
    // pinned core (if any) is one the unit allows.
    for rel in ["etc/fes/rt-core.toml", "bench/etc/fes/rt-core.toml"] {
        let t = shipped_toml(rel).expect("rt-core.toml is shipped");
        let prio = toml_int(&t, "rt", "priority").unwrap_or(80);
        assert!(
            prio <= limit(rt_core),
            "{rel}: [rt] priority {prio} > LimitRTPRIO {}",
            limit(rt_core)
        );
        if let Some(core) = toml_int(&t, "rt", "core") {
            assert!(
                rt_cpus.contains(&(core as usize)),
                "{rel}: [rt] core {core}"
            );
        }
    }
    // stim-driver.toml (the driver engineer's) when it is shipped: same rules.
    match shipped_toml("etc/fes/stim-driver.toml") {
        Some(t) => {
            for table in ["rt", "bus_rt"] {
                if let Some(prio) = toml_int(&t, table, "priority") {
                    assert!(
                        prio <= limit(driver),
                        "stim-driver.toml [{table}] priority {prio} > LimitRTPRIO {}",
                        limit(driver)
                    );
                }
                if let Some(core) = toml_int(&t, table, "core") {
                    assert!(
                        rt_cpus.contains(&(core as usize)),
                        "stim-driver.toml [{table}] core {core}"
                    );
                }
            }
        }
        None => println!("deploy/etc/fes/stim-driver.toml not shipped yet: not checked"),
    }
}

#[test]
fn safety_iceoryx2_and_hardening_settings() {
    let (scratch, units) = staged("--bench");
    let u = |n: &str| &units[n];
    let driver = u("fes-stim-driver.service");
    let stop_post = driver.values("Service", "ExecStopPost").join(" ");
    assert!(
        stop_post.contains("/stim-driver safe-stop --iface ${FES_CAN_IFACE}"),
        "the driver's ExecStopPost stops the stimulator: {stop_post:?}"
    );
    for s in ICEORYX2_USERS {
        let unit = u(s);
        assert!(unit.is("Service", "Type", "notify"), "{s}: Type=notify");
        assert!(unit.is("Service", "NotifyAccess", "main"), "{s}");
        let watchdog: u64 = unit
            .get("Service", "WatchdogSec")
            .unwrap_or_else(|| panic!("{s}: WatchdogSec"))
            .parse()
            .expect("whole seconds");
        assert!(watchdog > 0, "{s}");
        assert!(unit.is("Service", "Restart", "on-failure"), "{s}");
        assert!(
            unit.has_word("Service", "RestartPreventExitStatus", "1"),
            "{s}"
        );
        // iceoryx2: one shared /dev/shm and /tmp/iceoryx2 across the stack.
        assert!(unit.is("Service", "RemoveIPC", "no"), "{s}: RemoveIPC=no");
        assert!(unit.is("Service", "PrivateTmp", "no"), "{s}: PrivateTmp=no");
        for key in ["PrivateDevices", "DynamicUser", "PrivateIPC"] {
            assert!(
                !unit.is("Service", key, "yes"),
                "{s}: {key}=yes hides iceoryx2"
            );
        }
        for path in ["/dev/shm", "/tmp/iceoryx2", "/var/lib/fes"] {
            assert!(
                unit.has_word("Service", "ReadWritePaths", path),
                "{s}: ReadWritePaths {path}"
            );
        }
    }
    assert!(u("fes-rt-core.service").has_word("Service", "RestartPreventExitStatus", "2"));
    // The rig's watchdog on the pattern generator: a stalled loop is killed within 2 s
    // (docs/deployment.md). The boot test's guest lengthens it in a test-only drop-in.
    assert!(u("fes-rt-core.service").is("Service", "WatchdogSec", "2"));
    for s in SERVICES.iter().filter(|s| **s != "fes-can.service") {
        let unit = u(s);
        assert!(unit.is("Service", "User", "fes"), "{s}: User=fes");
        for (key, value) in [
            ("NoNewPrivileges", "yes"),
            ("ProtectSystem", "strict"),
            ("ProtectHome", "yes"),
            ("CapabilityBoundingSet", ""),
            ("MemoryDenyWriteExecute", "yes"),
        ] {
            assert!(unit.is("Service", key, value), "{s}: {key}={value}");
        }
        assert!(
            unit.is("Service", "StandardError", "journal"),
            "{s}: logs to the journal"
        );
    }
    // The user the units run as is created, and owns iceoryx2's shared directory.
    let sysusers =
        std::fs::read_to_string(scratch.path().join("etc/sysusers.d/fes.conf")).expect("sysusers");
    assert!(
        sysusers
            .lines()
            .any(|l| l.split_whitespace().take(2).eq(["u", "fes"])),
        "{sysusers}"
    );
    let tmpfiles =
        std::fs::read_to_string(scratch.path().join("etc/tmpfiles.d/fes.conf")).expect("tmpfiles");
    assert!(
        tmpfiles.lines().any(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            w.len() >= 5 && w[0] == "d" && w[1] == "/tmp/iceoryx2" && w[3] == "fes"
        }),
        "{tmpfiles}"
    );
    // Recordings (supervisor.toml's [recording] dir, when shipped) are writable.
    if let Some(t) = shipped_toml("etc/fes/supervisor.toml")
        && let Some(dir) = t
            .get("recording")
            .and_then(|r| r.get("dir"))
            .and_then(|d| d.as_str())
    {
        let rw = u("fes-supervisor.service").words("Service", "ReadWritePaths");
        assert!(
            rw.iter().any(|p| Path::new(dir).starts_with(p)),
            "supervisor recordings {dir} not under ReadWritePaths {rw:?}"
        );
    }
}

/// The stimulator's serial port (a RehaStim 2 takes a SinglePulse from whoever writes to
/// it) is open to the driver alone: every unit of the stack has the closed device policy,
/// no unit but the driver's may name a serial port or the port's group, and the service
/// user is not in that group (only the driver's unit adds it). With the policy removed
/// from any unit, or the group given to the user, this fails.
#[test]
fn the_stimulators_serial_port_is_closed_to_every_unit_but_the_driver() {
    let (scratch, units) = staged("--bench");
    for s in [
        "fes-stim-driver.service",
        "fes-rt-core.service",
        "fes-supervisor.service",
        "fes-sim-muscle.service",
    ] {
        let unit = &units[s];
        assert!(
            unit.is("Service", "DevicePolicy", "closed"),
            "{s}: DevicePolicy=closed"
        );
        for allowed in unit.values("Service", "DeviceAllow") {
            let allowed = allowed.to_string();
            assert!(
                !(allowed.contains("tty") || allowed.contains("rehastim")),
                "{s}: DeviceAllow={allowed} opens a serial port"
            );
            assert!(
                s == "fes-rt-core.service" && allowed == "/dev/cpu_dma_latency rw",
                "{s}: DeviceAllow={allowed}"
            );
        }
        assert!(
            !unit.has_word("Service", "SupplementaryGroups", "fes-stim"),
            "{s}: the port's group"
        );
    }
    let sysusers =
        std::fs::read_to_string(scratch.path().join("etc/sysusers.d/fes.conf")).expect("sysusers");
    let lines: Vec<Vec<&str>> = sysusers
        .lines()
        .map(|l| l.split_whitespace().collect())
        .collect();
    assert!(
        lines
            .iter()
            .any(|w| w.len() >= 2 && w[0] == "g" && w[1] == "fes-stim"),
        "the port's group is created: {sysusers}"
    );
    assert!(
        !lines
            .iter()
            .any(|w| w.len() >= 3 && w[0] == "m" && w[1] == "fes" && w[2] == "fes-stim"),
        "user fes is not in the port's group: {sysusers}"
    );
    // The rig's procedure gives the port to the driver's unit alone.
    let deployment = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/deployment.md"),
    )
    .unwrap();
    assert!(
        !deployment.contains("usermod -aG fes-stim"),
        "docs/deployment.md"
    );
    assert!(
        deployment.contains("SupplementaryGroups=fes-stim"),
        "docs/deployment.md"
    );
}

#[test]
fn installer_keeps_the_operators_configuration() {
    let bins = stack_binaries();
    let scratch = scratch("installer");
    let root = scratch.path();
    stage("--bench", root, &bins, &[]);
    let conf = root.join("etc/fes/rt-core.toml");
    let edited = std::fs::read_to_string(&conf).expect("config") + "\n# operator's edit\n";
    std::fs::write(&conf, &edited).expect("edit");
    // An upgrade keeps the edit, puts the new default beside it, keeps the interface.
    let text = stage("--bench", root, &bins, &[]);
    assert!(text.contains("rt-core.toml.dist"), "{text}");
    assert_eq!(std::fs::read_to_string(&conf).expect("config"), edited);
    let env = |root: &Path| std::fs::read_to_string(root.join("etc/fes/can.env")).expect("env");
    assert!(env(root).contains("FES_CAN_IFACE=vcan0\n"));
    stage("--bench", root, &bins, &["--iface", "vcan7"]);
    assert!(env(root).contains("FES_CAN_IFACE=vcan7\n"));
    stage("--bench", root, &bins, &[]);
    assert!(
        env(root).contains("FES_CAN_IFACE=vcan7\n"),
        "kept without --iface"
    );
    // Rig: the device dependency names the interface (Wants=, not BindsTo=: the device
    // unit goes when the interface moves into the private namespace); no virtual
    // stimulator.
    stage("--rig", root, &bins, &["--iface", "can1"]);
    let can = UnitFile::load(&root.join(UNIT_DIR).join("fes-can.service"));
    assert!(can.has_word("Unit", "Wants", "sys-subsystem-net-devices-can1.device"));
    assert!(can.has_word("Unit", "After", "sys-subsystem-net-devices-can1.device"));
    assert!(!can.has_word("Unit", "BindsTo", "sys-subsystem-net-devices-can1.device"));
    assert!(!root.join(UNIT_DIR).join("fes-sim-muscle.service").exists());
    // Bad options: exit status 2 and a message naming the problem.
    for (args, message) in [
        (vec!["--bench", "--iface", "a b"], "bad interface name"),
        (vec!["--rig", "--bitrate", "fast"], "--bitrate"),
        (vec!["--bench", "--rt-cpus", "x"], "--rt-cpus"),
        (vec!["--bench", "--iface"], "--iface needs a value"),
        (vec!["--frobnicate"], "unknown option"),
        (vec![], "choose --rig, --bench or --uninstall"),
    ] {
        let mut full = args.clone();
        let dest = root.to_str().expect("utf-8");
        if !args.is_empty() && args != ["--bench", "--iface"] {
            full.extend(["--destdir", dest]);
        }
        let out = Command::new(workspace_root().join("scripts/install"))
            .args(&full)
            .output()
            .expect("run install");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{full:?}: {err}");
        assert!(err.contains(message), "{full:?}: {err}");
    }
    // Uninstall removes units and binaries, keeps configuration.
    let (ok, text) =
        systemd_support::run_install(&["--uninstall", "--destdir", root.to_str().expect("utf-8")]);
    assert!(ok, "{text}");
    assert!(!root.join(UNIT_DIR).join("fes-rt-core.service").exists());
    assert!(!root.join("usr/local/bin/rt-core").exists());
    assert!(conf.exists(), "configuration kept");
}

/// The driver's `safe-stop` (the units' `ExecStopPost=`) lives for milliseconds, so it logs
/// through its stderr stream, each line with its `<priority>` prefix: journald attributes a
/// stream's lines to the unit, while a native-protocol datagram of a process that has
/// already exited loses its unit (the boot test's missing second "safe-stop: NMT stop
/// written" after a SIGKILL). Run with `JOURNAL_STREAM` naming its stderr,
/// as systemd starts it, on a host bus.
#[test]
fn safe_stop_logs_through_its_journal_stream_with_priorities() {
    use std::os::unix::fs::MetadataExt;
    let bins = stack_binaries();
    let dir = scratch("safe-stop-log");
    let err_path = dir.join("stderr");
    let err = std::fs::File::create(&err_path).unwrap();
    let meta = err.metadata().unwrap();
    let out = Command::new(bins.join("stim-driver"))
        .args(["safe-stop", "--iface"])
        .arg(format!("hostbus:{}", dir.join("bus").display()))
        .env("JOURNAL_STREAM", format!("{}:{}", meta.dev(), meta.ino()))
        .env_remove("RUST_LOG")
        .stderr(err)
        .output()
        .expect("run stim-driver safe-stop");
    assert!(out.status.success(), "{:?}", out.status);
    let text = std::fs::read_to_string(&err_path).unwrap();
    let line = text
        .lines()
        .find(|l| l.contains("safe-stop: NMT stop written"))
        .unwrap_or_else(|| panic!("no safe-stop line on the stream: {text:?}"));
    assert!(line.starts_with("<5>"), "info priority prefix: {line}");
    assert!(!line.contains('\u{1b}'), "no colour codes: {line}");
}

/// The prescription is shipped, bounds every shipped configuration, and
/// is installed root:root 0644 (read-only to the services, which run as `fes`), apart from
/// the 0640 configuration; an upgrade never replaces an operator's prescription. The
/// services cannot write it: every unit has `ProtectSystem=strict` and no writable path
/// under /etc.
#[test]
fn the_prescription_is_installed_read_only_and_bounds_every_shipped_config() {
    use std::os::unix::fs::PermissionsExt;
    let deploy = workspace_root().join("deploy");
    let text = std::fs::read_to_string(deploy.join("etc/fes/prescription.toml")).unwrap();
    let p = fes_prescription::Prescription::parse(&text).expect("the shipped prescription");
    // The dose: rt-core's pulse exactly, no margin.
    assert_eq!(
        (
            p.max_amplitude_ua,
            p.max_phase_width_us,
            p.max_charge_per_phase_nc
        ),
        (20_000, 200, 4000)
    );
    for dir in ["etc/fes", "bench/etc/fes"] {
        let driver = std::fs::read_to_string(deploy.join(dir).join("stim-driver.toml")).unwrap();
        let driver = stim_driver::config::DriverConfig::parse(&driver).unwrap();
        assert_eq!(driver.prescription, Path::new("/etc/fes/prescription.toml"));
        driver
            .check_prescription(&p)
            .unwrap_or_else(|e| panic!("{dir}/stim-driver.toml: {e}"));
        let rt = std::fs::read_to_string(deploy.join(dir).join("rt-core.toml")).unwrap();
        let rt = rt_core::rt::process_config::RtCoreConfig::parse(&rt).unwrap();
        assert_eq!(
            rt.prescription.as_deref(),
            Some(Path::new("/etc/fes/prescription.toml")),
            "{dir}/rt-core.toml names the prescription"
        );
        p.check_pulse(
            "rt-core",
            rt.pulse.amplitude_ua,
            u32::from(rt.pulse.width_us),
        )
        .unwrap_or_else(|e| panic!("{dir}/rt-core.toml: {e}"));
    }
    let sup = shipped_toml("etc/fes/supervisor.toml").unwrap();
    assert_eq!(
        sup["recording"]["prescription"].as_str(),
        Some("/etc/fes/prescription.toml")
    );
    // Installed: 0644 beside 0640 configuration; kept over an upgrade.
    let bins = stack_binaries();
    let scratch = scratch("prescription");
    let root = scratch.path();
    stage("--bench", root, &bins, &[]);
    let installed = root.join("etc/fes/prescription.toml");
    let mode = |f: &Path| std::fs::metadata(f).unwrap().permissions().mode() & 0o777;
    assert_eq!(std::fs::read_to_string(&installed).unwrap(), text);
    assert_eq!(mode(&installed), 0o644);
    assert_eq!(mode(&root.join("etc/fes/stim-driver.toml")), 0o640);
    let operators = text.replace("max_pulses_per_s = 100", "max_pulses_per_s = 50");
    std::fs::write(&installed, &operators).unwrap();
    let out = stage("--bench", root, &bins, &[]);
    assert!(out.contains("prescription.toml.dist"), "{out}");
    assert_eq!(std::fs::read_to_string(&installed).unwrap(), operators);
    assert_eq!(mode(&root.join("etc/fes/prescription.toml.dist")), 0o644);
    let installer = std::fs::read_to_string(workspace_root().join("scripts/install")).unwrap();
    assert!(
        installer.contains("-o root -g root")
            && installer.contains("-name 'prescription.toml*' -exec chown root:root"),
        "the installer makes the prescription root's"
    );
    for (name, unit) in &read_units(&root.join(UNIT_DIR)) {
        if !name.starts_with("fes-") || name == "fes-can.service" {
            continue;
        }
        if !unit.has_word("Service", "ProtectSystem", "strict") {
            continue;
        }
        for v in unit.values("Service", "ReadWritePaths") {
            assert!(
                !v.split_whitespace().any(|p| p.starts_with("/etc")),
                "{name}: ReadWritePaths={v}"
            );
        }
    }
    for name in [
        "fes-stim-driver.service",
        "fes-rt-core.service",
        "fes-supervisor.service",
    ] {
        let unit = &read_units(&root.join(UNIT_DIR))[name];
        assert!(
            unit.has_word("Service", "ProtectSystem", "strict"),
            "{name}"
        );
    }
}
