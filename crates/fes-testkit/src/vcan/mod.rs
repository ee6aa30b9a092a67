//! The vcan harness: every CAN test of the workspace runs through it.
//!
//! It picks, once per process:
//!
//! 1. **inside**: `FES_VCAN_IFACE` is set, i.e. this process already runs in a prepared
//!    environment (a UML guest, or under `vcan-run`): use that interface;
//! 2. **native, given interface**: `CAN_IFACE` names an existing CAN interface that is
//!    up (real hardware such as `can0`, or a vcan you made): use it, never anything else;
//! 3. **native vcan**: `vcan0` exists and is up, or `modprobe vcan` + `ip link add dev
//!    vcan0 type vcan` + `ip link set up vcan0` work (a kernel with CAN, run as root);
//! 4. **UML**: a User-Mode Linux guest with the host filesystem and its own `vcan0`
//!    (see `docs/vcan.md`);
//!
//! and fails loudly, naming what it tried, when none works: a CAN test never skips.
//! `FES_VCAN_BACKEND=native|uml` forces a backend (default `auto`).
//!
//! In a `#[test]`, wrap the whole body in [`with_vcan`]. On the UML path the host side
//! re-executes the current test binary inside the guest with
//! `<test name> --exact --nocapture --test-threads=1 --include-ignored`; the guest side sees
//! `FES_VCAN_IFACE` and runs the body. The guest's output is streamed into the test's
//! output and a failure inside fails the test. Because the whole test re-runs in the
//! guest, call `with_vcan` once, as the test's entire body.

use std::path::PathBuf;
use std::sync::OnceLock;
use std::time::Duration;

mod native;
mod process;
mod shell;
mod uml;
pub use uml::{
    GUEST_GLIBC_TUNABLES as UML_GUEST_GLIBC_TUNABLES, MODULES as UML_CAN_MODULES,
    MODULES_ROOT as UML_MODULES_ROOT, kernel_command as uml_kernel_command,
};

/// Set in a prepared environment: the CAN interface to use ("inside" mode).
pub const ENV_IFACE: &str = "FES_VCAN_IFACE";
/// Requests a backend (`auto`, `native`, `uml`); inside a guest it reads `uml`.
pub const ENV_BACKEND: &str = "FES_VCAN_BACKEND";
/// An existing CAN interface to test against natively (e.g. `can0`).
pub const ENV_CAN_IFACE: &str = "CAN_IFACE";
/// Per-run timeout in seconds (default 300).
pub const ENV_TIMEOUT: &str = "FES_VCAN_TIMEOUT_S";
/// Marks this process's guest run, so the host recognises the guest's markers.
const ENV_NONCE: &str = "FES_VCAN_NONCE";

const DEFAULT_TIMEOUT: Duration = Duration::from_secs(300);

/// Where the CAN bus comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// The host kernel's interface.
    Native,
    /// A User-Mode Linux guest's `vcan0`.
    Uml,
    /// The host bus (`fes_hostbus`, `hostbus:<dir>`): the CAN frames over Unix
    /// datagrams, on the host; not CAN (no `ip link`, no candump). For whole-stack tests
    /// on hosts without CAN, at the host's timing (docs/vcan.md).
    HostBus,
}

impl CanEnv {
    /// A fresh host bus in a temporary directory named after `tag` and this process.
    pub fn host_bus(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("fes-hostbus-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        Self {
            iface: format!("{}{}", fes_hostbus::SCHEME, dir.display()),
            backend: Backend::HostBus,
        }
    }
}

/// The CAN environment a test body runs in.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanEnv {
    /// Interface name (e.g. `vcan0`, `can0`).
    pub iface: String,
    /// Where it lives; timing checks should allow more slack under [`Backend::Uml`].
    pub backend: Backend,
}

/// Harness failures; each says what was tried and what to do.
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// Neither native vcan nor UML is available.
    #[error(
        "no CAN interface for the CAN tests.\n  native vcan: {native}\n  User-Mode Linux: {uml}\n\
         Fix: on a kernel with CAN run as root (`modprobe vcan`), or install the Debian packages \
         `user-mode-linux can-utils kmod` (scripts/setup does); see docs/vcan.md"
    )]
    NoCan {
        /// Why native vcan is unavailable.
        native: String,
        /// Why UML is unavailable.
        uml: String,
    },
    /// `CAN_IFACE` names an interface that cannot be used.
    #[error("CAN_IFACE={iface}: {reason}")]
    IfaceUnusable {
        /// The interface.
        iface: String,
        /// Why.
        reason: String,
    },
    /// `FES_VCAN_BACKEND` or another harness variable has a bad value.
    #[error("{var}={value:?}: {expected}")]
    BadEnv {
        /// Variable name.
        var: &'static str,
        /// Its value.
        value: String,
        /// What is accepted.
        expected: &'static str,
    },
    /// A program could not be started.
    #[error("starting {what}: {source}")]
    Spawn {
        /// What.
        what: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// A file operation failed.
    #[error("{what}: {source}")]
    Io {
        /// What.
        what: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// A path is not valid UTF-8 (it could not be written into the guest script).
    #[error("path {0:?} is not valid UTF-8")]
    BadPath(PathBuf),
    /// The guest failed while preparing CAN.
    #[error("UML guest setup failed at: {step}\n--- guest boot log ---\n{log}")]
    GuestSetup {
        /// The step that failed.
        step: String,
        /// The end of the boot log.
        log: String,
    },
    /// The guest stopped without reporting the command's exit status.
    #[error("UML guest ended without reporting an exit status\n--- guest log ---\n{log}")]
    GuestCrashed {
        /// The end of the guest's output.
        log: String,
    },
    /// The run exceeded its timeout and was killed.
    #[error("CAN run killed after {after:?} (FES_VCAN_TIMEOUT_S)\n--- output ---\n{log}")]
    Timeout {
        /// The timeout.
        after: Duration,
        /// The end of the output.
        log: String,
    },
    /// The environment could not be set up earlier in this process (same cause).
    #[error("{0}")]
    Unavailable(String),
    /// `with_vcan` was called outside a libtest test thread.
    #[error(
        "with_vcan must be called from a #[test] function (the thread is named after the test)"
    )]
    NotInTest,
}

/// A command to run in a CAN environment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GuestCommand {
    /// Program and arguments.
    pub argv: Vec<String>,
    /// Working directory.
    pub cwd: PathBuf,
    /// Variables added to the caller's environment.
    pub env: Vec<(String, String)>,
    /// Time limit for the whole run (boot included).
    pub timeout: Duration,
}

impl GuestCommand {
    /// `argv` in the current directory with the default timeout (`FES_VCAN_TIMEOUT_S`).
    pub fn new(argv: Vec<String>) -> Result<Self, HarnessError> {
        let cwd = std::env::current_dir().map_err(|source| HarnessError::Io {
            what: "current directory".into(),
            source,
        })?;
        Ok(Self {
            argv,
            cwd,
            env: Vec::new(),
            timeout: timeout_from_env()?,
        })
    }

    /// `sh -c script`.
    pub fn shell(script: &str) -> Result<Self, HarnessError> {
        Self::new(vec!["sh".into(), "-c".into(), script.into()])
    }
}

fn timeout_from_env() -> Result<Duration, HarnessError> {
    match std::env::var(ENV_TIMEOUT) {
        Err(_) => Ok(DEFAULT_TIMEOUT),
        Ok(v) => match v.parse::<u64>() {
            Ok(s) if s > 0 => Ok(Duration::from_secs(s)),
            _ => Err(HarnessError::BadEnv {
                var: ENV_TIMEOUT,
                value: v,
                expected: "a positive number of seconds",
            }),
        },
    }
}

/// What a run produced.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunOutcome {
    /// Where it ran.
    pub backend: Backend,
    /// Exit status (128 + n for a signal).
    pub status: i32,
    /// Output lines (stdout and stderr merged; UML boot messages excluded).
    pub output: Vec<String>,
    /// Test names whose body completed inside the guest.
    pub body_ok: Vec<String>,
    /// Time until the guest was ready (UML only).
    pub boot: Option<Duration>,
    /// Wall time of the whole run.
    pub total: Duration,
}

/// The environment this process will use.
#[derive(Debug, Clone)]
enum Plan {
    Inside(CanEnv),
    Native(String),
    Uml(uml::UmlKernel),
}

fn decide() -> Result<Plan, HarnessError> {
    if let Ok(iface) = std::env::var(ENV_IFACE) {
        let backend = match std::env::var(ENV_BACKEND).as_deref() {
            Ok("uml") => Backend::Uml,
            _ => Backend::Native,
        };
        return Ok(Plan::Inside(CanEnv { iface, backend }));
    }
    let requested = std::env::var(ENV_BACKEND).unwrap_or_else(|_| "auto".into());
    let (try_native, try_uml) = match requested.as_str() {
        "auto" | "" => (true, true),
        "native" => (true, false),
        "uml" => (false, true),
        _ => {
            return Err(HarnessError::BadEnv {
                var: ENV_BACKEND,
                value: requested,
                expected: "auto, native or uml",
            });
        }
    };
    if try_native && let Ok(iface) = std::env::var(ENV_CAN_IFACE) {
        return match native::usable(&iface) {
            Ok(()) => Ok(Plan::Native(iface)),
            Err(reason) => Err(HarnessError::IfaceUnusable { iface, reason }),
        };
    }
    let native_why = if try_native {
        match native::ensure_vcan0() {
            Ok(iface) => return Ok(Plan::Native(iface)),
            Err(why) => why,
        }
    } else {
        format!("not tried ({ENV_BACKEND}={requested})")
    };
    let uml_why = if try_uml {
        match uml::find() {
            Ok(k) => return Ok(Plan::Uml(k)),
            Err(why) => why,
        }
    } else {
        format!("not tried ({ENV_BACKEND}={requested})")
    };
    Err(HarnessError::NoCan {
        native: native_why,
        uml: uml_why,
    })
}

fn plan() -> Result<Plan, HarnessError> {
    static PLAN: OnceLock<Result<Plan, String>> = OnceLock::new();
    match PLAN.get_or_init(|| decide().map_err(|e| e.to_string())) {
        Ok(p) => Ok(p.clone()),
        // The first caller got the typed error; later ones get its text (same cause).
        Err(text) => Err(HarnessError::Unavailable(text.clone())),
    }
}

/// Runs `body` with a CAN interface, as described in the module docs. Panics (fails the
/// test) with the harness's explanation when no CAN environment can be had, or when the
/// body fails inside the guest.
pub fn with_vcan<F: FnOnce(&CanEnv)>(body: F) {
    if let Err(e) = try_with_vcan(body) {
        panic!("{e}");
    }
}

/// [`with_vcan`] returning the harness error instead of panicking on it (a failing body
/// still panics, as in any test).
pub fn try_with_vcan<F: FnOnce(&CanEnv)>(body: F) -> Result<(), HarnessError> {
    match plan()? {
        Plan::Inside(env) => {
            body(&env);
            if let (Ok(nonce), Some(name)) =
                (std::env::var(ENV_NONCE), std::thread::current().name())
            {
                println!("\n{}BODY-OK {nonce} {name}", uml::MARK);
            }
            Ok(())
        }
        Plan::Native(iface) => {
            let _lock = native::lock_iface(&iface)?;
            body(&CanEnv {
                iface,
                backend: Backend::Native,
            });
            Ok(())
        }
        Plan::Uml(kernel) => {
            let name = std::thread::current()
                .name()
                .map(str::to_owned)
                .filter(|n| n != "main")
                .ok_or(HarnessError::NotInTest)?;
            let exe = std::env::current_exe().map_err(|source| HarnessError::Io {
                what: "current executable".into(),
                source,
            })?;
            let exe = exe
                .to_str()
                .ok_or_else(|| HarnessError::BadPath(exe.clone()))?
                .to_owned();
            let argv = vec![
                exe,
                name.clone(),
                "--exact".into(),
                "--nocapture".into(),
                "--test-threads=1".into(),
                "--include-ignored".into(),
            ];
            let cmd = GuestCommand::new(argv)?;
            println!("vcan harness: running {name} inside a User-Mode Linux guest");
            let outcome = uml::run(&kernel, &cmd, &mut |line| println!("[uml] {line}"))?;
            println!(
                "vcan harness: guest ready after {:.1} s, run took {:.1} s, exit status {}",
                outcome.boot.unwrap_or_default().as_secs_f64(),
                outcome.total.as_secs_f64(),
                outcome.status
            );
            if outcome.status != 0 {
                panic!(
                    "test {name} failed inside the UML guest (exit status {}); its output is above",
                    outcome.status
                );
            }
            if !outcome.body_ok.contains(&name) {
                panic!(
                    "test {name} did not run its CAN body inside the UML guest (was it filtered out?); output above"
                );
            }
            Ok(())
        }
    }
}

/// Runs `cmd` in a CAN environment (native or UML) and streams its output lines to
/// `on_line`. Used by `vcan-run`; inside an environment the command simply runs.
pub fn run_command(
    cmd: &GuestCommand,
    on_line: &mut dyn FnMut(&str),
) -> Result<RunOutcome, HarnessError> {
    match plan()? {
        Plan::Inside(env) => run_local(cmd, &env, on_line),
        Plan::Native(iface) => {
            let _lock = native::lock_iface(&iface)?;
            run_local(
                cmd,
                &CanEnv {
                    iface,
                    backend: Backend::Native,
                },
                on_line,
            )
        }
        Plan::Uml(kernel) => uml::run(&kernel, cmd, on_line),
    }
}

/// The backend and interface a run would use, without running anything.
pub fn describe() -> Result<String, HarnessError> {
    Ok(match plan()? {
        Plan::Inside(env) => format!(
            "inside a prepared environment ({:?}), interface {}",
            env.backend, env.iface
        ),
        Plan::Native(iface) => format!("native, interface {iface}"),
        Plan::Uml(k) => format!(
            "User-Mode Linux guest ({:?}), interface {}",
            k,
            uml::GUEST_IFACE
        ),
    })
}

fn run_local(
    cmd: &GuestCommand,
    env: &CanEnv,
    on_line: &mut dyn FnMut(&str),
) -> Result<RunOutcome, HarnessError> {
    let start = std::time::Instant::now();
    let (program, args) = cmd.argv.split_first().ok_or(HarnessError::BadEnv {
        var: "argv",
        value: String::new(),
        expected: "a program to run",
    })?;
    let mut c = std::process::Command::new(program);
    c.args(args)
        .current_dir(&cmd.cwd)
        .envs(cmd.env.iter().map(|(k, v)| (k, v)));
    c.env(ENV_IFACE, &env.iface).env(ENV_CAN_IFACE, &env.iface);
    c.env(
        ENV_BACKEND,
        if env.backend == Backend::Uml {
            "uml"
        } else {
            "native"
        },
    );
    let mut child = process::Streamed::spawn(&mut c).map_err(|source| HarnessError::Spawn {
        what: program.clone(),
        source,
    })?;
    let deadline = start + cmd.timeout;
    let mut output = Vec::new();
    loop {
        match child.next_line(deadline) {
            process::Next::Line(l) => {
                on_line(&l);
                output.push(l);
            }
            process::Next::Eof => break,
            process::Next::TimedOut => {
                child.kill_group();
                return Err(HarnessError::Timeout {
                    after: cmd.timeout,
                    log: output.join("\n"),
                });
            }
        }
    }
    let status = child
        .wait_until(deadline)
        .map_err(|source| HarnessError::Io {
            what: format!("waiting for {program}"),
            source,
        })?;
    let Some(status) = status else {
        child.kill_group();
        return Err(HarnessError::Timeout {
            after: cmd.timeout,
            log: output.join("\n"),
        });
    };
    Ok(RunOutcome {
        backend: env.backend,
        status: process::exit_code(status),
        output,
        body_ok: Vec::new(),
        boot: None,
        total: start.elapsed(),
    })
}
