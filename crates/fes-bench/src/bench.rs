//! The end-to-end bench: sim-muscle (the virtual stimulator and fast muscle on vcan),
//! stim-driver, rt-core with the default controller, and the supervisor daemon, started
//! as separate processes on one CAN interface, driven through the control socket.
//!
//! [`Stack`] starts, watches and stops the processes (tests use it to kill one mid-run);
//! `fes bench` (the workbench binary's `cmd::bench`) runs a cardiac profile for a set time,
//! stops everything and summarises the recording ([`crate::summary`]).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Proc, Stdio};
use std::time::{Duration, Instant};

use fes_model::control::file::{Controller, ControllerFileError};

use supervisor::control;
use supervisor::profile::ProfileSpec;
use supervisor::protocol::{Command, ProcessState, Response, Status};

/// A bench failure.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A file or process operation failed.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A binary is missing.
    #[error("{0} not found: build the workspace first (cargo build --release --workspace)")]
    MissingBinary(PathBuf),
    /// The default controller could not be loaded.
    #[error("controller {path}: {source}")]
    Controller {
        /// File.
        path: PathBuf,
        /// Why.
        #[source]
        source: ControllerFileError,
    },
    /// The supervisor's control socket did not answer in time.
    #[error("the supervisor's control socket {} did not answer; its log:\n{log}", socket.display())]
    NoAnswer {
        /// The socket.
        socket: PathBuf,
        /// The end of the supervisor's log.
        log: String,
    },
    /// A process exited while the stack ran.
    #[error("{name} exited unexpectedly; its log ({}):\n{tail}", log.display())]
    Exited {
        /// The process.
        name: &'static str,
        /// Its log file.
        log: PathBuf,
        /// The end of its log.
        tail: String,
    },
    /// The supervisor's status answer carried no state.
    #[error("status without state: {reason}")]
    NoState {
        /// The supervisor's error text, or "no reason given".
        reason: String,
    },
    /// Some processes never became healthy in time.
    #[error("the supervisor has not heard from every process: {}", waiting.join("; "))]
    NotHealthy {
        /// Each waiting process: name, state and detail.
        waiting: Vec<String>,
    },
    /// No process of that name in the stack.
    #[error("no process {0}")]
    NoProcess(String),
    /// A signal could not be sent.
    #[error("kill {name}: {source}")]
    Signal {
        /// The process.
        name: String,
        /// The OS error.
        #[source]
        source: nix::errno::Errno,
    },
    /// The supervisor refused a command.
    #[error("supervisor refused `{command}`: {reason}")]
    Refused {
        /// Command.
        command: String,
        /// Reason.
        reason: String,
    },
    /// Control socket.
    #[error("control socket: {0}")]
    Client(#[from] control::ClientError),
}

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> BenchError {
    let what = what.into();
    move |source| BenchError::Io { what, source }
}

/// The processes of the bench, upstream first.
pub const PROCESSES: [&str; 4] = ["sim-muscle", "stim-driver", "rt-core", "supervisor"];

/// What to run.
#[derive(Debug, Clone)]
pub struct StackOptions {
    /// Directory for configurations, logs and the recording.
    pub dir: PathBuf,
    /// Directory of the binaries (rt-core, stim-driver, sim-muscle, supervisor).
    pub bin_dir: PathBuf,
    /// Controller file (fes-lcn/1) for rt-core.
    pub controller: PathBuf,
    /// CAN interface.
    pub iface: String,
    /// The chain's timeouts, by the test bed (the bench's own, a shared host's functional
    /// tests, a UML guest).
    pub timing: ChainTiming,
    /// Fatigue in the muscle.
    pub fatigue: bool,
    /// The simulated muscle.
    pub preset: sim_muscle::preset::Preset,
    /// Outer loop at start.
    pub outer_loop: bool,
    /// Outer-loop gain per beat (None: the supervisor's default).
    pub outer_gain: Option<f64>,
    /// iceoryx2 prefix (unique per bench).
    pub prefix: String,
    /// Extra environment of each process, by process name (the fault suite's test-only
    /// switches, e.g. stim-driver's `FES_TEST_PANIC_REPORT_AFTER_MS`); empty for a bench.
    pub env: Vec<(&'static str, String, String)>,
    /// rt-core's `pulse.amplitude_ua` (None: its default, the prescription's 20 mA); the
    /// fault suite sets a slip.
    pub pulse_amplitude_ua: Option<u32>,
    /// The stimulator the driver drives: the CAN virtual stimulator on `iface`, or the
    /// virtual RehaStim 2 on a pty (ScienceMode 2; `iface` unused).
    pub stimulator: StimulatorKind,
    /// How the virtual RehaStim 2 behaves (ScienceMode only).
    pub rehastim2: Rehastim2Options,
}

/// The virtual RehaStim 2's behaviour beyond its defaults (`sim-muscle rehastim2`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Rehastim2Options {
    /// `--processing-ms`: mean time to process a command, answering -8 busy meanwhile
    /// (protocol §2.3, §5.1); 0 = answered at once.
    pub processing_ms: u16,
    /// `--motomed`: ActualValues every 20 ms, unasked (§3.5).
    pub motomed: bool,
}

/// Which virtual stimulator a stack runs (`fes bench --stimulator`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum StimulatorKind {
    /// `sim-muscle stimulator`: this project's CAN protocol, on `iface`; the driver
    /// publishes its FORCE frames as ForceSamples.
    #[default]
    Can,
    /// `sim-muscle rehastim2`: a Hasomed RehaStim 2 over ScienceMode 2 on a pty
    /// (docs/sciencemode.md). A RehaStim 2 measures no force: the virtual device publishes
    /// the muscle's (measured) force as ForceSamples itself, as the rig's separate force
    /// sensor would.
    Sciencemode,
}

impl StimulatorKind {
    /// The virtual RehaStim 2's pty link in stack directory `dir`.
    pub fn pty_link(dir: &Path) -> PathBuf {
        dir.join("ttyUSB0")
    }
}

/// The prescription every stack runs under: the rig's default (deploy/etc/fes).
pub const PRESCRIPTION: &str = include_str!("../../../deploy/etc/fes/prescription.toml");

struct Proc1 {
    name: &'static str,
    child: Child,
    log: PathBuf,
}

/// The running processes.
pub struct Stack {
    opts: StackOptions,
    procs: Vec<Proc1>,
    socket: PathBuf,
    scale_n: f64,
    delay: usize,
}

/// The chain's timeouts, by the test bed the stack runs on.
///
/// Functional tests judge what the chain does (which fault, who is named, nothing after
/// the stop), not how fast: on a shared 2-core VM the host alone stalls a SCHED_FIFO
/// thread for 20-35 ms now and then (cyclictest: 14 wake-ups over 10 ms and a maximum of
/// 30 ms in 30 s at a noisy hour), which trips the bench's 20 ms StimTick watchdog before
/// a case can inject its fault. Their timeouts sit above that noise; how fast the real
/// thresholds react is the latency suite's to judge, against cyclictest in the same run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChainTiming {
    /// `fes bench`: the driver's StimTick watchdog 20 ms, the stimulator's 100 ms.
    Bench,
    /// Functional tests on a shared host: every watchdog several times above the host's
    /// own stalls (StimTick 100 ms, stimulator 300 ms).
    Tolerant,
    /// Inside a User-Mode Linux guest, whose wake-ups are often milliseconds late and
    /// which stalls for seconds under four 1 kHz loops (functional only).
    Uml,
}

/// The timeouts of one [`ChainTiming`], in the units of the configuration keys they set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChainTimeouts {
    /// rt-core `reference.stale_after_ms`.
    pub reference_stale_ms: u64,
    /// stim-driver `watchdog.timeout_ticks` and `stale_after_ticks` (1 ms ticks).
    pub driver_tick_ticks: u32,
    /// The stimulator's heartbeat watchdog and the driver's `stimulator_timeout_ms`.
    pub stimulator_watchdog_ms: u32,
    /// stim-driver `watchdog.arm_confirm_ms`.
    pub arm_confirm_ms: u32,
    /// stim-driver `watchdog.command_max_age_ms`.
    pub command_max_age_ms: u32,
    /// stim-driver `interlocks.max_pulse_delay_us`.
    pub max_pulse_delay_us: u32,
    /// supervisor `health.stim_tick_timeout_ms`.
    pub stim_tick_timeout_ms: u64,
    /// supervisor `health.driver_status_timeout_ms`.
    pub driver_status_timeout_ms: u64,
    /// supervisor `health.force_timeout_ms`.
    pub force_timeout_ms: u64,
    /// supervisor `health.self_stall_ms`.
    pub self_stall_ms: u64,
    /// How long the supervisor's control socket may take to answer at start, s.
    pub start_s: u64,
}

impl ChainTiming {
    /// The timeouts of this test bed.
    pub const fn timeouts(self) -> ChainTimeouts {
        match self {
            ChainTiming::Bench => ChainTimeouts {
                reference_stale_ms: 100,
                driver_tick_ticks: 20,
                stimulator_watchdog_ms: 100,
                arm_confirm_ms: 200,
                command_max_age_ms: 100,
                max_pulse_delay_us: 500,
                stim_tick_timeout_ms: 50,
                driver_status_timeout_ms: 500,
                force_timeout_ms: 100,
                // A bench shares its machine with builds and editors: a second (the rig's
                // systemd unit keeps the default).
                self_stall_ms: 1000,
                start_s: 20,
            },
            ChainTiming::Tolerant => ChainTimeouts {
                reference_stale_ms: 300,
                driver_tick_ticks: 100,
                stimulator_watchdog_ms: 300,
                arm_confirm_ms: 500,
                command_max_age_ms: 500,
                max_pulse_delay_us: 500,
                stim_tick_timeout_ms: 200,
                driver_status_timeout_ms: 1000,
                force_timeout_ms: 300,
                self_stall_ms: 1000,
                start_s: 20,
            },
            ChainTiming::Uml => ChainTimeouts {
                reference_stale_ms: 1000,
                driver_tick_ticks: 500,
                stimulator_watchdog_ms: 3000,
                arm_confirm_ms: 2000,
                command_max_age_ms: 2000,
                // The most the stimulator's 1 ms minimum IPI allows against the 2 ms grid
                // minimum (stim-driver's configuration check): later pulses are refused.
                max_pulse_delay_us: 1000,
                stim_tick_timeout_ms: 1500,
                driver_status_timeout_ms: 3000,
                force_timeout_ms: 1500,
                self_stall_ms: 3000,
                start_s: 60,
            },
        }
    }
}

/// The last 1500 bytes of each process's log in the stack directory `dir`, each under a
/// `--- <name>.log` line, for error messages.
pub fn process_logs(dir: &Path) -> String {
    PROCESSES
        .iter()
        .map(|p| {
            format!(
                "--- {p}.log\n{}",
                log_tail(&dir.join(format!("{p}.log")), 1500)
            )
        })
        .collect()
}

/// The last `n` bytes of a log, for error messages.
pub fn log_tail(path: &Path, n: u64) -> String {
    let Ok(mut f) = File::open(path) else {
        return String::new();
    };
    let len = f.metadata().map_or(0, |m| m.len());
    let _ = f.seek(SeekFrom::Start(len.saturating_sub(n)));
    let mut s = String::new();
    let _ = f.read_to_string(&mut s);
    s
}

impl Stack {
    /// Writes the configurations and starts the four processes, upstream first; returns
    /// once the supervisor's control socket answers.
    pub fn start(opts: StackOptions) -> Result<Self, BenchError> {
        let d = &opts.dir;
        std::fs::create_dir_all(d).map_err(io(format!("create {}", d.display())))?;
        check_binaries(&opts.bin_dir)?;
        let controller =
            Controller::load(&opts.controller).map_err(|source| BenchError::Controller {
                path: opts.controller.clone(),
                source,
            })?;
        let scale_n = controller.lmn.force_scale_n;
        let delay = controller.lmn.delay;
        let t = opts.timing.timeouts();
        let controller_path = std::fs::canonicalize(&opts.controller)
            .map_err(io(format!("resolve {}", opts.controller.display())))?;
        write_config(d, "prescription.toml", PRESCRIPTION.to_owned())?;
        let rt_cfg = write_config(d, "rt-core.toml", rt_core_toml(&opts, &t, &controller_path))?;
        let drv_cfg = write_config(d, "stim-driver.toml", stim_driver_toml(&opts, &t, scale_n))?;
        let socket = d.join("supervisor.sock");
        let mut procs = vec![spawn(
            &opts,
            "sim-muscle",
            sim_muscle_args(&opts, &t, scale_n),
        )?];
        std::thread::sleep(Duration::from_millis(300));
        if opts.stimulator == StimulatorKind::Sciencemode {
            // The driver opens the device's pty at start: wait for its link.
            let link = StimulatorKind::pty_link(d);
            let deadline = Instant::now() + Duration::from_secs(t.start_s);
            while !link.exists() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        let sim_pid = procs[0].child.id();
        let sup = SupervisorConfig {
            socket: &socket,
            delay,
            sim_pid,
            scale_n,
        };
        let sup_cfg = write_config(d, "supervisor.toml", supervisor_toml(&opts, &t, &sup))?;
        procs.push(spawn(
            &opts,
            "stim-driver",
            config_args(Some("run"), &drv_cfg),
        )?);
        procs.push(spawn(&opts, "rt-core", config_args(None, &rt_cfg))?);
        procs.push(spawn(
            &opts,
            "supervisor",
            config_args(Some("run"), &sup_cfg),
        )?);
        let stack = Self {
            opts,
            procs,
            socket,
            scale_n,
            delay,
        };
        stack.wait_for_control(Duration::from_secs(t.start_s))?;
        Ok(stack)
    }

    /// Waits until the supervisor's control socket answers (or `timeout`), failing early
    /// when a process has exited.
    fn wait_for_control(&self, timeout: Duration) -> Result<(), BenchError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.check_alive()?;
            if self.socket.exists() && self.command(Command::Status).is_ok() {
                return Ok(());
            }
            if Instant::now() > deadline {
                return Err(BenchError::NoAnswer {
                    socket: self.socket.clone(),
                    log: log_tail(&self.procs[3].log, 2000),
                });
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Newtons per normalised force of the controller's model.
    pub fn scale_n(&self) -> f64 {
        self.scale_n
    }

    /// The controller model's delay, samples.
    pub fn delay(&self) -> usize {
        self.delay
    }

    /// The options.
    pub fn options(&self) -> &StackOptions {
        &self.opts
    }

    /// Process id of a process by name.
    pub fn pid(&self, name: &str) -> Option<u32> {
        self.procs
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.child.id())
    }

    /// Fails with the log of the first process that has exited.
    pub fn check_alive(&self) -> Result<(), BenchError> {
        for p in &self.procs {
            if !Path::new(&format!("/proc/{}", p.child.id())).exists()
                || std::fs::read_to_string(format!("/proc/{}/stat", p.child.id())).is_ok_and(|s| {
                    s.rsplit(')')
                        .next()
                        .is_some_and(|r| r.trim_start().starts_with('Z'))
                })
            {
                return Err(BenchError::Exited {
                    name: p.name,
                    log: p.log.clone(),
                    tail: log_tail(&p.log, 3000),
                });
            }
        }
        Ok(())
    }

    /// Sends a command to the supervisor.
    pub fn command(&self, c: Command) -> Result<Response, BenchError> {
        Ok(control::request(&self.socket, c, Duration::from_secs(10))?)
    }

    /// Sends a command that must be accepted.
    pub fn must(&self, c: Command) -> Result<Response, BenchError> {
        let name = c.name().to_string();
        let r = self.command(c)?;
        if !r.ok {
            return Err(BenchError::Refused {
                command: name,
                reason: r.error.unwrap_or_default(),
            });
        }
        Ok(r)
    }

    /// Arms stimulation and starts `profile` (both must be accepted), once the driver
    /// reports itself armed.
    ///
    /// The supervisor answers an Arm when it has queued it, not when the driver has acted
    /// on it: a driver that has not yet seen rt-core's
    /// StimTick publisher alive refuses it and only logs why (seen once in a full test run:
    /// the Arm 14 ms before the driver's liveness check saw rt-core; the stack then never
    /// stimulated). Until the supervisor waits for the driver's answer itself, the bench
    /// checks the DriverStatus and arms again (stop, arm) when the driver stays disarmed.
    pub fn arm_with(&self, profile: ProfileSpec) -> Result<(), BenchError> {
        let armed = |s: &Status| matches!(s.driver_state.as_deref(), Some("Armed" | "Stimulating"));
        let mut last = None;
        for attempt in 0..3 {
            if attempt > 0 {
                self.must(Command::Stop)?;
            }
            self.must(Command::Arm)?;
            let deadline = Instant::now() + Duration::from_millis(600);
            loop {
                let s = self.status()?;
                if armed(&s) {
                    self.must(Command::Profile { profile })?;
                    return Ok(());
                }
                last = s.driver_state;
                if Instant::now() > deadline {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
        Err(BenchError::Refused {
            command: "arm".into(),
            reason: format!(
                "the driver did not arm in three attempts (driver state {})",
                last.as_deref().unwrap_or("unknown")
            ),
        })
    }

    /// The supervisor's status.
    pub fn status(&self) -> Result<Status, BenchError> {
        let r = self.command(Command::Status)?;
        r.status.ok_or_else(|| BenchError::NoState {
            reason: r.error.as_deref().unwrap_or("no reason given").to_owned(),
        })
    }

    /// Waits until the supervisor has heard from every process (or `timeout`).
    pub fn wait_healthy(&self, timeout: Duration) -> Result<Status, BenchError> {
        let deadline = Instant::now() + timeout;
        loop {
            self.check_alive()?;
            let s = self.status()?;
            if s.processes.iter().all(|p| p.state == ProcessState::Ok) {
                return Ok(s);
            }
            if Instant::now() > deadline {
                let waiting: Vec<String> = s
                    .processes
                    .iter()
                    .filter(|p| p.state != ProcessState::Ok)
                    .map(|p| format!("{} {} {}", p.name, p.state, p.detail))
                    .collect();
                return Err(BenchError::NotHealthy { waiting });
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// Sends `signal` to the process `name`.
    pub fn signal(&self, name: &str, signal: nix::sys::signal::Signal) -> Result<(), BenchError> {
        let pid = self
            .pid(name)
            .ok_or_else(|| BenchError::NoProcess(name.to_owned()))?;
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), signal).map_err(|source| {
            BenchError::Signal {
                name: name.to_owned(),
                source,
            }
        })
    }

    /// Stops every process: the supervisor first (it closes the recording), then rt-core,
    /// stim-driver and sim-muscle; SIGTERM, then SIGKILL after `grace`. Returns each
    /// process's exit status (None when it had to be killed or was already reaped).
    pub fn stop(mut self, grace: Duration) -> Vec<(&'static str, Option<i32>)> {
        let mut out = Vec::new();
        for name in ["supervisor", "rt-core", "stim-driver", "sim-muscle"] {
            let Some(i) = self.procs.iter().position(|p| p.name == name) else {
                continue;
            };
            let mut p = self.procs.remove(i);
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(p.child.id() as i32),
                nix::sys::signal::Signal::SIGTERM,
            );
            let deadline = Instant::now() + grace;
            let code = loop {
                match p.child.try_wait() {
                    Ok(Some(s)) => break s.code(),
                    Ok(None) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(20))
                    }
                    _ => {
                        let _ = p.child.kill();
                        let _ = p.child.wait();
                        break None;
                    }
                }
            };
            out.push((p.name, code));
        }
        out
    }

    /// The recording directories the supervisor wrote.
    pub fn recordings(&self) -> Vec<PathBuf> {
        recordings_in(&self.opts.dir.join("recording"))
    }
}

impl Drop for Stack {
    fn drop(&mut self) {
        for p in &mut self.procs {
            let _ = p.child.kill();
            let _ = p.child.wait();
        }
    }
}

/// Fails naming the first of the four binaries missing from `bin_dir`.
fn check_binaries(bin_dir: &Path) -> Result<(), BenchError> {
    for b in PROCESSES {
        let p = bin_dir.join(b);
        if !p.is_file() {
            return Err(BenchError::MissingBinary(p));
        }
    }
    Ok(())
}

/// Writes the configuration file `name` into `dir`; returns its path.
fn write_config(dir: &Path, name: &str, text: String) -> Result<PathBuf, BenchError> {
    let p = dir.join(name);
    std::fs::write(&p, text).map_err(io(format!("write {}", p.display())))?;
    Ok(p)
}

/// Starts `name` from the binary directory with `args`, its stdout and stderr into
/// `<name>.log` in the stack directory.
fn spawn(opts: &StackOptions, name: &'static str, args: Vec<String>) -> Result<Proc1, BenchError> {
    let log = opts.dir.join(format!("{name}.log"));
    let out = File::create(&log).map_err(io(format!("create {}", log.display())))?;
    let err = out.try_clone().map_err(io("log"))?;
    let child = Proc::new(opts.bin_dir.join(name))
        .args(&args)
        .envs(
            opts.env
                .iter()
                .filter(|(process, _, _)| *process == name)
                .map(|(_, k, v)| (k, v)),
        )
        .stdin(Stdio::null())
        .stdout(out)
        .stderr(err)
        .spawn()
        .map_err(io(format!("start {name}")))?;
    Ok(Proc1 { name, child, log })
}

/// `[command] --config <path>`.
fn config_args(command: Option<&str>, config: &Path) -> Vec<String> {
    command
        .into_iter()
        .map(String::from)
        .chain(["--config".into(), config.display().to_string()])
        .collect()
}

/// sim-muscle's name of a preset.
fn preset_name(p: sim_muscle::preset::Preset) -> &'static str {
    p.name()
}

/// The virtual stimulator and the muscle on the stack's interface, recording what it
/// receives.
fn sim_muscle_args(opts: &StackOptions, t: &ChainTimeouts, scale_n: f64) -> Vec<String> {
    if opts.stimulator == StimulatorKind::Sciencemode {
        // The same muscle and force sensor as the CAN stimulator's; the force goes out as
        // ForceSamples normalised by the driver's [force] max_n on CAN (the controller's
        // full scale). The device's watchdog stays its own (1.2 s, §2.3 of the protocol).
        let mut args: Vec<String> = vec![
            "rehastim2".into(),
            "--pty-link".into(),
            StimulatorKind::pty_link(&opts.dir).display().to_string(),
            "--pulse-log".into(),
            opts.dir.join("stimulator.csv").display().to_string(),
            "--preset".into(),
            preset_name(opts.preset).into(),
            "--measured".into(),
            "--offset-n".into(),
            "0".into(),
            "--force-prefix".into(),
            opts.prefix.clone(),
            "--force-max-n".into(),
            scale_n.to_string(),
        ];
        if opts.fatigue {
            args.push("--fatigue".into());
        }
        // Always stated: the device's own default is the documented device.
        args.push("--processing-ms".into());
        args.push(opts.rehastim2.processing_ms.to_string());
        if opts.rehastim2.motomed {
            args.push("--motomed".into());
        }
        return args;
    }
    let mut args: Vec<String> = vec![
        "stimulator".into(),
        "--iface".into(),
        opts.iface.clone(),
        "--preset".into(),
        preset_name(opts.preset).into(),
        "--measured".into(),
        "--offset-n".into(),
        "0".into(),
        "--watchdog-ms".into(),
        t.stimulator_watchdog_ms.to_string(),
        "--record".into(),
        opts.dir.join("stimulator.csv").display().to_string(),
    ];
    if opts.fatigue {
        args.push("--fatigue".into());
    }
    args
}

/// `rt-core.toml`: the controller file, the reference's staleness limit, telemetry and
/// the iceoryx2 prefix.
fn rt_core_toml(opts: &StackOptions, t: &ChainTimeouts, controller: &Path) -> String {
    format!(
        r#"schema = "fes-rt-core/1"
period_us = 1000
prescription = "prescription.toml"

[source]
kind = "controller"
path = "{controller}"

[rt]
priority = 80
on_missing_rights = "best-effort"

[reference]
stale_after_ms = {stale_ms}
stale_ramp_per_s = 2.0

[pulse]
amplitude_ua = {amplitude_ua}

[telemetry]
hlog = "{dir}/rt-core.hlog"
report_period_ms = 1000

[ipc]
prefix = "{prefix}"
"#,
        controller = controller.display(),
        stale_ms = t.reference_stale_ms,
        amplitude_ua = opts.pulse_amplitude_ua.unwrap_or(20_000),
        dir = opts.dir.display(),
        prefix = opts.prefix,
    )
}

/// `stim-driver.toml`: the prescription, the CAN interface, the dose-bound limits, the
/// interlocks and watchdogs of the test bed, the
/// force limit (the controller model's full scale), telemetry and the iceoryx2 prefix.
fn stim_driver_toml(opts: &StackOptions, t: &ChainTimeouts, scale_n: f64) -> String {
    let transport = match opts.stimulator {
        StimulatorKind::Can => format!("[can]\niface = \"{}\"\n", opts.iface),
        StimulatorKind::Sciencemode => format!(
            "[transport]\nkind = \"sciencemode\"\ndevice = \"{}\"\n",
            StimulatorKind::pty_link(&opts.dir).display()
        ),
    };
    format!(
        r#"schema = "fes-stim-driver/1"
prescription = "prescription.toml"

{transport}
[stimulator]
watchdog_ms = {stim_wd}
max_amplitude_ua = 20000
max_width_us = 200
max_charge_nc = 4000

[interlocks]
max_pulse_delay_us = {late_us}
max_amplitude_ua = 20000
max_width_us = 200
max_charge_nc = 4000

[watchdog]
timeout_ticks = {drv_ticks}
stale_after_ticks = {drv_ticks}
{stim_timeout}arm_confirm_ms = {arm_ms}
command_max_age_ms = {cmd_age}

[force]
max_n = {scale_n}

[rt]
priority = 79
on_missing_rights = "best-effort"

[telemetry]
hlog = "{dir}/stim-driver.hlog"

[ipc]
prefix = "{prefix}"
"#,
        stim_wd = t.stimulator_watchdog_ms,
        stim_timeout = match opts.stimulator {
            StimulatorKind::Can =>
                format!("stimulator_timeout_ms = {}\n", t.stimulator_watchdog_ms),
            // The driver's default for a RehaStim 2: its longest answer (100 ms, §2.3 of
            // the protocol) plus two liveness periods.
            StimulatorKind::Sciencemode => String::new(),
        },
        drv_ticks = t.driver_tick_ticks,
        arm_ms = t.arm_confirm_ms,
        late_us = t.max_pulse_delay_us,
        cmd_age = t.command_max_age_ms,
        dir = opts.dir.display(),
        prefix = opts.prefix,
    )
}

/// What the supervisor's configuration takes from the running stack.
struct SupervisorConfig<'a> {
    /// Its control socket.
    socket: &'a Path,
    /// The controller model's delay, samples (= ms).
    delay: usize,
    /// The virtual stimulator's process id (its health watches it).
    sim_pid: u32,
    /// Newtons per normalised force (the recording's scale).
    scale_n: f64,
}

/// `supervisor.toml`: control socket, outer loop, contraction delay, health timeouts of
/// the test bed, the stimulator's pid, the recording and the iceoryx2 prefix.
fn supervisor_toml(opts: &StackOptions, t: &ChainTimeouts, s: &SupervisorConfig<'_>) -> String {
    format!(
        r#"schema = "fes-supervisor/1"

[ipc]
prefix = "{prefix}"

[control]
socket = "{socket}"

[outer_loop]
enabled = {outer}{gain}

[contraction]
delay_ms = {delay}.0

[health]
stim_tick_timeout_ms = {tick_to}
driver_status_timeout_ms = {status_to}
force_timeout_ms = {force_to}
self_stall_ms = {self_stall}
stimulator_pid = {sim_pid}

[recording]
dir = "{dir}/recording"
scale_n = {scale_n}
source = "fes bench"
prescription = "prescription.toml"
"#,
        prefix = opts.prefix,
        socket = s.socket.display(),
        tick_to = t.stim_tick_timeout_ms,
        status_to = t.driver_status_timeout_ms,
        force_to = t.force_timeout_ms,
        self_stall = t.self_stall_ms,
        sim_pid = s.sim_pid,
        delay = s.delay,
        scale_n = s.scale_n,
        outer = opts.outer_loop,
        gain = opts
            .outer_gain
            .map_or(String::new(), |g| format!("\ngain = {g:?}")),
        dir = opts.dir.display(),
    )
}

/// Run directories under `root`, oldest first.
pub fn recordings_in(root: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root)
        .map(|r| {
            r.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_dir())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}
