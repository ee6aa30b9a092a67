//! The control socket end to end: the real daemon, the real CLI client. Invalid operator
//! commands are refused with a clear message and change nothing; a peer the policy does
//! not admit is refused by its SO_PEERCRED credentials.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::io::{BufRead, BufReader, Write};
use std::os::unix::fs::PermissionsExt;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use fes_testkit::Scratch;
use supervisor::config::ControlConfig;
use supervisor::control::{ControlServer, PeerPolicy};
use supervisor::protocol::{Response, Status};

const EXE: &str = env!("CARGO_BIN_EXE_supervisor");

struct Daemon {
    child: Child,
    /// Removed (when the test passed) after the daemon is stopped.
    _dir: Scratch,
    socket: PathBuf,
    /// The daemon's iceoryx2 service prefix.
    prefix: String,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn daemon(tag: &str) -> Daemon {
    daemon_with(tag, false)
}

/// The daemon, watching stim-driver's acknowledgements when `watch_driver` (no driver
/// runs in these tests: nothing acknowledges).
fn daemon_with(tag: &str, watch_driver: bool) -> Daemon {
    let dir = Scratch::new(&format!("sv-ctl-{tag}"));
    let prefix = format!("svctl{tag}{}", std::process::id());
    let cfg = dir.join("supervisor.toml");
    // Recording is on: the daemon needs the prescription whose checksum it records.
    std::fs::write(
        dir.join("prescription.toml"),
        include_str!("../../../deploy/etc/fes/prescription.toml"),
    )
    .unwrap();
    std::fs::write(
        &cfg,
        format!(
            r#"schema = "fes-supervisor/1"
[ipc]
prefix = "{prefix}"
node_name = "supervisor-test"
[control]
socket = "run/supervisor.sock"
[health]
watch_rt_core = false
watch_stim_driver = {watch_driver}
watch_stimulator = false
# No rt-core, driver or stimulator runs beside this daemon: the watches may be off.
test_configuration = true
[recording]
dir = "rec"
prescription = "prescription.toml"
"#,
        ),
    )
    .unwrap();
    let child = Command::new(EXE)
        .args(["run", "--config"])
        .arg(&cfg)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let socket = dir.join("run/supervisor.sock");
    let deadline = Instant::now() + Duration::from_secs(20);
    while !socket.exists() {
        assert!(
            Instant::now() < deadline,
            "the daemon did not create its socket"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    Daemon {
        child,
        _dir: dir,
        socket,
        prefix,
    }
}

fn cli(socket: &Path, args: &[&str]) -> Output {
    Command::new(EXE)
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE")
        .arg("--socket")
        .arg(socket)
        .output()
        .unwrap()
}

fn status(socket: &Path) -> Status {
    let o = cli(socket, &["status", "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: Response = serde_json::from_slice(&o.stdout).unwrap();
    r.status.unwrap()
}

/// Waits until the published reference is `force` (published every 10 ms).
fn wait_reference(socket: &Path, force: f64) -> Status {
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let s = status(socket);
        if s.reference == force {
            return s;
        }
        assert!(
            Instant::now() < deadline,
            "reference stays {} (want {force})",
            s.reference
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn invalid_commands_are_refused_clearly_and_change_nothing() {
    let d = daemon("inv");
    let mode = std::fs::metadata(&d.socket).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o660, "socket mode {mode:o}");

    // Not armed yet: refused with the remedy.
    let o = cli(&d.socket, &["set", "--force", "0.3"]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&o.stderr).trim(),
        "refused: not armed: run `supervisor arm` first"
    );
    let o = cli(&d.socket, &["arm"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = cli(&d.socket, &["set", "--force", "0.3", "--rate", "2"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let before = wait_reference(&d.socket, 0.3);
    assert_eq!(before.reference_rate_per_s, 2.0);
    assert_eq!(before.profile.as_deref(), Some("constant 0.3"));

    let cases: [(&[&str], &str); 7] = [
        (
            &["set", "--force", "1.5"],
            "refused: force 1.5 is outside [0, 1] (normalised force)",
        ),
        (
            &["set", "--force", "-0.2"],
            "refused: force -0.2 is outside [0, 1] (normalised force)",
        ),
        (
            &["set", "--force", "0.5", "--rate", "500"],
            "refused: rate 500 /s is faster than the rate limit 50 /s (normalised force per second)",
        ),
        (
            &["set", "--force", "NaN"],
            "Error: --force NaN: must be a finite number",
        ),
        (
            &["profile", "cardiac", "--hr", "250", "--amplitude", "0.3"],
            "refused: heart rate 250 beats/min is outside [60, 200] (thesis 1.1: 1-3.3 Hz)",
        ),
        (
            &["profile", "ramps", "--points", "0:0,0.01:1"],
            "refused: ramp from t = 0 s to 0.01 s: slope 100 /s is faster than the rate limit 50 /s (normalised force per second)",
        ),
        (
            &[
                "profile",
                "cardiac",
                "--hr",
                "75",
                "--amplitude",
                "0.5",
                "--edge-rate",
                "1",
            ],
            "refused: an edge of amplitude 0.5 at 1 /s takes 500.0 ms, longer than the contraction phase (320.0 ms): raise the edge rate or change the duty",
        ),
    ];
    for (args, message) in cases {
        let o = cli(&d.socket, args);
        assert_ne!(o.status.code(), Some(0), "{args:?} accepted");
        assert_eq!(
            String::from_utf8_lossy(&o.stderr).trim(),
            message,
            "{args:?}"
        );
    }
    // Garbage on the socket: one error line naming the problem.
    let mut s = UnixStream::connect(&d.socket).unwrap();
    s.write_all(b"{\"v\":1,\"command\":{\"kind\":\"set\",\"force\":0.9,\"extra\":1}}\n")
        .unwrap();
    let mut line = String::new();
    BufReader::new(&s).read_line(&mut line).unwrap();
    let r: Response = serde_json::from_str(&line).unwrap();
    assert!(!r.ok);
    assert!(r.error.unwrap().contains("unknown field `extra`"));

    std::thread::sleep(Duration::from_millis(50));
    let after = status(&d.socket);
    assert_eq!(after.state, "armed");
    assert_eq!(after.reference, before.reference);
    assert_eq!(after.reference_rate_per_s, before.reference_rate_per_s);
    assert_eq!(after.profile, before.profile);
    assert!(
        after.references_published > before.references_published,
        "still publishing"
    );

    // A valid stop takes effect at once.
    let o = cli(&d.socket, &["stop"]);
    assert!(o.status.success());
    let s = status(&d.socket);
    assert_eq!(s.state, "disarmed");
    assert!(s.reference_stop);
}

/// The operator's stop waits for the driver's acknowledgement: with none (no driver
/// answers here), `supervisor stop` does not say "stopped" and exit 0; it exits 4 with
/// the alarm naming the missing acknowledgement, and the daemon is in a fault the status
/// shows (an unacknowledged stop is not a quiet "disarmed"). With the acknowledgement
/// not awaited (the earlier client) or the unacknowledged stop only a note (the earlier
/// daemon), this fails.
#[test]
fn a_stop_the_driver_never_acknowledges_is_an_alarm_not_a_success() {
    let d = daemon_with("noack", true);
    let started = Instant::now();
    let o = cli(&d.socket, &["stop"]);
    let waited = started.elapsed();
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(
        o.status.code(),
        Some(4),
        "stdout: {stdout}\nstderr: {stderr}"
    );
    assert!(stdout.contains("stimulation stopped"), "{stdout}");
    assert!(!stdout.contains("acknowledged the stop"), "{stdout}");
    assert!(
        stderr.contains("ALARM") && stderr.contains("has not acknowledged"),
        "{stderr}"
    );
    // The link's acknowledgement timeout (1 s), not the client's (5 s), ended the wait.
    assert!(waited < Duration::from_secs(4), "{waited:?}");
    let s = status(&d.socket);
    assert_eq!(s.state, "fault", "{s:?}");
    assert!(
        s.fault
            .as_deref()
            .is_some_and(|f| f.contains("not acknowledged")),
        "{s:?}"
    );
    let order = s.driver_order.expect("the order is shown");
    assert!(order.is_stop(), "{order:?}");
    assert_ne!(order.outcome, "confirmed", "{order:?}");
    // An arm is refused while the driver is not there; the refusal is the daemon's (1).
    let o = cli(&d.socket, &["arm"]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// How long the real daemon takes from an operator's stop on the stop socket to the Stop
/// order on the driver's `driver_command` service, while [`MAX_CLIENTS`] clients trickle
/// bytes on the control socket and hold every connection it admits: the stop reaches the
/// driver's input, not only a reply.
///
/// [`MAX_CLIENTS`]: supervisor::control::MAX_CLIENTS
fn stop_to_driver_command_with_every_connection_taken(tag: &str) -> Duration {
    use fes_rt::msg::{DriverCommand, DriverCommandKind, port};
    use supervisor::control::{MAX_CLIENTS, request_stop};

    let d = daemon_with(tag, true);
    let node = fes_rt::rt::node::create_node(&format!("stop-probe-{tag}")).unwrap();
    let commands = port::subscriber::<DriverCommand>(&node, &d.prefix).unwrap();
    let tricklers = trickle(&d.socket, MAX_CLIENTS);
    std::thread::sleep(Duration::from_millis(300));
    while commands.receive().unwrap().is_some() {}
    let t0 = fes_rt::rt::clock::monotonic_ns();
    let sent = Instant::now();
    let stop_socket = supervisor::control::stop_socket_path(&d.socket);
    let r = request_stop(&stop_socket, Duration::from_secs(2)).unwrap();
    assert!(r.ok, "{r:?}");
    let published = loop {
        if let Some(c) = commands.receive().unwrap() {
            let stops = matches!(
                c.kind(),
                Ok(DriverCommandKind::Disarm | DriverCommandKind::SafeStop)
            );
            if stops && c.t_ns >= t0 {
                break sent.elapsed();
            }
            continue;
        }
        assert!(
            sent.elapsed() < Duration::from_secs(3),
            "no Stop order on driver_command within 3 s of the stop"
        );
        std::thread::sleep(Duration::from_micros(200));
    };
    for t in tricklers {
        t.join().unwrap();
    }
    eprintln!("stop -> driver_command Stop in {published:?}");
    published
}

/// `n` clients of `socket` that write a byte every 100 ms and never a newline, for 2 s.
fn trickle(socket: &Path, n: usize) -> Vec<std::thread::JoinHandle<()>> {
    (0..n)
        .map(|_| {
            let s = socket.to_path_buf();
            std::thread::spawn(move || {
                let mut c = UnixStream::connect(&s).unwrap();
                let t0 = Instant::now();
                while c.write_all(b" ").is_ok() && t0.elapsed() < Duration::from_secs(2) {
                    std::thread::sleep(Duration::from_millis(100));
                }
            })
        })
        .collect()
}

/// The real daemon, every control connection held by a trickling client: the operator's
/// stop still reaches the driver's command service. The functional bound is half the
/// control sockets' total deadline (a stop queued behind a trickler waits a whole one);
/// the 100 ms target is the timing check below. Served over the control socket, or with
/// the stop socket's thread waiting for a control slot, this fails.
#[test]
fn the_daemon_orders_the_stop_while_every_connection_is_taken() {
    let took = stop_to_driver_command_with_every_connection_taken("stopfn");
    assert!(
        took < supervisor::control::CLIENT_DEADLINE / 2,
        "stop -> driver_command Stop in {took:?}"
    );
}

/// Checks that depend on the host's timing (scripts/test runs them one at a time).
mod timing {
    /// The stop reaches the driver's command service within 100 ms of the operator's
    /// request (a Disarm or SafeStop order) on the real daemon with every control connection taken (a few ms on an
    /// idle host; the daemon's loop runs every 10 ms).
    #[test]
    fn the_daemon_orders_the_stop_within_100_ms() {
        let took = super::stop_to_driver_command_with_every_connection_taken("stoptm");
        assert!(
            took < std::time::Duration::from_millis(100),
            "stop -> driver_command Stop in {took:?}"
        );
    }
}

#[test]
fn a_peer_the_policy_does_not_admit_is_refused() {
    // The socket's directory is left for the server to create.
    let scratch = Scratch::new("sv-peer");
    let dir = scratch.join("run");
    let cfg = ControlConfig {
        socket: dir.join("s.sock"),
        ..ControlConfig::default()
    };
    let me = nix::unistd::geteuid().as_raw();
    let policy = PeerPolicy {
        own_uid: me.wrapping_add(12_345),
        uid: None,
        gid: Some(nix::unistd::getegid().as_raw().wrapping_add(777)),
        stop_gid: None,
        allow_root: false,
    };
    let (tx, rx) = std::sync::mpsc::channel();
    let server = ControlServer::start_with_policy(&cfg, policy, tx).unwrap();
    let o = cli(server.path(), &["status"]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&format!("permission denied: uid {me} (gid")),
        "{err}"
    );
    assert!(
        rx.try_recv().is_err(),
        "a refused peer's request reached the main loop"
    );
    drop(server);
    assert!(!dir.join("s.sock").exists(), "socket removed on shutdown");
}

/// Bad-input sweep of the daemon's configuration file: each malformed
/// file is refused by `supervisor run --check` with exit status 1 and a message naming the
/// problem, without a panic, and without creating the control socket or the recording
/// directory it names.
#[test]
fn malformed_configurations_are_refused_by_name_and_create_nothing() {
    let dir = Scratch::new("sv-badcfg");
    let example = Command::new(EXE)
        .args(["run", "--print-example-config"])
        .output()
        .unwrap();
    assert!(example.status.success());
    let good = String::from_utf8(example.stdout)
        .unwrap()
        .replace("/run/fes/supervisor.sock", "run/sv.sock")
        .replace("/var/lib/fes/recordings", "recordings")
        .replace("group = \"fes\"", "# group");
    let check = |name: &str, bytes: &[u8]| -> (Option<i32>, String) {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        let out = Command::new(EXE)
            .args(["run", "--check", "--config"])
            .arg(&path)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap();
        (
            out.status.code(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (code, err) = check("good.toml", good.as_bytes());
    assert_eq!(code, Some(0), "the example itself is valid: {err}");
    let edit = |from: &str, to: &str| {
        assert!(good.contains(from), "the example has {from:?}");
        good.replacen(from, to, 1).into_bytes()
    };
    let truncated = {
        let at = good.find("\"fes-supervisor\"").expect("the source key") + 5;
        good.as_bytes()[..at].to_vec()
    };
    let mut non_utf8 = good.clone().into_bytes();
    non_utf8.extend_from_slice(b"\n# \xff\xfe\n");
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            "nan",
            edit("max_force = 1.0", "max_force = nan"),
            "reference.max_force: NaN",
        ),
        (
            "inf",
            edit("gain = 0.3 ", "gain = inf "),
            "outer_loop.gain: inf",
        ),
        (
            "negative-time",
            edit("period_ms = 10 ", "period_ms = -5 "),
            "integer `-5`",
        ),
        (
            "huge",
            edit("max_record_ms = 1000 ", "max_record_ms = 99999999999 "),
            "recording.max_record_ms: 99999999999 must be in [100, 60000]",
        ),
        (
            "zero-flush",
            edit("flush_period_ms = 1000 ", "flush_period_ms = 0 "),
            "recording.flush_period_ms: 0",
        ),
        (
            "schema",
            edit("fes-supervisor/1", "fes-supervisor/2"),
            "schema: `fes-supervisor/2` is not `fes-supervisor/1`",
        ),
        (
            "no-schema",
            edit("schema = ", "# schema = "),
            "schema: missing",
        ),
        (
            "world-writable",
            edit("mode = 0o660", "mode = 0o666"),
            "control.mode: 0o666",
        ),
        (
            "driver-unwatched",
            edit("watch_stim_driver = true", "watch_stim_driver = false"),
            "health.watch_stim_driver: false turns a safety watch off",
        ),
        (
            "unknown-key",
            edit("enabled = true\ngain", "enabled = true\nbogus = 1\ngain"),
            "unknown field `bogus`",
        ),
        ("truncated", truncated, "TOML parse error"),
        ("non-utf8", non_utf8, "valid UTF-8"),
        ("empty", Vec::new(), "schema: missing"),
    ];
    for (name, bytes, fragment) in &cases {
        let (code, err) = check(&format!("{name}.toml"), bytes);
        assert_eq!(code, Some(1), "{name}: exit status 1 expected\n{err}");
        assert!(err.contains(fragment), "{name}: {fragment:?} not in\n{err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
    // Nothing was created next to the files: no socket directory, no recordings.
    assert!(!dir.join("run").exists() && !dir.join("recordings").exists());
}

/// A control server with a main loop that answers every request and records its commands.
/// The pids of this test process's children that play peers of another user
/// ([`foreign_marked_peer_of`]).
static FOREIGN_PIDS: std::sync::Mutex<Vec<i32>> = std::sync::Mutex::new(Vec::new());

/// The uid the foreign peers have: set by the kernel when the test runs as root (the
/// children run as it), by [`foreign_marked_peer_of`] otherwise.
const FOREIGN_UID: u32 = 65534;

/// The server's credentials as the kernel reports them, except that a child registered in
/// [`FOREIGN_PIDS`] is reported as [`FOREIGN_UID`]: an unprivileged test cannot connect as
/// another user, and what it proves is the policy's refusal before anything is read, which
/// runs on the credentials either way.
fn foreign_marked_peer_of(
    stream: &std::os::unix::net::UnixStream,
) -> std::io::Result<supervisor::control::Peer> {
    let mut peer = supervisor::control::peer_of(stream)?;
    if FOREIGN_PIDS.lock().unwrap().contains(&peer.pid) {
        peer.uid = FOREIGN_UID;
        peer.gid = FOREIGN_UID;
        peer.groups = vec![FOREIGN_UID];
    }
    Ok(peer)
}

struct StopFixture {
    server: Option<ControlServer>,
    seen: std::sync::Arc<std::sync::Mutex<Vec<supervisor::protocol::Command>>>,
    main_loop: Option<std::thread::JoinHandle<()>>,
    /// Removed (when the test passed) after the server and its main loop are gone.
    _dir: Scratch,
}

impl StopFixture {
    fn new(tag: &str) -> Self {
        let dir = Scratch::new(&format!("sv-stop-{tag}"));
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o755)).unwrap();
        let cfg = ControlConfig {
            socket: dir.join("s.sock"),
            mode: 0o666,
            ..ControlConfig::default()
        };
        let me = nix::unistd::geteuid().as_raw();
        let policy = PeerPolicy {
            own_uid: me,
            uid: None,
            gid: None,
            stop_gid: None,
            allow_root: me == 0,
        };
        let (tx, rx) = std::sync::mpsc::channel::<supervisor::control::Pending>();
        let server =
            ControlServer::start_with_peer_reader(&cfg, policy, foreign_marked_peer_of, tx)
                .unwrap();
        let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let seen2 = std::sync::Arc::clone(&seen);
        let main_loop = std::thread::spawn(move || {
            while let Ok(p) = rx.recv() {
                seen2.lock().unwrap().push(p.request.command.clone());
                let _ = p
                    .reply
                    .send(Response::ok(p.request.id, String::from("done"), None));
            }
        });
        Self {
            server: Some(server),
            seen,
            main_loop: Some(main_loop),
            _dir: dir,
        }
    }

    fn socket(&self) -> PathBuf {
        self.server.as_ref().unwrap().path().to_path_buf()
    }

    /// `n` clients that write a byte every 100 ms and never a newline; each returns how
    /// long it held its connection and the server's answer.
    fn tricklers(&self, n: usize) -> Vec<std::thread::JoinHandle<(Duration, String)>> {
        (0..n)
            .map(|_| {
                let s = self.socket();
                std::thread::spawn(move || {
                    let mut c = UnixStream::connect(&s).unwrap();
                    let t0 = Instant::now();
                    while c.write_all(b" ").is_ok() && t0.elapsed() < Duration::from_secs(10) {
                        std::thread::sleep(Duration::from_millis(100));
                    }
                    let mut answer = String::new();
                    let _ = BufReader::new(&c).read_line(&mut answer);
                    (t0.elapsed(), answer)
                })
            })
            .collect()
    }

    /// A stop over the stop socket: the answer and how long it took.
    fn stop(&self) -> (Response, Duration) {
        let t = Instant::now();
        let r = supervisor::control::request_stop(&self.socket(), Duration::from_secs(2)).unwrap();
        (r, t.elapsed())
    }
}

impl Drop for StopFixture {
    fn drop(&mut self) {
        drop(self.server.take());
        if let Some(t) = self.main_loop.take() {
            let _ = t.join();
        }
    }
}

/// The operator's stop cannot be held up. 16 clients trickle a byte every
/// 100 ms and never finish their request, and 16 peers the policy does not admit (run as
/// uid 65534: run as it when the test runs as root, marked as it by the test's credential
/// reader otherwise, [`foreign_marked_peer_of`]) connect and hold; meanwhile a `status` on the control
/// socket and a stop on the stop socket are each answered within 100 ms, the stop reaches the
/// main loop as `stop`, every trickling client is cut off at the total deadline
/// ([`CLIENT_DEADLINE`]) and every foreign peer is refused unread. (Served one connection at
/// a time, as before, the `status` waits behind the tricklers and this test fails.)
#[test]
fn the_stop_is_answered_while_trickling_and_refused_peers_hold_connections() {
    use supervisor::control::{CLIENT_DEADLINE, request};
    use supervisor::protocol::Command as Cmd;

    let f = StopFixture::new("trickle");
    let socket = f.socket();
    let tricklers = f.tricklers(16);
    let root = nix::unistd::geteuid().is_root();
    let mut foreign = Vec::new();
    {
        // Held while spawning: a child is registered before the server can read its
        // credentials (the reader waits for this lock).
        let mut pids = FOREIGN_PIDS.lock().unwrap();
        for _ in 0..16 {
            use std::os::unix::process::CommandExt;
            let mut cmd = Command::new("python3");
            cmd.args([
                "-c",
                "import socket,sys,time\ns=socket.socket(socket.AF_UNIX)\ns.connect(sys.argv[1])\nprint(s.recv(4096).decode().strip(), flush=True)\ntime.sleep(3)",
            ])
            .arg(&socket)
            .stdout(Stdio::piped());
            if root {
                cmd.uid(FOREIGN_UID).gid(FOREIGN_UID);
            }
            let child = cmd.spawn().unwrap();
            pids.push(child.id() as i32);
            foreign.push(child);
        }
    }
    std::thread::sleep(Duration::from_millis(300));
    let t = Instant::now();
    let r = request(&socket, Cmd::Status, Duration::from_secs(2)).unwrap();
    let status_time = t.elapsed();
    assert!(r.ok, "{r:?}");
    let (r, stop_time) = f.stop();
    assert!(r.ok, "{r:?}");
    // The target is 100 ms (measured here: a few ms). The functional bound is half
    // the total deadline: served behind a trickler, an answer waits at least a whole
    // deadline (1 s), so this separates "not held up" from "held up" on any host.
    eprintln!("status answered in {status_time:?}, stop in {stop_time:?}");
    assert!(
        status_time < CLIENT_DEADLINE / 2 && stop_time < CLIENT_DEADLINE / 2,
        "status answered in {status_time:?}, stop in {stop_time:?}"
    );
    for t in tricklers {
        let (held, answer) = t.join().unwrap();
        assert!(
            held < CLIENT_DEADLINE + Duration::from_millis(500),
            "a trickling client held its connection for {held:?}"
        );
        assert!(answer.contains("did not arrive within"), "{answer}");
    }
    for child in foreign {
        let out = child.wait_with_output().unwrap();
        let line = String::from_utf8_lossy(&out.stdout);
        assert!(line.contains("permission denied: uid 65534"), "{line}");
    }
    assert_eq!(*f.seen.lock().unwrap(), [Cmd::Status, Cmd::Stop]);
}

/// With every control connection taken ([`MAX_CLIENTS`] tricklers), the control socket
/// answers "busy" at once instead of queueing, and the stop socket still stops at once: the
/// stop never waits for a slot (sent over the control socket instead, this test fails: it
/// gets "busy").
#[test]
fn the_stop_socket_works_when_every_control_connection_is_taken() {
    use supervisor::control::{CLIENT_DEADLINE, MAX_CLIENTS, request};
    use supervisor::protocol::Command as Cmd;

    let f = StopFixture::new("full");
    let tricklers = f.tricklers(MAX_CLIENTS);
    std::thread::sleep(Duration::from_millis(300));
    let t = Instant::now();
    let r = request(&f.socket(), Cmd::Status, Duration::from_secs(2)).unwrap();
    assert!(
        !r.ok && r.error.as_deref().is_some_and(|e| e.starts_with("busy")),
        "{r:?}"
    );
    let busy_time = t.elapsed();
    let (r, stop_time) = f.stop();
    assert!(r.ok, "{r:?}");
    // Functional bound as above (the target, 100 ms, is met by a few ms here).
    eprintln!("busy answered in {busy_time:?}, stop in {stop_time:?}");
    assert!(
        busy_time < CLIENT_DEADLINE / 2 && stop_time < CLIENT_DEADLINE / 2,
        "busy in {busy_time:?}, stop in {stop_time:?}"
    );
    assert_eq!(*f.seen.lock().unwrap(), [Cmd::Stop]);
    for t in tricklers {
        t.join().unwrap();
    }
}

/// The exit-code convention (README "Exit codes"): no daemon at the socket is 3 for every
/// client command, the stop included, so that a script never reads "nothing answered" as
/// "refused" (1) or as done (0); a command line clap does not understand is 2.
#[test]
fn no_daemon_is_exit_3_and_bad_usage_is_exit_2() {
    let dir = Scratch::new("sup-nodaemon");
    let socket = dir.join("none.sock");
    for args in [
        &["status"][..],
        &["stop"],
        &["arm"],
        &["set", "--force", "0.1"],
    ] {
        let o = cli(&socket, args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(3), "{args:?}: {err}");
        assert!(err.contains("cannot connect to"), "{args:?}: {err}");
    }
    let o = cli(&socket, &["status", "--no-such-flag"]);
    assert_eq!(o.status.code(), Some(2));
}

/// A stop-only group over the real sockets: a peer admitted only as a member of
/// `stop_group` (here the test's own primary group; its uid, the control group and root are
/// not admitted) reaches the main loop with a stop through the stop socket, and is refused
/// on the control socket before anything is read. The stop socket is owned by that group.
#[test]
fn a_stop_only_group_member_may_stop_and_is_refused_everything_else() {
    use std::os::unix::fs::MetadataExt as _;
    use supervisor::control::{request, request_stop};
    use supervisor::protocol::Command as Cmd;

    let dir = fes_testkit::Scratch::new("sv-stopgroup");
    let cfg = ControlConfig {
        socket: dir.path().join("s.sock"),
        ..ControlConfig::default()
    };
    let me = nix::unistd::geteuid().as_raw();
    let my_gid = nix::unistd::getegid().as_raw();
    let policy = PeerPolicy {
        own_uid: me.wrapping_add(12_345),
        uid: None,
        gid: Some(my_gid.wrapping_add(777)),
        stop_gid: Some(my_gid),
        allow_root: false,
    };
    let (tx, rx) = std::sync::mpsc::channel::<supervisor::control::Pending>();
    let server = ControlServer::start_with_policy(&cfg, policy, tx).unwrap();
    assert_eq!(
        std::fs::metadata(server.stop_path()).unwrap().gid(),
        my_gid,
        "the stop socket belongs to the stop group"
    );
    let main_loop = std::thread::spawn(move || {
        let p = rx.recv_timeout(Duration::from_secs(5)).expect("the stop");
        let command = p.request.command.clone();
        let _ = p.reply.send(Response::ok(p.request.id, "stopped", None));
        (command, rx.recv_timeout(Duration::from_millis(300)).is_ok())
    });
    let r = request_stop(server.path(), Duration::from_secs(2)).unwrap();
    assert!(r.ok, "{r:?}");
    let r = request(server.path(), Cmd::Arm, Duration::from_secs(2)).unwrap();
    assert!(
        !r.ok
            && r.error
                .as_deref()
                .is_some_and(|e| e.starts_with("permission denied")),
        "{r:?}"
    );
    let (command, more) = main_loop.join().unwrap();
    assert_eq!(command, Cmd::Stop);
    assert!(!more, "the refused arm reached the main loop");
}
