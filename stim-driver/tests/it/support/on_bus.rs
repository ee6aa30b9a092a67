//! The `stim-driver` binary on a CAN bus (the vcan harness): a scripted StimTick publisher
//! (this test binary re-executed as a separate process, so that it can be SIGKILLed), the
//! driver process, and the virtual stimulator (`sim-muscle stimulator`'s code, in a thread
//! of this process, with the charge-integrator plant) as its peer. A raw-socket tap and
//! `candump -L` record what reaches the bus; the test process arms the driver through
//! DriverCommand and reads its DriverStatus like the supervisor does.
//!
//! Independent truths: the publisher prints every pulse decision it published (index,
//! StimTick seq, grid time), and gives pulse number `j` the amplitude `10 mA + j mod 100 x
//! 0.1 mA`, so each PULSE frame names the decision it carries; the stimulator's STATUS
//! counts what it applied; the legal subset of a burst is computed here by the plain
//! greedy rule (a pulse is legal when it is at least the minimum IPI after the last legal
//! one, on grid times).

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use fes_can::{Message, MessageKind, NmtCommand, Nodes, Pulse};
use fes_rt::msg::port;
use fes_rt::msg::service::{BACKPRESSURE, open_pubsub};
use fes_rt::msg::{
    Contract, DeviceState, DriverCommand, DriverCommandKind, DriverStatus, StimTick,
};
use fes_rt::rt::clock::{PeriodicClock, monotonic_ns};
use fes_rt::rt::node::create_node;
use fes_testkit::bus::{RxFrame, Tap};
use fes_testkit::vcan::{Backend, CanEnv};
use iceoryx2::prelude::*;

pub(crate) const EXE: &str = env!("CARGO_BIN_EXE_stim-driver");
/// Set (to "<prefix>;<script>") when this binary runs as the scripted publisher.
pub const ENV_PUBLISHER: &str = "STIM_DRIVER_TEST_PUBLISHER";
/// The publisher's test name (re-executed with `--exact --ignored`).
pub const PUBLISHER_TEST: &str = "forward_path::scripted_tick_publisher";
const MS: u64 = 1_000_000;

/// Real-time priorities, as on a rig: rt-core's loop (the publisher) 80 above the
/// driver's forward thread 79 and its receive thread 70 (`[bus_rt]`); the virtual
/// stimulator, a separate device in reality, above all. Without them a loaded UML guest
/// stalls the 1 ms loops for tens of ms (two PULSE frames in one stimulator tick are an
/// IPI violation there).
const PUBLISHER_PRIORITY: i32 = 80;
const STIMULATOR_PRIORITY: i32 = 82;

/// SCHED_FIFO for the calling thread, best effort (root in the guest and on CI).
fn fifo(priority: i32) {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: sched_setscheduler on the calling thread (pid 0) with a valid parameter.
    let _ = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
}

/// A publisher wake-up later than this after its grid time counts as the host's noise:
/// half the driver's `max_pulse_delay_us` (500) in the scenarios' configuration.
const LATE_WAKE_NS: u64 = 250_000;

/// Pulse `j`'s amplitude, µA.
fn amplitude_ua(j: u64) -> u32 {
    10_000 + 100 * (j % 100) as u32
}

/// Pulse `j`'s amplitude after the script's `mA` segment, mA (10..=58, even).
pub fn amplitude_ma(j: u64) -> u32 {
    // Even: a RehaStim 2 generates currents in 2 mA steps.
    10 + 2 * (j % 25) as u32
}

// ---------------------------------------------------------------------------------------
// The scripted publisher (a separate process).

/// Runs the publisher described by `spec` ("<prefix>;<script>"): idle StimTicks (no pulse)
/// every 1 ms until "go" arrives on stdin, then the script's segments, comma-separated:
/// `pE:N` N ticks, a pulse every E-th (from the first); `sM` a stall of M ms (the next tick
/// reports the skipped periods, as rt-core does); then a final tick. Prints `GO <seq>`,
/// `P <j> <seq> <t_ns>` per pulse decision, `END <seq>`.
pub fn run_publisher(spec: &str) {
    let (prefix, script) = spec.split_once(';').expect("<prefix>;<script>");
    let node = create_node("sdt-ticks").expect("node");
    let service = open_pubsub::<StimTick>(&node, prefix).expect("StimTick service");
    // A SIGKILLed predecessor holds the single publisher slot until the driver's liveness
    // check removes its stale resources.
    let deadline = Instant::now() + Duration::from_secs(5);
    let publisher = loop {
        match service
            .publisher_builder()
            .backpressure_strategy(BACKPRESSURE)
            .create()
        {
            Ok(p) => break p,
            Err(e) if Instant::now() < deadline => {
                let _ = e;
                std::thread::sleep(Duration::from_millis(20));
            }
            Err(e) => panic!("StimTick publisher: {e:?}"),
        }
    };
    let notifier = port::stim_tick_notifier(&node, prefix).expect("notifier");
    let go = Arc::new(AtomicBool::new(false));
    let g = go.clone();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            if line.is_ok_and(|l| l.trim() == "go") {
                g.store(true, Ordering::Relaxed);
            }
        }
    });
    fifo(PUBLISHER_PRIORITY);
    let mut out = std::io::stdout().lock();
    let mut clock = PeriodicClock::start(Duration::from_millis(1)).expect("clock");
    let mut seq = 0u64;
    // The host's own noise, as this process (SCHED_FIFO 80) sees it: wake-ups more than
    // LATE_WAKE_NS after their grid time, counted from "go" (printed at END).
    let late_wakes = std::cell::Cell::new(0u64);
    let scripted = std::cell::Cell::new(false);
    // The generator's minimum interval, as rt-core states it: the script's closest pulses
    // (the smallest E of its `pE` segments).
    let min_gap_ticks = script
        .split(',')
        .filter_map(|s| s.strip_prefix('p')?.split_once(':')?.0.parse::<u16>().ok())
        .min()
        .unwrap_or(0);
    let mut publish = |seq: u64, pulse: Option<u32>, flags: u16| {
        let w = clock.wait();
        if scripted.get() && w.wake_ns.saturating_sub(w.grid_ns) > LATE_WAKE_NS {
            late_wakes.set(late_wakes.get() + 1);
        }
        let mut flags = flags;
        if w.missed_periods > 0 {
            flags |= StimTick::FLAG_OVERRUN;
        }
        if scripted.get() {
            // Stimulating, as rt-core flags a running contraction.
            flags |= StimTick::FLAG_CONTRACTION_AHEAD;
        }
        let quiet = StimTick {
            t_wake_ns: w.wake_ns,
            t_publish_ns: 0,
            missed_periods: w.missed_periods,
            flags,
            min_gap_ticks,
            ..StimTick::quiet(seq, w.grid_ns)
        };
        let tick = match pulse {
            Some(amplitude_ua) => quiet.firing(0, amplitude_ua, 200),
            None => quiet,
        };
        let sample = publisher.loan_uninit().expect("loan");
        let mut sample = sample.write_payload(tick);
        sample.payload_mut().t_publish_ns = monotonic_ns().max(w.wake_ns);
        sample.send().expect("send");
        let _ = notifier.notify();
        w.grid_ns
    };
    while !go.load(Ordering::Relaxed) {
        seq += 1;
        publish(seq, None, 0);
    }
    writeln!(out, "GO {seq}").unwrap();
    scripted.set(true);
    let go_seq = seq;
    let mut j = 0u64;
    // "mA": whole-milliampere amplitudes from here on (a RehaStim 2 carries no 0.1 mA).
    let mut whole_ma = false;
    for segment in script.split(',') {
        if segment == "mA" {
            whole_ma = true;
        } else if let Some(ms) = segment.strip_prefix('s') {
            std::thread::sleep(Duration::from_millis(ms.parse().expect("stall ms")));
        } else if let Some(p) = segment.strip_prefix('p') {
            let (every, n) = p.split_once(':').expect("pE:N");
            let (every, n): (u64, u64) = (every.parse().unwrap(), n.parse().unwrap());
            for i in 0..n {
                seq += 1;
                if i % every == 0 {
                    let amplitude = if whole_ma {
                        amplitude_ma(j) * 1000
                    } else {
                        amplitude_ua(j)
                    };
                    let t = publish(seq, Some(amplitude), 0);
                    writeln!(out, "P {j} {seq} {t}").unwrap();
                    j += 1;
                } else {
                    publish(seq, None, 0);
                }
            }
        } else {
            panic!("unknown segment {segment:?}");
        }
    }
    seq += 1;
    publish(seq, None, StimTick::FLAG_FINAL);
    writeln!(out, "END {seq} {} {}", late_wakes.get(), seq - go_seq).unwrap();
    out.flush().unwrap();
}

/// One pulse decision the publisher made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Decision {
    pub(crate) j: u64,
    pub(crate) seq: u64,
    pub(crate) t_ns: u64,
}

/// A running publisher process.
pub(crate) struct Publisher {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: mpsc::Receiver<String>,
}

impl Publisher {
    pub(crate) fn start(prefix: &str, script: &str) -> Self {
        let mut child = fes_testkit::child::dies_with_parent(&mut Command::new(
            std::env::current_exe().expect("test binary"),
        ))
        .args([PUBLISHER_TEST, "--exact", "--ignored", "--nocapture"])
        .args(["--test-threads", "1"])
        .env(ENV_PUBLISHER, format!("{prefix};{script}"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start the publisher");
        let stdout = child.stdout.take().expect("stdout");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self {
            stdin: child.stdin.take(),
            child,
            lines,
        }
    }

    pub(crate) fn go(&mut self) {
        let stdin = self.stdin.as_mut().expect("stdin");
        stdin.write_all(b"go\n").expect("go");
        stdin.flush().expect("go");
    }

    /// Waits for the script to end; the decisions it published.
    pub(crate) fn finish(self, timeout: Duration) -> Vec<Decision> {
        self.finish_with_noise(timeout).0
    }

    /// [`Publisher::finish`], with the publisher's late wake-ups (more than
    /// [`LATE_WAKE_NS`]) and its scripted ticks.
    pub(crate) fn finish_with_noise(mut self, timeout: Duration) -> (Vec<Decision>, u64, u64) {
        let deadline = Instant::now() + timeout;
        let mut decisions = Vec::new();
        let (late, ticks) = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    let f: Vec<&str> = line.split_whitespace().collect();
                    match f.as_slice() {
                        ["P", j, seq, t] => decisions.push(Decision {
                            j: j.parse().unwrap(),
                            seq: seq.parse().unwrap(),
                            t_ns: t.parse().unwrap(),
                        }),
                        ["END", _, l, n] => break (l.parse().unwrap(), n.parse().unwrap()),
                        _ => {}
                    }
                }
                Err(_) => {
                    let _ = self.child.kill();
                    panic!("the publisher did not finish in {timeout:?}");
                }
            }
        };
        drop(self.stdin.take());
        let _ = self.child.wait();
        (decisions, late, ticks)
    }

    pub(crate) fn kill(mut self) {
        self.child.kill().expect("SIGKILL the publisher");
        let _ = self.child.wait();
    }
}

// ---------------------------------------------------------------------------------------
// The test side.

/// Timing of one environment (a UML guest is much slower and jittery).
#[derive(Debug, Clone, Copy)]
struct Timing {
    watchdog_ticks: u64,
    stim_watchdog_ms: u64,
    arm_ms: u64,
    max_pulse_delay_us: u64,
    margin_ms: u64,
}

impl Timing {
    fn for_backend(b: Backend) -> Self {
        match b {
            // The guest, on a loaded host, stalls for hundreds of ms at times (a whole
            // second was seen with a load average of 10 on 2 cores).
            Backend::Uml => Self {
                watchdog_ticks: 500,
                stim_watchdog_ms: 3000,
                arm_ms: 2000,
                // After a stall of the guest the driver refuses a late pulse rather than
                // sending two back to back; at most min_ipi (2000) - the stimulator's
                // min_ipi (1 ms), which the configuration check requires.
                max_pulse_delay_us: 1000,
                margin_ms: 100,
            },
            // This 2-core VM stalls a SCHED_FIFO thread for up to ~3 ms at a quiet hour
            // (cyclictest max 2.8 ms; docs/latency.md) and for 20-35 ms every few seconds
            // at a noisy one (2026-12-02: 10-24 ms old ticks voided all three 10 s runs of
            // a 10-tick watchdog). These scenarios check what the driver does, so the
            // host bus uses watchdogs far above that noise (the stall and the SIGKILL
            // bound scale with them); the native bus keeps the rig's 3 ticks.
            Backend::HostBus => Self {
                watchdog_ticks: 100,
                stim_watchdog_ms: 300,
                arm_ms: 500,
                max_pulse_delay_us: 500,
                margin_ms: 100,
            },
            _ => Self {
                watchdog_ticks: 3,
                stim_watchdog_ms: 100,
                arm_ms: 200,
                max_pulse_delay_us: 500,
                margin_ms: 10,
            },
        }
    }
}

/// The prescription of these scenarios: the driver's default limits (100 mA, 500 us, 50 uC
/// per phase, 2 ms, 100 pulses/s), so that what they exercise is the driver, not a dose.
pub(crate) const PRESCRIPTION: &str = r#"format = "fes-prescription/1"
label = "stim-driver on-bus scenarios: the driver's default limits"
max_amplitude_ua = 100000
max_phase_width_us = 500
max_charge_per_phase_nc = 50000
min_ipi_us = 2000
max_pulses_per_s = 100
"#;

fn write_config(dir: &Path, iface: &str, prefix: &str, t: &Timing) -> PathBuf {
    let path = dir.join("stim-driver.toml");
    std::fs::write(dir.join("prescription.toml"), PRESCRIPTION).expect("write the prescription");
    std::fs::write(
        &path,
        format!(
            r#"schema = "fes-stim-driver/1"
prescription = "prescription.toml"
[can]
iface = "{iface}"
[stimulator]
watchdog_ms = {wd}
min_ipi_ms = 1
[interlocks]
min_ipi_us = 2000
max_pulse_delay_us = {delay}
[watchdog]
timeout_ticks = {ticks}
stale_after_ticks = {ticks}
stimulator_timeout_ms = {wd}
arm_confirm_ms = {arm}
command_max_age_ms = {arm}
[force]
max_n = 40.0
[rt]
priority = 79
on_missing_rights = "best-effort"
[bus_rt]
priority = 70
on_missing_rights = "best-effort"
[telemetry]
hlog = "{hlog}"
[ipc]
prefix = "{prefix}"
"#,
            wd = t.stim_watchdog_ms,
            delay = t.max_pulse_delay_us,
            ticks = t.watchdog_ticks,
            arm = t.arm_ms,
            hlog = dir.join("stim-driver.hlog").display(),
        ),
    )
    .expect("write the configuration");
    path
}

/// The virtual stimulator in a thread of this process.
struct Stimulator {
    stop: &'static AtomicBool,
    thread: Option<std::thread::JoinHandle<fes_virtual_stimulator::RunSummary>>,
}

impl Stimulator {
    fn start(iface: &str, watchdog_ms: u64) -> Self {
        let stop: &'static AtomicBool = Box::leak(Box::new(AtomicBool::new(false)));
        let args = fes_virtual_stimulator::StimulatorArgs {
            iface: iface.to_owned(),
            node_id: Nodes::DEFAULT.stim(),
            host_node_id: Nodes::DEFAULT.host(),
            channels: 1,
            max_amplitude_ma: 100.0,
            max_width_us: 500,
            min_ipi_ms: 1,
            max_pulses: 100,
            rate_window_ms: 1000,
            watchdog_ms: watchdog_ms as u16,
            max_charge_uc: 50.0,
            test_fault_loose_config: false,
            heartbeat_ms: 100,
            host_heartbeat_ms: 10,
            record: None,
            duration_s: None,
        };
        let thread = std::thread::spawn(move || {
            fifo(STIMULATOR_PRIORITY);
            fes_virtual_stimulator::run_until(
                args,
                Box::new(fes_virtual_stimulator::test_plant::ChargeIntegrator::new()),
                stop,
            )
            .expect("the virtual stimulator")
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }

    fn stop(mut self) -> fes_virtual_stimulator::RunSummary {
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .take()
            .expect("running")
            .join()
            .expect("the stimulator thread")
    }
}

/// Records the publish time of the newest StimTick (for the kill measurement).
struct TickWatch {
    last_publish_ns: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
}

impl TickWatch {
    fn start(prefix: &str) -> Self {
        let last_publish_ns = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (l, s, prefix) = (last_publish_ns.clone(), stop.clone(), prefix.to_owned());
        let (ready_tx, ready_rx) = mpsc::channel();
        std::thread::spawn(move || {
            let node = create_node("sdt-watch").expect("node");
            let sub = port::subscriber::<StimTick>(&node, &prefix).expect("subscriber");
            let _ = ready_tx.send(());
            while !s.load(Ordering::Relaxed) {
                while let Ok(Some(t)) = sub.receive() {
                    l.fetch_max(t.payload().t_publish_ns, Ordering::Relaxed);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        });
        ready_rx.recv().expect("tick watch ready");
        Self {
            last_publish_ns,
            stop,
        }
    }
}

impl Drop for TickWatch {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// `Instant` (CLOCK_MONOTONIC on Linux) to monotonic ns.
struct Clocks {
    instant: Instant,
    ns: u64,
}

impl Clocks {
    fn now() -> Self {
        Self {
            instant: Instant::now(),
            ns: monotonic_ns(),
        }
    }
    fn ns(&self, at: Instant) -> u64 {
        if at >= self.instant {
            self.ns + (at - self.instant).as_nanos() as u64
        } else {
            self.ns - (self.instant - at).as_nanos() as u64
        }
    }
}

fn is_pulse(f: &RxFrame) -> Option<Pulse> {
    match f.msg() {
        Some(Message::Pulse(p)) => Some(*p),
        _ => None,
    }
}

fn is_stop(f: &RxFrame) -> bool {
    matches!(f.msg(), Some(Message::Nmt(n)) if n.command == NmtCommand::Stop)
}

fn last_status_pulses(frames: &[RxFrame]) -> Option<u32> {
    frames.iter().rev().find_map(|f| match f.msg() {
        Some(Message::Status(s)) => Some(s.pulses_delivered),
        _ => None,
    })
}

/// Maps the PULSE frames, in order, to the decisions they carry (by amplitude), checking
/// width and channel. Returns the decision indices `j`.
fn decisions_on_bus(pulses: &[Pulse], decisions: &[Decision]) -> Vec<u64> {
    let mut cursor = 0;
    let mut js = Vec::new();
    for p in pulses {
        assert_eq!((p.width_us, p.channel), (200, 0), "{p:?}");
        let k = (cursor..decisions.len())
            .find(|&k| amplitude_ua(decisions[k].j) == u32::from(p.amplitude_100ua) * 100)
            .unwrap_or_else(|| {
                panic!("PULSE {p:?} matches no later decision (out of order or duplicated)")
            });
        js.push(decisions[k].j);
        cursor = k + 1;
    }
    js
}

/// The greedy legal subset under a minimum IPI on grid times.
fn greedy_legal(decisions: &[Decision], min_ipi_ns: u64) -> Vec<u64> {
    let mut last: Option<u64> = None;
    let mut legal = Vec::new();
    for d in decisions {
        if last.is_none_or(|t| d.t_ns >= t + min_ipi_ns) {
            legal.push(d.j);
            last = Some(d.t_ns);
        }
    }
    legal
}

/// The test process's side of the iceoryx2 contracts (like the supervisor's).
pub(crate) struct Operator {
    _node: Node<ipc::Service>,
    commands: iceoryx2::port::publisher::Publisher<ipc::Service, DriverCommand, ()>,
    status: iceoryx2::port::subscriber::Subscriber<ipc::Service, DriverStatus, ()>,
    seq: u64,
    last: Option<DriverStatus>,
}

impl Operator {
    pub(crate) fn new(prefix: &str) -> Self {
        let node = create_node("sdt-operator").expect("node");
        let commands = port::publisher::<DriverCommand>(&node, prefix).expect("command publisher");
        let status = port::subscriber::<DriverStatus>(&node, prefix).expect("status subscriber");
        Self {
            _node: node,
            commands,
            status,
            seq: 0,
            last: None,
        }
    }

    pub(crate) fn status(&mut self) -> Option<DriverStatus> {
        while let Ok(Some(s)) = self.status.receive() {
            let s = *s.payload();
            assert_eq!(s.validate(), Ok(()), "DriverStatus {s:?}");
            self.last = Some(s);
        }
        self.last
    }

    pub(crate) fn wait_state(
        &mut self,
        timeout: Duration,
        ok: impl Fn(&DriverStatus) -> bool,
    ) -> Option<DriverStatus> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.status()
                && ok(&s)
            {
                return Some(s);
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    pub(crate) fn send(&mut self, kind: DriverCommandKind) {
        self.seq += 1;
        self.commands
            .send_copy(DriverCommand::new(self.seq, monotonic_ns(), kind))
            .expect("send a command");
    }

    /// Sends Arm until the driver reports armed.
    pub(crate) fn arm(&mut self, timeout: Duration, log: &Path) {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            self.send(DriverCommandKind::Arm);
            if self
                .wait_state(Duration::from_millis(300), |s| {
                    matches!(s.state(), Ok(DeviceState::Armed | DeviceState::Stimulating))
                })
                .is_some()
            {
                return;
            }
        }
        panic!(
            "the driver did not arm within {timeout:?}; status {:?}\n{}",
            self.last,
            tail(log)
        );
    }
}

/// The driver log's pulse refusals, each from its StimTick seq on: "<seq> refused (its
/// pulse NOT sent): <the interlock's reason>".
pub(crate) fn pulse_refusals(log_text: &str) -> impl Iterator<Item = &str> {
    log_text
        .lines()
        .filter(|l| l.contains("refused (its pulse NOT sent)"))
        .filter_map(|l| Some(l.split_once("StimTick ")?.1))
}

pub(crate) fn tail(log: &Path) -> String {
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(40)..].join("\n")
}

/// Each thread of process `pid`: name, state and where it sleeps (for a hang's report).
fn threads(pid: u32) -> String {
    let mut out = String::new();
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return format!("process {pid} is gone");
    };
    for t in tasks.flatten() {
        let p = t.path();
        let read = |f: &str| std::fs::read_to_string(p.join(f)).unwrap_or_default();
        let stat = read("stat");
        let state = stat
            .rsplit(')')
            .next()
            .unwrap_or("")
            .split_whitespace()
            .next()
            .unwrap_or("?")
            .to_owned();
        out.push_str(&format!(
            "{} {} {} {}\n",
            t.file_name().to_string_lossy(),
            read("comm").trim(),
            state,
            read("wchan")
        ));
    }
    out
}

fn ip_link(iface: &str, state: &str) {
    let ok = Command::new("ip")
        .args(["link", "set", iface, state])
        .status()
        .expect("run ip");
    assert!(ok.success(), "ip link set {iface} {state}");
}

fn fault_code(s: &DriverStatus) -> u16 {
    s.fault_code
}

/// The whole scenario (see the module documentation).
pub fn driver_on_the_bus(can: &CanEnv) {
    let t = Timing::for_backend(can.backend);
    let uml = can.backend == Backend::Uml;
    let pid = std::process::id();
    let prefix = format!("sdt{pid}");
    let dir = fes_testkit::Scratch::new("stim-driver-test");
    let config = write_config(&dir, &can.iface, &prefix, &t);
    let log = dir.join("driver.log");
    let nodes = Nodes::DEFAULT;
    let pulse_id = nodes.id_of(MessageKind::Pulse);
    let clocks = Clocks::now();
    let slow = |ms: u64| Duration::from_millis(if uml { ms * 10 } else { ms });

    let stimulator = Stimulator::start(&can.iface, t.stim_watchdog_ms);
    let mut tap = Tap::open(&can.iface).expect("tap");
    let host_bus = can.backend == Backend::HostBus;
    let candump_out = dir.join("candump.log");
    // candump needs a CAN interface; on the host bus the tap is the only observer.
    let mut candump = (!host_bus).then(|| {
        fes_testkit::child::dies_with_parent(&mut Command::new("candump"))
            .args(["-L", &can.iface])
            .stdout(std::fs::File::create(&candump_out).unwrap())
            .stderr(Stdio::null())
            .spawn()
            .expect("candump (can-utils) is needed: scripts/setup installs it")
    });
    let log_file = std::fs::File::create(&log).unwrap();
    // A panicking scenario takes the driver with it (the next test would share its load).
    let mut driver = fes_testkit::child::dies_with_parent(&mut Command::new(EXE))
        .args(["run", "--config"])
        .arg(&config)
        .env_remove("FES_CAN_IFACE")
        .env("RUST_LOG", "info")
        .stdout(log_file.try_clone().unwrap())
        .stderr(log_file)
        .spawn()
        .expect("start stim-driver");
    let mut op = Operator::new(&prefix);
    op.wait_state(slow(3000), |s| s.state() == Ok(DeviceState::PreOperational))
        .unwrap_or_else(|| panic!("the driver did not come up disarmed\n{}", tail(&log)));
    println!("driver up, stimulator configured, disarmed");

    // STIM_DRIVER_TEST_ONLY=4,5 runs only those scenarios (all by default).
    let only = std::env::var("STIM_DRIVER_TEST_ONLY").ok();
    let want = |n: u32| {
        only.as_deref()
            .is_none_or(|v| v.split(',').any(|x| x.trim() == n.to_string()))
    };
    let mut pulses_seen = None;

    // --- 1. 10 s at 50 Hz: every decision on the bus once, in order, applied. ---------
    if want(1) {
        // On a shared host or in the guest, another fault can come first (a tick older than
        // allowed after a stall: the driver trips, correctly); such a run is void and repeated.
        let mut voided = Vec::new();
        for attempt in 1..=3 {
            let mut p = Publisher::start(&prefix, "p20:10000");
            op.arm(slow(2000), &log);
            let start = tap.len();
            let before = last_status_pulses(&tap.frames()).expect("STATUS seen");
            let rejected_before = op.status().unwrap().pulses_rejected;
            p.go();
            let (decisions, late_wakes, scripted_ticks) =
                p.finish_with_noise(Duration::from_secs(60));
            let s = op
                .wait_state(slow(1000), |s| s.state() == Ok(DeviceState::Fault))
                .expect("the final tick puts the driver in its safe state");
            if fault_code(&s) != 0xFF25 && (uml || host_bus) && attempt < 3 {
                println!(
                    "10 s run {attempt} void: fault {:#06x} before the final tick",
                    fault_code(&s)
                );
                voided.push(fault_code(&s));
                continue;
            }
            assert_eq!(
                fault_code(&s),
                0xFF25,
                "the final tick, not another fault (voided runs {voided:04x?}): {s:?}\n{}",
                tail(&log)
            );
            std::thread::sleep(Duration::from_millis(100));
            let frames = tap.frames();
            let pulses: Vec<Pulse> = frames[start..].iter().filter_map(is_pulse).collect();
            assert_eq!(decisions.len(), 500);
            let js = decisions_on_bus(&pulses, &decisions);
            for w in pulses.windows(2) {
                assert_eq!(w[1].seq, w[0].seq.wrapping_add(1), "PULSE seq consecutive");
            }
            let refused = s.pulses_rejected - rejected_before;
            if host_bus {
                // On a shared host a tick can reach the driver later than max_pulse_delay
                // (500 us): it is refused and reported, never lost or sent late. The pulse
                // path has two wake-ups (publisher, driver) on a host whose cyclictest p99.9
                // is 0.8-1 ms (docs/realtime.md): CI has seen 6-10 of the 500 refused on a
                // quiet machine. A driver that delays or refuses pulses itself refuses most.
                assert_eq!(
                    js.len() as u64 + refused,
                    500,
                    "on the bus or reported: {s:?}"
                );
                // At a noisy hour of the VM (cyclictest p99 1.3-1.7 ms, seen in a CI dry
                // run) 59 of 500 were refused: the rate is judged only when the publisher's
                // own wake-ups were quiet (at most 1 % more than LATE_WAKE_NS late); the
                // floor of half the pulses delivered holds on any host.
                let noisy = late_wakes * 100 > scripted_ticks;
                println!(
                    "publisher: {late_wakes} of {scripted_ticks} wake-ups over {} us late{}",
                    LATE_WAKE_NS / 1000,
                    if noisy {
                        ": host too noisy to judge the refusal rate"
                    } else {
                        ""
                    }
                );
                assert!(js.len() >= 250, "{} of 500 delivered: {s:?}", js.len());
                // The driver's own account of each: how late, and the generator's share.
                let text = std::fs::read_to_string(&log).unwrap_or_default();
                for refusal in pulse_refusals(&text) {
                    println!("  {refusal}");
                }
                assert!(
                    noisy || refused <= 25,
                    "{refused} pulses refused as late on a quiet host: {s:?}"
                );
                assert!(js.windows(2).all(|w| w[0] < w[1]), "in order: {js:?}");
            } else if uml {
                // The guest stalls for tens of ms under load: a pulse that would leave more than
                // max_pulse_delay late is refused, and must then be reported, not lost.
                assert_eq!(
                    js.len() as u64 + refused,
                    500,
                    "on the bus or reported: {s:?}"
                );
            } else {
                assert_eq!(
                    js,
                    (0..500).collect::<Vec<u64>>(),
                    "every decision once, in order"
                );
            }
            let after = last_status_pulses(&frames).expect("STATUS");
            assert_eq!(
                u64::from(after.wrapping_sub(before) & 0xFF_FFFF),
                js.len() as u64,
                "the stimulator applied every PULSE (STATUS pulses_delivered)"
            );
            println!(
                "10 s run: 500 decisions -> {} PULSE frames in order, each applied by the stimulator; \
         {refused} refused as late and reported",
                js.len()
            );
            break;
        }
    }
    // --- 2. a burst violating the minimum IPI: only the legal pulses. -----------------
    if want(2) {
        let mut p = Publisher::start(&prefix, "p20:100,p1:12,p20:100");
        op.arm(slow(2000), &log);
        let start = tap.len();
        let log_start = std::fs::read_to_string(&log).map_or(0, |t| t.len());
        p.go();
        let decisions = p.finish(Duration::from_secs(30));
        op.wait_state(slow(1000), |s| s.state() == Ok(DeviceState::Fault))
            .expect("safe state after the final tick");
        std::thread::sleep(Duration::from_millis(50));
        let frames = tap.frames();
        let pulses: Vec<Pulse> = frames[start..].iter().filter_map(is_pulse).collect();
        let js = decisions_on_bus(&pulses, &decisions);
        let legal = greedy_legal(&decisions, 2 * MS);
        let t_of = |j: u64| decisions.iter().find(|d| d.j == j).unwrap().t_ns;
        for w in js.windows(2) {
            assert!(
                t_of(w[1]) >= t_of(w[0]) + 2 * MS,
                "pulses {} and {} less than 2 ms apart on the bus",
                w[0],
                w[1]
            );
        }
        if uml || host_bus {
            // Late pulses (beyond max_pulse_delay) may be refused in the guest and on a
            // shared host; the minimum IPI then counts from the pulses let through, so the
            // expected subset is the greedy rule over the decisions the driver did not
            // refuse as late (its log names each by StimTick seq).
            let text = std::fs::read_to_string(&log).unwrap_or_default();
            let late: Vec<u64> = pulse_refusals(&text[log_start.min(text.len())..])
                .filter(|r| r.contains("after its grid time"))
                .filter_map(|r| r.split_whitespace().next()?.parse().ok())
                .collect();
            let on_time: Vec<Decision> = decisions
                .iter()
                .copied()
                .filter(|d| !late.contains(&d.seq))
                .collect();
            assert_eq!(
                js,
                greedy_legal(&on_time, 2 * MS),
                "the legal subset of the pulses not refused as late (StimTicks {late:?})"
            );
            if host_bus && late.is_empty() {
                assert_eq!(js, legal, "exactly the legal subset");
            }
        } else {
            assert_eq!(js, legal, "exactly the legal subset");
        }
        // p20:100 -> 5 pulses, p1:12 -> 12 at 1 ms of which every other is legal at a 2 ms
        // minimum IPI, p20:100 -> 5 (its first 2 ms after the last legal burst pulse).
        assert_eq!(decisions.len(), 5 + 12 + 5);
        assert_eq!(
            legal.len(),
            5 + 6 + 5,
            "the greedy rule keeps every other burst pulse"
        );
        println!(
            "burst: {} decisions, {} legal, {} on the bus",
            decisions.len(),
            legal.len(),
            js.len()
        );
    }
    // --- 3. publisher stalled 100 ms: stop, no burst after, stopped until re-armed. ----
    if want(3) {
        // 100 ms on a native bus; in the guest it must outlast the longer watchdog.
        let stall_ms = 100.max(2 * t.watchdog_ticks + 100);
        let mut p = Publisher::start(&prefix, &format!("p20:300,s{stall_ms},p20:4000"));
        op.arm(slow(2000), &log);
        let start = tap.len();
        p.go();
        let (stop_at, _) = tap
            .wait_for(start, Duration::from_secs(10), is_stop)
            .expect("NMT stop after the stall");
        std::thread::sleep(Duration::from_millis(300));
        let frames = tap.frames();
        assert_eq!(
            frames[stop_at..].iter().filter_map(is_pulse).count(),
            0,
            "no PULSE after the stop while the publisher runs again"
        );
        let s = op.status().unwrap();
        assert_eq!(s.state(), Ok(DeviceState::Fault));
        if uml || host_bus {
            // On a loaded host the driver can wake to the first tick after the stall before
            // its timer fires: that tick is stale (0xFF24); either trip is the watchdog's.
            assert!(
                matches!(fault_code(&s), 0xFF21 | 0xFF24),
                "tick timeout or stale tick: {s:?}"
            );
        } else {
            assert_eq!(fault_code(&s), 0xFF21, "tick timeout");
        }
        let rearm_at = tap.len();
        op.arm(slow(2000), &log);
        tap.wait_for(rearm_at, Duration::from_secs(5), |f| is_pulse(f).is_some())
            .expect("pulses again after the re-arm");
        let _ = p.finish(Duration::from_secs(30));
        println!("stall: stopped, no burst, resumed only after re-arm");
    }
    // --- 4. publisher SIGKILLed: NMT stop within the watchdog + 1 tick. ----------------
    if want(4) {
        // Started only now: its polling costs CPU a loaded guest does not have to spare.
        let watch = TickWatch::start(&prefix);
        let reps = 5;
        let mut latencies_ms = Vec::new();
        let mut voided = Vec::new();
        for _ in 0..2 * reps {
            if latencies_ms.len() == reps {
                break;
            }
            let mut p = Publisher::start(&prefix, "p20:1000000");
            op.arm(slow(3000), &log);
            p.go();
            std::thread::sleep(Duration::from_millis(200));
            let start = tap.len();
            // A run in which the driver tripped before the kill (in a stalled guest: the
            // stimulator's EMCY, a stale tick) measures nothing: it is reported, not counted.
            let armed = op
                .status()
                .filter(|s| matches!(s.state(), Ok(DeviceState::Armed | DeviceState::Stimulating)))
                .is_some()
                && !tap.frames()[..start].iter().rev().take(50).any(is_stop);
            p.kill();
            if !armed {
                voided.push(op.status().map_or(0, |s| fault_code(&s)));
                op.wait_state(slow(500), |s| s.state() == Ok(DeviceState::Fault));
                continue;
            }
            let (i, stop) = tap
                .wait_for(start, Duration::from_secs(5), is_stop)
                .unwrap_or_else(|| {
                    panic!(
                        "no NMT stop after SIGKILL\n{}\n{}",
                        tail(&log),
                        threads(driver.id())
                    )
                });
            let last_tick = watch.last_publish_ns.load(Ordering::Relaxed);
            let ms = (clocks.ns(stop.at) as f64 - last_tick as f64) / 1e6;
            latencies_ms.push(ms);
            std::thread::sleep(Duration::from_millis(100));
            assert_eq!(
                tap.frames()[i..].iter().filter_map(is_pulse).count(),
                0,
                "no PULSE after the stop"
            );
            op.wait_state(slow(500), |s| s.state() == Ok(DeviceState::Fault))
                .expect("safe state");
        }
        println!("SIGKILL runs voided by an earlier trip (fault codes): {voided:04x?}");
        assert!(
            latencies_ms.len() >= 3,
            "too few valid SIGKILL runs: {voided:04x?}"
        );
        let bound = (t.watchdog_ticks + 1 + t.margin_ms) as f64;
        println!(
            "SIGKILL -> NMT stop, ms after the last StimTick ({} runs, watchdog {} ms + 1 tick, \
         allowed {bound} ms): {latencies_ms:.3?}",
            latencies_ms.len(),
            t.watchdog_ticks
        );
        for ms in &latencies_ms {
            assert!(*ms > 0.0 && *ms <= bound, "{ms} ms");
        }
    }
    // --- 5. the interface goes down mid-run (CAN only: the host bus has no link). --------
    if want(5) && !host_bus {
        let p = {
            let mut p = Publisher::start(&prefix, "p20:1000000");
            op.arm(slow(3000), &log);
            p.go();
            p
        };
        std::thread::sleep(Duration::from_millis(300));
        // candump ends when the interface goes down: compare what it saw up to here.
        pulses_seen = Some(tap.frames().iter().filter_map(is_pulse).count());
        ip_link(&can.iface, "down");
        let s = op
            .wait_state(slow(1000), |s| s.state() == Ok(DeviceState::Fault))
            .unwrap_or_else(|| panic!("no safe state after link down\n{}", tail(&log)));
        assert_eq!(fault_code(&s), 0xFF26, "link down: {s:?}");
        std::thread::sleep(Duration::from_millis(200));
        assert!(driver.try_wait().unwrap().is_none(), "the driver survives");
        ip_link(&can.iface, "up");
        drop(tap);
        tap = Tap::open(&can.iface).expect("tap");
        std::thread::sleep(Duration::from_millis(300));
        assert_eq!(
            tap.frames().iter().filter_map(is_pulse).count(),
            0,
            "no PULSE once the link is back, before a re-arm"
        );
        op.arm(slow(5000), &log);
        tap.wait_for(0, Duration::from_secs(5), |f| is_pulse(f).is_some())
            .expect("pulses again after the re-arm");
        p.kill();
        println!("link down: safe state, driver alive, resumed only after re-arm");
    }
    // --- SIGTERM: NMT stop, exit 0. ----------------------------------------------------
    let start = tap.len();
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(driver.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = driver.wait().unwrap();
    assert!(status.success(), "exit status {status:?}\n{}", tail(&log));
    assert!(
        tap.wait_for(start, Duration::from_secs(2), is_stop)
            .is_some(),
        "NMT stop on SIGTERM"
    );
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(!text.contains("panicked"), "{text}");
    let on_tap = tap.frames().iter().filter_map(is_pulse).count();
    drop(tap);
    let summary = stimulator.stop();
    if let Some(mut candump) = candump.take() {
        let _ = candump.kill();
        let _ = candump.wait();
        let dump = std::fs::read_to_string(&candump_out).unwrap();
        let needle = format!(" {pulse_id:03X}#");
        let dumped = dump.lines().filter(|l| l.contains(&needle)).count();
        if let Some(on_tap) = pulses_seen {
            assert!(
                dumped >= on_tap,
                "candump saw {dumped} PULSE frames, the tap {on_tap}"
            );
        }
        println!("candump -L: {dumped} PULSE frames");
    }
    println!(
        "tap: {on_tap} PULSE frames since the last re-open; stimulator: {} pulses applied, {} missed ticks",
        summary.pulses_delivered, summary.missed_ticks
    );
    println!("{}", tail(&log));
}
