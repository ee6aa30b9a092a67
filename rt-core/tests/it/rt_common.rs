//! Helpers shared by the rt-core process tests: scratch directories, configurations,
//! starting rt-core and rt-probe, dropping real-time rights in a child.

use std::io::{BufRead, BufReader};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use fes_rt::rt::probe::{ProbeSummary, TickRecord, read_records};
use fes_rt::rt::{MissingRightsPolicy, RtConfig};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use rt_core::rt::process_config::{RtCoreConfig, SourceConfig};

pub const RT_CORE: &str = env!("CARGO_BIN_EXE_rt-core");
pub const RT_PROBE: &str = env!("CARGO_BIN_EXE_rt-probe");

pub use fes_testkit::Scratch;

/// A unique iceoryx2 prefix for one test.
pub fn prefix(name: &str) -> String {
    format!("t{}{}", std::process::id(), name)
}

/// A test configuration: test pattern, real-time best effort at a moderate priority, not
/// pinned (tests run in parallel), memory locked.
pub fn config(prefix: &str, ipi_ticks: u32) -> RtCoreConfig {
    let mut c = RtCoreConfig::with_source(SourceConfig::TestPattern { ipi_ticks });
    c.ipc.prefix = prefix.to_owned();
    c.rt = RtConfig {
        priority: 60,
        core: None,
        on_missing_rights: MissingRightsPolicy::BestEffort,
        lock_memory: true,
        prefault_stack_bytes: 128 * 1024,
        cpu_dma_latency_us: Some(0),
    };
    c.telemetry.report_period_ms = 100;
    c
}

pub fn write_config(dir: &Scratch, config: &RtCoreConfig) -> PathBuf {
    let path = dir.join("rt-core.toml");
    std::fs::write(&path, config.to_toml()).unwrap();
    path
}

/// Drops the rights to SCHED_FIFO in the child before exec: RLIMIT_RTPRIO = 0 and
/// CAP_SYS_NICE removed from the capability bounding set, so that even root comes out of
/// exec without it (the child stays root, so it can still use /tmp/iceoryx2).
pub fn without_rt_rights(cmd: &mut Command) -> &mut Command {
    // SAFETY: the closure runs between fork and exec and only makes two raw system calls
    // (setrlimit, prctl), both async-signal-safe; it touches no locks and no allocator.
    unsafe {
        cmd.pre_exec(|| {
            let zero = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            if libc::setrlimit(libc::RLIMIT_RTPRIO, &zero) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            const CAP_SYS_NICE: libc::c_ulong = 23;
            if libc::prctl(libc::PR_CAPBSET_DROP, CAP_SYS_NICE, 0, 0, 0) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        })
    }
}

/// A child process killed on drop if still running.
pub struct Proc {
    pub child: Child,
    pub name: &'static str,
}

impl Proc {
    pub fn pid(&self) -> Pid {
        Pid::from_raw(self.child.id() as i32)
    }

    pub fn signal(&self, s: Signal) {
        kill(self.pid(), s).unwrap();
    }

    pub fn wait_timeout(&mut self, timeout: Duration) -> ExitStatus {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                return s;
            }
            assert!(
                Instant::now() < deadline,
                "{} did not exit in {timeout:?}",
                self.name
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Waits and returns (status, stderr).
    pub fn finish(mut self, timeout: Duration) -> (ExitStatus, String) {
        let status = self.wait_timeout(timeout);
        let mut err = String::new();
        if let Some(mut e) = self.child.stderr.take() {
            use std::io::Read;
            let _ = e.read_to_string(&mut err);
        }
        (status, err)
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Starts rt-core with `config_path`; stderr is captured.
pub fn start_rt_core(config_path: &Path, drop_rights: bool) -> Proc {
    let mut cmd = Command::new(RT_CORE);
    cmd.arg("--config").arg(config_path).stderr(Stdio::piped());
    if drop_rights {
        without_rt_rights(&mut cmd);
    }
    Proc {
        child: cmd.spawn().unwrap(),
        name: "rt-core",
    }
}

/// Starts rt-probe recording every tick, and waits until it has subscribed.
pub fn start_probe(dir: &Scratch, prefix: &str) -> Proc {
    let mut child = Command::new(RT_PROBE)
        .arg("--prefix")
        .arg(prefix)
        .arg("--record")
        .arg(dir.join("ticks.csv"))
        .arg("--summary")
        .arg(dir.join("probe.json"))
        .arg("--hlog")
        .arg(dir.join("probe.hlog"))
        // Above rt-core's 60: tests run in parallel, and a probe that falls 64 ticks behind
        // loses ticks (safe overflow), which the tests would report as gaps.
        .args(["--priority", "70", "--idle-timeout-ms", "5000"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert_eq!(line.trim(), "ready");
    Proc {
        child,
        name: "rt-probe",
    }
}

pub fn read_summary(dir: &Scratch) -> ProbeSummary {
    serde_json::from_slice(&std::fs::read(dir.join("probe.json")).unwrap()).unwrap()
}

pub fn read_ticks(dir: &Scratch) -> Vec<TickRecord> {
    read_records(BufReader::new(
        std::fs::File::open(dir.join("ticks.csv")).unwrap(),
    ))
    .unwrap()
}

use fes_testkit::control;

/// Designs a controller for the control tests' fast-muscle-like LMN with `units` units
/// (thesis Table 6.1 rise times, xi = 1.2) through the control library, and writes it.
pub fn write_controller(path: &Path, units: usize) -> fes_model::control::file::Controller {
    write_controller_with(
        path,
        units,
        fes_model::control::file::ControllerSettings::default(),
    )
}

/// [`write_controller`] for the measured-force mode (estimator poles from a 5 ms rise time,
/// xi = 1.2, as in the control library's benchmark).
pub fn write_measured_controller(
    path: &Path,
    units: usize,
) -> fes_model::control::file::Controller {
    use fes_model::control::design::EstimatorPoles;
    use fes_model::control::file::ControllerSettings;
    use fes_model::control::pattern_generator::FeedbackMode;
    let [p1, p2] = fes_model::control::poles::dominant_pair(0.005, 1.2, control::TS).unwrap();
    write_controller_with(
        path,
        units,
        ControllerSettings {
            mode: FeedbackMode::MeasuredForce,
            estimator_poles: Some(EstimatorPoles { p1, p2 }),
            ..ControllerSettings::default()
        },
    )
}

fn write_controller_with(
    path: &Path,
    units: usize,
    settings: fes_model::control::file::ControllerSettings,
) -> fes_model::control::file::Controller {
    use fes_model::control::file::Controller;
    let controller = Controller::design(
        control::fast_muscle(units),
        &control::table_6_1_specs(units),
        settings,
    )
    .unwrap();
    controller.save(path).unwrap();
    controller
}
