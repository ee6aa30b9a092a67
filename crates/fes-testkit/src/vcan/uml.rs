//! Running a command inside a User-Mode Linux guest that has `vcan0`.
//!
//! The guest mounts the host's root filesystem through hostfs, so it sees the same
//! binaries, sources and `/tmp`; its init script (generated per run) mounts /proc, /sys,
//! /dev/shm and a fresh iceoryx2 root, loads can, can-raw, can-dev and vcan, brings up
//! `lo` and `vcan0`, runs the command in the caller's directory with the caller's
//! environment, prints its exit status between markers and powers off. Boots are
//! serialised host-wide by a lock file; each run has its own umid and temp directory.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use super::native::{lock_file, lock_path};
use super::process::{Next, Streamed};
use super::shell::{exports, quote};
use super::{
    Backend, ENV_BACKEND, ENV_CAN_IFACE, ENV_IFACE, ENV_NONCE, GuestCommand, HarnessError,
    RunOutcome,
};

/// Kernel modules the guest loads, in dependency order (relative to the modules' `kernel/`).
pub const MODULES: [&str; 4] = [
    "net/can/can.ko",
    "net/can/can-raw.ko",
    "drivers/net/can/dev/can-dev.ko",
    "drivers/net/can/vcan.ko",
];
/// Where the Debian user-mode-linux package puts the guest's modules.
pub const MODULES_ROOT: &str = "/usr/lib/uml/modules";
/// Marker prefix of the lines the guest script prints for the host.
pub(crate) const MARK: &str = "@@FES-VCAN-";
/// Guest memory unless `FES_UML_MEM` says otherwise.
const DEFAULT_MEM: &str = "1G";
/// The interface the guest creates.
pub(crate) const GUEST_IFACE: &str = "vcan0";

/// A usable UML kernel.
#[derive(Debug, Clone)]
pub(crate) struct UmlKernel {
    binary: PathBuf,
}

fn in_path(name: &str) -> Option<PathBuf> {
    std::env::var_os("PATH").and_then(|p| {
        std::env::split_paths(&p)
            .map(|d| d.join(name))
            .find(|c| c.is_file())
    })
}

/// Finds `linux.uml` (or `$FES_UML_KERNEL`) and the guest's CAN modules.
pub(crate) fn find() -> Result<UmlKernel, String> {
    let binary = match std::env::var_os("FES_UML_KERNEL") {
        Some(p) => PathBuf::from(p),
        None => in_path("linux.uml")
            .ok_or("linux.uml not found in PATH (Debian package user-mode-linux)")?,
    };
    if !binary.is_file() {
        return Err(format!("UML kernel {} does not exist", binary.display()));
    }
    let versions = std::fs::read_dir(MODULES_ROOT).map_err(|e| format!("{MODULES_ROOT}: {e}"))?;
    let complete = versions.flatten().any(|v| {
        MODULES
            .iter()
            .all(|m| v.path().join("kernel").join(m).is_file())
    });
    if !complete {
        return Err(format!(
            "no UML module set under {MODULES_ROOT} has {}",
            MODULES.join(", ")
        ));
    }
    for tool in ["insmod", "ip"] {
        if in_path(tool).is_none()
            && !Path::new("/usr/sbin").join(tool).is_file()
            && !Path::new("/sbin").join(tool).is_file()
        {
            return Err(format!("{tool} not found (packages kmod, iproute2)"));
        }
    }
    Ok(UmlKernel { binary })
}

/// A per-run directory under the temp dir, removed on drop unless `FES_VCAN_KEEP` is set.
struct RunDir {
    path: PathBuf,
}

static RUNS: AtomicU64 = AtomicU64::new(0);

impl RunDir {
    fn create() -> Result<(Self, String), HarnessError> {
        let n = RUNS.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let umid = format!("fes-{pid}-{n}");
        let path = std::env::temp_dir().join(format!("fes-vcan-{pid}-{n}"));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir(&path).map_err(|source| HarnessError::Io {
            what: format!("creating {}", path.display()),
            source,
        })?;
        Ok((Self { path }, umid))
    }
}

impl Drop for RunDir {
    fn drop(&mut self) {
        if std::env::var_os("FES_VCAN_KEEP").is_some() {
            eprintln!("vcan harness: keeping {}", self.path.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

fn nonce() -> String {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!(
        "{:x}{:x}{:x}",
        t,
        std::process::id(),
        RUNS.load(Ordering::Relaxed)
    )
}

/// The guest's init script.
fn init_script(run_dir: &Path, nonce: &str, cmd: &GuestCommand) -> Result<String, HarnessError> {
    let dir = run_dir
        .to_str()
        .ok_or_else(|| HarnessError::BadPath(run_dir.to_path_buf()))?;
    let cwd = cmd
        .cwd
        .to_str()
        .ok_or_else(|| HarnessError::BadPath(cmd.cwd.clone()))?;
    let mut env: Vec<(String, String)> = std::env::vars().collect();
    env.extend(cmd.env.iter().cloned());
    env.push((ENV_IFACE.into(), GUEST_IFACE.into()));
    env.push((ENV_CAN_IFACE.into(), GUEST_IFACE.into()));
    env.push((ENV_BACKEND.into(), "uml".into()));
    env.push((ENV_NONCE.into(), nonce.into()));
    env.push(("FES_VCAN_RUN_DIR".into(), dir.into()));
    env.push(("FES_IOX2_ROOT".into(), format!("{dir}/iceoryx2")));
    let exports = exports(env.iter().map(|(k, v)| (k.as_str(), v.as_str())));
    let argv: Vec<String> = cmd.argv.iter().map(|a| quote(a)).collect();
    let modules: Vec<String> = MODULES.iter().map(|m| quote(m)).collect();
    Ok(format!(
        r#"#!/bin/sh
# Generated by the fes-tests vcan harness: init of a User-Mode Linux guest.
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
N={nonce}
fail() {{ echo "{MARK}SETUP-FAILED $N $*"; sync; halt -f; }}
mount -t proc proc /proc || fail "mount /proc"
mount -t sysfs sysfs /sys || fail "mount /sys"
[ -c /dev/null ] || mount -t devtmpfs devtmpfs /dev || fail "mount /dev"
mkdir -p /dev/shm /dev/pts && mount -t tmpfs -o mode=1777 shm /dev/shm || fail "mount /dev/shm"
mount -t devpts devpts /dev/pts 2>/dev/null
mkdir -p {dir}/iceoryx2 /tmp/iceoryx2 && mount --bind {dir}/iceoryx2 /tmp/iceoryx2 || fail "iceoryx2 root"
M=/usr/lib/uml/modules/$(uname -r)/kernel
for m in {modules}; do insmod "$M/$m" || fail "insmod $m"; done
ip link set up dev lo || fail "ip link set up lo"
ip link add dev {GUEST_IFACE} type vcan || fail "ip link add {GUEST_IFACE}"
ip link set up dev {GUEST_IFACE} || fail "ip link set up {GUEST_IFACE}"
cd {cwd} || fail "cd {cwd}"
{exports}echo "{MARK}READY $N"
{argv} </dev/null 2>&1
echo "{MARK}EXIT $N $?"
sync
halt -f
"#,
        dir = quote(dir),
        cwd = quote(cwd),
        modules = modules.join(" "),
        argv = argv.join(" "),
    ))
}

/// Writes the guest's init script into the run's directory (executable).
fn write_init_script(dir: &Path, nonce: &str, cmd: &GuestCommand) -> Result<PathBuf, HarnessError> {
    let script_path = dir.join("init.sh");
    let script = init_script(dir, nonce, cmd)?;
    let io = |what: String| move |source| HarnessError::Io { what, source };
    std::fs::write(&script_path, script)
        .map_err(io(format!("writing {}", script_path.display())))?;
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&script_path, std::fs::Permissions::from_mode(0o755))
        .map_err(io(format!("chmod {}", script_path.display())))?;
    Ok(script_path)
}

/// The UML kernel's command line: the host's root read-write over hostfs, the init
/// script, the console on stdin/stdout, memory from `FES_UML_MEM`.
fn guest_command(kernel: &UmlKernel, script_path: &Path, umid: &str, dir: &Path) -> Command {
    let mem = std::env::var("FES_UML_MEM").unwrap_or_else(|_| DEFAULT_MEM.into());
    let mut command = Command::new(&kernel.binary);
    command.args([
        format!("mem={mem}"),
        "rootfstype=hostfs".into(),
        "rw".into(),
        format!("init={}", script_path.display()),
        "con=null".into(),
        "con0=fd:0,fd:1".into(),
        format!("umid={umid}"),
        format!("uml_dir={}", dir.display()),
        "quiet".into(),
    ]);
    command
}

/// Runs `cmd` in a fresh guest; streams its output lines to `on_line`.
pub(crate) fn run(
    kernel: &UmlKernel,
    cmd: &GuestCommand,
    on_line: &mut dyn FnMut(&str),
) -> Result<RunOutcome, HarnessError> {
    let lock = lock_path("fes-vcan-uml.lock");
    let _guard = lock_file(&lock)?;
    let (dir, umid) = RunDir::create()?;
    let nonce = nonce();
    let script_path = write_init_script(&dir.path, &nonce, cmd)?;
    let mut command = guest_command(kernel, &script_path, &umid, &dir.path);
    let start = Instant::now();
    let mut child = Streamed::spawn(&mut command).map_err(|source| HarnessError::Spawn {
        what: kernel.binary.display().to_string(),
        source,
    })?;
    let deadline = start + cmd.timeout;
    let mut boot_log: Vec<String> = Vec::new();
    let mut output: Vec<String> = Vec::new();
    let mut ready: Option<Duration> = None;
    let mut status: Option<i32> = None;
    let mut body_ok: Vec<String> = Vec::new();
    // A marker may follow other output on the same line (libtest prints "test x ... "
    // before the body runs); it must carry this run's nonce.
    let marker = |line: &str, what: &str| -> Option<String> {
        let at = line.find(MARK)?;
        line[at..]
            .strip_prefix(MARK)?
            .strip_prefix(what)?
            .strip_prefix(' ')?
            .strip_prefix(nonce.as_str())
            .map(|r| r.trim().to_string())
    };
    while status.is_none() {
        match child.next_line(deadline) {
            Next::Line(line) => {
                if let Some(at) = line.find(MARK).filter(|&at| at > 0 && ready.is_some()) {
                    on_line(&line[..at]);
                    output.push(line[..at].to_string());
                }
                if let Some(step) = marker(&line, "SETUP-FAILED") {
                    let _ = child.wait_until(Instant::now() + Duration::from_secs(10));
                    return Err(HarnessError::GuestSetup {
                        step,
                        log: tail(&boot_log),
                    });
                } else if marker(&line, "READY").is_some() {
                    ready = Some(start.elapsed());
                } else if let Some(code) = marker(&line, "EXIT") {
                    status = Some(code.parse().unwrap_or(-1));
                } else if let Some(name) = marker(&line, "BODY-OK") {
                    body_ok.push(name);
                } else if ready.is_some() {
                    on_line(&line);
                    output.push(line);
                } else {
                    boot_log.push(line);
                }
            }
            Next::Eof => break,
            Next::TimedOut => {
                child.kill_group();
                let mut log = boot_log;
                log.extend(output);
                return Err(HarnessError::Timeout {
                    after: cmd.timeout,
                    log: tail(&log),
                });
            }
        }
    }
    // The guest halts right after the exit marker; give it a moment, then make sure.
    if child
        .wait_until(Instant::now() + Duration::from_secs(20))
        .ok()
        .flatten()
        .is_none()
    {
        child.kill_group();
    }
    let Some(status) = status else {
        let mut log = boot_log;
        log.extend(output);
        log.extend(child.remaining_lines());
        return Err(HarnessError::GuestCrashed { log: tail(&log) });
    };
    Ok(RunOutcome {
        backend: Backend::Uml,
        status,
        output,
        body_ok,
        boot: ready,
        total: start.elapsed(),
    })
}

fn tail(lines: &[String]) -> String {
    let from = lines.len().saturating_sub(40);
    lines[from..].join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn init_script_quotes_the_command_and_exports_the_environment() {
        let cmd = GuestCommand {
            argv: vec!["/bin/echo".into(), "it's here".into()],
            cwd: PathBuf::from("/tmp/a dir"),
            env: vec![("EXTRA".into(), "1".into())],
            timeout: Duration::from_secs(1),
        };
        let s = init_script(Path::new("/tmp/run1"), "abc", &cmd).unwrap();
        assert!(
            s.contains("'/bin/echo' 'it'\\''s here' </dev/null 2>&1\n"),
            "{s}"
        );
        assert!(s.contains("cd '/tmp/a dir' ||"));
        assert!(s.contains("export EXTRA='1'\n"));
        assert!(s.contains("export FES_VCAN_IFACE='vcan0'\n"));
        assert!(s.contains("echo \"@@FES-VCAN-EXIT $N $?\""));
        // The script is valid shell.
        let out = Command::new("sh")
            .arg("-n")
            .arg("-c")
            .arg(&s)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}
