//! The units booted by a real systemd: PID 1 of a User-Mode Linux guest whose root is the
//! host's filesystem, mounted **read-only** (hostfs `ro`), with tmpfs over everything the
//! guest writes (`/run`, `/tmp`, `/var/*`, `/usr/local`, `/home`, `/root`), a writable
//! copy of `/etc` (empty `fstab`, our test target as the only unit in
//! `/etc/systemd/system`), and overlays with a tmpfs upper layer over `/usr` and
//! `/var/lib/dpkg` so that dpkg can install (the host's files stay untouched). The check
//! script (`boot-check.sh`, a oneshot unit) installs the bench package as an operator
//! would (`dpkg -i fes-stack-bench_*.deb`, built by [`crate::package::packages`]), starts
//! `fes.target` and exercises ordering, the private bus (the CAN interface only in the namespace the driver and the
//! virtual stimulator join), the watchdog, `BindsTo=` and the driver's `ExecStopPost=`
//! safe stop; it prints
//! `@@SD` lines that [`booted_units_start_in_order_and_stop_safely`] asserts on.
//!
//! The guest has one CPU, emulated with ptrace: the four processes' 1 ms loops saturate it
//! and every `systemctl` call takes seconds, so one boot takes 2-5 minutes on this
//! project's 2-core machines. The README's test command runs it in a phase of its own,
//! after the other functional tests (`scripts/test`; docs/deployment.md, "Boot under
//! systemd"); alone: `cargo test -p fes-tests --test it systemd_units::boot:: -- --nocapture`.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use crate::systemd_support::{target_dir, workspace_root};

/// Longest a boot may take before the test gives up (the guest is killed).
const BOOT_TIMEOUT: Duration = Duration::from_secs(900);
/// Marker of the check script's result lines.
const MARK: &str = "@@SD ";

/// `systemctl show` properties of one unit at one snapshot.
type Props = BTreeMap<String, String>;

/// Everything the check script reported.
#[derive(Debug, Default)]
struct Report {
    /// Single-valued keys (`install`, `start`, `safe-stop-log`...): the rest of the line.
    values: BTreeMap<String, String>,
    /// Snapshots: tag -> unit id -> properties.
    snapshots: BTreeMap<String, BTreeMap<String, Props>>,
    /// `fail` lines.
    failures: Vec<String>,
    /// Lines between `journal-begin` and `journal-end`.
    journal: Vec<String>,
}

impl Report {
    fn parse(console: &[String]) -> Self {
        let mut r = Report::default();
        let mut in_journal = false;
        for line in console {
            let Some(at) = line.find(MARK) else {
                if in_journal {
                    r.journal.push(line.clone());
                }
                continue;
            };
            let rest = line[at + MARK.len()..].trim();
            let (key, value) = rest.split_once(' ').unwrap_or((rest, ""));
            match key {
                "journal-begin" => in_journal = true,
                "journal-end" => in_journal = false,
                "fail" => r.failures.push(value.to_owned()),
                _ if value.contains("Id=") => {
                    let props: Props = value
                        .split_whitespace()
                        .filter_map(|kv| kv.split_once('='))
                        .map(|(k, v)| (k.to_owned(), v.to_owned()))
                        .collect();
                    let id = props.get("Id").cloned().unwrap_or_default();
                    r.snapshots
                        .entry(key.to_owned())
                        .or_default()
                        .insert(id, props);
                }
                _ => {
                    r.values.insert(key.to_owned(), value.to_owned());
                }
            }
        }
        r
    }

    fn value(&self, key: &str) -> &str {
        self.values
            .get(key)
            .unwrap_or_else(|| panic!("the check script reported no {key:?}: {self:#?}"))
    }

    fn prop(&self, tag: &str, unit: &str, prop: &str) -> &str {
        self.snapshots
            .get(tag)
            .and_then(|s| s.get(unit))
            .and_then(|p| p.get(prop))
            .unwrap_or_else(|| panic!("no {prop} of {unit} at {tag:?}: {self:#?}"))
    }

    fn mono(&self, tag: &str, unit: &str, prop: &str) -> u64 {
        self.prop(tag, unit, prop)
            .parse()
            .unwrap_or_else(|e| panic!("{prop} of {unit} at {tag:?}: {e}"))
    }
}

fn uml_kernel() -> PathBuf {
    if let Some(k) = std::env::var_os("FES_UML_KERNEL") {
        return PathBuf::from(k);
    }
    std::env::var_os("PATH")
        .into_iter()
        .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .map(|d| d.join("linux.uml"))
        .find(|p| p.is_file())
        .expect("linux.uml not in PATH (apt-get install user-mode-linux; scripts/setup does)")
}

/// The guest's init: read-only host root, tmpfs where the guest writes, overlays where dpkg
/// writes, CAN modules, then systemd with the test target as the default unit.
fn init_script(run_dir: &Path) -> String {
    let modules: Vec<&str> = fes_testkit::vcan::UML_CAN_MODULES.to_vec();
    format!(
        r#"#!/bin/sh
# Generated by tests/tests/it/systemd_units/boot.rs: init of the systemd boot test's guest.
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
export GLIBC_TUNABLES={tunables}
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t tmpfs -o mode=755 tmpfs /run
mkdir -p /run/etc && cp -a /etc/. /run/etc/ && mount --bind /run/etc /etc
# Every service keeps off AVX-512 too (fes_testkit::vcan::UML_GUEST_GLIBC_TUNABLES).
mkdir -p /etc/systemd/system.conf.d
printf '[Manager]\nDefaultEnvironment=GLIBC_TUNABLES=%s\n' {tunables} > /etc/systemd/system.conf.d/fes-uml.conf
: > /etc/fstab
rm -rf /etc/systemd/system/* && cp {dir}/fes-boot-test.* /etc/systemd/system/
# dpkg -i of the package writes /usr (binaries, units, generator) and its database: overlays
# of the read-only host's with a tmpfs upper layer (hostfs works as a lower layer).
M={root}/$(uname -r)/kernel
insmod "$M/fs/overlayfs/overlay.ko"
mkdir -p /run/ovl/usr/upper /run/ovl/usr/work /run/ovl/dpkg/upper /run/ovl/dpkg/work /run/ovl/dpkg/lower
mount --bind /var/lib/dpkg /run/ovl/dpkg/lower
mount -t overlay overlay -o lowerdir=/usr,upperdir=/run/ovl/usr/upper,workdir=/run/ovl/usr/work /usr
for d in {tmpfs}; do
  mount -t tmpfs tmpfs "$d"
done
mkdir -p /var/lib/dpkg
mount -t overlay overlay -o lowerdir=/run/ovl/dpkg/lower,upperdir=/run/ovl/dpkg/upper,workdir=/run/ovl/dpkg/work /var/lib/dpkg
chmod 1777 /tmp /var/tmp
mkdir -p /dev/shm && mount -t tmpfs -o mode=1777 shm /dev/shm
for m in {modules}; do insmod "$M/$m"; done
exec /lib/systemd/systemd systemd.unit=fes-boot-test.target
"#,
        dir = run_dir.display(),
        root = fes_testkit::vcan::UML_MODULES_ROOT,
        modules = modules.join(" "),
        tmpfs = GUEST_TMPFS.join(" "),
        tunables = fes_testkit::vcan::UML_GUEST_GLIBC_TUNABLES,
    )
}

/// Where the guest mounts a tmpfs over the host's tree ([`init_script`]): a path under one
/// of them is not the host's inside the guest.
const GUEST_TMPFS: [&str; 9] = [
    "/usr/local",
    "/var/lib",
    "/var/log",
    "/var/tmp",
    "/var/cache",
    "/tmp",
    "/home",
    "/root",
    "/srv",
];

/// The tmpfs mount that hides `path` in the guest, if one does.
fn hidden_in_guest(path: &Path) -> Option<&'static str> {
    GUEST_TMPFS.into_iter().find(|m| path.starts_with(m))
}

fn write_guest_files(run_dir: &Path, deb: &Path) {
    // The check script, the package and the run directory must be the host's in the guest:
    // under a hidden path the check unit cannot start and the guest idles until
    // BOOT_TIMEOUT (seen with a checkout in /tmp), so say so at once.
    let repo = workspace_root();
    for p in [repo.as_path(), deb, run_dir] {
        if let Some(m) = hidden_in_guest(p) {
            panic!(
                "{} is under {m}, which the boot test's guest covers with a tmpfs: run the \
                 test from a checkout and target directory outside {GUEST_TMPFS:?}",
                p.display()
            );
        }
    }
    let check = repo.join("tests/tests/it/systemd_units/boot-check.sh");
    std::fs::create_dir_all(run_dir).unwrap();
    std::fs::write(
        run_dir.join("fes-boot-test.service"),
        format!(
            "[Unit]\nDescription=FES boot test (install, start, watchdog, binding)\n\
             After=basic.target\n\n[Service]\nType=oneshot\n\
             Environment=FES_REPO={} FES_DEB={}\nExecStart={}\n",
            repo.display(),
            deb.display(),
            check.display()
        ),
    )
    .unwrap();
    std::fs::write(
        run_dir.join("fes-boot-test.target"),
        "[Unit]\nDescription=FES boot test target\nRequires=basic.target\n\
         After=basic.target\nWants=fes-boot-test.service\n",
    )
    .unwrap();
    let init = run_dir.join("init.sh");
    std::fs::write(&init, init_script(run_dir)).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&init, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// Boots the guest and returns its console lines.
fn boot(run_dir: &Path) -> Vec<String> {
    let mut child = fes_testkit::vcan::uml_kernel_command(&uml_kernel())
        .args([
            "mem=1G".to_owned(),
            "rootfstype=hostfs".to_owned(),
            "ro".to_owned(),
            format!("init={}", run_dir.join("init.sh").display()),
            "con=null".to_owned(),
            "con0=fd:0,fd:1".to_owned(),
            format!("umid=fes-boot-{}", std::process::id()),
            format!("uml_dir={}", run_dir.display()),
            "quiet".to_owned(),
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        // Its own process group: UML's helper processes hold the console pipe too, and
        // survive a SIGKILL of the kernel process; the timeout kills the whole group, or
        // the read below would never see the end of the console.
        .process_group(0)
        .spawn()
        .expect("start linux.uml");
    let pid = child.id();
    let killer = std::thread::spawn(move || {
        let start = Instant::now();
        while start.elapsed() < BOOT_TIMEOUT {
            std::thread::sleep(Duration::from_secs(1));
            // SAFETY: kill(2) with signal 0 only probes whether the child still exists.
            if unsafe { libc::kill(pid as i32, 0) } != 0 {
                return false;
            }
        }
        // SAFETY: kill(2) on the process group our own child leads; no memory is touched.
        unsafe { libc::kill(-(pid as i32), libc::SIGKILL) };
        true
    });
    let mut lines = Vec::new();
    let out = child.stdout.take().unwrap();
    for line in BufReader::new(out).split(b'\n') {
        let Ok(line) = line else { break };
        let line = String::from_utf8_lossy(&line).into_owned();
        if line.contains(MARK) {
            eprintln!("[guest] {}", line.trim_end());
        }
        lines.push(line);
    }
    child.wait().ok();
    // The guest's PID may be reused only after wait(): the killer checks before that.
    let _ = killer.join();
    lines
}

/// Installs the bench package with dpkg and boots the stack under systemd; asserts that
/// the package enabled but did not start it and that its generator placed the units, the
/// start order, that the watchdog ends a stalled rt-core, that stopping the driver stops
/// rt-core and the virtual stimulator and sends the safe stop, and that a SIGKILLed driver
/// gets the safe stop and is restarted (disarmed) while rt-core stays stopped.
#[test]
fn booted_units_start_in_order_and_stop_safely() {
    let deb = &crate::package::packages().bench;
    let run_dir = target_dir().join(format!("tmp/systemd-boot-{}", std::process::id()));
    write_guest_files(&run_dir, deb);
    let started = Instant::now();
    let console = boot(&run_dir);
    let took = started.elapsed();
    // FES_BOOT_CONSOLE=FILE keeps the guest's whole console (boot, journal, install logs).
    if let Some(path) = std::env::var_os("FES_BOOT_CONSOLE") {
        std::fs::write(path, console.join("\n")).unwrap();
    }
    let r = Report::parse(&console);
    eprintln!("boot test: guest ran {took:.0?}; the stack's journal:");
    for line in &r.journal {
        eprintln!("[journal] {line}");
    }
    assert!(
        r.values.contains_key("done"),
        "the check did not finish: {r:#?}"
    );
    assert!(
        r.failures.is_empty(),
        "{:?}\n{}",
        r.failures,
        r.journal.join("\n")
    );
    assert!(
        r.value("install").starts_with('0'),
        "install: {}",
        r.value("install")
    );
    assert_eq!(r.value("enabled"), "enabled");
    // postinst enables, never starts: nothing ran before the check started fes.target.
    assert_eq!(r.value("active-after-install"), "inactive", "{r:#?}");
    // The package's generator placed rt-core (the guest has one CPU: CPU 0) in a drop-in.
    assert!(
        r.value("rt-core-dropins")
            .contains("/run/systemd/generator/fes-rt-core.service.d/50-fes-placement.conf"),
        "{r:#?}"
    );
    assert_eq!(r.value("rt-core-cpus"), "0", "{r:#?}");
    // The private bus: the interface only in /run/netns/fes, joined by
    // the driver and the virtual stimulator, not by rt-core (nor the host).
    assert_eq!(r.value("netns-host-iface"), "absent", "{r:#?}");
    assert_eq!(r.value("netns-fes-iface"), "present", "{r:#?}");
    let ns: Vec<&str> = r.value("netns-ids").split_whitespace().collect();
    assert_eq!(
        ns.len(),
        5,
        "driver, stimulator, rt-core, fes, host: {ns:?}"
    );
    let (driver, stim, rt, fes, host) = (ns[0], ns[1], ns[2], ns[3], ns[4]);
    assert_ne!(fes, host, "{ns:?}");
    assert_eq!(driver, fes, "the driver joins the private bus: {ns:?}");
    assert_eq!(
        stim, fes,
        "the virtual stimulator joins the private bus: {ns:?}"
    );
    assert_eq!(rt, host, "rt-core stays in the host's namespace: {ns:?}");
    assert_eq!(r.value("start"), "0");

    // Whose publishers (docs/stim-driver.md): the driver, told the units rt-core and the
    // supervisor run in, finds both publishers' processes in them under systemd.
    assert!(
        r.value("supervisor-cgroup")
            .ends_with("/fes-supervisor.service"),
        "{r:#?}"
    );
    for key in ["driver-sees-supervisor", "driver-sees-generator"] {
        assert!(
            r.value(key).trim().parse::<u32>().unwrap_or(0) >= 1,
            "{key}: {}\n{}",
            r.value(key),
            r.journal.join("\n")
        );
    }
    assert_eq!(
        r.value("driver-foreign").trim(),
        "0",
        "{}",
        r.journal.join("\n")
    );

    // Order: CAN -> stimulator, driver -> rt-core (after the driver's READY) -> supervisor.
    let t = |unit: &str, p: &str| r.mono("up", unit, p);
    let enter = "ActiveEnterTimestampMonotonic";
    let start = "ExecMainStartTimestampMonotonic";
    for unit in [
        "fes-can.service",
        "fes-sim-muscle.service",
        "fes-stim-driver.service",
        "fes-rt-core.service",
        "fes-supervisor.service",
    ] {
        assert_eq!(
            r.prop("up", unit, "ActiveState"),
            "active",
            "{unit}: {r:#?}"
        );
    }
    assert!(t("fes-can.service", enter) <= t("fes-stim-driver.service", start));
    assert!(t("fes-can.service", enter) <= t("fes-sim-muscle.service", start));
    assert!(t("fes-stim-driver.service", enter) <= t("fes-rt-core.service", start));
    assert!(t("fes-rt-core.service", enter) <= t("fes-supervisor.service", start));

    // Watchdog: the stopped rt-core is no longer the one running.
    let stalled = r.value("stopped-rt-core").trim().to_owned();
    let rt_after = r.prop("after-watchdog", "fes-rt-core.service", "MainPID");
    assert_ne!(rt_after, stalled, "the stalled rt-core still runs: {r:#?}");
    let before: u64 = r.value("rt-core-restarts-before").trim().parse().unwrap();
    let rt_restarts = r.mono("after-watchdog", "fes-rt-core.service", "NRestarts");
    assert!(
        rt_restarts > before,
        "the watchdog did not restart the stalled rt-core ({before} -> {rt_restarts} restarts): {r:#?}"
    );
    assert_eq!(
        r.prop("after-watchdog", "fes-rt-core.service", "ActiveState"),
        "active",
        "rt-core not back after the watchdog: {r:#?}"
    );

    // BindsTo / PartOf: the driver stopped -> rt-core and the virtual stimulator stopped,
    // and ExecStopPost sent the safe stop.
    assert_eq!(r.value("stop-driver"), "0");
    for unit in ["fes-rt-core.service", "fes-sim-muscle.service"] {
        let state = r.prop("after-driver-stop", unit, "ActiveState");
        assert!(
            state != "active",
            "{unit} still {state} after the driver stopped"
        );
    }
    let safe_stops: u32 = r.value("safe-stop-log").trim().parse().unwrap();
    assert!(
        safe_stops >= 1,
        "no safe stop when the driver stopped: {r:#?}"
    );

    // SIGKILL of the driver: safe stop again, restarted by Restart=on-failure.
    let killed = r.value("killed-driver").trim().to_owned();
    assert_ne!(
        r.prop("after-driver-kill", "fes-stim-driver.service", "MainPID"),
        killed
    );
    assert_eq!(
        r.prop(
            "after-driver-kill",
            "fes-stim-driver.service",
            "ActiveState"
        ),
        "active"
    );
    let safe_stops_2: u32 = r.value("safe-stop-log-2").trim().parse().unwrap();
    assert!(
        safe_stops_2 > safe_stops,
        "no safe stop after SIGKILL: {r:#?}"
    );
    // rt-core was stopped with its driver (BindsTo=) and is not brought back by the
    // driver's restart: it stays down until the operator starts fes.target again.
    assert_ne!(
        r.prop("after-driver-kill", "fes-rt-core.service", "ActiveState"),
        "active"
    );

    // The package's life cycle: a reinstall keeps the operator's choices (disabled, an
    // edited prescription with the new default beside it); a purge stops the stack (the
    // safe stop runs once more), removes it, keeps the recordings and the user.
    assert_eq!(r.value("reinstall"), "0", "{r:#?}");
    assert_eq!(r.value("enabled-after-reinstall"), "disabled", "{r:#?}");
    assert_eq!(r.value("prescription-kept"), "1 dist", "{r:#?}");
    assert_eq!(r.value("purge"), "0", "{r:#?}");
    assert_ne!(r.value("after-purge-driver"), "active", "{r:#?}");
    let safe_stops_3: u32 = r.value("safe-stop-log-3").trim().parse().unwrap();
    assert!(
        safe_stops_3 > safe_stops_2,
        "no safe stop when the purge stopped the stack: {r:#?}"
    );
    assert_eq!(r.value("purge-left"), "none", "{r:#?}");
    assert_eq!(r.value("purge-kept"), "/var/lib/fes user-fes", "{r:#?}");
    std::fs::remove_dir_all(&run_dir).ok();
}
