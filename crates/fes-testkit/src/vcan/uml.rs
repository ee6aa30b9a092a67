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
/// `GLIBC_TUNABLES` of every program in a guest: glibc's AVX-512 code paths off. UML
/// saves a guest thread's x87, SSE and AVX registers only; on a host with a larger XSAVE
/// area (AVX-512, AMX) the rest is shared by the threads of a guest process
/// (`uml_xstate.c`), so guest code must not use it. Rust code for the baseline x86-64
/// uses SSE only.
pub const GUEST_GLIBC_TUNABLES: &str =
    "glibc.cpu.hwcaps=-AVX512F,-AVX512VL,-AVX512BW,-AVX512DQ,-AVX512CD";
/// The XSAVE shim `build.rs` compiled from `uml_xstate.c` (empty off x86-64 Linux).
const XSTATE_SHIM: &str = env!("FES_UML_XSTATE_SHIM");

/// A command that runs the UML kernel `binary` with the XSAVE shim preloaded: without
/// it the packaged UML 6.1 panics at the guest's first system call on a host whose XSAVE
/// area is larger than AVX's ("ptrace set fp regs failed, errno = 14"; `uml_xstate.c`).
pub fn kernel_command(binary: &Path) -> Command {
    let mut command = Command::new(binary);
    if !XSTATE_SHIM.is_empty() {
        command.env("LD_PRELOAD", XSTATE_SHIM);
    }
    command
}

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
    // The script exports GLIBC_TUNABLES once, first, for every guest program; a value of
    // the caller's exported later would undo it.
    env.retain(|(k, _)| k != "GLIBC_TUNABLES");
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
export GLIBC_TUNABLES={tunables}
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
        tunables = quote(GUEST_GLIBC_TUNABLES),
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
    let mut command = kernel_command(&kernel.binary);
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
            env: vec![
                ("EXTRA".into(), "1".into()),
                ("GLIBC_TUNABLES".into(), "glibc.malloc.check=3".into()),
            ],
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
        // Every guest program, from the first insmod on, keeps off AVX-512, whatever
        // the caller's environment says.
        let tunables = format!("export GLIBC_TUNABLES='{GUEST_GLIBC_TUNABLES}'\n");
        let at = s.find(&tunables).expect("GLIBC_TUNABLES exported");
        assert!(at < s.find("insmod").expect("insmod"), "{s}");
        assert_eq!(s.matches("GLIBC_TUNABLES=").count(), 1, "{s}");
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

/// The XSAVE shim against the host kernel: a write of UML's 832 bytes, refused by the
/// host where its XSAVE area is larger, succeeds through the shim and lands.
#[cfg(all(test, target_arch = "x86_64", target_os = "linux"))]
mod xstate_shim_tests {
    use super::XSTATE_SHIM;
    use std::ffi::CString;

    /// UML 6.1's buffer: `sizeof(struct _xstate)` (x87 + SSE 512, header 64, AVX 256).
    const UML_FP_BYTES: usize = 832;
    /// `NT_X86_XSTATE`, the regset of the whole XSAVE area.
    const NT_X86_XSTATE: libc::c_int = 0x202;
    /// Offset of xmm0 in the legacy (FXSAVE) area.
    const XMM0: usize = 160;

    type PtraceFn = unsafe extern "C" fn(
        libc::c_int,
        libc::pid_t,
        *mut libc::c_void,
        *mut libc::c_void,
    ) -> libc::c_long;

    /// A stopped child traced by this process; killed on drop.
    struct Tracee(libc::pid_t);

    impl Tracee {
        fn stopped() -> Self {
            // SAFETY: the child calls only async-signal-safe functions (ptrace, raise,
            // _exit) before it is stopped and later killed.
            let pid = unsafe { libc::fork() };
            assert!(pid >= 0, "fork failed");
            if pid == 0 {
                // SAFETY: see above; the child never returns into the test harness.
                unsafe {
                    libc::ptrace(libc::PTRACE_TRACEME, 0, 0, 0);
                    libc::raise(libc::SIGSTOP);
                    libc::_exit(0);
                }
            }
            let mut status = 0;
            // SAFETY: waiting for our own child.
            let r = unsafe { libc::waitpid(pid, &mut status, 0) };
            assert_eq!(r, pid, "waitpid");
            assert!(libc::WIFSTOPPED(status), "child not stopped: {status:#x}");
            Self(pid)
        }

        fn xstate(&self, len: usize) -> Vec<u8> {
            let mut buf = vec![0u8; len];
            let mut iov = libc::iovec {
                iov_base: buf.as_mut_ptr().cast(),
                iov_len: len,
            };
            // SAFETY: the iovec points at `len` writable bytes; the child is our tracee.
            let r = unsafe {
                libc::ptrace(
                    libc::PTRACE_GETREGSET,
                    self.0,
                    NT_X86_XSTATE as usize,
                    &mut iov as *mut libc::iovec,
                )
            };
            assert_eq!(r, 0, "GETREGSET: {}", std::io::Error::last_os_error());
            buf.truncate(iov.iov_len);
            buf
        }
    }

    impl Drop for Tracee {
        fn drop(&mut self) {
            // SAFETY: kill and reap our own child.
            unsafe {
                libc::kill(self.0, libc::SIGKILL);
                libc::waitpid(self.0, std::ptr::null_mut(), 0);
            }
        }
    }

    fn set(ptrace: PtraceFn, pid: libc::pid_t, bytes: &mut [u8]) -> Result<(), std::io::Error> {
        let mut iov = libc::iovec {
            iov_base: bytes.as_mut_ptr().cast(),
            iov_len: bytes.len(),
        };
        let request = libc::PTRACE_SETREGSET as libc::c_int;
        // SAFETY: the iovec points at `bytes`; the child is our stopped tracee.
        let r = unsafe {
            ptrace(
                request,
                pid,
                NT_X86_XSTATE as usize as *mut _,
                (&mut iov as *mut libc::iovec).cast(),
            )
        };
        if r == 0 {
            Ok(())
        } else {
            Err(std::io::Error::last_os_error())
        }
    }

    #[test]
    fn an_avx_sized_write_lands_through_the_shim() {
        let path = CString::new(XSTATE_SHIM).unwrap();
        // SAFETY: loading the shared object build.rs compiled; its only symbol is `ptrace`.
        let lib = unsafe { libc::dlopen(path.as_ptr(), libc::RTLD_NOW | libc::RTLD_LOCAL) };
        assert!(!lib.is_null(), "dlopen {XSTATE_SHIM} failed");
        // SAFETY: looking up a symbol of the library just loaded.
        let sym = unsafe { libc::dlsym(lib, c"ptrace".as_ptr()) };
        assert!(!sym.is_null(), "the shim exports no ptrace");
        // SAFETY: the shim's `ptrace` has the C prototype of ptrace(2) (variadic; its four
        // arguments are passed in registers as in this non-variadic type on x86-64).
        let shim: PtraceFn = unsafe { std::mem::transmute::<*mut libc::c_void, PtraceFn>(sym) };
        // The host's own ptrace, for the refusal.
        // SAFETY: libc's ptrace symbol, same prototype as above.
        let host: PtraceFn = unsafe {
            std::mem::transmute::<*mut libc::c_void, PtraceFn>(libc::dlsym(
                libc::RTLD_DEFAULT,
                c"ptrace".as_ptr(),
            ))
        };

        let child = Tracee::stopped();
        let whole = child.xstate(1 << 16).len();
        let mut uml = child.xstate(UML_FP_BYTES);
        assert_eq!(uml.len(), UML_FP_BYTES.min(whole));
        let marker: [u8; 16] = *b"fes-uml-xstate!!";
        uml[XMM0..XMM0 + 16].copy_from_slice(&marker);
        if whole > UML_FP_BYTES {
            let refused = set(host, child.0, &mut uml.clone()).unwrap_err();
            assert_eq!(refused.raw_os_error(), Some(libc::EFAULT), "{refused}");
        }
        set(shim, child.0, &mut uml).expect("the shim's write");
        let back = child.xstate(UML_FP_BYTES);
        assert_eq!(&back[XMM0..XMM0 + 16], &marker, "xmm0 as written");
        assert_eq!(back, uml, "the whole of UML's part as written");
    }
}
