//! The real `rt-core` binary against a fake service manager: a datagram socket named by
//! `NOTIFY_SOCKET`, as systemd provides for `Type=notify` units.
//!
//! - READY=1 (with a status) once the loop ticks, WATCHDOG=1 often enough that systemd
//!   never fires while it ticks, STOPPING=1 and exit 0 on SIGTERM;
//! - a watchdog meant for another pid (`WATCHDOG_PID`) is not fed;
//! - with the loop slowed to one tick per 1.5 s (test hook `FES_TEST_TICK_BUSY_US`) the
//!   feeding stops: no two feeds closer than the watchdog period, a "stalled" status;
//! - malformed variables are refused at start-up with a message naming them.
//!
//! rt-core runs without real-time rights here (RLIMIT_RTPRIO 0 and CAP_SYS_NICE dropped,
//! best-effort policy), so the slowed loop busy-waits at normal priority.

use std::io::Read;
use std::os::unix::net::UnixDatagram;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::systemd_support::{Scratch, scratch, stack_binaries};

/// A fake service manager: the socket rt-core notifies.
struct FakeManager {
    socket: UnixDatagram,
    path: PathBuf,
    start: Instant,
    /// Holds the socket; removed (when the test passed) after it is closed.
    _dir: Scratch,
}

impl FakeManager {
    fn new(tag: &str) -> Self {
        // sun_path holds at most 107 bytes: keep the socket in a scratch directory in the
        // (short) temp dir, not in the target directory's.
        let dir = Scratch::new(&format!("notify-{tag}"));
        let path = dir.join("notify.sock");
        let socket = UnixDatagram::bind(&path).expect("bind the fake notify socket");
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .expect("timeout");
        Self {
            socket,
            path,
            start: Instant::now(),
            _dir: dir,
        }
    }

    /// Every datagram until `until` (or until `child` exits and the socket is drained),
    /// with its arrival time since the manager was created.
    fn collect(&self, until: Instant, mut child: Option<&mut Child>) -> Vec<(Duration, String)> {
        let mut out = Vec::new();
        let mut buf = [0u8; 4096];
        let mut exited_at: Option<Instant> = None;
        while Instant::now() < until {
            match self.socket.recv(&mut buf) {
                Ok(n) => out.push((
                    self.start.elapsed(),
                    String::from_utf8_lossy(&buf[..n]).into_owned(),
                )),
                Err(_) => {
                    if let Some(t) = exited_at
                        && t.elapsed() > Duration::from_millis(200)
                    {
                        break;
                    }
                }
            }
            if exited_at.is_none()
                && let Some(c) = child.as_deref_mut()
                && c.try_wait().expect("try_wait").is_some()
            {
                exited_at = Some(Instant::now());
            }
        }
        out
    }
}

/// Writes a test-pattern configuration with its own iceoryx2 prefix.
fn config(scratch: &Scratch, tag: &str) -> PathBuf {
    let path = scratch.path().join("rt-core.toml");
    std::fs::write(
        &path,
        format!(
            "schema = \"fes-rt-core/1\"\n\
             [source]\nkind = \"test-pattern\"\nipi_ticks = 20\n\
             [rt]\npriority = 80\non_missing_rights = \"best-effort\"\n\
             [ipc]\nprefix = \"notifytest{tag}{}\"\n",
            std::process::id()
        ),
    )
    .expect("write config");
    path
}

/// Starts rt-core without real-time rights, with `env` added, stderr captured.
fn spawn_rt_core(config: &PathBuf, env: &[(&str, String)]) -> Child {
    let bin = stack_binaries().join("rt-core");
    let mut cmd = Command::new(bin);
    cmd.arg("--config")
        .arg(config)
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("WATCHDOG_PID")
        .env_remove("FES_TEST_TICK_BUSY_US")
        .env_remove("JOURNAL_STREAM")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    for (k, v) in env {
        cmd.env(k, v);
    }
    // SAFETY: between fork and exec only async-signal-safe calls (setrlimit, prctl) that
    // touch no memory of the parent.
    unsafe {
        cmd.pre_exec(|| {
            let zero = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            if libc::setrlimit(libc::RLIMIT_RTPRIO, &zero) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // CAP_SYS_NICE (23) out of the bounding set: root without it after exec.
            if libc::prctl(libc::PR_CAPBSET_DROP, 23, 0, 0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.spawn().expect("start rt-core")
}

fn terminate(child: &mut Child) {
    // SAFETY: kill(2) on the pid of a child we started and have not reaped.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGTERM);
    }
}

fn stderr_of(child: &mut Child) -> String {
    let mut text = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = e.read_to_string(&mut text);
    }
    text
}

/// Waits at most 10 s for the exit status.
fn wait(child: &mut Child) -> std::process::ExitStatus {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Some(s) = child.try_wait().expect("try_wait") {
            return s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("rt-core did not exit within 10 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn feeds(messages: &[(Duration, String)]) -> Vec<Duration> {
    messages
        .iter()
        .filter(|(_, m)| m.lines().any(|l| l == "WATCHDOG=1"))
        .map(|(t, _)| *t)
        .collect()
}

fn print(messages: &[(Duration, String)]) {
    for (t, m) in messages {
        println!("{:>6} ms {m:?}", t.as_millis());
    }
}

#[test]
fn ready_then_fed_watchdog_while_ticking_then_stopping() {
    let scratch = scratch("notify-ok");
    let config = config(&scratch, "ok");
    let manager = FakeManager::new("ok");
    let watchdog = Duration::from_millis(400);
    let mut child = spawn_rt_core(
        &config,
        &[
            ("NOTIFY_SOCKET", manager.path.display().to_string()),
            ("WATCHDOG_USEC", watchdog.as_micros().to_string()),
        ],
    );
    let mut messages = manager.collect(Instant::now() + Duration::from_secs(3), None);
    terminate(&mut child);
    messages.extend(manager.collect(Instant::now() + Duration::from_secs(10), Some(&mut child)));
    let status = wait(&mut child);
    let log = stderr_of(&mut child);
    print(&messages);
    assert!(status.success(), "rt-core exit {status}:\n{log}");
    let first = &messages.first().expect("notifications").1;
    assert!(first.starts_with("READY=1\n"), "first message {first:?}");
    assert!(
        first.contains("STATUS=real-time DEGRADED") && first.contains(" ticks, "),
        "READY carries the real-time status and the tick count: {first:?}"
    );
    assert_eq!(
        messages
            .iter()
            .filter(|(_, m)| m.contains("READY=1"))
            .count(),
        1
    );
    let fed = feeds(&messages);
    // Fed every check (watchdog / 4 = 100 ms): ~29 in 3 s; systemd fires only after a
    // whole watchdog period without one.
    assert!(fed.len() >= 15, "{} feeds in 3 s", fed.len());
    let max_gap = fed.windows(2).map(|w| w[1] - w[0]).max().expect("feeds");
    println!("largest gap between feeds: {max_gap:?} (watchdog {watchdog:?})");
    assert!(
        max_gap < watchdog,
        "a gap of {max_gap:?} would trip systemd"
    );
    let last = &messages.last().expect("messages").1;
    assert!(last.starts_with("STOPPING=1\n"), "last message {last:?}");
}

#[test]
fn a_watchdog_meant_for_another_process_is_not_fed() {
    let scratch = scratch("notify-pid");
    let config = config(&scratch, "pid");
    let manager = FakeManager::new("pid");
    let mut child = spawn_rt_core(
        &config,
        &[
            ("NOTIFY_SOCKET", manager.path.display().to_string()),
            ("WATCHDOG_USEC", "400000".to_owned()),
            // pid 1 is never rt-core.
            ("WATCHDOG_PID", "1".to_owned()),
        ],
    );
    let mut messages = manager.collect(Instant::now() + Duration::from_millis(1500), None);
    terminate(&mut child);
    messages.extend(manager.collect(Instant::now() + Duration::from_secs(10), Some(&mut child)));
    let status = wait(&mut child);
    print(&messages);
    assert!(status.success());
    assert!(messages.iter().any(|(_, m)| m.contains("READY=1")));
    assert!(
        feeds(&messages).is_empty(),
        "fed a watchdog that is not ours"
    );
}

#[test]
fn a_stalled_loop_stops_feeding_the_watchdog() {
    let scratch = scratch("notify-stall");
    let config = config(&scratch, "stall");
    let manager = FakeManager::new("stall");
    let watchdog = Duration::from_millis(400);
    let tick = Duration::from_millis(1500);
    let mut child = spawn_rt_core(
        &config,
        &[
            ("NOTIFY_SOCKET", manager.path.display().to_string()),
            ("WATCHDOG_USEC", watchdog.as_micros().to_string()),
            ("FES_TEST_TICK_BUSY_US", tick.as_micros().to_string()),
        ],
    );
    let mut messages = manager.collect(Instant::now() + Duration::from_millis(6500), None);
    terminate(&mut child);
    messages.extend(manager.collect(Instant::now() + Duration::from_secs(10), Some(&mut child)));
    let status = wait(&mut child);
    let log = stderr_of(&mut child);
    print(&messages);
    assert!(status.success(), "rt-core exit {status}:\n{log}");
    assert!(
        log.contains("TEST HOOK FES_TEST_TICK_BUSY_US=1500000"),
        "the hook announces itself:\n{log}"
    );
    let ready = messages
        .iter()
        .find(|(_, m)| m.contains("READY=1"))
        .expect("READY=1 after the first (slow) tick");
    assert!(ready.1.contains("STATUS=TEST SLOWDOWN"), "{:?}", ready.1);
    // One feed per completed tick at most: consecutive feeds are a tick apart (less one
    // check period of phase), never within a watchdog period of each other.
    let fed = feeds(&messages);
    assert!(fed.len() >= 2, "a feed after each completed tick: {fed:?}");
    for w in fed.windows(2) {
        let gap = w[1] - w[0];
        assert!(
            gap > watchdog && gap >= tick - watchdog / 4 - Duration::from_millis(50),
            "feeds {gap:?} apart while each tick takes {tick:?}"
        );
    }
    assert!(
        messages.iter().any(|(_, m)| m.contains("stalled")),
        "the stall shows in STATUS"
    );
}

#[test]
fn malformed_variables_are_refused_naming_them() {
    let scratch = scratch("notify-bad");
    let config = config(&scratch, "bad");
    for (env, name) in [
        (("WATCHDOG_USEC", "2s"), "WATCHDOG_USEC"),
        (("WATCHDOG_PID", "me"), "WATCHDOG_USEC"),
        (("NOTIFY_SOCKET", "relative/path"), "NOTIFY_SOCKET"),
        (("FES_TEST_TICK_BUSY_US", "lots"), "FES_TEST_TICK_BUSY_US"),
    ] {
        let mut vars = vec![(env.0, env.1.to_owned())];
        if env.0 == "WATCHDOG_PID" {
            vars.push(("WATCHDOG_USEC", "1000000".to_owned()));
        }
        let mut child = spawn_rt_core(&config, &vars);
        let status = wait(&mut child);
        let log = stderr_of(&mut child);
        let expected = if env.0 == "WATCHDOG_PID" {
            "WATCHDOG_PID"
        } else {
            name
        };
        assert_eq!(status.code(), Some(1), "{env:?}: {log}");
        assert!(
            log.contains(expected),
            "{env:?}: the error names {expected}:\n{log}"
        );
    }
}
