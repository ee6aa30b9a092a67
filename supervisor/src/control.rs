//! The operator control socket: a Unix stream socket (default `/run/fes/supervisor.sock`,
//! mode 0660) speaking [`crate::protocol`], and the client the CLI uses.
//!
//! Access is checked twice: by the socket file's permissions, and on every connection by
//! the peer's credentials (`SO_PEERCRED`): the peer's uid must be the daemon's own, the
//! configured `user`, or root (when `allow_root`), or its primary or supplementary groups
//! (`SO_PEERGROUPS`: as the kernel recorded them at connect, not read from /proc by a pid
//! that may be reused) must include the configured `group`. Others get one error line and
//! are disconnected.
//!
//! The server only reads, parses and checks; commands are carried out by the daemon's main
//! loop (which owns the state), through a channel, and the response goes back on the same
//! connection. Nothing a client does can hold up another client or the operator's stop:
//!
//! - every connection is served by a thread of its own (at most [`MAX_CLIENTS`] at once;
//!   beyond that a connection is told "busy" and closed at once);
//! - the peer's credentials are checked **before** anything is read: a peer the policy does
//!   not admit gets its one error line and is disconnected unread;
//! - a request must arrive whole within [`CLIENT_DEADLINE`] in total (not per read), at most
//!   [`MAX_LINE`] bytes;
//! - **the stop socket** ([`stop_socket_path`], `supervisor-stop.sock` beside the control
//!   socket, same mode and policy): connecting to it *is* the stop command. The server
//!   reads nothing from it, checks the peer, hands `stop` to the main loop and answers;
//!   `supervisor stop` uses it. With `stop_group` configured it also admits that group's
//!   members, and is owned by it, where the control socket (arm, set, profile) does not:
//!   who may stop need not be who may arm.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::fs::{DirBuilderExt, FileTypeExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

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

/// A peer the [`PeerPolicy`] does not admit: its uid and primary gid, in the one line it
/// is answered before it is disconnected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "permission denied: uid {uid} (gid {gid}) is not allowed on this socket (see [control] user/group in the supervisor's configuration)"
)]
pub struct PermissionDenied {
    /// The peer's user id.
    pub uid: u32,
    /// The peer's primary group id.
    pub gid: u32,
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
    /// A group allowed on the stop socket only.
    pub stop_gid: Option<u32>,
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
    /// Supplementary groups, as the kernel recorded them when the peer connected
    /// (`SO_PEERGROUPS`).
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
        let group = |key: &'static str, name: &Option<String>| match name {
            Some(name) => nix::unistd::Group::from_name(name)
                .ok()
                .flatten()
                .map(|g| Some(g.gid.as_raw()))
                .ok_or_else(|| ControlError::UnknownName {
                    key,
                    name: name.clone(),
                }),
            None => Ok(None),
        };
        Ok(Self {
            own_uid: nix::unistd::geteuid().as_raw(),
            uid,
            gid: group("group", &cfg.group)?,
            stop_gid: group("stop_group", &cfg.stop_group)?,
            allow_root: cfg.allow_root,
        })
    }

    /// Whether `peer` may use the stop socket: as [`Self::check`], or a member of the
    /// stop-only group.
    pub fn check_stop(&self, peer: &Peer) -> Result<(), PermissionDenied> {
        let in_stop_group = self
            .stop_gid
            .is_some_and(|g| peer.gid == g || peer.groups.contains(&g));
        if in_stop_group {
            Ok(())
        } else {
            self.check(peer)
        }
    }

    /// Whether `peer` may use the socket; the error says why not.
    pub fn check(&self, peer: &Peer) -> Result<(), PermissionDenied> {
        let ok = peer.uid == self.own_uid
            || (peer.uid == 0 && self.allow_root)
            || self.uid == Some(peer.uid)
            || self
                .gid
                .is_some_and(|g| peer.gid == g || peer.groups.contains(&g));
        if ok {
            Ok(())
        } else {
            Err(PermissionDenied {
                uid: peer.uid,
                gid: peer.gid,
            })
        }
    }
}

/// Supplementary groups of the peer of `stream`, as the kernel recorded them when it
/// connected (`SO_PEERGROUPS`, Linux 4.13). Reading `/proc/<pid>/status` after the accept
/// instead asked about whatever process has that pid by then: a peer that exits after
/// connecting leaves its pid to be reused, and an admitted group could be read from
/// another process.
fn peer_groups(stream: &UnixStream) -> std::io::Result<Vec<u32>> {
    use std::os::fd::AsRawFd as _;
    let mut groups: Vec<libc::gid_t> = vec![0; 64];
    loop {
        let mut len = libc::socklen_t::try_from(groups.len() * size_of::<libc::gid_t>())
            .map_err(|_| std::io::Error::from_raw_os_error(libc::ERANGE))?;
        // SAFETY: `groups` holds `len` bytes, which the kernel fills with at most that
        // many, and writes the length it needs or used to `len`.
        let r = unsafe {
            libc::getsockopt(
                stream.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_PEERGROUPS,
                groups.as_mut_ptr().cast(),
                &raw mut len,
            )
        };
        let count = len as usize / size_of::<libc::gid_t>();
        if r == 0 {
            groups.truncate(count);
            return Ok(groups);
        }
        let e = std::io::Error::last_os_error();
        if e.raw_os_error() == Some(libc::ERANGE) && count > groups.len() {
            groups.resize(count, 0);
            continue;
        }
        return Err(e);
    }
}

/// How the server learns a connection's credentials ([`peer_of`] outside tests).
pub type PeerReader = fn(&UnixStream) -> std::io::Result<Peer>;

/// The credentials of the process at the other end of `stream`.
pub fn peer_of(stream: &UnixStream) -> std::io::Result<Peer> {
    let c = nix::sys::socket::getsockopt(stream, nix::sys::socket::sockopt::PeerCredentials)
        .map_err(std::io::Error::from)?;
    Ok(Peer {
        pid: c.pid(),
        uid: c.uid(),
        gid: c.gid(),
        groups: peer_groups(stream)?,
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

/// The stop socket that goes with the control socket at `socket`:
/// `<dir>/<stem>-stop.sock` (`/run/fes/supervisor-stop.sock` for the default).
pub fn stop_socket_path(socket: &Path) -> PathBuf {
    let stem = socket
        .file_stem()
        .map_or_else(|| "supervisor".into(), |s| s.to_string_lossy().into_owned());
    socket.with_file_name(format!("{stem}-stop.sock"))
}

/// The listening sockets (control and stop) and their threads.
pub struct ControlServer {
    path: PathBuf,
    stop_path: PathBuf,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

/// How long a client may take to send its whole request.
pub const CLIENT_DEADLINE: Duration = Duration::from_secs(1);
/// Connections served at once on the control socket; more are refused as busy.
pub const MAX_CLIENTS: usize = 32;
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
        Self::start_with_peer_reader(cfg, policy, peer_of, requests)
    }

    /// [`ControlServer::start_with_policy`] reading each peer's credentials with `peers`
    /// instead of [`peer_of`]. For tests only: an unprivileged test cannot connect as
    /// another user, so it marks some of its own connections as a foreign uid to prove
    /// the refusal path (checked before anything is read) without root.
    pub fn start_with_peer_reader(
        cfg: &ControlConfig,
        policy: PeerPolicy,
        peers: PeerReader,
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
        let listener = bind(&path, cfg.mode, policy.gid)?;
        let stop_path = stop_socket_path(&path);
        let stop_listener = bind(&stop_path, cfg.mode, policy.stop_gid.or(policy.gid))?;
        let stop = Arc::new(AtomicBool::new(false));
        let policy = Arc::new(policy);
        let spawn = |name: &str, f: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name.into())
                .spawn(f)
                .map_err(io("start thread for", &cfg.socket))
        };
        let control = {
            let (policy, requests, stop) =
                (Arc::clone(&policy), requests.clone(), Arc::clone(&stop));
            spawn(
                "control",
                Box::new(move || serve(listener, policy, peers, requests, stop)),
            )?
        };
        let stopper = {
            let stop = Arc::clone(&stop);
            spawn(
                "control-stop",
                Box::new(move || serve_stop(stop_listener, policy, peers, requests, stop)),
            )?
        };
        Ok(Self {
            path,
            stop_path,
            stop,
            threads: vec![control, stopper],
        })
    }

    /// The socket path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The stop socket's path.
    pub fn stop_path(&self) -> &Path {
        &self.stop_path
    }
}

impl Drop for ControlServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
        let _ = std::fs::remove_file(&self.path);
        let _ = std::fs::remove_file(&self.stop_path);
    }
}

/// Binds a listening socket at `path` (removing a stale one; refusing a live one or a
/// non-socket), with `mode` and, if given, group `gid`; non-blocking.
fn bind(path: &Path, mode: u32, gid: Option<u32>) -> Result<UnixListener, ControlError> {
    let io = |op: &'static str| {
        let path = path.to_path_buf();
        move |source| ControlError::Io { op, path, source }
    };
    match std::fs::symlink_metadata(path) {
        Ok(meta) if meta.file_type().is_socket() => {
            if UnixStream::connect(path).is_ok() {
                return Err(ControlError::InUse {
                    path: path.to_path_buf(),
                });
            }
            std::fs::remove_file(path).map_err(io("remove stale socket"))?;
        }
        Ok(_) => {
            return Err(ControlError::NotASocket {
                path: path.to_path_buf(),
            });
        }
        Err(_) => {}
    }
    let listener = UnixListener::bind(path).map_err(io("bind"))?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).map_err(io("chmod"))?;
    if let Some(gid) = gid {
        nix::unistd::chown(path, None, Some(nix::unistd::Gid::from_raw(gid))).map_err(|e| {
            ControlError::Io {
                op: "chgrp",
                path: path.to_path_buf(),
                source: e.into(),
            }
        })?;
    }
    listener.set_nonblocking(true).map_err(io("configure"))?;
    Ok(listener)
}

/// Accepts on `listener` until `stop`, calling `each` with every new connection.
fn accept_loop(listener: &UnixListener, stop: &AtomicBool, mut each: impl FnMut(UnixStream)) {
    while !stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => each(stream),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// Writes one response line.
fn send(stream: &mut UnixStream, r: &Response) -> std::io::Result<()> {
    stream.write_all(r.to_line().as_bytes())?;
    stream.write_all(b"\n")?;
    stream.flush()
}

fn serve(
    listener: UnixListener,
    policy: Arc<PeerPolicy>,
    peers: PeerReader,
    requests: mpsc::Sender<Pending>,
    stop: Arc<AtomicBool>,
) {
    let active = Arc::new(AtomicUsize::new(0));
    accept_loop(&listener, &stop, |mut stream| {
        if active.fetch_add(1, Ordering::AcqRel) >= MAX_CLIENTS {
            active.fetch_sub(1, Ordering::AcqRel);
            let _ = stream.set_write_timeout(Some(CLIENT_DEADLINE));
            let _ = send(
                &mut stream,
                &Response::error(0, "busy: too many control connections; try again"),
            );
            return;
        }
        let (policy, requests, done) = (Arc::clone(&policy), requests.clone(), Arc::clone(&active));
        let spawned = std::thread::Builder::new()
            .name("control-client".into())
            .spawn(move || {
                let _ = handle(stream, &policy, peers, &requests);
                done.fetch_sub(1, Ordering::AcqRel);
            });
        if spawned.is_err() {
            active.fetch_sub(1, Ordering::AcqRel);
        }
    });
}

/// The stop socket: every admitted connection is a stop, nothing is read.
fn serve_stop(
    listener: UnixListener,
    policy: Arc<PeerPolicy>,
    peers: PeerReader,
    requests: mpsc::Sender<Pending>,
    stop: Arc<AtomicBool>,
) {
    accept_loop(&listener, &stop, |mut stream| {
        let _ = stream.set_nonblocking(false);
        let _ = stream.set_write_timeout(Some(CLIENT_DEADLINE));
        let Ok(peer) = peers(&stream) else {
            return;
        };
        if let Err(e) = policy.check_stop(&peer) {
            let _ = send(&mut stream, &Response::error(0, e.to_string()));
            return;
        }
        let request = Request {
            v: VERSION,
            id: 0,
            command: Command::Stop,
        };
        let _ = answer(&mut stream, request, peer, &requests);
    });
}

/// Hands `request` to the main loop and writes its answer.
fn answer(
    stream: &mut UnixStream,
    request: Request,
    peer: Peer,
    requests: &mpsc::Sender<Pending>,
) -> std::io::Result<()> {
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
        return send(
            stream,
            &Response::error(id, "the supervisor is shutting down"),
        );
    }
    match rx.recv_timeout(ANSWER_TIMEOUT) {
        Ok(resp) => send(stream, &resp),
        Err(_) => send(
            stream,
            &Response::error(id, "the supervisor did not answer in time"),
        ),
    }
}

/// Reads one request line of at most [`MAX_LINE`] bytes within `deadline` in total.
/// `Ok(None)`: the line is too long.
fn read_line(stream: &mut UnixStream, deadline: Instant) -> std::io::Result<Option<Vec<u8>>> {
    let mut line = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "the request did not arrive in time",
            ));
        }
        stream.set_read_timeout(Some(left))?;
        let n = stream.read(&mut buf)?;
        if n == 0 {
            return Ok(Some(line));
        }
        line.extend_from_slice(&buf[..n]);
        if let Some(i) = line.iter().position(|&b| b == b'\n') {
            line.truncate(i);
            return Ok(Some(line));
        }
        if line.len() > MAX_LINE {
            return Ok(None);
        }
    }
}

fn handle(
    mut stream: UnixStream,
    policy: &PeerPolicy,
    peers: PeerReader,
    requests: &mpsc::Sender<Pending>,
) -> std::io::Result<()> {
    let deadline = Instant::now() + CLIENT_DEADLINE;
    stream.set_nonblocking(false)?;
    stream.set_write_timeout(Some(CLIENT_DEADLINE))?;
    let peer = peers(&stream)?;
    // The policy first: a peer it does not admit is answered and disconnected unread (the
    // client reads the answer even when its own write fails, `request`).
    if let Err(e) = policy.check(&peer) {
        return send(&mut stream, &Response::error(0, e.to_string()));
    }
    let line = match read_line(&mut stream, deadline) {
        Ok(Some(line)) => line,
        Ok(None) => {
            return send(
                &mut stream,
                &Response::error(0, ProtocolError::TooLong.to_string()),
            );
        }
        Err(e)
            if e.kind() == std::io::ErrorKind::TimedOut
                || e.kind() == std::io::ErrorKind::WouldBlock =>
        {
            return send(
                &mut stream,
                &Response::error(
                    0,
                    format!(
                        "the request did not arrive within {} ms",
                        CLIENT_DEADLINE.as_millis()
                    ),
                ),
            );
        }
        Err(e) => return Err(e),
    };
    let request = match protocol::parse_request(&line) {
        Ok(r) => r,
        Err(e) => return send(&mut stream, &Response::error(0, e.to_string())),
    };
    answer(&mut stream, request, peer, requests)
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

/// Connects to `socket`, with an error that says what to check.
fn connect(socket: &Path) -> Result<UnixStream, ClientError> {
    UnixStream::connect(socket).map_err(|source| {
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
    })
}

/// Reads the daemon's one response line.
fn read_response(stream: UnixStream) -> Result<Response, ClientError> {
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

/// Sends `command` to the daemon at `socket` and returns its response.
pub fn request(
    socket: &Path,
    command: Command,
    timeout: Duration,
) -> Result<Response, ClientError> {
    let stream = connect(socket)?;
    stream.set_read_timeout(Some(timeout))?;
    stream.set_write_timeout(Some(timeout))?;
    let req = Request {
        v: VERSION,
        id: u64::from(std::process::id()),
        command,
    };
    let mut w = stream.try_clone()?;
    let line = serde_json::to_string(&req).map_err(ProtocolError::Malformed)?;
    let sent = w
        .write_all(line.as_bytes())
        .and_then(|()| w.write_all(b"\n"))
        .and_then(|()| w.flush());
    // A refused peer is answered and disconnected before its request is read, so the write
    // may fail (EPIPE) while the answer is already waiting: read it first.
    match read_response(stream) {
        Ok(r) => Ok(r),
        Err(e) => {
            sent?;
            Err(e)
        }
    }
}

/// The operator's stop over the stop socket beside `socket` ([`stop_socket_path`]):
/// connecting is the command, nothing is sent. Falls back to the control socket when there
/// is no stop socket (a daemon from before it existed).
pub fn request_stop(socket: &Path, timeout: Duration) -> Result<Response, ClientError> {
    let stop = stop_socket_path(socket);
    match UnixStream::connect(&stop) {
        Ok(stream) => {
            stream.set_read_timeout(Some(timeout))?;
            read_response(stream)
        }
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::NotFound | std::io::ErrorKind::ConnectionRefused
            ) =>
        {
            request(socket, Command::Stop, timeout)
        }
        Err(source) => Err(ClientError::Connect {
            path: stop,
            source,
            hint: "",
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The peer's supplementary groups are the ones it had when it connected, also once
    /// it has exited (its pid free for another process): a child with groups 4242 and 4343
    /// connects and exits before the credentials are read. Read from /proc after the
    /// accept (the earlier way), they come out empty here, or another process's. Root
    /// only (setgroups); run as root as CI does.
    #[test]
    fn a_peers_groups_are_those_it_connected_with() {
        let dir = fes_testkit::Scratch::new("sv-groups");
        let path = dir.join("s.sock");
        let listener = std::os::unix::net::UnixListener::bind(&path).unwrap();
        // Same process: the groups are this process's own.
        let me = UnixStream::connect(&path).unwrap();
        let (accepted, _) = listener.accept().unwrap();
        let mut own: Vec<u32> = nix::unistd::getgroups()
            .unwrap()
            .iter()
            .map(|g| g.as_raw())
            .collect();
        let mut seen = peer_of(&accepted).unwrap().groups;
        own.sort_unstable();
        seen.sort_unstable();
        assert_eq!(seen, own);
        drop((me, accepted));
        if !nix::unistd::geteuid().is_root() {
            eprintln!("SKIPPED: setting a child's groups needs root");
            return;
        }
        // A child that connects with groups of its own and exits at once.
        // SAFETY: sockaddr_un is plain data; all zeros is a valid (empty) address.
        let mut addr: libc::sockaddr_un = unsafe { std::mem::zeroed() };
        addr.sun_family = libc::AF_UNIX as libc::sa_family_t;
        for (d, s) in addr
            .sun_path
            .iter_mut()
            .zip(path.as_os_str().as_encoded_bytes())
        {
            *d = *s as libc::c_char;
        }
        let groups: [libc::gid_t; 2] = [4242, 4343];
        // SAFETY: the child calls only async-signal-safe functions (setgroups, socket,
        // connect, _exit) on memory prepared before the fork.
        let pid = unsafe { libc::fork() };
        if pid == 0 {
            // SAFETY: as above.
            unsafe {
                let code = if libc::setgroups(2, groups.as_ptr()) != 0 {
                    2
                } else {
                    let fd = libc::socket(libc::AF_UNIX, libc::SOCK_STREAM, 0);
                    let len = size_of::<libc::sockaddr_un>() as libc::socklen_t;
                    if fd < 0 || libc::connect(fd, (&raw const addr).cast(), len) != 0 {
                        3
                    } else {
                        0
                    }
                };
                libc::_exit(code);
            }
        }
        assert!(pid > 0, "fork");
        let (accepted, _) = listener.accept().unwrap();
        let mut status = 0;
        // SAFETY: waits for the child just forked; `status` is a local.
        assert_eq!(unsafe { libc::waitpid(pid, &mut status, 0) }, pid);
        assert_eq!(libc::WEXITSTATUS(status), 0, "the child could not connect");
        let mut seen = peer_of(&accepted).unwrap().groups;
        seen.sort_unstable();
        assert_eq!(seen, vec![4242, 4343], "the groups it connected with");
    }

    #[test]
    fn policy_admits_owner_root_user_and_group_members_only() {
        let p = PeerPolicy {
            own_uid: 500,
            uid: Some(600),
            gid: Some(700),
            stop_gid: None,
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
        let e = p.check(&peer(1000, 1000, vec![4])).unwrap_err().to_string();
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

    /// A stop-only group: its members may stop (the stop socket) and nothing else (the
    /// control socket refuses them); the control group's members may do both.
    #[test]
    fn a_stop_only_group_may_stop_and_not_arm() {
        let p = PeerPolicy {
            own_uid: 500,
            uid: None,
            gid: Some(700),
            stop_gid: Some(800),
            allow_root: false,
        };
        let peer = |gid, groups: Vec<u32>| Peer {
            pid: 1,
            uid: 1000,
            gid,
            groups,
        };
        for stopper in [peer(800, vec![]), peer(1000, vec![4, 800])] {
            assert!(p.check_stop(&stopper).is_ok(), "{stopper:?}");
            assert!(p.check(&stopper).is_err(), "{stopper:?} may not arm");
        }
        let operator = peer(1000, vec![700]);
        assert!(p.check(&operator).is_ok() && p.check_stop(&operator).is_ok());
        let other = peer(1000, vec![4]);
        assert!(p.check(&other).is_err() && p.check_stop(&other).is_err());
        // Without a stop group the stop socket admits exactly the control policy.
        let p = PeerPolicy {
            stop_gid: None,
            ..p
        };
        assert!(p.check_stop(&peer(800, vec![])).is_err());
        assert!(p.check_stop(&operator).is_ok());
    }
}
