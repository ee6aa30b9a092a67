//! The Debian packages `fes-stack` (rig) and `fes-stack-bench`, built
//! once per test run with `scripts/package --fast` (cargo-deb, release binaries; under the
//! README's test command, by `scripts/test` before the tests: [`PACKAGES_ENV`]) and read
//! with `dpkg-deb`:
//!
//! - control fields, dependencies and the two variants' conflict;
//! - the maintainer scripts: present, executable, `sh -n` clean; postinst enables and never
//!   starts or arms; prerm stops fes.target on removal only;
//! - conffiles: exactly every file under /etc (the prescription is not one);
//! - contents (`dpkg-deb -x`): every unit and binary where expected, every executable,
//!   configuration file and document a unit names shipped in the package; the packaged
//!   units are the installer's rendering of the same templates, less the placement;
//! - `systemd-analyze verify` of the packaged units with the generator's drop-ins;
//! - the generator: defaults equal scripts/install's, explicit values, the rig's device
//!   dependency, a bad value refused, a source-installed unit left alone.
//!
//! The boot test (`systemd_units::boot`) installs `fes-stack-bench` with `dpkg -i` in a
//! guest booted with systemd and runs the stack from it.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use crate::systemd_support::{Scratch, UnitFile, scratch, stage, target_dir, workspace_root};
use crate::systemd_units::analyze_verify;

/// The two packages' files.
#[derive(Debug)]
pub struct Packages {
    pub rig: PathBuf,
    pub bench: PathBuf,
}

/// Names the packages `scripts/test` built before the tests (one path a line), so that the
/// package tests and the boot test, which run at the same time in separate processes,
/// read them instead of each running `scripts/package` over the same staging directory.
pub const PACKAGES_ENV: &str = "FES_TEST_PACKAGES";

/// Both packages (once per test binary): the files [`PACKAGES_ENV`] names, else
/// `scripts/package --fast`, which builds the release binaries first (a no-op when they are
/// fresh).
pub fn packages() -> &'static Packages {
    static PACKAGES: OnceLock<Packages> = OnceLock::new();
    PACKAGES.get_or_init(|| {
        let debs: Vec<PathBuf> = if let Some(list) = std::env::var_os(PACKAGES_ENV) {
            let list = list.into_string().expect("UTF-8 package paths");
            let debs: Vec<PathBuf> = list.lines().map(PathBuf::from).collect();
            for d in &debs {
                assert!(
                    d.is_file(),
                    "{PACKAGES_ENV} names {}, not a file",
                    d.display()
                );
            }
            debs
        } else {
            let out = Command::new(workspace_root().join("scripts/package"))
                .arg("--fast")
                .env("CARGO_TARGET_DIR", target_dir())
                .output()
                .expect("run scripts/package");
            let stdout = String::from_utf8_lossy(&out.stdout);
            assert!(
                out.status.success(),
                "scripts/package failed (cargo-deb: scripts/setup installs it):\n{stdout}\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
            stdout.lines().map(PathBuf::from).collect()
        };
        let find = |prefix: &str| {
            debs.iter()
                .find(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with(prefix) && n.ends_with(".deb"))
                })
                .unwrap_or_else(|| panic!("no {prefix}*.deb in {debs:?}"))
                .clone()
        };
        Packages {
            rig: find("fes-stack_"),
            bench: find("fes-stack-bench_"),
        }
    })
}

/// One variant: its package, name, and what it must hold.
struct Variant {
    deb: &'static Path,
    name: &'static str,
    other: &'static str,
    bench: bool,
}

fn variants() -> [Variant; 2] {
    let p = packages();
    [
        Variant {
            deb: &p.rig,
            name: "fes-stack",
            other: "fes-stack-bench",
            bench: false,
        },
        Variant {
            deb: &p.bench,
            name: "fes-stack-bench",
            other: "fes-stack",
            bench: true,
        },
    ]
}

impl Variant {
    fn units(&self) -> Vec<&'static str> {
        let mut u = vec![
            "fes.target",
            "fes-can-netns.service",
            "fes-can.service",
            "fes-stim-driver.service",
            "fes-rt-core.service",
            "fes-supervisor.service",
        ];
        if self.bench {
            u.push("fes-sim-muscle.service");
        }
        u
    }

    fn binaries(&self) -> Vec<&'static str> {
        let mut b = vec!["rt-core", "stim-driver", "supervisor", "fes"];
        if self.bench {
            b.push("sim-muscle");
        }
        b
    }

    fn field(&self, name: &str) -> String {
        let out = Command::new("dpkg-deb")
            .arg("--field")
            .arg(self.deb)
            .arg(name)
            .output()
            .expect("dpkg-deb");
        assert!(out.status.success(), "dpkg-deb --field {name}");
        String::from_utf8_lossy(&out.stdout).trim().to_owned()
    }

    /// The package's control file `name` (conffiles, postinst...).
    fn control_file(&self, name: &str) -> Option<String> {
        let out = Command::new("sh")
            .arg("-c")
            .arg(format!(
                "dpkg-deb --ctrl-tarfile \"$1\" | tar -xOf - ./{name}"
            ))
            .arg("sh")
            .arg(self.deb)
            .output()
            .expect("dpkg-deb --ctrl-tarfile");
        out.status
            .success()
            .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
    }

    /// `dpkg-deb -c`: (mode string, path without the leading '.') of every entry.
    fn contents(&self) -> Vec<(String, String)> {
        let out = Command::new("dpkg-deb")
            .arg("--contents")
            .arg(self.deb)
            .output()
            .expect("dpkg-deb --contents");
        assert!(out.status.success());
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .map(|l| {
                let w: Vec<&str> = l.split_whitespace().collect();
                (
                    w[0].to_owned(),
                    w[5].trim_start_matches('.')
                        .trim_end_matches('/')
                        .to_owned(),
                )
            })
            .collect()
    }

    /// The package unpacked (`dpkg-deb -x`) into a scratch directory.
    fn extract(&self) -> Scratch {
        let dir = scratch(&format!("deb-{}", self.name));
        let status = Command::new("dpkg-deb")
            .arg("-x")
            .arg(self.deb)
            .arg(dir.path())
            .status()
            .expect("dpkg-deb -x");
        assert!(status.success());
        dir
    }
}

#[test]
fn control_fields_and_the_variants_conflict() {
    let version = env!("CARGO_PKG_VERSION");
    let arch = Command::new("dpkg")
        .arg("--print-architecture")
        .output()
        .expect("dpkg");
    let arch = String::from_utf8_lossy(&arch.stdout).trim().to_owned();
    for v in variants() {
        assert_eq!(v.field("Package"), v.name);
        assert_eq!(v.field("Version"), format!("{version}-1"), "{}", v.name);
        assert_eq!(v.field("Architecture"), arch, "{}", v.name);
        let depends = v.field("Depends");
        println!("{} Depends: {depends}", v.name);
        let names: BTreeSet<&str> = depends
            .split(',')
            .map(|d| d.split_whitespace().next().unwrap_or(""))
            .collect();
        // systemd: units, sysusers, tmpfiles; iproute2: `ip netns` / `ip link`; libc6 and
        // the others from the binaries ($auto).
        for d in ["systemd", "iproute2", "libc6"] {
            assert!(names.contains(d), "{}: Depends {depends}", v.name);
        }
        assert_eq!(
            names.contains("kmod"),
            v.bench,
            "kmod (modprobe vcan): bench only"
        );
        assert_eq!(v.field("Conflicts"), v.other, "{}", v.name);
        assert!(v.field("Description").contains("FES stimulation stack"));
        let about = v.field("Description");
        assert!(
            about.contains("does not") && about.contains("disarmed"),
            "{}: the description says it is not started and comes up disarmed: {about}",
            v.name
        );
    }
}

/// A maintainer script's command lines: comments, blank lines and `echo` messages dropped.
fn commands(script: &str) -> Vec<String> {
    script
        .lines()
        .map(|l| l.split(" #").next().unwrap_or("").trim())
        .filter(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with("echo "))
        .map(str::to_owned)
        .collect()
}

/// The verbs of every `systemctl` call in `lines`.
fn systemctl_verbs(lines: &[String]) -> Vec<String> {
    let mut verbs = Vec::new();
    for l in lines {
        let words: Vec<&str> = l.split_whitespace().collect();
        for (i, w) in words.iter().enumerate() {
            if *w == "systemctl" {
                let verb = words[i + 1..]
                    .iter()
                    .find(|a| !a.starts_with('-'))
                    .unwrap_or_else(|| panic!("systemctl without a verb: {l}"));
                verbs.push(verb.trim_end_matches([';', '&', '|']).to_owned());
            }
        }
    }
    verbs
}

#[test]
fn maintainer_scripts_enable_but_never_start_or_arm() {
    use std::os::unix::fs::PermissionsExt;
    for v in variants() {
        for name in ["postinst", "prerm", "postrm"] {
            let text = v
                .control_file(name)
                .unwrap_or_else(|| panic!("{}: no {name}", v.name));
            assert!(text.starts_with("#!/bin/sh\n"), "{}: {name}", v.name);
            let check = Command::new("sh")
                .arg("-n")
                .arg("-c")
                .arg(&text)
                .output()
                .expect("sh -n");
            assert!(
                check.status.success(),
                "{}: {name} is not valid sh: {}",
                v.name,
                String::from_utf8_lossy(&check.stderr)
            );
        }
        // Executable, as dpkg needs them.
        let dir = scratch(&format!("ctrl-{}", v.name));
        let status = Command::new("dpkg-deb")
            .arg("-e")
            .arg(v.deb)
            .arg(dir.path())
            .status()
            .expect("dpkg-deb -e");
        assert!(status.success());
        for name in ["postinst", "prerm", "postrm"] {
            let mode = std::fs::metadata(dir.join(name))
                .unwrap()
                .permissions()
                .mode();
            assert_eq!(mode & 0o111, 0o111, "{}: {name} mode {mode:o}", v.name);
        }

        let postinst = commands(&v.control_file("postinst").unwrap());
        let verbs = systemctl_verbs(&postinst);
        println!("{}: postinst systemctl verbs {verbs:?}", v.name);
        assert!(verbs.iter().any(|v| v == "enable"), "postinst enables");
        for verb in &verbs {
            assert!(
                ["daemon-reload", "enable", "is-active"].contains(&verb.as_str()),
                "{}: postinst runs `systemctl {verb}`: it may enable, never start",
                v.name
            );
        }
        let joined = postinst.join("\n");
        assert!(joined.contains("systemctl enable $units"), "{joined}");
        for needle in [
            "fes.target",
            "systemd-sysusers",
            "systemd-tmpfiles --create",
        ] {
            assert!(joined.contains(needle), "{}: postinst {needle}", v.name);
        }
        // Arming is the operator's: no maintainer script talks to the supervisor or the
        // driver's arm command.
        for name in ["postinst", "prerm", "postrm"] {
            for l in commands(&v.control_file(name).unwrap()) {
                let words: Vec<&str> = l.split_whitespace().collect();
                assert!(
                    !words
                        .iter()
                        .any(|w| w.ends_with("supervisor") || *w == "arm"),
                    "{}: {name} arms or drives the stack: {l}",
                    v.name
                );
            }
        }

        let prerm = v.control_file("prerm").unwrap();
        let prerm_cmds = commands(&prerm);
        assert_eq!(systemctl_verbs(&prerm_cmds), ["stop"], "{}: prerm", v.name);
        assert!(prerm_cmds.iter().any(|l| l == "remove | deconfigure)"));
        // Every unit by name, so that the stop waits for the driver's safe stop.
        assert!(
            prerm_cmds.contains(&"systemctl stop $units || true".to_owned()),
            "{prerm}"
        );
        for unit in v.units() {
            assert!(prerm.contains(unit), "{}: prerm stops {unit}", v.name);
        }
        let postrm = commands(&v.control_file("postrm").unwrap());
        let verbs = systemctl_verbs(&postrm);
        assert!(
            verbs.iter().all(|v| v == "daemon-reload"),
            "{}: postrm systemctl {verbs:?}",
            v.name
        );
        assert!(
            postrm.iter().any(|l| l == "rm -rf /run/fes /tmp/iceoryx2"),
            "{postrm:?}"
        );
        assert!(
            !postrm
                .iter()
                .any(|l| l.starts_with("rm ") && l.contains("/var/lib/fes")),
            "purge keeps the recordings: {postrm:?}"
        );
    }
}

#[test]
fn conffiles_are_every_file_under_etc() {
    for v in variants() {
        let conffiles: BTreeSet<String> = v
            .control_file("conffiles")
            .expect("conffiles")
            .lines()
            .map(str::to_owned)
            .collect();
        let etc: BTreeSet<String> = v
            .contents()
            .into_iter()
            .filter(|(mode, path)| !mode.starts_with('d') && path.starts_with("/etc/"))
            .map(|(_, path)| path)
            .collect();
        println!("{}: conffiles {conffiles:?}", v.name);
        assert_eq!(conffiles, etc, "{}", v.name);
        let mut expected: BTreeSet<String> = [
            "rt-core.toml",
            "stim-driver.toml",
            "supervisor.toml",
            "can.env",
            "placement.env",
        ]
        .iter()
        .map(|f| format!("/etc/fes/{f}"))
        .collect();
        if v.bench {
            expected.insert("/etc/fes/sim-muscle.env".to_owned());
        }
        assert_eq!(conffiles, expected, "{}", v.name);
        // The prescription is copied by postinst, never replaced by an upgrade.
        assert!(!conffiles.iter().any(|c| c.contains("prescription")));
    }
}

/// Every absolute path a unit names in `key` (first word of each value, `-`/`@`/`+` prefix
/// dropped).
fn unit_paths(u: &UnitFile, key: &str) -> Vec<String> {
    u.values("Service", key)
        .iter()
        .map(|v| {
            v.split_whitespace()
                .next()
                .unwrap_or("")
                .trim_start_matches(['-', '@', '+', '!'])
                .to_owned()
        })
        .collect()
}

#[test]
fn units_binaries_configuration_and_docs_are_where_the_units_say() {
    use std::os::unix::fs::PermissionsExt;
    for v in variants() {
        let root = v.extract();
        let unit_dir = root.join("usr/lib/systemd/system");
        let shipped: BTreeSet<String> = std::fs::read_dir(&unit_dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        let expected: BTreeSet<String> = v.units().iter().map(|s| (*s).to_owned()).collect();
        assert_eq!(shipped, expected, "{}: units", v.name);
        for b in v.binaries() {
            let path = root.join("usr/bin").join(b);
            let mode = std::fs::metadata(&path)
                .unwrap_or_else(|e| panic!("{}: /usr/bin/{b}: {e}", v.name))
                .permissions()
                .mode();
            assert_eq!(mode & 0o755, 0o755, "{}: /usr/bin/{b}", v.name);
        }
        for f in [
            "usr/lib/systemd/system-generators/fes-placement-generator",
            "usr/lib/fes/units.sh",
            "usr/lib/fes/variant",
            "usr/lib/sysusers.d/fes.conf",
            "usr/lib/tmpfiles.d/fes.conf",
            "usr/share/fes/prescription.toml",
        ] {
            assert!(root.join(f).is_file(), "{}: /{f}", v.name);
        }
        let variant = std::fs::read_to_string(root.join("usr/lib/fes/variant")).unwrap();
        assert_eq!(variant.trim(), if v.bench { "bench" } else { "rig" });

        for name in v.units() {
            let u = UnitFile::load(&unit_dir.join(name));
            for key in ["ExecStart", "ExecStartPre", "ExecStop", "ExecStopPost"] {
                for exe in unit_paths(&u, key) {
                    if exe.starts_with("/usr/bin/") {
                        assert!(
                            root.join(exe.trim_start_matches('/')).is_file(),
                            "{}: {name} {key}={exe} is not in the package",
                            v.name
                        );
                    } else {
                        // ip, modprobe: the Depends (iproute2, kmod).
                        assert!(
                            ["/sbin/ip", "/sbin/modprobe"].contains(&exe.as_str()),
                            "{}: {name} {key}={exe}: from which package?",
                            v.name
                        );
                    }
                }
            }
            for v_ in u.values("Service", "ExecStart") {
                assert!(!v_.contains("/usr/local"), "{name}: {v_}");
                if let Some(conf) = v_
                    .split_whitespace()
                    .skip_while(|w| *w != "--config")
                    .nth(1)
                {
                    assert!(
                        root.join(conf.trim_start_matches('/')).is_file(),
                        "{}: {name} reads {conf}, not in the package",
                        v.name
                    );
                }
            }
            for env in u.values("Service", "EnvironmentFile") {
                assert!(
                    root.join(env.trim_start_matches(['-', '/'])).is_file(),
                    "{}: {name} EnvironmentFile={env} not in the package",
                    v.name
                );
            }
            for doc in u.words("Unit", "Documentation") {
                let path = doc.strip_prefix("file:").expect("file: documentation");
                assert!(
                    path.starts_with(&format!("/usr/share/doc/{}/", v.name)),
                    "{}: {name} Documentation={doc}",
                    v.name
                );
                assert!(
                    root.join(path.trim_start_matches('/')).is_file(),
                    "{}: {name} Documentation={doc} not in the package",
                    v.name
                );
            }
            // Static: no placement, no device dependency (the generator's drop-ins).
            let cpus = u.values("Service", "CPUAffinity");
            assert!(cpus.is_empty(), "{}: {name} CPUAffinity={cpus:?}", v.name);
            assert!(
                !u.words("Unit", "Wants")
                    .iter()
                    .any(|w| w.starts_with("sys-subsystem-net-devices-")),
                "{}: {name} names a device",
                v.name
            );
        }
    }
}

/// The packaged units are scripts/install's rendering of the same templates (the shared
/// deploy/lib/units.sh): equal to a staged install with prefix /usr, once the installer's
/// placement, device dependency and doc directory are taken out.
#[test]
fn packaged_units_are_the_installers_less_the_placement() {
    let bins = crate::systemd_support::stack_binaries();
    for v in variants() {
        let root = v.extract();
        let staged = scratch(&format!("stage-{}", v.name));
        let mode = if v.bench { "--bench" } else { "--rig" };
        stage(
            mode,
            staged.path(),
            &bins,
            &[
                "--prefix",
                "/usr",
                "--iface",
                "can7",
                "--rt-cpus",
                "3",
                "--housekeeping-cpus",
                "0-2",
            ],
        );
        for name in v.units() {
            let installed =
                std::fs::read_to_string(staged.join("etc/systemd/system").join(name)).unwrap();
            let normalised: String = installed
                .replace(
                    "/usr/share/doc/fes/",
                    &format!("/usr/share/doc/{}/", v.name),
                )
                .replace(" can7 (rig", " (rig")
                .lines()
                .filter(|l| !l.contains("sys-subsystem-net-devices-can7.device"))
                .map(|l| match l {
                    "CPUAffinity=3" | "CPUAffinity=0-2" => "CPUAffinity=\n".to_owned(),
                    _ => format!("{l}\n"),
                })
                .collect();
            let packaged =
                std::fs::read_to_string(root.join("usr/lib/systemd/system").join(name)).unwrap();
            assert_eq!(packaged, normalised, "{}: {name}", v.name);
        }
    }
}

/// Runs the extracted package's generator into `out` with its configuration at `conf`
/// (`FES_CONF_DIR`) and the administrator's unit directory `admin`; returns its stderr.
fn run_generator(root: &Path, conf: &Path, admin: &Path, out: &Path) -> String {
    std::fs::create_dir_all(out).unwrap();
    let result =
        Command::new(root.join("usr/lib/systemd/system-generators/fes-placement-generator"))
            .arg(out)
            .arg(out.join("early"))
            .arg(out.join("late"))
            .env("FES_LIB_DIR", root.join("usr/lib/fes"))
            .env("FES_CONF_DIR", conf)
            .env("FES_ADMIN_UNIT_DIR", admin)
            .output()
            .expect("run the generator");
    let stderr = String::from_utf8_lossy(&result.stderr).into_owned();
    assert!(result.status.success(), "generator failed: {stderr}");
    stderr
}

/// The drop-in the generator wrote for `unit`, parsed.
fn dropin(out: &Path, unit: &str) -> Option<UnitFile> {
    let path = out.join(format!("{unit}.d/50-fes-placement.conf"));
    path.exists().then(|| UnitFile::load(&path))
}

/// `systemd-analyze verify` of the packaged units with the generator's drop-ins beside them
/// (the unit search path holds both), executables pointed at the extracted binaries.
fn verify_with_dropins(root: &Path, generated: &Path, dir: &Path) -> (bool, String) {
    std::fs::create_dir_all(dir).unwrap();
    let bindir = root.join("usr/bin");
    for entry in std::fs::read_dir(root.join("usr/lib/systemd/system")).unwrap() {
        let path = entry.unwrap().path();
        let text = std::fs::read_to_string(&path)
            .unwrap()
            .replace("/usr/bin/", &format!("{}/", bindir.display()));
        std::fs::write(dir.join(path.file_name().unwrap()), text).unwrap();
    }
    for entry in std::fs::read_dir(generated).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.ends_with(".d") {
            let dest = dir.join(&name);
            std::fs::create_dir_all(&dest).unwrap();
            for f in std::fs::read_dir(&path).unwrap() {
                let f = f.unwrap().path();
                std::fs::copy(&f, dest.join(f.file_name().unwrap())).unwrap();
            }
        }
    }
    analyze_verify(dir)
}

#[test]
fn systemd_analyze_verify_accepts_the_packaged_units_with_their_dropins() {
    for v in variants() {
        let root = v.extract();
        let generated = root.join("run-generator");
        run_generator(
            root.path(),
            &root.join("etc/fes"),
            &root.join("no-admin-units"),
            &generated,
        );
        let (ok, text) = verify_with_dropins(root.path(), &generated, &root.join("verify"));
        println!(
            "{}: systemd-analyze verify: ok={ok} output={text:?}",
            v.name
        );
        assert!(
            ok && text.trim().is_empty(),
            "{}: systemd-analyze verify must pass without any output:\n{text}",
            v.name
        );
    }
}

/// The CPUs `getconf _NPROCESSORS_ONLN` reports, as the installer and the generator count.
fn online_cpus() -> usize {
    let out = Command::new("getconf")
        .arg("_NPROCESSORS_ONLN")
        .output()
        .expect("getconf");
    String::from_utf8_lossy(&out.stdout).trim().parse().unwrap()
}

#[test]
fn generator_places_the_units_like_the_installer_and_refuses_bad_values() {
    let [rig, _] = variants();
    let root = rig.extract();
    let conf = root.join("etc/fes");
    let none = root.join("no-admin-units");
    let affinity = |out: &Path, unit: &str| {
        dropin(out, unit)
            .unwrap_or_else(|| panic!("no drop-in for {unit}"))
            .get("Service", "CPUAffinity")
    };

    // Defaults (placement.env as shipped: empty): the installer's.
    let out = root.join("gen-default");
    let stderr = run_generator(root.path(), &conf, &none, &out);
    let bins = crate::systemd_support::stack_binaries();
    let staged = scratch("gen-vs-install");
    stage("--rig", staged.path(), &bins, &[]);
    let installed = |unit: &str| {
        UnitFile::load(&staged.join("etc/systemd/system").join(unit)).get("Service", "CPUAffinity")
    };
    for unit in [
        "fes-rt-core.service",
        "fes-stim-driver.service",
        "fes-supervisor.service",
    ] {
        assert_eq!(affinity(&out, unit), installed(unit), "{unit}");
    }
    let last = online_cpus() - 1;
    assert_eq!(
        affinity(&out, "fes-rt-core.service"),
        Some(last.to_string())
    );
    assert_eq!(
        online_cpus() == 1,
        stderr.contains("one CPU only"),
        "{stderr}"
    );
    // The rig waits for can.env's interface; no virtual stimulator on a rig.
    let can = dropin(&out, "fes-can.service").expect("fes-can drop-in");
    assert!(can.has_word("Unit", "Wants", "sys-subsystem-net-devices-can0.device"));
    assert!(can.has_word("Unit", "After", "sys-subsystem-net-devices-can0.device"));
    assert!(!can.has_word("Unit", "BindsTo", "sys-subsystem-net-devices-can0.device"));
    assert!(dropin(&out, "fes-sim-muscle.service").is_none());

    // The engineer's values.
    std::fs::write(
        conf.join("placement.env"),
        "FES_RT_CPUS=\"2-3\"\nFES_HOUSEKEEPING_CPUS=0,1\n",
    )
    .unwrap();
    std::fs::write(
        conf.join("can.env"),
        "FES_CAN_IFACE=can1\nFES_CAN_BITRATE=500000\n",
    )
    .unwrap();
    let out = root.join("gen-set");
    run_generator(root.path(), &conf, &none, &out);
    assert_eq!(
        affinity(&out, "fes-rt-core.service").as_deref(),
        Some("2-3")
    );
    assert_eq!(
        affinity(&out, "fes-stim-driver.service").as_deref(),
        Some("2-3")
    );
    assert_eq!(
        affinity(&out, "fes-supervisor.service").as_deref(),
        Some("0,1")
    );
    let can = dropin(&out, "fes-can.service").unwrap();
    assert!(can.has_word("Unit", "Wants", "sys-subsystem-net-devices-can1.device"));

    // Bad values: the units concerned refuse to start, saying why; verify still passes.
    std::fs::write(
        conf.join("placement.env"),
        "FES_RT_CPUS=last\nFES_HOUSEKEEPING_CPUS=0\n",
    )
    .unwrap();
    std::fs::write(conf.join("can.env"), "FES_CAN_IFACE=can 0\n").unwrap();
    let out = root.join("gen-bad");
    let stderr = run_generator(root.path(), &conf, &none, &out);
    for unit in [
        "fes-rt-core.service",
        "fes-stim-driver.service",
        "fes-can.service",
    ] {
        let d = dropin(&out, unit).unwrap();
        let pre = d.values("Service", "ExecStartPre").join(" ");
        let key = if unit == "fes-can.service" {
            "FES_CAN_IFACE"
        } else {
            "FES_RT_CPUS"
        };
        assert!(
            pre.starts_with("/bin/sh -c ") && pre.contains(key) && pre.ends_with("exit 1'"),
            "{unit}: {pre}"
        );
        assert_eq!(d.get("Service", "CPUAffinity"), None, "{unit}");
    }
    assert!(stderr.contains("FES_RT_CPUS"), "{stderr}");
    assert!(stderr.contains("FES_CAN_IFACE"), "{stderr}");
    assert_eq!(
        affinity(&out, "fes-supervisor.service").as_deref(),
        Some("0")
    );
    let (ok, text) = verify_with_dropins(root.path(), &out, &root.join("verify-bad"));
    assert!(ok && text.trim().is_empty(), "{text}");

    // A unit installed from source (scripts/install: a full unit in /etc/systemd/system)
    // is not the package's: no drop-in for it.
    let admin = root.join("admin-units");
    std::fs::create_dir_all(&admin).unwrap();
    std::fs::write(admin.join("fes-rt-core.service"), "[Unit]\n").unwrap();
    let out = root.join("gen-admin");
    run_generator(root.path(), &conf, &admin, &out);
    assert!(dropin(&out, "fes-rt-core.service").is_none());
    assert!(dropin(&out, "fes-stim-driver.service").is_some());
}

/// The bench's generator places the virtual stimulator on the housekeeping CPUs and
/// leaves the virtual bus without a device dependency.
#[test]
fn bench_generator_places_the_virtual_stimulator() {
    let [_, bench] = variants();
    let root = bench.extract();
    let out = root.join("gen");
    run_generator(root.path(), &root.join("etc/fes"), &root.join("none"), &out);
    let sup = dropin(&out, "fes-supervisor.service").unwrap();
    let sim = dropin(&out, "fes-sim-muscle.service").expect("sim-muscle placed");
    assert_eq!(
        sim.get("Service", "CPUAffinity"),
        sup.get("Service", "CPUAffinity")
    );
    assert!(
        dropin(&out, "fes-can.service").is_none(),
        "vcan has no device"
    );
    let env = std::fs::read_to_string(root.join("etc/fes/can.env")).unwrap();
    assert!(env.contains("FES_CAN_IFACE=vcan0\n"), "{env}");
}
