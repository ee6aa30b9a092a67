//! CAN interfaces of the host kernel: checks, creating `vcan0`, and the per-interface
//! lock that keeps two test processes from sharing a bus at the same time.

use std::fs::File;
use std::path::PathBuf;
use std::process::{Command, Stdio};

use super::HarnessError;

/// ARPHRD_CAN, the link type of CAN interfaces in /sys/class/net/*/type.
const ARPHRD_CAN: u32 = 280;
/// IFF_UP in /sys/class/net/*/flags.
const IFF_UP: u32 = 0x1;

fn sysfs(iface: &str, attr: &str) -> Option<String> {
    std::fs::read_to_string(format!("/sys/class/net/{iface}/{attr}"))
        .ok()
        .map(|s| s.trim().to_string())
}

fn parse_hex(s: &str) -> Option<u32> {
    u32::from_str_radix(s.trim_start_matches("0x"), 16).ok()
}

/// Why `iface` cannot be used for CAN tests, or `Ok` when it is an existing CAN
/// interface that is up.
pub(crate) fn usable(iface: &str) -> Result<(), String> {
    if iface.is_empty() || iface.contains('/') || iface.len() > 15 {
        return Err(format!("{iface:?} is not an interface name"));
    }
    let Some(ty) = sysfs(iface, "type") else {
        return Err(format!("interface {iface} does not exist"));
    };
    if ty.parse::<u32>().ok() != Some(ARPHRD_CAN) {
        return Err(format!(
            "interface {iface} is not a CAN interface (link type {ty}, CAN is {ARPHRD_CAN})"
        ));
    }
    let flags = sysfs(iface, "flags")
        .and_then(|f| parse_hex(&f))
        .unwrap_or(0);
    if flags & IFF_UP == 0 {
        return Err(format!(
            "interface {iface} is down (ip link set up {iface})"
        ));
    }
    Ok(())
}

fn run_quiet(program: &str, args: &[&str]) -> Result<(), String> {
    let out = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("{program}: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        let err = String::from_utf8_lossy(&out.stderr);
        Err(format!(
            "`{program} {}` failed: {}",
            args.join(" "),
            err.trim()
        ))
    }
}

/// Makes `vcan0` available on the host kernel if it can be (module `vcan`, root).
pub(crate) fn ensure_vcan0() -> Result<String, String> {
    const IFACE: &str = "vcan0";
    if usable(IFACE).is_ok() {
        return Ok(IFACE.to_string());
    }
    let mut why = Vec::new();
    if sysfs(IFACE, "type").is_none() {
        if let Err(e) = run_quiet("modprobe", &["vcan"]) {
            why.push(e);
        }
        if let Err(e) = run_quiet("ip", &["link", "add", "dev", IFACE, "type", "vcan"]) {
            why.push(e);
        }
    }
    if sysfs(IFACE, "type").is_some()
        && let Err(e) = run_quiet("ip", &["link", "set", "up", "dev", IFACE])
    {
        why.push(e);
    }
    match usable(IFACE) {
        Ok(()) => Ok(IFACE.to_string()),
        Err(e) => {
            why.push(e);
            Err(why.join("; "))
        }
    }
}

/// An exclusive lock on one CAN interface of this host, held while a test uses it.
pub(crate) struct IfaceLock {
    _file: File,
}

/// Takes the host-wide lock for `iface` (blocking; says so when it has to wait).
pub(crate) fn lock_iface(iface: &str) -> Result<IfaceLock, HarnessError> {
    let path = lock_path(&format!("fes-vcan-iface-{iface}.lock"));
    let file = lock_file(&path)?;
    Ok(IfaceLock { _file: file })
}

/// Where the harness keeps its lock files.
pub(crate) fn lock_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(name)
}

/// Opens `path` and takes an exclusive flock on it, waiting if another process holds it.
pub(crate) fn lock_file(path: &std::path::Path) -> Result<File, HarnessError> {
    let io = |source| HarnessError::Io {
        what: format!("lock file {}", path.display()),
        source,
    };
    let file = File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(path)
        .map_err(io)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            eprintln!(
                "vcan harness: waiting for {} (another CAN test is running)",
                path.display()
            );
            file.lock().map_err(io)?;
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(io(e)),
    }
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_is_not_a_can_interface() {
        let e = usable("lo").unwrap_err();
        assert!(e.contains("not a CAN interface"), "{e}");
        assert!(
            usable("no-such-if0")
                .unwrap_err()
                .contains("does not exist")
        );
        assert!(
            usable("../etc")
                .unwrap_err()
                .contains("not an interface name")
        );
    }

    #[test]
    fn the_lock_excludes_a_second_holder() {
        let path = lock_path(&format!("fes-vcan-selftest-{}.lock", std::process::id()));
        let a = lock_file(&path).unwrap();
        let b = File::options().write(true).open(&path).unwrap();
        assert!(matches!(
            b.try_lock(),
            Err(std::fs::TryLockError::WouldBlock)
        ));
        drop(a);
        assert!(b.try_lock().is_ok());
        let _ = std::fs::remove_file(&path);
    }
}
