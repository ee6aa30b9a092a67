//! The iceoryx2 node of a real-time process and the failures of its real-time thread,
//! shared by rt-core's loop and stim-driver's forward path.

use iceoryx2::node::NodeCreationFailure;
use iceoryx2::port::update_connections::ConnectionFailure;
use iceoryx2::prelude::*;

use super::clock::PeriodError;
use super::hlog::HlogError;
use super::realtime::RtError;
use crate::msg::port::PortError;
use crate::msg::service::ServiceError;

/// Failure of the real-time loop thread before or while it runs.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Real time could not be entered (refused, or invalid settings).
    #[error("refused to start: {0}")]
    Realtime(#[from] RtError),
    /// A service could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// A port could not be created.
    #[error(transparent)]
    Port(#[from] PortError),
    /// A port could not connect to its peers.
    #[error("cannot connect the {port}: {source}")]
    Connect {
        /// Which port.
        port: &'static str,
        /// iceoryx2's reason.
        #[source]
        source: ConnectionFailure,
    },
    /// The period is invalid.
    #[error(transparent)]
    Period(#[from] PeriodError),
    /// The name is not a valid iceoryx2 node name.
    #[error("cannot create the iceoryx2 node: invalid node name {name:?}: {source}")]
    NodeName {
        /// The name asked for.
        name: String,
        /// iceoryx2's reason.
        #[source]
        source: SemanticStringError,
    },
    /// The iceoryx2 node could not be created.
    #[error("cannot create the iceoryx2 node: {0}")]
    Node(#[source] NodeCreationFailure),
    /// The process's configuration is not usable by the real-time thread (the
    /// process's own configuration error, kept as the source).
    #[error("configuration: {0}")]
    Config(#[source] Box<dyn std::error::Error + Send + Sync>),
    /// iceoryx2's root directory is not this user's alone to write: another user could
    /// replace its services' bookkeeping.
    #[error(
        "iceoryx2's root {}: {problem}; refusing to use it (it must be a directory of this \
         user, uid {uid}, that nobody else may write: systemd-tmpfiles makes it on a rig)",
        path.display()
    )]
    IpcRoot {
        /// The directory.
        path: std::path::PathBuf,
        /// What is wrong with it.
        problem: String,
        /// This process's effective uid.
        uid: u32,
    },
    /// iceoryx2's root directory could not be made or examined.
    #[error(
        "iceoryx2's root {}: {what}: {source}; refusing to use it (it must be a directory of \
         this user, uid {uid}, that nobody else may write: systemd-tmpfiles makes it on a rig)",
        path.display()
    )]
    IpcRootIo {
        /// The directory.
        path: std::path::PathBuf,
        /// What was being done.
        what: &'static str,
        /// The OS error.
        #[source]
        source: std::io::Error,
        /// This process's effective uid.
        uid: u32,
    },
    /// The interval log could not be written.
    #[error(transparent)]
    Hlog(#[from] HlogError),
}

/// A map from an iceoryx2 connection error to [`RunError::Connect`] naming the port.
pub fn connect_err(port: &'static str) -> impl Fn(ConnectionFailure) -> RunError {
    move |source| RunError::Connect { port, source }
}

/// Creates an iceoryx2 node named `name` with iceoryx2's own signal handling disabled (the
/// process installs [`super::signals::install_stop_handler`]).
pub fn create_node(name: &str) -> Result<Node<ipc::Service>, RunError> {
    let node_name = NodeName::new(name).map_err(|source| RunError::NodeName {
        name: name.to_owned(),
        source,
    })?;
    // An explicit default configuration: iceoryx2's defaults, without its warning that no
    // global configuration file was found.
    let config = iceoryx2::config::Config::default();
    let root = std::path::PathBuf::from(config.global.root_path().to_string());
    check_ipc_root(&root, nix::unistd::geteuid().as_raw())?;
    NodeBuilder::new()
        .config(&config)
        .name(&node_name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(RunError::Node)
}

/// Checks iceoryx2's root directory (its node and service bookkeeping, `/tmp/iceoryx2` by
/// default, made by systemd-tmpfiles on a rig): it must be a real directory (not a
/// symbolic link) owned by `uid` and writable by nobody else, and so must its `nodes` and
/// `services` directories where they exist. A missing root is made here, mode 0700, before
/// iceoryx2 would make it with its own mode. In the world-writable `/tmp`, a root another
/// user made first (or a link to one) would let that user replace the services' static
/// configuration, or remove a node's bookkeeping, under the stack.
pub fn check_ipc_root(root: &std::path::Path, uid: u32) -> Result<(), RunError> {
    use std::os::unix::fs::{DirBuilderExt as _, MetadataExt as _};
    let refuse = |path: &std::path::Path, problem: String| RunError::IpcRoot {
        path: path.to_path_buf(),
        problem,
        uid,
    };
    if std::fs::symlink_metadata(root).is_err() {
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(root)
            .map_err(|source| RunError::IpcRootIo {
                path: root.to_path_buf(),
                what: "cannot be made",
                source,
                uid,
            })?;
    }
    for path in [
        root.to_path_buf(),
        root.join("nodes"),
        root.join("services"),
    ] {
        let meta = match std::fs::symlink_metadata(&path) {
            Ok(m) => m,
            Err(_) if path != root => continue,
            Err(source) => {
                return Err(RunError::IpcRootIo {
                    path,
                    what: "cannot be examined",
                    source,
                    uid,
                });
            }
        };
        if !meta.file_type().is_dir() {
            return Err(refuse(&path, "not a directory (a link, or a file)".into()));
        }
        if meta.uid() != uid {
            return Err(refuse(&path, format!("owned by uid {}", meta.uid())));
        }
        if meta.mode() & 0o022 != 0 {
            return Err(refuse(
                &path,
                format!("mode {:o}: others may write it", meta.mode() & 0o7777),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt as _;

    fn is_refused(r: Result<(), RunError>, what: &str) -> String {
        match r {
            Err(e @ RunError::IpcRoot { .. }) => e.to_string(),
            other => panic!("{what}: {other:?}"),
        }
    }

    /// A missing root is made private; this user's root passes; a root others may write,
    /// a link in its place or a file is refused by name.
    #[test]
    fn the_ipc_root_must_be_this_users_alone() {
        let scratch = fes_testkit::Scratch::new("ipc-root");
        let uid = nix::unistd::geteuid().as_raw();
        let root = scratch.path().join("iceoryx2");
        check_ipc_root(&root, uid).unwrap();
        let mode = std::fs::metadata(&root).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o700, "made private");
        std::fs::create_dir(root.join("nodes")).unwrap();
        std::fs::set_permissions(&root, std::fs::Permissions::from_mode(0o755)).unwrap();
        check_ipc_root(&root, uid).unwrap();
        std::fs::set_permissions(root.join("nodes"), std::fs::Permissions::from_mode(0o777))
            .unwrap();
        let e = is_refused(
            check_ipc_root(&root, uid),
            "a world-writable nodes directory",
        );
        assert!(e.contains("nodes") && e.contains("mode 777"), "{e}");
        std::fs::set_permissions(root.join("nodes"), std::fs::Permissions::from_mode(0o750))
            .unwrap();
        check_ipc_root(&root, uid).unwrap();
        let e = is_refused(check_ipc_root(&root, uid.wrapping_add(1)), "another owner");
        assert!(e.contains(&format!("owned by uid {uid}")), "{e}");
        let link = scratch.path().join("link");
        std::os::unix::fs::symlink(&root, &link).unwrap();
        let e = is_refused(check_ipc_root(&link, uid), "a link");
        assert!(e.contains("not a directory"), "{e}");
        let file = scratch.path().join("file");
        std::fs::write(&file, b"").unwrap();
        is_refused(check_ipc_root(&file, uid), "a file");
    }
}
