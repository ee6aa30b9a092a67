//! `rt-latency`: measures the real rt-core process against cyclictest on this machine.
//!
//! 1. Optional background load on another core (`stress-ng --cpu 1 --taskset <other>`),
//!    kept running for both measurements.
//! 2. `rt-probe` (a subscriber process, same core, one priority below) is started; then the
//!    real `rt-core` binary runs for N seconds (from its sd_notify READY=1, i.e. its first
//!    tick) with the same period, priority and core,
//!    while a reference publisher (a supervisor stand-in) steps the reference every second.
//!    rt-core writes wake-up lateness, input, compute and publish times to `rt-core.hlog`; the probe
//!    writes publish-to-receive latency to `rt-probe.hlog`.
//! 3. After rt-core has exited, `cyclictest` runs with the same period, priority and core for
//!    N seconds (never concurrently on the same core).
//! 4. One table (p50 / p99 / p99.9 / max), tick and miss counts, and the ratios of our
//!    wake-up lateness to cyclictest's; `--json` writes the same as JSON, and
//!    `cyclictest.hlog` (tag `cyclictest`, one interval per round) holds cyclictest's
//!    histograms next to the
//!    per-round `rt-core-N.hlog` / `rt-probe-N.hlog`.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow, bail};
use clap::Parser;
use fes_latency::DriverCounters;
use fes_rt::msg::Reference;
use fes_rt::msg::port;
use fes_rt::rt::MissingRightsPolicy;
use fes_rt::rt::clock::monotonic_ns;
use fes_rt::rt::histogram::LatencyHistogram;
use fes_rt::rt::hlog::{HlogWriter, merge_by_tag};
use fes_rt::rt::node::create_node;
use fes_rt::rt::probe::ProbeSummary;
use fes_rt::rt::telemetry::{TAG_COMPUTE, TAG_INPUT, TAG_IPC, TAG_PUBLISH, TAG_RECEIVE, TAG_WAKE};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use rt_core::rt::process_config::{RtCoreConfig, SourceConfig};
use serde::Serialize;

/// The driver's hlog tag for StimTick publish → PULSE written (stim-driver's telemetry).
const TAG_TICK_TO_CAN: &str = "tick_to_can";

use fes_latency::Percentiles;
use fes_latency::cyclictest::{self, CyclictestHistogram};

/// Runs the real rt-core loop for N seconds with a subscriber process measuring IPC latency,
/// then cyclictest with the same period, priority and core, and compares them.
#[derive(Debug, Parser)]
#[command(name = "rt-latency", version)]
struct Cli {
    /// Duration of each measurement (rt-core, then cyclictest), seconds.
    #[arg(long, default_value_t = 10)]
    seconds: u64,
    /// Load another core with `stress-ng --cpu 1 --taskset <other core>` during both runs.
    #[arg(long)]
    load: bool,
    /// Core for rt-core, the probe and cyclictest.
    #[arg(long, default_value_t = 1)]
    core: usize,
    /// SCHED_FIFO priority of rt-core and cyclictest (the probe runs one below).
    #[arg(long, default_value_t = 80)]
    priority: u8,
    /// Core for the probe (default: rt-core's core; it runs one priority below, so it
    /// receives when rt-core sleeps, as a driver sharing the real-time core would).
    #[arg(long)]
    probe_core: Option<usize>,
    /// Tick period, µs.
    #[arg(long, default_value_t = 1000)]
    period_us: u64,
    /// Base rt-core configuration (e.g. with a controller source); period, rt, telemetry and
    /// ipc settings are overridden. Default: a test-pattern source firing every 20 ticks.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Write the results as JSON.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Directory for the configuration, the .hlog files, the probe summary and cyclictest's
    /// output.
    #[arg(long, value_name = "DIR", default_value = "rt-latency-out")]
    out_dir: PathBuf,
    /// Largest latency cyclictest's histogram resolves, µs.
    #[arg(long, default_value_t = 5000)]
    hist_max_us: u64,
    /// Skip the cyclictest comparison.
    #[arg(long)]
    no_cyclictest: bool,
    /// Also measure the stim-driver's forward path: run `driver-latency` (the driver's
    /// real forward thread on a socket-pair bus with a virtual stimulator; fes-latency) at
    /// the probe's place, one priority below rt-core, and move the probe one lower.
    #[arg(long)]
    driver: bool,
    /// Alternate rt-core and cyclictest in this many rounds (each `seconds / rounds` long),
    /// so that both see the same background on a shared machine. Default: 10 s rounds.
    #[arg(long)]
    rounds: Option<u64>,
}

/// The JSON document (`--json`).
#[derive(Debug, Serialize)]
struct Results {
    ticks: u64,
    misses: u64,
    overruns: u64,
    wake_us: Percentiles,
    input_us: Percentiles,
    compute_us: Percentiles,
    publish_us: Percentiles,
    ipc_us: Percentiles,
    receive_us: Percentiles,
    cyclictest_us: Option<Percentiles>,
    ratio_p99: Option<f64>,
    ratio_p999: Option<f64>,
    cyclictest_samples: u64,
    cyclictest_over_period: u64,
    probe_received: u64,
    probe_lost: u64,
    probe_core: usize,
    /// StimTick publish → PULSE written by the driver (`--driver`).
    driver_forward_us: Option<Percentiles>,
    /// The driver's counters summed over the rounds (`--driver`).
    driver: Option<DriverCounters>,
    hot_path_allocations: u64,
    queue_overflows: u64,
    seconds: u64,
    rounds: u64,
    period_us: u64,
    priority: u8,
    core: usize,
    load: Option<String>,
    cyclictest_command: Option<String>,
    kernel: String,
    sched_rt_runtime_us: String,
}

fn main() -> std::process::ExitCode {
    fes_rt::rt::logging::init("rt-latency");
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
    match run(&Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            tracing::error!("{}", fes_rt::rt::error_text::one_line(e.as_ref()));
            fes_rt::rt::exit::Exit::Failed.into()
        }
    }
}

/// A child process that is stopped (SIGTERM, then SIGKILL) when dropped.
struct Guarded {
    name: &'static str,
    child: Child,
}

impl Guarded {
    fn pid(&self) -> Pid {
        Pid::from_raw(self.child.id() as i32)
    }

    /// Sends SIGTERM and waits up to `timeout` for the exit status.
    fn terminate(&mut self, timeout: Duration) -> anyhow::Result<std::process::ExitStatus> {
        if let Some(status) = self.child.try_wait()? {
            return Ok(status);
        }
        kill(self.pid(), Signal::SIGTERM).with_context(|| format!("SIGTERM to {}", self.name))?;
        self.wait(timeout)
    }

    /// Waits up to `timeout` for the process to exit by itself.
    fn wait(&mut self, timeout: Duration) -> anyhow::Result<std::process::ExitStatus> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait()? {
                return Ok(status);
            }
            if Instant::now() > deadline {
                bail!("{} did not exit within {:?}", self.name, timeout);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Guarded {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = kill(self.pid(), Signal::SIGTERM);
            std::thread::sleep(Duration::from_millis(200));
            if let Ok(None) = self.child.try_wait() {
                let _ = self.child.kill();
            }
            let _ = self.child.wait();
        }
    }
}

fn sibling_binary(name: &str) -> anyhow::Result<PathBuf> {
    let me = std::env::current_exe().context("locating rt-latency")?;
    let path = me.with_file_name(name);
    if !path.exists() {
        bail!(
            "{} not found next to rt-latency (build it: cargo build -p rt-core --release)",
            path.display()
        );
    }
    Ok(path)
}

/// The binaries one round starts: rt-core, the probe and (`--driver`) driver-latency.
struct Binaries {
    rt_core: PathBuf,
    probe: PathBuf,
    driver: Option<PathBuf>,
}

impl Binaries {
    /// Finds the binaries next to rt-latency.
    fn locate(cli: &Cli) -> anyhow::Result<Self> {
        let rt_core = sibling_binary("rt-core")?;
        let probe = sibling_binary("rt-probe")?;
        let driver = if cli.driver {
            Some(sibling_binary("driver-latency")?)
        } else {
            None
        };
        Ok(Self {
            rt_core,
            probe,
            driver,
        })
    }
}

/// Measures rt-core and cyclictest in alternating rounds, then prints and writes the results.
fn run(cli: &Cli) -> anyhow::Result<()> {
    let cores = check_args(cli)?;
    std::fs::create_dir_all(&cli.out_dir)
        .with_context(|| format!("creating {}", cli.out_dir.display()))?;
    let bins = Binaries::locate(cli)?;
    let config = rt_core_config(cli)?;

    // Background load, kept for every round of both measurements.
    let (load, load_desc) = start_load(cli, &cores)?;

    // Rounds: rt-core, then cyclictest, alternating, so that both see the same background.
    let rounds = cli
        .rounds
        .unwrap_or(cli.seconds.div_ceil(10))
        .clamp(1, cli.seconds);
    let mut total = RoundTotals::default();
    let mut cyclic = CyclictestRounds::default();
    for round in 0..rounds {
        let seconds =
            cli.seconds / rounds + u64::from(round + 1 == rounds) * (cli.seconds % rounds);
        tracing::info!("round {}/{rounds}: rt-core for {seconds} s", round + 1);
        total.add(measure_rt_core(cli, &config, round, seconds, &bins)?);
        if !cli.no_cyclictest {
            cyclic.measure(cli, round, rounds, seconds)?;
        }
    }
    drop(load);
    cyclic.write_hlog(&cli.out_dir.join("cyclictest.hlog"))?;

    let results = results(cli, total, cyclic, rounds, load_desc);
    print_table(&results);
    if let Some(path) = &cli.json {
        std::fs::write(path, serde_json::to_string_pretty(&results)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Checks the arguments; returns the cores of this machine.
fn check_args(cli: &Cli) -> anyhow::Result<Vec<core_affinity::CoreId>> {
    if cli.seconds == 0 {
        bail!("--seconds must be at least 1");
    }
    if !(3..=99).contains(&cli.priority) {
        bail!("--priority must be in 3..=99 (the probe and the driver run below it)");
    }
    let cores = core_affinity::get_core_ids().unwrap_or_default();
    if !cores.iter().any(|c| c.id == cli.core) {
        bail!(
            "core {} is not available here ({} core(s))",
            cli.core,
            cores.len()
        );
    }
    Ok(cores)
}

/// The rt-core configuration common to every round (each round adds its own prefix and
/// interval log).
fn rt_core_config(cli: &Cli) -> anyhow::Result<RtCoreConfig> {
    let mut config = match &cli.config {
        Some(path) => RtCoreConfig::load(path).context("--config")?,
        None => RtCoreConfig::with_source(SourceConfig::TestPattern { ipi_ticks: 20 }),
    };
    config.period_us = cli.period_us;
    config.rt.priority = cli.priority;
    config.rt.core = Some(cli.core);
    config.rt.on_missing_rights = MissingRightsPolicy::Refuse;
    config.rt.lock_memory = true;
    config.telemetry.report_period_ms = 1000;
    config.ipc.own.notify = true;
    config.validate().context("rt-core configuration")?;
    Ok(config)
}

/// Starts the background load on another core (`--load`): the process and its description.
fn start_load(
    cli: &Cli,
    cores: &[core_affinity::CoreId],
) -> anyhow::Result<(Option<Guarded>, Option<String>)> {
    if !cli.load {
        return Ok((None, None));
    }
    let other = cores
        .iter()
        .map(|c| c.id)
        .find(|&c| c != cli.core)
        .ok_or_else(|| anyhow!("--load needs a second core"))?;
    let timeout = 3 * cli.seconds + 60;
    let child = Command::new("stress-ng")
        .args([
            "--cpu",
            "1",
            "--taskset",
            &other.to_string(),
            "--timeout",
            &format!("{timeout}s"),
            "-q",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .context("starting stress-ng (install it: scripts/setup)")?;
    let load_desc = Some(format!("stress-ng --cpu 1 --taskset {other}"));
    std::thread::sleep(Duration::from_millis(500));
    let load = Guarded {
        name: "stress-ng",
        child,
    };
    Ok((Some(load), load_desc))
}

/// What the cyclictest rounds gave: their merged histogram, the command line and each
/// round's histogram with its length in seconds.
#[derive(Default)]
struct CyclictestRounds {
    merged: Option<CyclictestHistogram>,
    command: Option<String>,
    rounds: Vec<(u64, CyclictestHistogram)>,
}

impl CyclictestRounds {
    /// Runs cyclictest for one round of `seconds` and adds its histogram.
    fn measure(&mut self, cli: &Cli, round: u64, rounds: u64, seconds: u64) -> anyhow::Result<()> {
        let args = cyclictest::command_line(
            cli.priority,
            cli.core,
            cli.period_us,
            seconds,
            cli.hist_max_us,
        );
        tracing::info!("round {}/{rounds}: {}", round + 1, args.join(" "));
        let text = cyclictest::run(&args)?;
        std::fs::write(cli.out_dir.join(format!("cyclictest-{round}.txt")), &text)?;
        let h = CyclictestHistogram::parse(&text)?;
        self.rounds.push((seconds, h.clone()));
        match &mut self.merged {
            Some(all) => all.merge(&h),
            None => self.merged = Some(h),
        }
        self.command = Some(args.join(" "));
        Ok(())
    }

    /// Writes the rounds' histograms to `path`, if cyclictest ran.
    fn write_hlog(&self, path: &std::path::Path) -> anyhow::Result<()> {
        if self.rounds.is_empty() {
            return Ok(());
        }
        // One interval per round (its start = the round's offset in cyclictest time).
        let mut log = HlogWriter::create(
            path,
            "cyclictest (rt-tests), one interval per round, bucket middles",
            std::time::SystemTime::now(),
        )?;
        let mut start = Duration::ZERO;
        for (seconds, h) in &self.rounds {
            let length = Duration::from_secs(*seconds);
            log.write(&h.to_latency_histogram(), "cyclictest", start, length)?;
            start += length;
        }
        log.flush()?;
        Ok(())
    }
}

/// Assembles the results from the rounds' totals and cyclictest's histograms.
fn results(
    cli: &Cli,
    total: RoundTotals,
    cyclic: CyclictestRounds,
    rounds: u64,
    load_desc: Option<String>,
) -> Results {
    let RoundTotals {
        wake,
        input,
        compute,
        publish,
        ipc,
        receive,
        ticks,
        misses,
        overruns,
        hot_path_allocations,
        queue_overflows,
        received,
        lost,
        driver_forward,
        driver,
    } = total;
    let CyclictestRounds {
        merged: cyclic,
        command: cyclic_cmd,
        ..
    } = cyclic;

    let wake_p = Percentiles::from_histogram(&wake);
    let cyclic_p = cyclic.as_ref().map(Percentiles::from_cyclictest);
    // cyclictest truncates to whole µs: compare against the middle of its bucket.
    let ratio = |ours: f64, theirs: f64| ours / (theirs + 0.5);
    Results {
        ticks,
        misses,
        overruns,
        wake_us: wake_p,
        input_us: Percentiles::from_histogram(&input),
        compute_us: Percentiles::from_histogram(&compute),
        publish_us: Percentiles::from_histogram(&publish),
        ipc_us: Percentiles::from_histogram(&ipc),
        receive_us: Percentiles::from_histogram(&receive),
        cyclictest_us: cyclic_p,
        ratio_p99: cyclic_p.map(|c| ratio(wake_p.p99, c.p99)),
        ratio_p999: cyclic_p.map(|c| ratio(wake_p.p999, c.p999)),
        cyclictest_samples: cyclic.as_ref().map_or(0, CyclictestHistogram::total),
        cyclictest_over_period: cyclic
            .as_ref()
            .map_or(0, |h| h.at_least(cli.period_us as usize)),
        probe_received: received,
        probe_core: cli.probe_core.unwrap_or(cli.core),
        probe_lost: lost,
        driver_forward_us: driver.map(|_| Percentiles::from_histogram(&driver_forward)),
        driver,
        hot_path_allocations,
        queue_overflows,
        seconds: cli.seconds,
        rounds,
        period_us: cli.period_us,
        priority: cli.priority,
        core: cli.core,
        load: load_desc,
        cyclictest_command: cyclic_cmd,
        kernel: read_trim("/proc/sys/kernel/osrelease"),
        sched_rt_runtime_us: read_trim("/proc/sys/kernel/sched_rt_runtime_us"),
    }
}

/// What one or more rounds of the rt-core measurement gave.
#[derive(Default)]
struct RoundTotals {
    wake: LatencyHistogram,
    input: LatencyHistogram,
    compute: LatencyHistogram,
    publish: LatencyHistogram,
    ipc: LatencyHistogram,
    receive: LatencyHistogram,
    ticks: u64,
    misses: u64,
    overruns: u64,
    hot_path_allocations: u64,
    queue_overflows: u64,
    received: u64,
    lost: u64,
    driver_forward: LatencyHistogram,
    driver: Option<DriverCounters>,
}

impl RoundTotals {
    fn add(&mut self, r: RoundTotals) {
        self.wake.add(&r.wake);
        self.input.add(&r.input);
        self.compute.add(&r.compute);
        self.publish.add(&r.publish);
        self.ipc.add(&r.ipc);
        self.receive.add(&r.receive);
        self.ticks += r.ticks;
        self.misses += r.misses;
        self.overruns += r.overruns;
        self.hot_path_allocations += r.hot_path_allocations;
        self.queue_overflows += r.queue_overflows;
        self.received += r.received;
        self.lost += r.lost;
        self.driver_forward.add(&r.driver_forward);
        if let Some(d) = &r.driver {
            self.driver.get_or_insert_default().add(d);
        }
    }
}

/// The files of one round in the out directory.
struct RoundFiles {
    /// rt-core's configuration.
    config: PathBuf,
    /// rt-core's interval log (absolute: rt-core gets it in its configuration).
    core_hlog: PathBuf,
    probe_hlog: PathBuf,
    probe_summary: PathBuf,
    driver_hlog: PathBuf,
    driver_summary: PathBuf,
}

impl RoundFiles {
    /// The file names of round `round` in `out_dir`.
    fn new(out_dir: &std::path::Path, round: u64) -> anyhow::Result<Self> {
        let out = |name: &str| out_dir.join(name);
        Ok(Self {
            config: out(&format!("rt-core-{round}.toml")),
            core_hlog: std::path::absolute(out(&format!("rt-core-{round}.hlog")))?,
            probe_hlog: out(&format!("rt-probe-{round}.hlog")),
            probe_summary: out(&format!("probe-{round}.json")),
            driver_hlog: out(&format!("driver-{round}.hlog")),
            driver_summary: out(&format!("driver-{round}.json")),
        })
    }
}

/// One round: the probe, then the real rt-core process for `seconds`, with a reference
/// publisher; returns the merged interval logs and the counters.
fn measure_rt_core(
    cli: &Cli,
    base: &RtCoreConfig,
    round: u64,
    seconds: u64,
    bins: &Binaries,
) -> anyhow::Result<RoundTotals> {
    let files = RoundFiles::new(&cli.out_dir, round)?;
    let mut config = base.clone();
    config.telemetry.hlog = Some(files.core_hlog.clone());
    config.ipc.prefix = format!("rtlatency{}r{round}", std::process::id());
    std::fs::write(&files.config, config.to_toml())?;
    let prefix = config.ipc.prefix.clone();

    let mut probe = start_probe(cli, &bins.probe, &prefix, &files, bins.driver.is_some())?;
    let mut driver = match &bins.driver {
        Some(bin) => Some(start_driver(cli, bin, &prefix, &files)?),
        None => None,
    };
    let measured = with_references(&prefix, || {
        run_rt_core(cli, round, seconds, &bins.rt_core, &files.config)
    });
    let probe_status = probe.wait(Duration::from_secs(10));
    let driver_status = driver
        .as_mut()
        .map(|d| d.terminate(Duration::from_secs(10)));
    measured?;
    let driver_totals = match driver_status {
        Some(status) => Some(driver_totals(status?, &files.driver_summary)?),
        None => None,
    };
    round_totals(probe_status?, &files, driver_totals)
}

/// Starts rt-probe on the round's prefix and waits for its `ready`; it runs one priority
/// below rt-core, or two with the driver between them.
fn start_probe(
    cli: &Cli,
    bin: &std::path::Path,
    prefix: &str,
    files: &RoundFiles,
    with_driver: bool,
) -> anyhow::Result<Guarded> {
    let mut probe = Guarded {
        name: "rt-probe",
        child: Command::new(bin)
            .arg("--prefix")
            .arg(prefix)
            .arg("--hlog")
            .arg(&files.probe_hlog)
            .arg("--summary")
            .arg(&files.probe_summary)
            .arg("--priority")
            .arg((cli.priority - 1 - u8::from(with_driver)).to_string())
            .arg("--core")
            .arg(cli.probe_core.unwrap_or(cli.core).to_string())
            .stdout(Stdio::piped())
            .spawn()
            .context("starting rt-probe")?,
    };
    wait_for_ready(&mut probe)?;
    Ok(probe)
}

/// Starts driver-latency on the round's prefix and waits for its `ready`.
fn start_driver(
    cli: &Cli,
    bin: &std::path::Path,
    prefix: &str,
    files: &RoundFiles,
) -> anyhow::Result<Guarded> {
    // The driver sits where the deployment puts it: one priority below rt-core, on the
    // probe's core; its virtual stimulator (hardware, in reality) on another core.
    let core = cli.probe_core.unwrap_or(cli.core);
    let mut cmd = Command::new(bin);
    cmd.arg("--prefix")
        .arg(prefix)
        .arg("--hlog")
        .arg(&files.driver_hlog)
        .arg("--summary")
        .arg(&files.driver_summary)
        .arg("--priority")
        .arg((cli.priority - 1).to_string())
        .arg("--core")
        .arg(core.to_string())
        .stdout(Stdio::piped());
    if let Some(other) = core_affinity::get_core_ids()
        .unwrap_or_default()
        .iter()
        .map(|c| c.id)
        .find(|&c| c != core)
    {
        cmd.arg("--stim-core").arg(other.to_string());
    }
    let mut d = Guarded {
        name: "driver-latency",
        child: cmd.spawn().context("starting driver-latency")?,
    };
    wait_for_ready(&mut d)?;
    Ok(d)
}

/// Runs `measure` while a reference publisher steps the reference on `prefix`.
fn with_references(
    prefix: &str,
    measure: impl FnOnce() -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let stop_references = AtomicBool::new(false);
    std::thread::scope(|s| -> anyhow::Result<()> {
        let publisher = s.spawn(|| publish_references(prefix, &stop_references));
        let result = measure();
        stop_references.store(true, Ordering::Relaxed);
        publisher
            .join()
            .map_err(|_| anyhow!("reference publisher panicked"))??;
        result
    })
}

/// Runs rt-core with `config` for `seconds` from its READY=1, then stops it.
fn run_rt_core(
    cli: &Cli,
    round: u64,
    seconds: u64,
    bin: &std::path::Path,
    config: &std::path::Path,
) -> anyhow::Result<()> {
    // rt-core says READY=1 (sd_notify) once its loop ticks; the round's time runs
    // from then, not from the spawn (start-up, mlockall included, can take seconds
    // on a loaded machine).
    let ready = ReadySocket::bind(&cli.out_dir, round)?;
    let mut rt_core = Guarded {
        name: "rt-core",
        child: Command::new(bin)
            .arg("--config")
            .arg(config)
            .env("NOTIFY_SOCKET", &ready.path)
            .env_remove("WATCHDOG_USEC")
            .env_remove("WATCHDOG_PID")
            .spawn()
            .context("starting rt-core")?,
    };
    ready.wait(&mut rt_core, Duration::from_secs(30))?;
    let end = Instant::now() + Duration::from_secs(seconds);
    while Instant::now() < end {
        if let Some(status) = rt_core.child.try_wait()? {
            bail!("rt-core exited early ({status}); see its log above");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let status = rt_core.terminate(Duration::from_secs(10))?;
    if !status.success() {
        bail!("rt-core ended with {status}");
    }
    Ok(())
}

/// Checks driver-latency's exit status and reads its summary.
fn driver_totals(
    status: std::process::ExitStatus,
    summary: &std::path::Path,
) -> anyhow::Result<DriverCounters> {
    if !status.success() {
        bail!("driver-latency ended with {status}");
    }
    let totals: DriverCounters =
        serde_json::from_slice(&std::fs::read(summary).context("reading the driver summary")?)
            .context("parsing the driver summary")?;
    Ok(totals)
}

/// Checks rt-probe's exit status and collects the round's interval logs and counters.
fn round_totals(
    probe_status: std::process::ExitStatus,
    files: &RoundFiles,
    driver_totals: Option<DriverCounters>,
) -> anyhow::Result<RoundTotals> {
    if !probe_status.success() {
        bail!("rt-probe ended with {probe_status}");
    }
    let summary: ProbeSummary = serde_json::from_slice(
        &std::fs::read(&files.probe_summary).context("reading the probe summary")?,
    )
    .context("parsing the probe summary")?;
    let timing = summary
        .rt_core
        .ok_or_else(|| anyhow!("the probe received no TimingReport from rt-core"))?;
    let core_hists = merge_by_tag(&files.core_hlog)?;
    let probe_hists = merge_by_tag(&files.probe_hlog)?;
    let tag = |m: &std::collections::BTreeMap<String, LatencyHistogram>, t: &str| {
        m.get(t)
            .cloned()
            .ok_or_else(|| anyhow!("no '{t}' intervals in the interval log"))
    };
    Ok(RoundTotals {
        wake: tag(&core_hists, TAG_WAKE)?,
        input: tag(&core_hists, TAG_INPUT)?,
        compute: tag(&core_hists, TAG_COMPUTE)?,
        publish: tag(&core_hists, TAG_PUBLISH)?,
        ipc: tag(&probe_hists, TAG_IPC)?,
        receive: tag(&probe_hists, TAG_RECEIVE)?,
        ticks: timing.ticks,
        misses: timing.misses,
        overruns: timing.overruns,
        hot_path_allocations: timing.hot_path_allocations,
        queue_overflows: timing.queue_overflows,
        received: summary.received,
        lost: summary.lost,
        driver_forward: match &driver_totals {
            Some(_) => merge_by_tag(&files.driver_hlog)?
                .remove(TAG_TICK_TO_CAN)
                .unwrap_or_default(),
            None => LatencyHistogram::new(),
        },
        driver: driver_totals,
    })
}

/// The datagram socket rt-core notifies (`NOTIFY_SOCKET`), to learn when it ticks.
struct ReadySocket {
    socket: std::os::unix::net::UnixDatagram,
    path: PathBuf,
}

impl ReadySocket {
    fn bind(out_dir: &std::path::Path, round: u64) -> anyhow::Result<Self> {
        // sun_path holds at most 107 bytes: an absolute path in the out directory if it
        // fits, else in the temp directory.
        let name = format!("notify-{}-{round}.sock", std::process::id());
        let mut path = std::path::absolute(out_dir.join(&name))?;
        if path.as_os_str().len() > 100 {
            path = std::env::temp_dir().join(format!("rt-latency-{name}"));
        }
        let _ = std::fs::remove_file(&path);
        let socket = std::os::unix::net::UnixDatagram::bind(&path)
            .with_context(|| format!("binding {}", path.display()))?;
        socket.set_read_timeout(Some(Duration::from_millis(50)))?;
        Ok(Self { socket, path })
    }

    /// Waits for READY=1, failing if rt-core exits first or `timeout` passes.
    fn wait(&self, rt_core: &mut Guarded, timeout: Duration) -> anyhow::Result<()> {
        let deadline = Instant::now() + timeout;
        let mut buf = [0u8; 4096];
        while Instant::now() < deadline {
            if let Ok(n) = self.socket.recv(&mut buf)
                && buf[..n].split(|&b| b == b'\n').any(|l| l == b"READY=1")
            {
                return Ok(());
            }
            if let Some(status) = rt_core.child.try_wait()? {
                bail!("rt-core exited before it was ready ({status}); see its log above");
            }
        }
        bail!("rt-core did not report READY=1 within {timeout:?}")
    }
}

impl Drop for ReadySocket {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

fn read_trim(path: &str) -> String {
    std::fs::read_to_string(path)
        .map(|s| s.trim().to_owned())
        .unwrap_or_else(|_| "unknown".to_owned())
}

/// Waits for the `ready` line of a subscriber process (rt-probe, driver-latency).
fn wait_for_ready(probe: &mut Guarded) -> anyhow::Result<()> {
    let name = probe.name;
    let stdout = probe
        .child
        .stdout
        .take()
        .ok_or_else(|| anyhow!("{name} stdout not captured"))?;
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut lines = BufReader::new(stdout).lines();
        let first = lines.next();
        let _ = tx.send(first);
        // Keep draining so the probe never blocks on a full pipe.
        for _ in lines {}
    });
    match rx.recv_timeout(Duration::from_secs(10)) {
        Ok(Some(Ok(line))) if line.trim() == "ready" => Ok(()),
        Ok(other) => bail!("{name} did not report ready: {other:?}"),
        Err(_) => bail!("{name} did not report ready within 10 s"),
    }
}

/// A supervisor stand-in: a fresh Reference every 10 ms, stepping between 0.2 and 0.6
/// every second.
fn publish_references(prefix: &str, stop: &AtomicBool) -> anyhow::Result<()> {
    let node = create_node("rt-latency-reference")?;
    let publisher = port::publisher::<Reference>(&node, prefix)?;
    let start = Instant::now();
    let mut seq = 0;
    while !stop.load(Ordering::Relaxed) {
        seq += 1;
        let force = if start.elapsed().as_secs().is_multiple_of(2) {
            0.2
        } else {
            0.6
        };
        publisher
            .send_copy(Reference::new(seq, monotonic_ns(), force))
            .map_err(|e| anyhow!("Reference send: {e:?}"))?;
        std::thread::sleep(Duration::from_millis(10));
    }
    Ok(())
}

fn print_table(r: &Results) {
    println!(
        "rt-latency: {} s in {} round(s), period {} us, SCHED_FIFO {} on core {}, load: {}",
        r.seconds,
        r.rounds,
        r.period_us,
        r.priority,
        r.core,
        r.load.as_deref().unwrap_or("none")
    );
    Percentiles::print_header();
    let row = |name: &str, p: &Percentiles| p.print_row(name);
    row("wake-up lateness", &r.wake_us);
    row("input (receive references)", &r.input_us);
    row("compute (tick source)", &r.compute_us);
    row("publish (+notify)", &r.publish_us);
    row("ipc publish->receive", &r.ipc_us);
    row("  of which receive", &r.receive_us);
    if let Some(d) = &r.driver_forward_us {
        row("driver StimTick->PULSE write", d);
    }
    if let Some(c) = &r.cyclictest_us {
        row("cyclictest latency", c);
    }
    println!(
        "ticks {}, missed periods {} in {} late wake-ups (>= 1 period late), probe received {} (lost {}), hot-path heap allocations {}, telemetry overflows {}",
        r.ticks,
        r.misses,
        r.overruns,
        r.probe_received,
        r.probe_lost,
        r.hot_path_allocations,
        r.queue_overflows
    );
    if let Some(d) = &r.driver {
        println!(
            "driver: {} StimTicks ({} lost, {} refused), {} PULSE written, {} refused by its interlocks, {} while not armed, stimulator applied {}, {} write errors, {} trips ({} arms), hot-path heap allocations {}",
            d.ticks_received,
            d.ticks_lost,
            d.ticks_refused,
            d.pulses_sent,
            d.pulses_rejected,
            d.pulses_not_armed,
            d.stimulator_pulses,
            d.can_tx_errors,
            d.trips,
            d.arms,
            d.hot_path_allocations
        );
    }
    if let (Some(p99), Some(p999)) = (r.ratio_p99, r.ratio_p999) {
        println!(
            "cyclictest: {} samples, {} at or above one period; wake/cyclictest ratio p99 {:.2}, p99.9 {:.2}",
            r.cyclictest_samples, r.cyclictest_over_period, p99, p999
        );
    }
}
