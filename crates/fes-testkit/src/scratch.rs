//! Scratch directories.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A fresh, empty directory for one test: removed on drop when the test passed; kept, and
/// its path printed, when the test is panicking or `FES_TEST_KEEP` is set in the
/// environment.
///
/// Made with `mkdir(2)`, which fails on an existing name, so two scratch directories never
/// share one. Not the `tempfile` crate: through rustix it turned on `bitflags/std` and
/// more `linux-raw-sys` features, so every release tool built with this crate in the
/// graph (`scripts/latency-regression`) recompiled nix, iceoryx2 and their dependents
/// apart from the shipped binaries' build (docs/architecture.md, "Tests").
#[derive(Debug)]
pub struct Scratch {
    path: PathBuf,
}

/// Distinguishes the directories one process makes.
static NEXT: AtomicU64 = AtomicU64::new(0);

impl Scratch {
    /// A new directory `fes-<tag>-<pid>-<n>-<t>` under the system's temporary directory.
    ///
    /// # Panics
    /// When the directory cannot be made (a test cannot go on without it).
    pub fn new(tag: &str) -> Self {
        Self::new_in(&std::env::temp_dir(), tag)
    }

    /// A new directory `fes-<tag>-<pid>-<n>-<t>` under `base` (created if missing): tests that
    /// run a User-Mode Linux guest use the target directory, since the guest has its own
    /// `/tmp`.
    ///
    /// # Panics
    /// When the directory cannot be made.
    pub fn new_in(base: &Path, tag: &str) -> Self {
        if let Err(e) = std::fs::create_dir_all(base) {
            panic!("scratch base {}: {e}", base.display());
        }
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        loop {
            let n = NEXT.fetch_add(1, Ordering::Relaxed);
            let path = base.join(format!("fes-{tag}-{}-{n}-{nanos:x}", std::process::id()));
            match std::fs::create_dir(&path) {
                Ok(()) => return Self { path },
                // A directory left by an earlier process with the same pid: take the next.
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => panic!("scratch directory in {}: {e}", base.display()),
            }
        }
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// `name` inside the directory.
    pub fn join(&self, name: impl AsRef<Path>) -> PathBuf {
        self.path.join(name)
    }
}

/// A scratch directory is used where a path is: `&scratch` is a `&Path`.
impl std::ops::Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let keep = std::thread::panicking() || std::env::var_os("FES_TEST_KEEP").is_some();
        if keep {
            eprintln!("kept scratch directory {}", self.path.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removed_after_a_passing_test_and_unique() {
        let a = Scratch::new("unit");
        let b = Scratch::new("unit");
        assert_ne!(a.path(), b.path());
        assert!(a.path().is_dir());
        std::fs::write(a.join("f"), b"x").unwrap_or_else(|e| panic!("{e}"));
        let p = a.path().to_path_buf();
        drop(a);
        assert!(!p.exists());
    }

    #[test]
    fn kept_when_the_test_panics() {
        let path = std::thread::spawn(|| {
            let s = Scratch::new("unit-panic");
            let p = s.path().to_path_buf();
            std::panic::panic_any(p);
        })
        .join()
        .err()
        .and_then(|e| e.downcast::<PathBuf>().ok())
        .map(|p| *p);
        let Some(path) = path else {
            panic!("the thread did not panic with its path")
        };
        assert!(path.is_dir(), "{} was removed", path.display());
        let _ = std::fs::remove_dir_all(&path);
    }
}
