//! What the latency tests share: the workspace's directories and scratch directories.

use std::path::{Path, PathBuf};

/// The workspace root (two levels above this package's directory).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .expect("fes-latency lives in crates/ of the workspace")
        .to_path_buf()
}

/// The cargo target directory the tests were built in.
pub fn target_dir() -> PathBuf {
    fes_testkit::target_dir(&workspace_root())
}

/// A scratch directory inside the target directory, from the testkit: removed when the
/// test passes, kept when it fails or `FES_TEST_KEEP` is set.
pub fn scratch(tag: &str) -> fes_testkit::Scratch {
    fes_testkit::Scratch::new_in(&target_dir().join("test-scratch"), tag)
}
