//! Which systemd unit a process belongs to: the last component of its cgroup v2 path
//! (`/proc/<pid>/cgroup`, line `0::/system.slice/fes-supervisor.service`).
//!
//! A process of the same user can publish on an iceoryx2 service once the real publisher
//! is gone, and iceoryx2 names the publisher's node, whose id carries its creator's pid;
//! it cannot move itself into another unit's cgroup (the unit's `cgroup.procs` is
//! root's). So "the publisher's process runs in unit X" is a check a squatter of the same
//! user cannot pass, where its name or executable it can copy.

use std::io;
use std::path::Path;

/// The cgroup v2 path of process `pid` (`0::<path>` of `/proc/<pid>/cgroup`).
pub fn cgroup_of(pid: u32) -> io::Result<String> {
    cgroup_in(&Path::new("/proc").join(pid.to_string()).join("cgroup"))
}

/// The cgroup v2 path in a `cgroup` file of procfs' format.
pub fn cgroup_in(file: &Path) -> io::Result<String> {
    let text = std::fs::read_to_string(file)?;
    text.lines()
        .find_map(|l| l.strip_prefix("0::"))
        .map(str::to_owned)
        .ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!("{}: no cgroup v2 line (0::)", file.display()),
            )
        })
}

/// Whether the cgroup path `cgroup` is the unit `unit`'s (its last component), e.g.
/// `/system.slice/fes-supervisor.service` for `fes-supervisor.service`.
pub fn cgroup_is_unit(cgroup: &str, unit: &str) -> bool {
    !unit.is_empty() && !unit.contains('/') && cgroup.rsplit('/').next() == Some(unit)
}

/// Whether process `pid` runs in systemd unit `unit` (false when its cgroup cannot be
/// read: a process that is gone, or another user's under `hidepid`).
pub fn runs_in_unit(pid: u32, unit: &str) -> bool {
    cgroup_of(pid).is_ok_and(|c| cgroup_is_unit(&c, unit))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_unit_is_the_last_component_of_the_cgroup_path() {
        let c = "/system.slice/fes-supervisor.service";
        assert!(cgroup_is_unit(c, "fes-supervisor.service"));
        assert!(!cgroup_is_unit(c, "supervisor.service"));
        assert!(!cgroup_is_unit(c, "system.slice/fes-supervisor.service"));
        assert!(!cgroup_is_unit(c, ""));
        assert!(!cgroup_is_unit(
            "/user.slice/user-1000.slice/session-3.scope",
            "fes-supervisor.service"
        ));
    }

    /// This process's own cgroup reads back, and it runs in the unit its cgroup names and
    /// in no other.
    #[test]
    fn a_process_runs_in_the_unit_its_cgroup_names() {
        let me = std::process::id();
        let c = cgroup_of(me).expect("/proc/self/cgroup");
        let own = c.rsplit('/').next().unwrap_or_default().to_owned();
        if !own.is_empty() {
            assert!(runs_in_unit(me, &own), "{c}");
        }
        assert!(!runs_in_unit(me, "fes-no-such-unit.service"));
        assert!(
            !runs_in_unit(u32::MAX, &own),
            "a process that does not exist"
        );
    }
}
