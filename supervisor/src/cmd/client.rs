//! The operator client: `supervisor set`, `profile`, `stop`, `arm`, `status`. Each sends
//! one command over the control socket and prints the answer; a refused command exits
//! with status 1 and the daemon's reason.

use std::path::PathBuf;
use std::time::Duration;
use supervisor::cli::OnOff;

use anyhow::{Context, bail};
use supervisor::control;
use supervisor::profile::{CardiacSpec, ProfileSpec, RampPoint, Step};
use supervisor::protocol::{Command, DriverOrderStatus, Response, Status};

/// Where the daemon is.
#[derive(Debug, Clone, clap::Args)]
pub struct SocketArgs {
    /// Control socket of the daemon.
    #[arg(long, global = true, default_value = "/run/fes/supervisor.sock")]
    pub socket: PathBuf,
    /// Seconds to wait for the answer.
    #[arg(long, global = true, default_value_t = 5.0)]
    pub timeout_s: f64,
}

/// `supervisor set`.
#[derive(Debug, clap::Args)]
pub struct SetArgs {
    /// Reference force, normalised to the muscle's maximum, [0, 1].
    #[arg(long, allow_negative_numbers = true)]
    pub force: f64,
    /// Ramp rate towards it, normalised force per second (default: the daemon's).
    #[arg(long)]
    pub rate: Option<f64>,
    #[command(flatten)]
    socket: SocketArgs,
}

/// `supervisor status`.
#[derive(Debug, clap::Args)]
pub struct StatusArgs {
    /// Print the daemon's answer as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    socket: SocketArgs,
}

/// `supervisor watch`.
#[derive(Debug, clap::Args)]
pub struct WatchArgs {
    /// Stop watching after this many seconds of stimulation without an unplanned stop
    /// (exit 0); default: watch until stimulation ends.
    #[arg(long)]
    pub for_s: Option<f64>,
    /// Status poll period, ms.
    #[arg(long, default_value_t = 100)]
    pub poll_ms: u64,
    #[command(flatten)]
    socket: SocketArgs,
}

/// How a watch ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum WatchEnd {
    /// The operator stopped stimulation (disarmed), or `--for-s` passed: exit 0.
    Planned,
    /// A fault stopped stimulation: the alarm, exit 4.
    Unplanned(String),
}

/// Why a watch could not go on.
#[derive(Debug, thiserror::Error)]
pub enum WatchError {
    /// `--for-s` or `--poll-ms` out of range.
    #[error("{0}")]
    Usage(String),
    /// No daemon answered the first request.
    #[error(transparent)]
    Unreachable(control::ClientError),
    /// The daemon stopped answering while stimulation ran: an unplanned stop of the
    /// supervisor itself (the driver's supervisor watch stops the stimulator).
    #[error("ALARM: the supervisor stopped answering while stimulation ran: {0}")]
    Gone(#[source] control::ClientError),
}

/// Follows the daemon's state: waits while it is disarmed, then while it is armed, and
/// ends when stimulation ends (every unplanned stop raises an alarm a waiting command can
/// act on). Prints each change of state.
pub fn watch(a: &WatchArgs) -> Result<WatchEnd, WatchError> {
    let usage = |m: String| WatchError::Usage(m);
    check_timeout(&a.socket).map_err(|e| usage(e.to_string()))?;
    if !(1..=10_000).contains(&a.poll_ms) {
        return Err(usage(format!(
            "--poll-ms {} must be in 1..=10000",
            a.poll_ms
        )));
    }
    if a.for_s.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
        return Err(usage("--for-s must be a positive number".into()));
    }
    let timeout = Duration::from_secs_f64(a.socket.timeout_s);
    let mut last = String::new();
    let mut armed_since: Option<std::time::Instant> = None;
    loop {
        let status = control::request(&a.socket.socket, Command::Status, timeout)
            .map_err(|e| {
                if last.is_empty() {
                    WatchError::Unreachable(e)
                } else {
                    WatchError::Gone(e)
                }
            })?
            .status;
        let (state, fault) = status.map_or(("unknown".to_owned(), None), |s| (s.state, s.fault));
        if state != last {
            println!(
                "{state}{}",
                fault
                    .as_deref()
                    .map(|f| format!(": {f}"))
                    .unwrap_or_default()
            );
            last.clone_from(&state);
        }
        match state.as_str() {
            "fault" => {
                return Ok(WatchEnd::Unplanned(fault.unwrap_or_else(|| "fault".into())));
            }
            "armed" => {
                let since = *armed_since.get_or_insert_with(std::time::Instant::now);
                if a.for_s.is_some_and(|s| since.elapsed().as_secs_f64() >= s) {
                    return Ok(WatchEnd::Planned);
                }
            }
            _ if armed_since.is_some() => return Ok(WatchEnd::Planned),
            _ => {}
        }
        std::thread::sleep(Duration::from_millis(a.poll_ms));
    }
}

/// `supervisor profile <kind>`.
#[derive(Debug, clap::Args)]
pub struct ProfileArgs {
    #[command(subcommand)]
    kind: ProfileKind,
    #[command(flatten)]
    socket: SocketArgs,
}

#[derive(Debug, clap::Subcommand)]
enum ProfileKind {
    /// Square-wave contractions synchronised to a heart rate (thesis 1.1); while one runs,
    /// the new values take effect at the next beat.
    Cardiac {
        /// Heart rate, beats per minute, 60..=200.
        #[arg(long)]
        hr: f64,
        /// Fraction of the beat that contracts.
        #[arg(long, default_value_t = 0.4)]
        duty: f64,
        /// Target contraction, normalised force.
        #[arg(long)]
        amplitude: f64,
        /// Rate of the edges, normalised force per second (default: the rate limit).
        #[arg(long)]
        edge_rate: Option<f64>,
        /// Switch the outer loop on or off with this profile.
        #[arg(long, value_enum)]
        outer_loop: Option<OnOff>,
        /// Rest before the first contraction, ms, 0..=2000 (default: the profile's, 200).
        /// The first onset is announced from the start, so rt-core's planner plans the
        /// first contraction as it plans the others.
        #[arg(long)]
        start_rest_ms: Option<f64>,
    },
    /// A constant force.
    Constant {
        /// Normalised force.
        #[arg(long)]
        force: f64,
        /// Ramp rate towards it, /s.
        #[arg(long)]
        rate: Option<f64>,
    },
    /// Levels held in turn: `--levels 0.2:1.0,0.5:0.5` (force:seconds, ...).
    Steps {
        /// force:hold_s pairs, comma separated.
        #[arg(long)]
        levels: String,
        /// Start again after the last level.
        #[arg(long)]
        repeat: bool,
        /// Ramp rate between levels, /s.
        #[arg(long)]
        rate: Option<f64>,
    },
    /// Piecewise-linear: `--points 0:0,2:0.5,3:0.5` (seconds:force, ...; the first at 0).
    Ramps {
        /// t_s:force pairs, comma separated.
        #[arg(long)]
        points: String,
        /// Start again after the last point.
        #[arg(long)]
        repeat: bool,
    },
}

fn pairs(text: &str, what: &str) -> anyhow::Result<Vec<(f64, f64)>> {
    text.split(',')
        .map(|p| {
            let (a, b) = p
                .split_once(':')
                .with_context(|| format!("{what}: `{p}` is not a:b"))?;
            let a: f64 = a
                .trim()
                .parse()
                .with_context(|| format!("{what}: `{a}` is not a number"))?;
            let b: f64 = b
                .trim()
                .parse()
                .with_context(|| format!("{what}: `{b}` is not a number"))?;
            Ok((a, b))
        })
        .collect()
}

fn check_timeout(socket: &SocketArgs) -> anyhow::Result<()> {
    if !(socket.timeout_s.is_finite() && socket.timeout_s > 0.0 && socket.timeout_s <= 600.0) {
        bail!("--timeout-s {} must be in (0, 600]", socket.timeout_s);
    }
    Ok(())
}

fn send(socket: &SocketArgs, command: Command) -> anyhow::Result<Response> {
    check_timeout(socket)?;
    Ok(control::request(
        &socket.socket,
        command,
        Duration::from_secs_f64(socket.timeout_s),
    )?)
}

fn finish(r: Response) -> anyhow::Result<()> {
    if r.ok {
        println!("{}", r.message.unwrap_or_default());
        Ok(())
    } else {
        eprintln!("refused: {}", r.error.unwrap_or_default());
        std::process::exit(fes_rt::rt::exit::Exit::Failed.code().into());
    }
}

fn finite(flag: &str, v: Option<f64>) -> anyhow::Result<()> {
    match v {
        Some(x) if !x.is_finite() => bail!("{flag} {x}: must be a finite number"),
        _ => Ok(()),
    }
}

/// `supervisor set`.
pub fn set(a: SetArgs) -> anyhow::Result<()> {
    finite("--force", Some(a.force))?;
    finite("--rate", a.rate)?;
    finish(send(
        &a.socket,
        Command::Set {
            force: a.force,
            rate_per_s: a.rate,
        },
    )?)
}

/// `supervisor profile`.
pub fn profile(a: ProfileArgs) -> anyhow::Result<()> {
    if let ProfileKind::Cardiac {
        hr,
        duty,
        amplitude,
        edge_rate,
        start_rest_ms,
        ..
    } = &a.kind
    {
        finite("--hr", Some(*hr))?;
        finite("--duty", Some(*duty))?;
        finite("--amplitude", Some(*amplitude))?;
        finite("--edge-rate", *edge_rate)?;
        finite("--start-rest-ms", *start_rest_ms)?;
    }
    if let ProfileKind::Constant { force, rate } = &a.kind {
        finite("--force", Some(*force))?;
        finite("--rate", *rate)?;
    }
    let profile = match a.kind {
        ProfileKind::Cardiac {
            hr,
            duty,
            amplitude,
            edge_rate,
            outer_loop,
            start_rest_ms,
        } => ProfileSpec::Cardiac(CardiacSpec {
            bpm: hr,
            duty,
            amplitude,
            edge_rate_per_s: edge_rate,
            outer_loop: outer_loop.map(|o| o == OnOff::On),
            start_rest_ms,
        }),
        ProfileKind::Constant { force, rate } => ProfileSpec::Constant {
            force,
            rate_per_s: rate,
        },
        ProfileKind::Steps {
            levels,
            repeat,
            rate,
        } => ProfileSpec::Steps {
            steps: pairs(&levels, "--levels")?
                .into_iter()
                .map(|(force, hold_s)| Step { force, hold_s })
                .collect(),
            repeat,
            rate_per_s: rate,
        },
        ProfileKind::Ramps { points, repeat } => ProfileSpec::Ramps {
            points: pairs(&points, "--points")?
                .into_iter()
                .map(|(t_s, force)| RampPoint { t_s, force })
                .collect(),
            repeat,
        },
    };
    finish(send(&a.socket, Command::Profile { profile })?)
}

/// `supervisor stop`.
pub fn stop(a: SocketArgs) -> anyhow::Result<()> {
    check_timeout(&a)?;
    let r = control::request_stop(&a.socket, Duration::from_secs_f64(a.timeout_s))?;
    await_order(&a, r, Awaited::Stop)
}

/// `supervisor arm`.
pub fn arm(a: SocketArgs) -> anyhow::Result<()> {
    let r = send(&a, Command::Arm)?;
    await_order(&a, r, Awaited::Arm)
}

/// Which order the operator's command gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Awaited {
    Stop,
    Arm,
}

impl Awaited {
    fn matches(self, o: &DriverOrderStatus) -> bool {
        match self {
            Awaited::Stop => o.is_stop(),
            Awaited::Arm => o.order == "arm",
        }
    }

    fn name(self) -> &'static str {
        match self {
            Awaited::Stop => "stop",
            Awaited::Arm => "arm",
        }
    }
}

/// The driver did not carry out the operator's order: what the exit status says.
#[derive(Debug, thiserror::Error)]
pub enum OrderError {
    /// The driver refused the arm (exit 1).
    #[error("stim-driver refused the arm: {0}")]
    ArmRefused(String),
    /// The order was not acknowledged, or a fault took over (exit 4).
    #[error("ALARM: {0}")]
    NotAcknowledged(String),
}

impl OrderError {
    /// The exit status (README "Exit codes").
    pub fn exit(&self) -> fes_rt::rt::exit::Exit {
        match self {
            OrderError::ArmRefused(_) => fes_rt::rt::exit::Exit::Failed,
            OrderError::NotAcknowledged(_) => fes_rt::rt::exit::Exit::Fault,
        }
    }
}

/// After the daemon's answer `r` to a stop or an arm: waits (up to `--timeout-s`) until
/// the driver acknowledged the order the command gave, as the daemon's status shows it
/// (`driver_order`), and says so. A refused arm is exit 1; a stop or arm the driver did
/// not acknowledge in time, or a fault meanwhile, exit 4, naming it: the operator must
/// not read "stopped" where the driver's stop is not known.
fn await_order(a: &SocketArgs, r: Response, want: Awaited) -> anyhow::Result<()> {
    if !r.ok {
        return finish(r);
    }
    println!("{}", r.message.clone().unwrap_or_default());
    let timeout = Duration::from_secs_f64(a.timeout_s);
    let deadline = std::time::Instant::now() + timeout;
    let mut status = r.status;
    // The order the answer names (the daemon sends it before answering).
    let Some(mut id) = status
        .as_ref()
        .and_then(|s| s.driver_order.as_ref())
        .filter(|o| want.matches(o))
        .map(|o| o.id)
    else {
        println!("no order was sent to stim-driver: nothing to acknowledge");
        return Ok(());
    };
    loop {
        let s = status
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("the daemon sent no status"))?;
        let fault = || s.fault.clone().unwrap_or_else(|| "fault".into());
        match s.driver_order.as_ref() {
            Some(o) if o.id == id => match o.outcome.as_str() {
                "confirmed" => {
                    println!("stim-driver acknowledged the {}", want.name());
                    return Ok(());
                }
                "unwatched" => {
                    eprintln!(
                        "warning: stim-driver's acknowledgements are not watched \
                         (health.watch_stim_driver = false): the {} is not confirmed",
                        want.name()
                    );
                    return Ok(());
                }
                "refused" if want == Awaited::Arm => {
                    return Err(OrderError::ArmRefused(o.reason.clone().unwrap_or_default()).into());
                }
                "unacknowledged" => {
                    return Err(OrderError::NotAcknowledged(format!(
                        "stim-driver has not acknowledged the {}{}",
                        want.name(),
                        if s.state == "fault" {
                            format!(": {}", fault())
                        } else {
                            String::new()
                        }
                    ))
                    .into());
                }
                // Pending, or a stop refused for now (it is re-sent).
                _ => {}
            },
            // A newer stop (a fault's safe stop) carries on what a stop asked for.
            Some(o) if o.id > id && want == Awaited::Stop && o.is_stop() => id = o.id,
            Some(o) if o.id > id => {
                return Err(OrderError::NotAcknowledged(format!(
                    "the {} was overtaken by a {} before stim-driver acknowledged it{}",
                    want.name(),
                    o.order,
                    if s.state == "fault" {
                        format!(" ({})", fault())
                    } else {
                        String::new()
                    }
                ))
                .into());
            }
            _ => {}
        }
        if std::time::Instant::now() >= deadline {
            return Err(OrderError::NotAcknowledged(format!(
                "stim-driver did not acknowledge the {} within {:.1} s (--timeout-s)",
                want.name(),
                timeout.as_secs_f64()
            ))
            .into());
        }
        std::thread::sleep(Duration::from_millis(20));
        status = control::request(&a.socket, Command::Status, timeout)?.status;
    }
}

/// `supervisor status`.
pub fn status(a: StatusArgs) -> anyhow::Result<()> {
    let r = send(&a.socket, Command::Status)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    match r.status {
        Some(s) => print!("{}", render(&s)),
        None => bail!("the daemon sent no status: {}", r.error.unwrap_or_default()),
    }
    Ok(())
}

/// Human-readable status.
pub fn render(s: &Status) -> String {
    use std::fmt::Write;
    let mut o = String::new();
    let _ = writeln!(o, "state:        {}", s.state);
    if let Some(f) = &s.fault {
        let _ = writeln!(o, "fault:        {f}");
    }
    let _ = writeln!(
        o,
        "reference:    {:.4}{} (ramp {} /s), {} published",
        s.reference,
        if s.reference_stop { " STOP" } else { "" },
        s.reference_rate_per_s,
        s.references_published
    );
    let _ = writeln!(
        o,
        "profile:      {}",
        s.profile.as_deref().unwrap_or("none")
    );
    if let Some(b) = s.beat {
        let _ = writeln!(o, "beat:         {b}");
    }
    let _ = writeln!(
        o,
        "outer loop:   {} (correction {:+.4}, last contraction {})",
        if s.outer_loop { "on" } else { "off" },
        s.outer_loop_correction,
        s.last_contraction
            .map_or("-".to_string(), |c| format!("{c:.4}"))
    );
    let _ = writeln!(
        o,
        "driver:       {} / stimulator {}",
        s.driver_state.as_deref().unwrap_or("not heard"),
        s.stimulator_state.as_deref().unwrap_or("not heard")
    );
    if let Some(d) = &s.driver_order {
        let _ = writeln!(
            o,
            "last order:   {} {}{}",
            d.order,
            d.outcome,
            d.reason
                .as_deref()
                .map(|r| format!(" ({r})"))
                .unwrap_or_default()
        );
    }
    for p in &s.processes {
        let _ = writeln!(
            o,
            "  {:<12} {:<8} pid {:<8} last message {}{}",
            p.name,
            p.state,
            p.pid.map_or("-".into(), |x| x.to_string()),
            p.last_message_age_ms
                .map_or("-".into(), |a| format!("{a:.0} ms ago")),
            if p.detail.is_empty() {
                String::new()
            } else {
                format!("  ({})", p.detail)
            }
        );
    }
    if let Some(r) = &s.recording {
        let _ = writeln!(o, "recording:    {r}");
    }
    let _ = writeln!(o, "uptime:       {:.1} s", s.uptime_s);
    for e in &s.events {
        let _ = writeln!(o, "  event: {e}");
    }
    o
}
