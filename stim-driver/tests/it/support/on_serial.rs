//! The `stim-driver` binary on the ScienceMode 2 transport: the scripted
//! StimTick publisher of [`crate::on_bus`] (a separate process), the driver process with
//! `[transport] kind = "sciencemode"`, and the virtual RehaStim 2 (`sim-muscle
//! rehastim2`'s code, in a thread of this process, on a pseudo-terminal, with the
//! charge-integrator plant) as its peer. The test process arms the driver through
//! DriverCommand and reads its DriverStatus like the supervisor does.
//!
//! Independent truths: the publisher prints every pulse decision it published and gives
//! pulse `j` the current `10 + j mod 50` mA ([`crate::on_bus::amplitude_ma`]), so each row
//! of the device's pulse log names the decision it carries; the device's own pulse log is
//! what was delivered.

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fes_rt::msg::{DeviceState, DriverStatus};
use fes_virtual_stimulator::rehastim2::{Rehastim2Settings, TestFault};
use fes_virtual_stimulator::rehastim2_pty::{PtyRunSummary, Rehastim2Args, run_rehastim2_until};
use fes_virtual_stimulator::test_plant::ChargeIntegrator;

use crate::on_bus::{Decision, EXE, Operator, PRESCRIPTION, Publisher, amplitude_ma, tail};

/// The final tick's fault (the generator stopped).
pub const GENERATOR_STOPPED: u16 = DriverStatus::FAULT_GENERATOR_STOPPED;

/// One pulse row of the device's log: device time (ms since it started), current (mA).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoggedPulse {
    pub t_ms: u64,
    pub current_ma: u32,
}

/// How the virtual RehaStim 2 behaves beyond the document's defaults.
#[derive(Debug, Clone, Copy, Default)]
pub struct DeviceOptions {
    /// A fault to inject.
    pub test_fault: Option<TestFault>,
    /// Every command executed and answered this late (a pipelined device), ms.
    pub latency_ms: u16,
    /// ActualValues every 20 ms (a MOTOmed attached).
    pub motomed: bool,
    /// Mean processing time per command, answering -8 busy meanwhile (§5.1), ms.
    pub processing_ms: u16,
}

/// The virtual RehaStim 2 in a thread of this process.
pub struct Device {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<PtyRunSummary>>,
    pub link: PathBuf,
    pub log: PathBuf,
}

impl Device {
    pub fn start(dir: &Path, options: DeviceOptions) -> Self {
        let DeviceOptions {
            test_fault,
            latency_ms,
            motomed,
            processing_ms,
        } = options;
        let link = dir.join("ttyUSB0");
        let log = dir.join("pulses.csv");
        let args = Rehastim2Args {
            pty_link: link.clone(),
            pulse_log: Some(log.clone()),
            watchdog_ms: Rehastim2Settings::DEFAULT.watchdog_ms,
            init_period_ms: Rehastim2Settings::DEFAULT.init_period_ms,
            muscle_channel: 1,
            duration_s: None,
            test_fault,
            latency_ms,
            motomed,
            processing_ms,
            force_prefix: None,
            force_max_n: None,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut plant = ChargeIntegrator::new();
            run_rehastim2_until(&args, &mut plant, &s).expect("the virtual RehaStim 2")
        });
        let deadline = Instant::now() + Duration::from_secs(5);
        while !link.exists() {
            assert!(
                Instant::now() < deadline,
                "the device's pty link did not appear"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
        Self {
            stop,
            thread: Some(thread),
            link,
            log,
        }
    }

    /// The pulses the device delivered so far, in order.
    pub fn pulses(&self) -> Vec<LoggedPulse> {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        text.lines()
            .skip(1)
            .filter_map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (f.get(1) == Some(&"pulse")).then(|| LoggedPulse {
                    t_ms: f[0].parse().unwrap(),
                    current_ma: f[4].parse().unwrap(),
                })
            })
            .collect()
    }

    /// Switches the device off (its pty closes: the driver's port reads EIO).
    pub fn stop(&mut self) -> Option<PtyRunSummary> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .take()
            .map(|t| t.join().expect("the device thread"))
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The configuration of these scenarios: the host-bus scenarios' generous watchdogs
/// (a shared 2-core host stalls a 1 ms loop by tens of ms at times), the ScienceMode
/// transport on the device's pty, polling every 20 ms (a lost device is seen within the
/// 300 ms stimulator timeout) or, with `shipped_polling`, as shipped (`poll_ms` and the
/// stimulator timeout left to their defaults: a query only in the pauses between
/// contractions, as a document-faithful device needs).
pub fn write_config(dir: &Path, device: &Path, prefix: &str, shipped_polling: bool) -> PathBuf {
    let (poll, stimulator_timeout) = if shipped_polling {
        ("", "")
    } else {
        ("poll_ms = 20\n", "stimulator_timeout_ms = 300\n")
    };
    let path = dir.join("stim-driver.toml");
    std::fs::write(dir.join("prescription.toml"), PRESCRIPTION).expect("write the prescription");
    std::fs::write(
        &path,
        format!(
            r#"schema = "fes-stim-driver/1"
prescription = "prescription.toml"
[transport]
kind = "sciencemode"
device = "{device}"
{poll}[stimulator]
min_ipi_ms = 1
[interlocks]
min_ipi_us = 2000
max_pulse_delay_us = 500
[watchdog]
timeout_ticks = 100
stale_after_ticks = 100
{stimulator_timeout}arm_confirm_ms = 500
command_max_age_ms = 500
[force]
max_n = 40.0
[rt]
priority = 79
on_missing_rights = "best-effort"
[bus_rt]
priority = 70
on_missing_rights = "best-effort"
[ipc]
prefix = "{prefix}"
"#,
            device = device.display(),
        ),
    )
    .expect("write the configuration");
    path
}

/// The driver process, the device and an operator, the driver up and disarmed.
pub struct Rig {
    /// Removed (when the test passed) after the driver and the device are stopped.
    _dir: fes_testkit::Scratch,
    pub prefix: String,
    pub device: Device,
    pub driver: Child,
    pub op: Operator,
    pub log: PathBuf,
}

impl Rig {
    pub fn start(name: &str) -> Self {
        Self::start_with(name, None, 0)
    }

    /// [`Rig::start`] with a device that injects `fault` and takes `latency_ms` to execute
    /// a command.
    pub fn start_with(name: &str, fault: Option<TestFault>, latency_ms: u16) -> Self {
        Self::start_device(
            name,
            DeviceOptions {
                test_fault: fault,
                latency_ms,
                ..DeviceOptions::default()
            },
        )
    }

    /// [`Rig::start`] with a MOTOmed attached to the device: ActualValues every 20 ms
    /// (`sim-muscle rehastim2 --motomed`).
    pub fn start_with_motomed(name: &str) -> Self {
        Self::start_device(
            name,
            DeviceOptions {
                motomed: true,
                ..DeviceOptions::default()
            },
        )
    }

    /// [`Rig::start`] with a device that processes each command for `processing_ms` on
    /// average and answers -8 busy to any command meanwhile (§5.1; `sim-muscle rehastim2
    /// --processing-ms`), and the driver polling it as shipped.
    pub fn start_with_processing(name: &str, processing_ms: u16) -> Self {
        Self::start_device(
            name,
            DeviceOptions {
                processing_ms,
                ..DeviceOptions::default()
            },
        )
    }

    fn start_device(name: &str, options: DeviceOptions) -> Self {
        let pid = std::process::id();
        let prefix = format!("sds{pid}{name}");
        let dir = fes_testkit::Scratch::new(&format!("stim-driver-serial-{name}"));
        let device = Device::start(&dir, options);
        let config = write_config(&dir, &device.link, &prefix, options.processing_ms > 0);
        let log = dir.join("driver.log");
        let log_file = std::fs::File::create(&log).unwrap();
        let driver = fes_testkit::child::dies_with_parent(&mut Command::new(EXE))
            .args(["run", "--config"])
            .arg(&config)
            .env_remove("FES_CAN_IFACE")
            .env("RUST_LOG", "info")
            .stdout(log_file.try_clone().unwrap())
            .stderr(log_file)
            .spawn()
            .expect("start stim-driver");
        let mut op = Operator::new(&prefix);
        // Disarmed = the handshake done, the device seen outside channel list mode, the
        // configuration confirmed and read back (docs/sciencemode.md).
        op.wait_state(Duration::from_secs(10), |s| {
            s.state() == Ok(DeviceState::PreOperational)
        })
        .unwrap_or_else(|| panic!("the driver did not come up disarmed\n{}", tail(&log)));
        Self {
            _dir: dir,
            prefix,
            device,
            driver,
            op,
            log,
        }
    }

    /// Waits for the safe state; its fault code.
    pub fn wait_fault(&mut self, timeout: Duration) -> DriverStatus {
        self.op
            .wait_state(timeout, |s| s.state() == Ok(DeviceState::Fault))
            .unwrap_or_else(|| {
                panic!(
                    "no safe state within {timeout:?}: {:?}\n{}",
                    self.op.status(),
                    tail(&self.log)
                )
            })
    }

    /// The driver's log.
    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The decisions the driver's log reports dropped as late (the device still busy
    /// with the previous command beyond the lateness bound).
    pub fn reported_late(&self, decisions: &[Decision]) -> u64 {
        let log = self.log_text();
        decisions
            .iter()
            .filter(|d| log.contains(&format!("pulse of tick {} NOT sent", d.seq)))
            .count() as u64
    }

    /// Stops the driver (SIGTERM) and returns the count of acknowledged pulses its final
    /// line reports ("N pulses sent (M applied by the stimulator ...": M, the delivered
    /// count of its last STATUS).
    pub fn stop_driver_applied(&mut self) -> Option<u64> {
        // SAFETY: kill(2) on the driver's pid, a child of this process not yet reaped.
        unsafe { libc::kill(self.driver.id() as i32, libc::SIGTERM) };
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.driver.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.log_text()
            .lines()
            .filter(|l| l.contains("final: "))
            .filter_map(|l| {
                let (_, tail) = l.split_once(" pulses sent (")?;
                tail.split_whitespace().next()?.parse().ok()
            })
            .next_back()
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        // SIGTERM: the driver's orderly stop (it is killed with the test otherwise).
        // SAFETY: kill(2) on the driver's pid, a child of this process not yet reaped.
        unsafe { libc::kill(self.driver.id() as i32, libc::SIGTERM) };
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.driver.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
        self.device.stop();
    }
}

/// Sends `signal` to the driver process.
pub fn signal_driver(rig: &Rig, signal: i32) {
    // SAFETY: kill(2) on the driver's pid, a child of this process not yet reaped.
    let rc = unsafe { libc::kill(rig.driver.id() as i32, signal) };
    assert_eq!(rc, 0, "kill({signal})");
}

/// Matches the device's pulses to the decisions, in order, by current: the decision
/// index of each (a pulse matching no later decision panics).
pub fn decisions_delivered(pulses: &[LoggedPulse], decisions: &[Decision]) -> Vec<u64> {
    let mut next = 0;
    pulses
        .iter()
        .map(|p| {
            let d = decisions[next..]
                .iter()
                .find(|d| amplitude_ma(d.j) == p.current_ma)
                .unwrap_or_else(|| panic!("pulse {p:?} is no decision after {next}"));
            next = d.j as usize + 1;
            d.j
        })
        .collect()
}

/// Runs the publisher's `script` armed until its final tick; retried (at most 3 times)
/// when the shared host's noise trips the driver first (a stale tick or the StimTick
/// watchdog: correct behaviour, but not the scenario). The decisions, the final
/// DriverStatus, and the device's pulses before the run.
pub fn run_armed(
    rig: &mut Rig,
    script: &str,
) -> (Vec<Decision>, DriverStatus, DriverStatus, usize) {
    let mut voided = Vec::new();
    for attempt in 1..=3 {
        let mut p = Publisher::start(&rig.prefix, script);
        rig.op.arm(Duration::from_secs(5), &rig.log);
        let before = rig.op.status().unwrap();
        let pulses_before = rig.device.pulses().len();
        p.go();
        let decisions = p.finish(Duration::from_secs(60));
        let s = rig.wait_fault(Duration::from_secs(5));
        let noise = [
            DriverStatus::FAULT_STALE_TICK,
            DriverStatus::FAULT_TICK_TIMEOUT,
        ];
        if noise.contains(&s.fault_code) && attempt < 3 {
            println!(
                "run {attempt} void: fault {:#06x} (host noise)",
                s.fault_code
            );
            voided.push(s.fault_code);
            continue;
        }
        assert_eq!(
            s.fault_code,
            GENERATOR_STOPPED,
            "the final tick, not another fault (voided {voided:04x?}): {s:?}\n{}",
            tail(&rig.log)
        );
        return (decisions, before, s, pulses_before);
    }
    unreachable!()
}
