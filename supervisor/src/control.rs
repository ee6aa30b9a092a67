//! The operator control socket: a Unix stream socket (default `/run/fes/supervisor.sock`,
//! mode 0660) speaking [`crate::protocol`], and the client the CLI uses.
//!
//! Access is checked twice: by the socket file's permissions, and on every connection by
//! the peer's credentials (`SO_PEERCRED`): the peer's uid must be the daemon's own, the
//! configured `user`, or root (when `allow_root`), or its primary or supplementary groups
//! must include the configured `group`. Others get one error line and are disconnected.
//!
//! The server thread only reads, parses and checks; commands are carried out by the
//! daemon's main loop (which owns the state), through a channel, and the response goes
//! back on the same connection. One connection is served at a time, each with a read
//! timeout, so a stalled client cannot hold the socket for long.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::fs::{DirBuilderExt, FileTypeExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use crate::config::ControlConfig;
use crate::protocol::{self, Command, MAX_LINE, ProtocolError, Request, Response, VERSION};

/// A control-socket failure.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// Another live daemon owns the socket.
    #[error("{path}: another supervisor is already listening there")]
    InUse {
        /// Socket path.
        path: PathBuf,
    },
    /// The path exists and is not a socket.
    #[error("{path}: exists and is not a socket; refusing to replace it")]
    NotASocket {
        /// Path.
        path: PathBuf,
    },
    /// A configured user or group does not exist.
    #[error("control.{key}: no such {key} `{name}`")]
    UnknownName {
        /// `user` or `group`.
        key: &'static str,
        /// The name.
        name: String,
    },
    /// An operating-system call failed.
    #[error("{op} {path}: {source}")]
    Io {
        /// What was being done.
        op: &'static str,
        /// Path.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
}

/// Who may connect.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PeerPolicy {
    /// The daemon's own uid (always allowed).
    pub own_uid: u32,
    /// A further allowed uid.
    pub uid: Option<u32>,
    /// An allowed group.
    pub gid: Option<u32>,
    /// Root allowed.
    pub allow_root: bool,
}

/// A peer's credentials.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Peer {
    /// Process id.
    pub pid: i32,
    /// User id.
    pub uid: u32,
    /// Primary group id.
    pub gid: u32,
    /// Supplementary groups (from `/proc/<pid>/status`; empty if unreadable).
    pub groups: Vec<u32>,
}

impl PeerPolicy {
    /// Resolves the configured names.
    pub fn from_config(cfg: &ControlConfig) -> Result<Self, ControlError> {
        let uid = match &cfg.user {
            Some(name) => Some(
                nix::unistd::User::from_name(name)
                    .ok()
                    .flatten()
                    .ok_or_else(|| ControlError::UnknownName {
                        key: "user",
                        name: name.clone(),
                    })?
                    .uid
                    .as_raw(),
            ),
            None => None,
        };
        let gid = match &cfg.group {
            Some(name) => Some(
                nix::unistd::Group::from_name(name)
                    .ok()
                    .flatten()
                    .ok_or_else(|| ControlError::UnknownName {
                        key: "group",
                        name: name.clone(),
                    })?
                    .gid
                    .as_raw(),
            ),
            None => None,
        };
        Ok(Self {
            own_uid: nix::unistd::geteuid().as_raw(),
            uid,
            gid,
            allow_root: cfg.allow_root,
        })
    }

    /// Whether `peer` may use the socket; the error says why not.
    pub fn check(&self, peer: &Peer) -> Result<(), String> {
        let ok = peer.uid == self.own_uid
            || (peer.uid == 0 && self.allow_root)
            || self.uid == Some(peer.uid)
            || self
                .gid
                .is_some_and(|g| peer.gid == g || peer.groups.contains(&g));
        if ok {
            Ok(())
        } else {
            Err(format!(
                "permission denied: uid {} (gid {}) is not allowed on this socket (see [control] user/group in the supervisor's configuration)",
                peer.uid, peer.gid
            ))
        }
    }
}

/// Supplementary groups of `pid` from `/proc/<pid>/status`.
fn supplementary_groups(pid: i32) -> Vec<u32> {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines().find_map(|l| l.strip_prefix("Groups:")).map(|g| {
                g.split_whitespace()
                    .filter_map(|x| x.parse().ok())
                    .collect()
            })
        })
        .unwrap_or_default()
}

/// The credentials of the process at the other end of `stream`.
pub fn peer_of(stream: &UnixStream) -> std::io::Result<Peer> {
    let c = nix::sys::socket::getsockopt(stream, nix::sys::socket::sockopt::PeerCredentials)
        .map_err(std::io::Error::from)?;
    Ok(Peer {
        pid: c.pid(),
        uid: c.uid(),
        gid: c.gid(),
        groups: supplementary_groups(c.pid()),
    })
}

/// A request waiting for the main loop, with the way back.
pub struct Pending {
    /// The parsed request.
    pub request: Request,
    /// The client.
    pub peer: Peer,
    /// Where the response goes.
    pub reply: mpsc::SyncSender<Response>,
}

/// The listening socket and its thread.
pub struct ControlServer {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// How long a client may take to send its request.
pub const CLIENT_READ_TIMEOUT: Duration = Duration::from_secs(2);
/// How long the server waits for the main loop's answer.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

impl ControlServer {
    /// Binds the socket (removing a stale one), sets its mode and group, and starts the
    /// thread that feeds `requests`.
    pub fn start(
        cfg: &ControlConfig,
        requests: mpsc::Sender<Pending>,
    ) -> Result<Self, ControlError> {
        let policy = PeerPolicy::from_config(cfg)?;
        Self::start_with_policy(cfg, policy, requests)
    }

    /// [`ControlServer::start`] with an explicit peer policy (tests use one that excludes
    /// the test's own user).
    pub fn start_with_policy(
        cfg: &ControlConfig,
        policy: PeerPolicy,
        requests: mpsc::Sender<Pending>,
    ) -> Result<Self, ControlError> {
        let path = cfg.socket.clone();
        let io = |op: &'static str, p: &Path| {
            let path = p.to_path_buf();
            move |source| ControlError::Io { op, path, source }
        };
        if let Some(parent) = path.parent()
            && !parent.as_os_str().is_empty()
            && !parent.exists()
        {
            std::fs::DirBuilder::new()
                .recursive(true)
                .mode(0o750)
                .create(parent)
                .map_err(io("create directory", parent))?;
        }
        match std::fs::symlink_metadata(&path) {
            Ok(meta) if meta.file_type().is_socket() => {
                if UnixStream::connect(&path).is_ok() {
                    return Err(ControlError::InUse { path });
                }
                std::fs::remove_file(&path).map_err(io("remove stale socket", &path))?;
            }
            Ok(_) => return Err(ControlError::NotASocket { path }),
            Err(_) => {}
        }
        let listener = UnixListener::bind(&path).map_err(io("bind", &path))?;
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(cfg.mode))
            .map_err(io("chmod", &path))?;
        if let Some(gid) = policy.gid {
            nix::unistd::chown(&path, None, Some(nix::unistd::Gid::from_raw(gid))).map_err(
                |e| ControlError::Io {
                    op: "chgrp",
                    path: path.clone(),
                    source: e.into(),
                },
            )?;
        }
        listener
            .set_nonblocking(true)
            .map_err(io("configure", &path))?;
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("control".into())
            .spawn(move || serve(listener, policy, requests, stop2))
            .map_err(io("start thread for", &cfg.socket))?;
        Ok(Self {
            path,
            stop,
            thread: Some(thread),
        })
    }

    /// The socket path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for ControlServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.path);
    }
}

fn serve(
    listener: UnixListener,
    policy: PeerPolicy,
    requests: mpsc::Sender<Pending>,
    stop: Arc<AtomicBool>,
) {
    while !stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                let _ = handle(stream, &policy, &requests);
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(100)),
        }
    }
}

fn handle(
    stream: UnixStream,
    policy: &PeerPolicy,
    requests: &mpsc::Sender<Pending>,
) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_read_timeout(Some(CLIENT_READ_TIMEOUT))?;
    stream.set_write_timeout(Some(CLIENT_READ_TIMEOUT))?;
    let mut writer = stream.try_clone()?;
    let mut send = |r: Response| -> std::io::Result<()> {
        writer.write_all(r.to_line().as_bytes())?;
        writer.write_all(b"\n")?;
        writer.flush()
    };
    let peer = peer_of(&stream)?;
    // The request is read (bounded) before a refusal too: refusing and closing first raced
    // the client's write, which then failed with EPIPE and never showed why it was refused.
    let mut reader = BufReader::new(stream.take(MAX_LINE as u64 + 2));
    let mut line = Vec::new();
    let read = reader.read_until(b'\n', &mut line);
    if let Err(e) = policy.check(&peer) {
        return send(Response::error(0, e));
    }
    read?;
    if line.last() == Some(&b'\n') {
        line.pop();
    } else if line.len() > MAX_LINE {
        return send(Response::error(0, ProtocolError::TooLong.to_string()));
    }
    let request = match protocol::parse_request(&line) {
        Ok(r) => r,
        Err(e) => return send(Response::error(0, e.to_string())),
    };
    let id = request.id;
    let (tx, rx) = mpsc::sync_channel(1);
    if requests
        .send(Pending {
            request,
            peer,
            reply: tx,
        })
        .is_err()
    {
        return send(Response::error(id, "the supervisor is shutting down"));
    }
    match rx.recv_timeout(ANSWER_TIMEOUT) {
        Ok(resp) => send(resp),
        Err(_) => send(Response::error(id, "the supervisor did not answer in time")),
    }
}

/// A client failure.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// No daemon at the socket.
    #[error("cannot connect to {path}: {source}{hint}")]
    Connect {
        /// Socket.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
        /// What to check.
        hint: &'static str,
    },
    /// The exchange failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
    /// The daemon's answer could not be read.
    #[error("unreadable answer from the supervisor: {0}")]
    Protocol(#[from] ProtocolError),
}

/// Sends `command` to the daemon at `socket` and returns its response.
pub fn request(
    socket: &Path,
    command: Command,
    timeout: Duration,
) -> Result<Response, ClientError> {
    let stream = UnixStream::connect(socket).map_err(|source| {
        let hint = match source.kind() {
            std::io::ErrorKind::NotFound | std::io::ErrorKind::ConnectionRefused => {
                " (is `supervisor run` running? is --socket right?)"
            }
            std::io::ErrorKind::PermissionDenied => {
                " (your user needs to be in the socket's group, or use sudo)"
            }
            _ => "",
        };
        ClientError::Connect {
            path: socket.to_path_buf(),
            source,
            hint,
        }
    })?;
    stream.set_read_timeout(Some(timeout))?;
    stream.set_write_timeout(Some(timeout))?;
    let req = Request {
        v: VERSION,
        id: u64::from(std::process::id()),
        command,
    };
    let mut w = stream.try_clone()?;
    let line = serde_json::to_string(&req).map_err(|e| ProtocolError::Malformed(e.to_string()))?;
    w.write_all(line.as_bytes())?;
    w.write_all(b"\n")?;
    w.flush()?;
    let mut reader = BufReader::new(stream.take(16 * MAX_LINE as u64));
    let mut resp = Vec::new();
    reader.read_until(b'\n', &mut resp)?;
    if resp.is_empty() {
        return Err(ClientError::Io(std::io::Error::new(
            std::io::ErrorKind::UnexpectedEof,
            "the supervisor closed the connection without answering",
        )));
    }
    Ok(protocol::parse_response(&resp)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policy_admits_owner_root_user_and_group_members_only() {
        let p = PeerPolicy {
            own_uid: 500,
            uid: Some(600),
            gid: Some(700),
            allow_root: false,
        };
        let peer = |uid, gid, groups: Vec<u32>| Peer {
            pid: 1,
            uid,
            gid,
            groups,
        };
        assert!(p.check(&peer(500, 1, vec![])).is_ok());
        assert!(p.check(&peer(600, 1, vec![])).is_ok());
        assert!(p.check(&peer(1000, 700, vec![])).is_ok());
        assert!(p.check(&peer(1000, 1000, vec![4, 700])).is_ok());
        let e = p.check(&peer(1000, 1000, vec![4])).unwrap_err();
        assert!(
            e.starts_with("permission denied: uid 1000 (gid 1000)"),
            "{e}"
        );
        assert!(p.check(&peer(0, 0, vec![])).is_err());
        let p = PeerPolicy {
            allow_root: true,
            ..p
        };
        assert!(p.check(&peer(0, 0, vec![])).is_ok());
    }
}
