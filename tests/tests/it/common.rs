//! Shared pieces of the stimulator tests: the stimulator process, message pickers and a
//! small deterministic random generator.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use fes_can::{Emcy, ErrorCode, Force, Message, NmtState, Status};
use fes_testkit::bus::{RxFrame, Tap};

/// The virtual stimulator (with the charge-integrator plant) as a child process whose
/// log lines are echoed with a `[stim]` prefix.
pub struct StimProcess {
    child: Option<Child>,
    echo: Vec<JoinHandle<()>>,
}

impl StimProcess {
    /// Starts `test-stimulator --iface <iface> <args>`.
    pub fn spawn(iface: &str, args: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_test-stimulator"))
            .arg("--iface")
            .arg(iface)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start test-stimulator");
        let mut echo = Vec::new();
        if let Some(out) = child.stdout.take() {
            echo.push(std::thread::spawn(move || {
                for line in BufReader::new(out).lines().map_while(Result::ok) {
                    println!("[stim] {line}");
                }
            }));
        }
        if let Some(err) = child.stderr.take() {
            echo.push(std::thread::spawn(move || {
                for line in BufReader::new(err).lines().map_while(Result::ok) {
                    println!("[stim] {line}");
                }
            }));
        }
        Self {
            child: Some(child),
            echo,
        }
    }

    /// Sends SIGTERM and waits (at most 10 s) for the exit status.
    pub fn terminate(mut self) -> ExitStatus {
        let mut child = self.child.take().expect("running");
        let pid = i32::try_from(child.id()).expect("pid fits i32");
        // SAFETY: kill(2) on the pid of a child we started and have not reaped yet.
        unsafe {
            libc::kill(pid, libc::SIGTERM);
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some(s) = child.try_wait().expect("wait for test-stimulator") {
                for t in self.echo.drain(..) {
                    let _ = t.join();
                }
                return s;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                panic!("test-stimulator did not exit within 10 s of SIGTERM");
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for StimProcess {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Waiting time for anything the stimulator should do "now" (UML can be slow).
pub const PROMPT: Duration = Duration::from_secs(3);

pub fn status(m: &Message) -> Option<Status> {
    if let Message::Status(s) = m {
        Some(*s)
    } else {
        None
    }
}

pub fn emcy(m: &Message) -> Option<Emcy> {
    if let Message::Emcy(e) = m {
        Some(*e)
    } else {
        None
    }
}

pub fn force(m: &Message) -> Option<Force> {
    if let Message::Force(f) = m {
        Some(*f)
    } else {
        None
    }
}

pub fn boot_up(m: &Message) -> Option<()> {
    matches!(m, Message::StimHeartbeat(h) if h.state == NmtState::BootUp).then_some(())
}

/// Waits for a STATUS at index `>= from` satisfying `pred`; panics with the last STATUS
/// seen when none comes within `timeout`.
pub fn wait_status(
    tap: &Tap,
    from: usize,
    timeout: Duration,
    what: &str,
    pred: impl Fn(&Status) -> bool,
) -> (usize, Status) {
    match tap.wait_msg(from, timeout, |m| status(m).filter(|s| pred(s))) {
        Some((i, _, s)) => (i, s),
        None => {
            let last = tap
                .frames()
                .iter()
                .rev()
                .find_map(|f| f.msg().and_then(status));
            panic!("no STATUS with {what} within {timeout:?}; last STATUS: {last:?}");
        }
    }
}

/// Waits for an EMCY with `code` at index `>= from`.
pub fn wait_emcy(tap: &Tap, from: usize, code: ErrorCode) -> (usize, Instant, Emcy) {
    tap.wait_msg(from, PROMPT, |m| emcy(m).filter(|e| e.code == code))
        .unwrap_or_else(|| {
            let seen: Vec<Emcy> = tap.frames()[from.min(tap.len())..]
                .iter()
                .filter_map(|f| f.msg().and_then(emcy))
                .collect();
            panic!("no EMCY {code} within {PROMPT:?}; EMCYs seen: {seen:?}")
        })
}

/// All EMCYs in `frames`.
pub fn emcys(frames: &[RxFrame]) -> Vec<Emcy> {
    frames
        .iter()
        .filter_map(|f| f.msg().and_then(emcy))
        .collect()
}

/// All FORCE frames in `frames`.
pub fn forces(frames: &[RxFrame]) -> Vec<Force> {
    frames
        .iter()
        .filter_map(|f| f.msg().and_then(force))
        .collect()
}

/// The newest FORCE sample at index `>= from` after waiting `settle`.
pub fn force_after(tap: &Tap, settle: Duration) -> Force {
    std::thread::sleep(settle);
    *forces(&tap.frames()).last().expect("FORCE frames flow")
}

/// The force once everything sent so far has been applied: the FORCE two samples after
/// a STATUS sent after this call (a pulse shows in FORCE one tick after it is applied,
/// and STATUS comes no earlier than the tick that applied it).
pub fn settled_force(tap: &Tap) -> Force {
    let (i, _) = wait_status(tap, tap.len(), PROMPT, "a fresh STATUS", |_| true);
    let (j, _, _) = tap.wait_msg(i, PROMPT, force).expect("FORCE flows");
    let (_, _, f) = tap.wait_msg(j + 1, PROMPT, force).expect("FORCE flows");
    f
}

/// xorshift32: a fixed, seedable sequence for the test's random IPIs and pulses.
pub struct XorShift(pub u32);

impl XorShift {
    /// A value in `lo..=hi`.
    pub fn range(&mut self, lo: u32, hi: u32) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        lo + self.0 % (hi - lo + 1)
    }
}

/// Charge of a pulse in uC, which is what the charge-integrator plant adds to its force.
pub fn charge_uc(p: &fes_can::Pulse) -> f64 {
    p.amplitude_ma() * f64::from(p.width_us) * 1e-3
}
