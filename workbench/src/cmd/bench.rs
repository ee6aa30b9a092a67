//! `fes bench`: the end-to-end bench (docs/bench.md).
//!
//! Without a CAN interface in reach (no `FES_VCAN_IFACE`), it re-runs itself through
//! `vcan-run`, which uses native vcan when the kernel has it and a User-Mode Linux guest
//! otherwise; inside, it starts sim-muscle, stim-driver, rt-core and the supervisor daemon,
//! arms, runs the cardiac profile, stops everything and prints the summary.
//!
//! `--in-process` runs the same chain in one process in simulated time instead
//! ([`fes_bench::simulation`]: the supervisor's profile and outer loop, rt-core's reference
//! tracking and pattern generator with the same controller file, the same sim-muscle preset
//! and force sensor): no CAN, no processes, no latencies; the same summary otherwise.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use fes_bench::baseline::{BeatShape, baseline_40hz};
use fes_bench::bench::{ChainTiming, Stack, StackOptions, StimulatorKind, process_logs};
use fes_bench::canlog::CanLog;
use fes_bench::cft::FrontPoint;
use fes_bench::summary::{
    AnalysisInput, BaselineFn, Latency, RunTiming, Series, Summary, analyse, read_series, summarise,
};
use supervisor::profile::{CardiacSpec, ProfileSpec};
use supervisor::protocol::Command;
use workbench::plots::{
    LatencyCurve, RunSeries, percentile_grid, plot_front, plot_latency, plot_run,
};

use supervisor::cli::OnOff;

/// Arguments of `fes bench`.
#[derive(Debug, Clone, clap::Args)]
#[command(
    args_override_self = true,
    after_help = "Example: fes bench --seconds 30 --hr 75 --json bench.json\n\
The README's `scripts/bench` builds everything and runs this with --seconds 30 (a later \
option overrides an earlier one, so `scripts/bench --seconds 60` works)."
)]
pub struct Args {
    /// Length of the cardiac profile, s.
    #[arg(long, default_value_t = 30.0)]
    pub seconds: f64,
    /// Heart rate, beats per minute (60..=200).
    #[arg(long, default_value_t = 75.0)]
    pub hr: f64,
    /// Fraction of each beat that contracts.
    #[arg(long, default_value_t = 0.4)]
    pub duty: f64,
    /// Target contraction, normalised force.
    #[arg(long, default_value_t = 0.3)]
    pub amplitude: f64,
    /// Stimulation lead, ms: stimulate this much shorter than the contraction (`--duty`)
    /// and judge the run, and the constant-frequency trains over the same shorter window,
    /// against the whole contraction (the muscle relaxes over ~100 ms after its last pulse;
    /// docs/bench.md, "The CFT front"). 0: stimulate the whole contraction.
    #[arg(long, default_value_t = 0)]
    pub stim_lead_ms: u32,
    /// Rest before the first contraction, ms (default: the profile's). The first onset is
    /// announced in the reference preview from the start, so the planner plans the first
    /// contraction as it plans every later one (docs/control.md, section 11).
    #[arg(long)]
    pub start_rest_ms: Option<f64>,
    /// Outer loop (thesis Controller 1).
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub outer_loop: OnOff,
    /// Outer-loop integral gain per beat, (0, 1] (default: the supervisor's, 0.3).
    #[arg(long)]
    pub outer_gain: Option<f64>,
    /// Fatigue in the simulated muscle (Ding 2003).
    #[arg(long)]
    pub fatigue: bool,
    /// The simulated muscle: sim-muscle's fast or slow preset (thesis 5.1's two rabbit
    /// muscles), with its shipped controller unless --controller names another.
    #[arg(long, value_enum, default_value_t = MuscleChoice::Fast)]
    pub muscle: MuscleChoice,
    /// Controller file for rt-core (fes-lcn/1); default `models/<muscle>.lcn.json`, with
    /// `--stimulator sciencemode` `models/<muscle>-rehastim2.lcn.json` (designed with the
    /// RehaStim 2's 20 ms minimum pulse interval).
    #[arg(long)]
    pub controller: Option<PathBuf>,
    /// Output directory (configurations, logs, recording, plots); default
    /// `target/bench/<UTC time>`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write the summary as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Length of the time window shown in the force plot, s.
    #[arg(long, default_value_t = 4.0)]
    pub plot_window_s: f64,
    /// Simulate the chain in this process (simulated time; no CAN, no processes, no
    /// latencies) instead of running the processes on CAN.
    #[arg(long)]
    pub in_process: bool,
    /// With `--in-process`: also try every pattern of K pulses per contraction (1-3), the
    /// same in every beat, on the run's muscle: each pulse on a 1 ms grid (2 ms for 3),
    /// the controller's minimum interval apart. Prints the best by RMS and the best that
    /// misses the level by no more than the run: how far any pattern of that count can
    /// go, trains or not (docs/bench.md, "Every pattern, not only trains"). Seconds for 1
    /// pulse, about two minutes for 2, five (fast muscle) to twenty (slow) for 3.
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u8).range(1..=3), requires = "in_process")]
    pub pattern_search: Option<u8>,
    /// The bus between stim-driver and the virtual stimulator. `can`: SocketCAN (native
    /// vcan0, or a User-Mode Linux guest when the kernel has no CAN: functional timings
    /// only); `host`: the host bus (the same frames over Unix datagrams, on this host at
    /// its real-time latencies); `auto`: `can` where the kernel has CAN, else `host`.
    #[arg(long, value_enum, default_value_t = BusChoice::Auto)]
    pub bus: BusChoice,
    /// The stimulator the driver drives. `can`: the CAN virtual stimulator on `--bus`;
    /// `sciencemode`: the virtual Hasomed RehaStim 2 on a pseudo-terminal, driven over
    /// ScienceMode 2 (docs/sciencemode.md; no CAN, `--bus` unused), publishing the
    /// muscle's measured force itself as the rig's separate force sensor would.
    #[arg(long, value_enum, default_value_t = StimulatorKind::Can)]
    pub stimulator: StimulatorKind,
    /// With `--stimulator sciencemode`: the virtual RehaStim 2 processes each command for
    /// this long on average (0.5-1.5 x, 3 % of them 100 ms) and answers -8 busy to any
    /// command meanwhile, as HASOMED documents the device (protocol §2.3, §5.1; the
    /// default); 0: it answers at once. The driver waits for each answer; pulses it could
    /// not send in time are counted in the summary.
    #[arg(long, default_value_t = fes_virtual_stimulator::rehastim2_pty::DOCUMENTED_PROCESSING_MS, value_name = "MS")]
    pub device_processing_ms: u16,
    /// With `--stimulator sciencemode`: a MOTOmed attached to the virtual RehaStim 2 (it
    /// sends ActualValues every 20 ms, unasked).
    #[arg(long)]
    pub device_motomed: bool,
    /// Format of the figures: png (raster) or svg (vector, for papers).
    #[arg(long, value_enum, default_value_t = workbench::plots::FigureFormat::Png)]
    pub format: workbench::plots::FigureFormat,
}

/// `--muscle`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MuscleChoice {
    /// Fast twitch, strong catch-like effect (the control muscle).
    Fast,
    /// Chronically stimulated: slower, no catch-like gain.
    Slow,
}

impl MuscleChoice {
    /// The sim-muscle preset.
    pub fn preset(self) -> sim_muscle::preset::Preset {
        match self {
            Self::Fast => sim_muscle::preset::Preset::Fast,
            Self::Slow => sim_muscle::preset::Preset::Slow,
        }
    }

    /// The shipped controller for this muscle.
    pub fn controller(self) -> PathBuf {
        PathBuf::from(match self {
            Self::Fast => "models/fast.lcn.json",
            Self::Slow => "models/slow.lcn.json",
        })
    }

    /// The muscle's shipped controller for a RehaStim 2: designed with the transport's
    /// minimum pulse interval (20 ms, `fes design --min-interval-ms 20`), which its driver
    /// requires before it arms.
    pub fn rehastim2_controller(self) -> PathBuf {
        PathBuf::from(match self {
            Self::Fast => "models/fast-rehastim2.lcn.json",
            Self::Slow => "models/slow-rehastim2.lcn.json",
        })
    }

    fn name(self) -> &'static str {
        match self {
            Self::Fast => "fast",
            Self::Slow => "slow",
        }
    }
}

/// `--bus`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BusChoice {
    /// SocketCAN where the kernel has it, else the host bus.
    Auto,
    /// SocketCAN: native vcan or a User-Mode Linux guest.
    Can,
    /// The host bus (Unix datagrams carrying the CAN frames).
    Host,
}

/// Whether this kernel has SocketCAN (the CAN core loaded, or a vcan module to load).
fn kernel_has_can() -> bool {
    Path::new("/proc/net/can").exists()
        || std::process::Command::new("modprobe")
            .args(["-n", "-q", "vcan"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
}

fn check(a: &Args) -> anyhow::Result<()> {
    if !(a.seconds.is_finite() && (2.0..=3600.0).contains(&a.seconds)) {
        bail!("--seconds {} must be in [2, 3600]", a.seconds);
    }
    if !(a.plot_window_s.is_finite() && a.plot_window_s > 0.0) {
        bail!("--plot-window-s {} must be > 0", a.plot_window_s);
    }
    outer_settings(a)
        .validate()
        .map_err(|e| anyhow::anyhow!("--outer-gain: {e}"))?;
    let spec = ProfileSpec::Cardiac(cardiac(a));
    spec.validate(&supervisor::limits::ReferenceLimits::default())
        .map_err(|e| match a.stim_lead_ms {
            0 => anyhow::anyhow!("{e}"),
            l => anyhow::anyhow!("{e} (with --stim-lead-ms {l})"),
        })?;
    if !a.controller().is_file() {
        bail!(
            "controller file {} not found (run from the repository root, or give --controller; models/README.md says how it is made)",
            a.controller().display()
        );
    }
    Ok(())
}

impl Args {
    /// The controller file: `--controller`, else the muscle's shipped one for the
    /// stimulator.
    pub fn controller(&self) -> PathBuf {
        self.controller
            .clone()
            .unwrap_or_else(|| match self.stimulator {
                StimulatorKind::Can => self.muscle.controller(),
                StimulatorKind::Sciencemode => self.muscle.rehastim2_controller(),
            })
    }
}

fn outer_settings(a: &Args) -> supervisor::outer_loop::OuterLoopSettings {
    let d = supervisor::outer_loop::OuterLoopSettings::default();
    supervisor::outer_loop::OuterLoopSettings {
        enabled: a.outer_loop == OnOff::On,
        gain: a.outer_gain.unwrap_or(d.gain),
        ..d
    }
}

/// The profile rt-core follows: the contraction shortened by the stimulation lead.
fn cardiac(a: &Args) -> CardiacSpec {
    CardiacSpec {
        bpm: a.hr,
        duty: a.duty - f64::from(a.stim_lead_ms) * 1e-3 * a.hr / 60.0,
        amplitude: a.amplitude,
        edge_rate_per_s: None,
        outer_loop: Some(a.outer_loop == OnOff::On),
        start_rest_ms: a.start_rest_ms,
    }
}

/// Runs the bench.
pub fn run(a: Args) -> anyhow::Result<()> {
    check(&a)?;
    let exe = std::env::current_exe().context("own executable")?;
    let bin_dir = exe.parent().context("executable directory")?.to_path_buf();
    let out = match &a.out {
        Some(o) => o.clone(),
        None => PathBuf::from("target/bench").join(supervisor::recording::utc_stamp()),
    };
    if a.in_process {
        return in_process(&a, &out);
    }
    if a.stimulator == StimulatorKind::Sciencemode {
        // A serial line on a pty: no CAN environment needed.
        std::fs::create_dir_all(&out).with_context(|| format!("create {}", out.display()))?;
        let out = std::fs::canonicalize(&out)?;
        return inside(&a, &bin_dir, &out, String::new(), false);
    }
    let in_can_env = std::env::var_os("FES_VCAN_IFACE").is_some();
    let host_bus = match a.bus {
        BusChoice::Host => true,
        BusChoice::Can => false,
        BusChoice::Auto => !in_can_env && !kernel_has_can(),
    };
    if host_bus {
        std::fs::create_dir_all(&out).with_context(|| format!("create {}", out.display()))?;
        let out = std::fs::canonicalize(&out)?;
        let iface = format!("{}{}", fes_hostbus::SCHEME, out.join("bus").display());
        return inside(&a, &bin_dir, &out, iface, false);
    }
    if !in_can_env {
        // Not in a CAN environment yet: run this same command inside one.
        let vcan_run = bin_dir.join("vcan-run");
        if !vcan_run.is_file() {
            bail!(
                "{} not found: build it (cargo build --release -p fes-tests --bins)",
                vcan_run.display()
            );
        }
        let mut args: Vec<String> = std::env::args().skip(1).collect();
        if a.out.is_none() {
            args.push("--out".into());
            args.push(out.display().to_string());
        }
        let timeout = (a.seconds + 300.0).ceil() as u64;
        eprintln!(
            "bench: no CAN interface here; running inside `vcan-run` (native vcan or a User-Mode Linux guest)"
        );
        let status = std::process::Command::new(&vcan_run)
            .arg("--timeout-s")
            .arg(timeout.to_string())
            .arg("--")
            .arg(&exe)
            .args(&args)
            .status()
            .with_context(|| format!("start {}", vcan_run.display()))?;
        std::process::exit(status.code().unwrap_or(1));
    }
    let iface = std::env::var("FES_VCAN_IFACE").unwrap_or_else(|_| "vcan0".into());
    let uml = std::env::var("FES_VCAN_BACKEND").is_ok_and(|b| b == "uml");
    inside(&a, &bin_dir, &out, iface, uml)
}

/// The bench on a CAN interface (or the host bus): start the four processes, arm, run the
/// profile, stop everything, summarise the recording.
fn inside(a: &Args, bin_dir: &Path, out: &Path, iface: String, uml: bool) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("create {}", out.display()))?;
    let out = std::fs::canonicalize(out)?;
    announce(a, &iface, uml);
    // Every frame of the run, bring-up included, in candump -L format (CAN only: on
    // ScienceMode the device's pulse log, stimulator.csv, records what it received).
    let can_log = out.join("can.log");
    let canlog = match a.stimulator {
        StimulatorKind::Can => Some(CanLog::start(&iface, &can_log)?),
        StimulatorKind::Sciencemode => None,
    };
    let stack = start_healthy(a, bin_dir, &out, iface, uml)?;
    stack.arm_with(ProfileSpec::Cardiac(cardiac(a)))?;
    println!(
        "bench: armed; cardiac profile {} beats/min, duty {}, amplitude {}, outer loop {} for {} s",
        a.hr,
        a.duty,
        a.amplitude,
        if a.outer_loop == OnOff::On {
            "on"
        } else {
            "off"
        },
        a.seconds
    );
    let failure = run_profile(&stack, a);
    let _ = std::io::stdout().flush();
    let _ = stack.command(Command::Stop);
    std::thread::sleep(Duration::from_millis(300));
    let scale_n = stack.scale_n();
    let delay = stack.delay();
    let unclean = stop(stack, uml);
    if let Some(canlog) = canlog {
        let frames = canlog.finish()?;
        println!("bench: {frames} CAN frames in {}", can_log.display());
    }
    if let Some(f) = failure {
        bail!("bench run failed: {f}");
    }
    summarise_recording(a, &out, scale_n, delay, uml, &unclean)
}

/// The bench's first line: the processes, the controller and the bus.
fn announce(a: &Args, iface: &str, uml: bool) {
    if a.stimulator == StimulatorKind::Sciencemode {
        println!(
            "bench: sim-muscle rehastim2 ({}{}; a virtual RehaStim 2 on a pty, ScienceMode 2{}{}), stim-driver, rt-core ({}), supervisor",
            a.muscle.name(),
            if a.fatigue { ", fatigue" } else { "" },
            if a.device_processing_ms > 0 {
                format!(", processing {} ms per command", a.device_processing_ms)
            } else {
                String::new()
            },
            if a.device_motomed { ", MOTOmed" } else { "" },
            a.controller().display()
        );
        return;
    }
    println!(
        "bench: sim-muscle ({}{}), stim-driver, rt-core ({}), supervisor on {iface} ({})",
        a.muscle.name(),
        if a.fatigue { ", fatigue" } else { "" },
        a.controller().display(),
        if uml {
            "User-Mode Linux guest: timings are functional only"
        } else if fes_hostbus::bus_dir(iface).is_some() {
            "the host bus: Unix datagrams carrying the CAN frames, real-time on this host"
        } else {
            "native"
        }
    );
}

/// Starts the stack in `out` and waits until the supervisor has heard from every
/// process; otherwise stops it and fails with the processes' logs.
fn start_healthy(
    a: &Args,
    bin_dir: &Path,
    out: &Path,
    iface: String,
    uml: bool,
) -> anyhow::Result<Stack> {
    let stack = Stack::start(StackOptions {
        dir: out.to_path_buf(),
        bin_dir: bin_dir.to_path_buf(),
        controller: a.controller(),
        preset: a.muscle.preset(),
        iface,
        timing: if uml {
            ChainTiming::Uml
        } else {
            ChainTiming::Bench
        },
        fatigue: a.fatigue,
        outer_loop: a.outer_loop == OnOff::On,
        outer_gain: a.outer_gain,
        prefix: format!("bench{}", std::process::id()),
        env: Vec::new(),
        pulse_amplitude_ua: None,
        stimulator: a.stimulator,
        rehastim2: fes_bench::bench::Rehastim2Options {
            processing_ms: a.device_processing_ms,
            motomed: a.device_motomed,
        },
    })?;
    let healthy = stack.wait_healthy(Duration::from_secs(if uml { 120 } else { 30 }));
    if let Err(e) = healthy {
        let logs = process_logs(out);
        let _ = stack.stop(Duration::from_secs(3));
        bail!("{e}\n{logs}");
    }
    Ok(stack)
}

/// Watches the running profile for `--seconds`, printing the status every 5 s; returns why
/// it ended early (a process exited, the supervisor stopped stimulation), if it did.
fn run_profile(stack: &Stack, a: &Args) -> Option<String> {
    let start = Instant::now();
    let run_for = Duration::from_secs_f64(a.seconds);
    let mut next_report = Duration::from_secs(5);
    while start.elapsed() < run_for {
        std::thread::sleep(Duration::from_millis(200));
        if let Err(e) = stack.check_alive() {
            return Some(e.to_string());
        }
        if start.elapsed() >= next_report {
            next_report += Duration::from_secs(5);
            if let Ok(s) = stack.status() {
                println!(
                    "  {:5.1} s  {}  beat {:>3}  contraction {}  outer-loop correction {:+.3}",
                    start.elapsed().as_secs_f64(),
                    s.state,
                    s.beat.map_or("-".into(), |b| b.to_string()),
                    s.last_contraction.map_or("-".into(), |c| format!("{c:.3}")),
                    s.outer_loop_correction
                );
                if let Some(f) = s.fault {
                    return Some(format!("the supervisor stopped stimulation: {f}"));
                }
            }
        }
    }
    None
}

/// Stops every process; returns those that did not exit cleanly, as "name (exit ...)".
fn stop(stack: Stack, uml: bool) -> Vec<String> {
    let exits = stack.stop(Duration::from_secs(if uml { 10 } else { 5 }));
    exits
        .iter()
        .filter(|(_, c)| *c != Some(0))
        .map(|(n, c)| {
            format!(
                "{n} (exit {})",
                c.map_or("killed".into(), |c| c.to_string())
            )
        })
        .collect()
}

/// Analyses the supervisor's last recording under `out` (with the CFT front of the same
/// muscle simulated), draws it, prints the summary and writes `--json`.
fn summarise_recording(
    a: &Args,
    out: &Path,
    scale_n: f64,
    delay: usize,
    uml: bool,
    unclean: &[String],
) -> anyhow::Result<()> {
    let rec = fes_bench::bench::recordings_in(&out.join("recording"));
    let Some(rec) = rec.last() else {
        bail!(
            "the supervisor wrote no recording under {}",
            out.join("recording").display()
        );
    };
    // The same muscle and sensor as the stimulator's, simulated for the CFT front.
    let front = fes_model::control::file::Controller::load(a.controller())
        .ok()
        .and_then(|c| sim_settings(&c, a).ok())
        .map(|s| s.front(a.amplitude, a.stim_lead_ms as usize));
    let summary = analyse(
        rec,
        &AnalysisInput {
            delay,
            target: a.amplitude,
            baseline: Some(baseline(a.muscle.preset(), a.amplitude, scale_n, delay)),
            uml,
            front,
        },
    )?;
    let series = read_series(rec)?;
    let plots = draw(&series, out, &summary, a, delay, true)?;
    print_summary(&summary, &plots, unclean);
    write_json(&summary, &plots, a)
}

/// The 40 Hz baseline of equal FTI on the bench's preset (without fatigue), for beats of
/// the profile's amplitude.
fn baseline(
    preset: sim_muscle::preset::Preset,
    amplitude: f64,
    scale_n: f64,
    delay: usize,
) -> BaselineFn {
    Box::new(move |fti: f64, period_ms: usize, on_ms: usize| {
        let muscle = sim_muscle::muscle::MuscleConfig::preset(preset);
        let shape = BeatShape {
            period_ms,
            on_ms,
            amplitude,
            edge_rate_per_s: supervisor::limits::ReferenceLimits::default().max_rate_per_s,
            delay,
        };
        baseline_40hz(&muscle, scale_n, &shape, fti)
    })
}

/// The bench's muscle, sensor, cardiac profile and outer loop under `controller`: what both
/// the CFT front and `--in-process` simulate.
fn sim_settings(
    controller: &fes_model::control::file::Controller,
    a: &Args,
) -> Result<fes_bench::simulation::SimSettings, fes_bench::simulation::SimError> {
    fes_bench::simulation::SimSettings::bench_muscle(
        controller,
        a.muscle.preset(),
        a.fatigue,
        ProfileSpec::Cardiac(cardiac(a)),
        outer_settings(a),
        a.seconds,
    )
}

/// `--in-process`: the chain in simulated time, with the bench's muscle and sensor.
fn in_process(a: &Args, out: &Path) -> anyhow::Result<()> {
    use fes_bench::simulation::simulate;

    let controller = fes_model::control::file::Controller::load(a.controller())
        .with_context(|| format!("controller {}", a.controller().display()))?;
    let (scale_n, delay) = (controller.lmn.force_scale_n, controller.lmn.delay);
    println!(
        "bench: in-process simulation (simulated time; no CAN, no processes, no latencies): {} muscle{}, {}",
        a.muscle.name(),
        if a.fatigue { " with fatigue" } else { "" },
        a.controller().display()
    );
    let settings = sim_settings(&controller, a)?;
    let front = settings.front(a.amplitude, a.stim_lead_ms as usize);
    let run = simulate(&controller, &settings)?;
    std::fs::create_dir_all(out).with_context(|| format!("create {}", out.display()))?;
    let beats_csv = out.join("beats.csv");
    let mut text =
        String::from("index,start_s,plateau_mean,peak,fti,pulses,correction,next_amplitude\n");
    for b in &run.beats {
        let m = &b.measurement;
        text += &format!(
            "{},{:.3},{},{:.6},{:.6},{},{:.6},{:.6}\n",
            m.beat.index,
            (m.beat.start_ns - fes_bench::simulation::T0_NS) as f64 * 1e-9,
            m.plateau_mean.map_or(String::new(), |p| format!("{p:.6}")),
            m.peak,
            m.fti,
            m.pulses,
            b.update.correction,
            b.update.amplitude
        );
    }
    std::fs::write(&beats_csv, text).with_context(|| format!("write {}", beats_csv.display()))?;
    // The time series, one row per 1 ms tick (pandas / Octave: a plain CSV with a header).
    let series_csv = out.join("series.csv");
    let mut text = String::from("t_s,reference,model_force,measured_force,pulse\n");
    for k in 0..run.pulse.len() {
        text += &format!(
            "{:.3},{:.6},{:.6},{:.6},{}\n",
            k as f64 * 1e-3,
            run.reference[k],
            run.model_force[k],
            run.measured[k],
            u8::from(run.pulse[k])
        );
    }
    std::fs::write(&series_csv, text).with_context(|| format!("write {}", series_csv.display()))?;
    let series = run.series();
    let none = Latency {
        wake_us: [f64::NAN; 3],
        ipc_us: [f64::NAN; 3],
        compute_p99_us: f64::NAN,
        publish_p99_us: f64::NAN,
        publish_us: [f64::NAN; 3],
        ..Default::default()
    };
    let summary = summarise(
        &series,
        &AnalysisInput {
            delay,
            target: a.amplitude,
            baseline: Some(baseline(a.muscle.preset(), a.amplitude, scale_n, delay)),
            uml: false,
            front: Some(front.clone()),
        },
        RunTiming {
            rt_core: none,
            stim_driver: None,
            pulses_sent: None,
            ledger: None,
        },
        "none (in-process simulation)".into(),
    );
    let plots = draw(&series, out, &summary, a, delay, false)?;
    print_summary(&summary, &plots, &[]);
    if controller.settings.planning.mode != fes_model::control::planner::PlanningMode::Off {
        let p = &run.planner;
        println!(
            "  planner: {} contractions planned ({} converged, {} replanned), {} ticks decided by a plan, {} causal for want of one, {} cut by a deadline",
            p.windows, p.converged, p.replans, p.planned_ticks, p.causal_fallbacks, p.deadline_cuts
        );
    }
    let mut extra = vec![("planner", serde_json::to_value(run.planner)?)];
    if let Some(k) = a.pattern_search {
        let r = search_patterns(&controller, &front, &series, &summary, k)?;
        extra.push(("pattern_search", serde_json::to_value(&r)?));
    }
    println!("  per beat: {}", beats_csv.display());
    println!("  per tick: {}", series_csv.display());
    write_json_with(&summary, &plots, a, &extra)
}

/// `--pattern-search K`: every pattern of K pulses on the run's muscle (1 ms grid, 2 ms for
/// three pulses; the controller's minimum interval apart), printed.
fn search_patterns(
    controller: &fes_model::control::file::Controller,
    front: &fes_bench::cft::FrontSettings,
    series: &Series,
    summary: &Summary,
    k: u8,
) -> anyhow::Result<fes_bench::cft::PatternSearch> {
    let k = usize::from(k);
    let grid = if k > 2 { 2 } else { 1 };
    let min_interval = (fes_bench::simulation::min_pulse_interval_s(controller) * 1e3).round();
    let level_error = summary.front.as_ref().map_or(0.0, |v| v.lcn.level_error);
    let bar = super::inputs::progress(0, &format!("every pattern of {k} pulses"));
    let r = front.pattern_search(
        series,
        k,
        grid,
        min_interval as usize,
        level_error,
        &mut |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )?;
    bar.finish_and_clear();
    print_pattern_search(&r, level_error);
    Ok(r)
}

/// `--pattern-search`: the best patterns of the count searched.
fn print_pattern_search(r: &fes_bench::cft::PatternSearch, level_error: f64) {
    let show = |p: &Option<fes_bench::cft::SearchedPattern>| {
        p.as_ref().map_or("none".to_string(), |p| {
            format!(
                "{:?} ms, RMS {}, level missed by {:.1} %",
                p.offsets_ms,
                fmt(p.point.rms_error, 4),
                100.0 * p.point.level_error
            )
        })
    };
    println!(
        "  every pattern of {} pulses ({} patterns, {} ms grid): best {}",
        r.pulses,
        r.patterns,
        r.grid_ms,
        show(&r.best)
    );
    println!(
        "    ... of those, missing the level by no more than the run ({:.1} %): {}",
        100.0 * level_error,
        show(&r.best_holding_level)
    );
}

/// `--json FILE`: the summary, the plots and the command line.
fn write_json(summary: &Summary, plots: &[PathBuf], a: &Args) -> anyhow::Result<()> {
    write_json_with(summary, plots, a, &[])
}

/// [`write_json`] with more keys.
fn write_json_with(
    summary: &Summary,
    plots: &[PathBuf],
    a: &Args,
    extra: &[(&str, serde_json::Value)],
) -> anyhow::Result<()> {
    if let Some(j) = &a.json {
        let mut v = serde_json::to_value(summary)?;
        if let Some(o) = v.as_object_mut() {
            for (k, x) in extra {
                o.insert((*k).into(), x.clone());
            }
            o.insert(
                "plots".into(),
                serde_json::json!(
                    plots
                        .iter()
                        .map(|p| p.display().to_string())
                        .collect::<Vec<_>>()
                ),
            );
            o.insert(
                "command".into(),
                serde_json::json!(std::env::args().collect::<Vec<_>>().join(" ")),
            );
        }
        std::fs::write(j, serde_json::to_string_pretty(&v)? + "\n")
            .with_context(|| format!("write {}", j.display()))?;
        println!("summary JSON: {}", j.display());
    }
    Ok(())
}

fn draw(
    series: &Series,
    out: &Path,
    s: &Summary,
    a: &Args,
    delay: usize,
    latency: bool,
) -> anyhow::Result<Vec<PathBuf>> {
    let mut paths = Vec::new();
    let t0 = series.beats.first().map_or(0, |b| b.start_ns);
    let run = RunSeries {
        t_s: series
            .t_ns
            .iter()
            .map(|&t| (t as f64 - t0 as f64) * 1e-9)
            .collect(),
        reference: series.reference.clone(),
        model: series.model.clone(),
        measured: series.measured.clone(),
        pulses_s: series
            .t_ns
            .iter()
            .zip(&series.pulse)
            .filter(|(_, p)| **p)
            .map(|(&t, _)| (t as f64 - t0 as f64) * 1e-9)
            .collect(),
    };
    if let Some(v) = &s.front {
        let p = a.format.file(out, "front");
        plot_front(
            &p,
            &format!(
                "CFT front: target {}, FTI per contraction {:.4} s (green: equal FTI +-5 %)",
                a.amplitude, v.reference_fti_per_contraction
            ),
            v,
        )?;
        paths.push(p);
    }
    let from = 2.0f64.min(s.duration_s / 2.0);
    let p = a.format.file(out, "force");
    plot_run(
        &p,
        &format!(
            "Bench: cardiac {} beats/min, target {} (model delay {delay} ms), {} pulses/contraction",
            a.hr,
            a.amplitude,
            fmt(s.pulses_per_contraction, 1)
        ),
        &run,
        (from, from + a.plot_window_s),
    )?;
    paths.push(p);
    let mut curves = Vec::new();
    for (file, who) in [
        ("rt-core.hlog", "rt-core"),
        ("stim-driver.hlog", "stim-driver"),
    ] {
        let path = out.join(file);
        if let Ok(tags) = fes_rt::rt::hlog::merge_by_tag(&path) {
            for (tag, h) in tags {
                if h.count() == 0 {
                    continue;
                }
                curves.push(LatencyCurve {
                    label: format!("{who} {tag}"),
                    points: percentile_grid()
                        .into_iter()
                        .map(|q| (q * 100.0, h.quantile_ns(q) as f64 * 1e-3))
                        .collect(),
                });
            }
        }
    }
    if latency && !curves.is_empty() {
        let p = a.format.file(out, "latency");
        plot_latency(
            &p,
            if s.timing_functional_only {
                "Latency percentiles (UML guest: functional only, not representative)"
            } else {
                "Latency percentiles"
            },
            &curves,
        )?;
        paths.push(p);
    }
    Ok(paths)
}

fn fmt(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "-".into()
    }
}

/// The summary's pulse lines: decided, not sent, and the recording's decided / sent /
/// applied ledger.
fn print_pulses(s: &Summary) {
    println!(
        "  pulses decided             {} ({} per contraction), {} not sent by the driver (refused or late, {} %){}",
        s.pulses,
        fmt(s.pulses_per_contraction, 2),
        s.pulses_not_sent,
        fmt(
            100.0 * s.pulses_not_sent as f64 / (s.pulses.max(1)) as f64,
            1
        ),
        s.pulses_sent.map_or(String::new(), |p| format!(
            "; stimulator driver sent {p} in all"
        ))
    );
    if let Some(l) = &s.pulse_ledger {
        let pct = |n: u64| fmt(100.0 * n as f64 / l.decided.max(1) as f64, 1);
        println!(
            "  pulse ledger (whole run)   {} decided, {} sent by the driver ({} %), {} applied by the stimulator ({} %)",
            l.decided,
            l.sent,
            pct(l.sent),
            l.applied,
            pct(l.applied)
        );
    }
}

fn print_summary(s: &Summary, plots: &[PathBuf], unclean: &[String]) {
    println!();
    println!(
        "== bench summary ({:.1} s of cardiac profile, {} contractions)",
        s.duration_s, s.contractions
    );
    println!("  tracking error (RMS, normalised force, vs reference delayed by the model delay)");
    println!("    model force              {}", fmt(s.rms_error_model, 4));
    println!(
        "    measured force           {}",
        fmt(s.rms_error_measured, 4)
    );
    println!(
        "  contraction (plateau mean) target {}: mean {}, first 5 beats {}, last 5 beats {}, worst after beat 10 {} %",
        s.target,
        fmt(s.mean_contraction, 4),
        fmt(s.first_last_contraction[0], 4),
        fmt(s.first_last_contraction[1], 4),
        fmt(s.worst_deviation_after_10 * 100.0, 1)
    );
    if s.beats_with_refused_pulses > 0 {
        println!(
            "    {} beat(s) with a pulse refused by the driver (not learned from by the outer loop); worst after beat 10 without them {} %",
            s.beats_with_refused_pulses,
            fmt(s.worst_deviation_after_10_delivered * 100.0, 1)
        );
    }
    print_pulses(s);
    if let Some(v) = &s.front {
        print_front(v);
    }
    println!(
        "  40 Hz baseline, same FTI   {} pulses per contraction, RMS error {} (FTI per contraction {} s)",
        fmt(s.baseline_pulses_per_contraction, 2),
        fmt(s.baseline_rms_error, 4),
        fmt(s.fti_per_contraction, 4)
    );
    if let Some(b) = &s.baseline {
        println!(
            "    (a 40 Hz train over the whole contraction: {} pulses, FTI {} s{})",
            b.full_contraction_pulses,
            fmt(b.full_contraction_fti, 4),
            if b.saturated {
                "; even a whole-beat 40 Hz train stays below the target FTI"
            } else {
                ""
            }
        );
    }
    if s.rt_core.ticks == 0 && s.stim_driver.is_none() {
        println!("  latency: not measured (in-process simulation: no processes)");
    } else {
        print_latency(s);
    }
    println!("  recording: {}", s.recording);
    for p in plots {
        println!("  plot: {}", p.display());
    }
    if !unclean.is_empty() {
        println!("  note: not stopped cleanly: {}", unclean.join(", "));
    }
}

/// The CFT front's verdict on the run: the user's question first answered by the pulses
/// and RMS of the best train with no more pulses.
fn print_front(v: &fes_bench::cft::FrontVerdict) {
    let opt = |x: Option<f64>, d: usize| x.map_or("none".into(), |x| fmt(x, d));
    let cheapest = v
        .cft_front
        .iter()
        .filter(|p| p.rms_error <= v.lcn.rms_error)
        .min_by(|a, b| {
            a.pulses_per_contraction
                .total_cmp(&b.pulses_per_contraction)
        });
    let (low_hz, top_hz) = v.hz_range;
    println!(
        "  CFT front (every {low_hz}-{top_hz} Hz train from each onset, whole or stopped after n pulses; same muscle and sensor): LCN {} pulses, RMS {}, FTIpP {} (FTI {} s; reference {} s)",
        fmt(v.lcn.pulses_per_contraction, 2),
        fmt(v.lcn.rms_error, 4),
        fmt(v.lcn.ftipp, 3),
        fmt(v.lcn.fti_per_contraction, 4),
        fmt(v.reference_fti_per_contraction, 4)
    );
    println!(
        "    dominated by a CFT of equal FTI: {}; pulses vs the cheapest CFT as good {}{}; FTIpP vs the best CFT of equal FTI {}",
        if v.lcn_dominated { "YES" } else { "no" },
        opt(v.pulses_vs_equal_rms_cft, 3),
        cheapest.map_or(String::new(), |p| format!(
            " ({} Hz x {}: RMS {})",
            p.hz.unwrap_or(0),
            p.n.unwrap_or(0),
            fmt(p.rms_error, 4)
        )),
        opt(v.ftipp_vs_best_cft, 3)
    );
    // The user's question: does any train with no more pulses track as well? Then the same
    // at the run's count rounded to a whole pulse (2.97 pulses and a 3-pulse train are the
    // same count to a user), and among the trains that hold the level as closely as the
    // run (those lines name the best train's level error too).
    let train = |best: &Option<FrontPoint>, beats: bool, level: bool| match (best, beats) {
        (_, true) => "none (the run beats every one)".to_string(),
        (Some(p), false) => format!(
            "{} Hz x {} pulses, RMS {}{}",
            p.hz.unwrap_or(0),
            p.n.unwrap_or(0),
            fmt(p.rms_error, 4),
            if level {
                format!(", level missed by {:.1} %", 100.0 * p.level_error)
            } else {
                String::new()
            }
        ),
        (None, false) => "none has so few pulses".to_string(),
    };
    println!(
        "    a train with no more pulses that tracks as well: {}",
        train(&v.best_cft_no_more_pulses, v.beats_every_cft, false)
    );
    println!(
        "    ... with no more than {} pulses (the count rounded): {}",
        v.lcn.pulses_per_contraction.round(),
        train(&v.best_cft_whole_count, v.beats_every_cft_whole_count, true)
    );
    println!(
        "    ... of those, missing the level by no more than the run ({:.1} %): {}",
        100.0 * v.lcn.level_error,
        train(
            &v.best_cft_holding_level,
            v.beats_every_cft_holding_level,
            true
        )
    );
}

fn print_latency(s: &Summary) {
    println!(
        "  latency (us){}       p50       p99       max",
        if s.timing_functional_only {
            " [UML guest: functional only]"
        } else {
            ""
        }
    );
    let row = |name: &str, v: [f64; 3]| {
        println!(
            "    {name:<26} {:>9} {:>9} {:>9}",
            fmt(v[0], 1),
            fmt(v[1], 1),
            fmt(v[2], 1)
        );
    };
    row("rt-core wake-up lateness", s.rt_core.wake_us);
    if let Some(d) = &s.stim_driver {
        row("StimTick -> stim-driver", d.ipc_us);
        row("StimTick -> PULSE written", d.publish_us);
    }
    println!(
        "    rt-core compute p99 {} us, publish p99 {} us",
        fmt(s.rt_core.compute_p99_us, 1),
        fmt(s.rt_core.publish_p99_us, 1)
    );
    println!(
        "  deadline misses (rt-core skipped periods) {}",
        s.deadline_misses
    );
}
