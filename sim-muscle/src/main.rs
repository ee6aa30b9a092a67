//! `sim-muscle`: simulate the Ding muscle, record thesis-protocol data sets, plot them.

use std::collections::BTreeMap;
use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use fes_rt::rt::exit::Exit;

use anyhow::{Context, Result, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use fes_dataset::{DataSet, FORCE_SLACK, WriteMode};
use sim_muscle::ding::{FatigueParams, PulseWidthParams};
use sim_muscle::lmn_plant::LmnPlant;
use sim_muscle::muscle::{Muscle, MuscleConfig, max_force};
use sim_muscle::pattern::{constant_train, from_samples, from_times_ms, samples_on_grid};
use sim_muscle::plant::{MusclePlant, OnDevice, Pulse};
use sim_muscle::plot::{default_selection, plot_records};
use sim_muscle::preset::Preset;
use sim_muscle::protocol::{ProtocolConfig, ProtocolKind};
use sim_muscle::recorder::{Normalise, Origin, record_normalised};
use sim_muscle::sensor::{ForceSensor, Measured, SensorConfig};
use sim_muscle::simulate::simulate;

const ABOUT: &str = "Virtual skeletal muscle for FES work: the Ding / Wexler / Binder-Macleod \
force model with the catch-like effect, optional fatigue, and the thesis's recording protocol.";

const LONG_ABOUT: &str = "\
Virtual skeletal muscle for FES work: the Ding / Wexler / Binder-Macleod force model
(Ding et al. 2002/2003) standing in for the rabbit muscles of Gollee's thesis.

  simulate  force of one stimulation pattern, CSV on stdout
  record    a data set with the thesis recording protocol (5.1)
  plot      records of a data set as a PNG, like thesis Fig. 5.2

Two presets: `fast` (control muscle: fast twitch, strong catch-like effect: a 5 ms
doublet gives 2.8 times a twitch's force-time integral) and `slow` (chronically
stimulated: slower, no catch-like gain). Pulses are supramaximal (200 us) and fire at
the start of a 1 ms sample; the force appears after a 7 ms electromechanical delay.
See docs/sim-muscle.md for the model, the parameter sources and the data-set format.";

#[derive(Parser)]
#[command(name = "sim-muscle", version, about = ABOUT, long_about = LONG_ABOUT)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate one stimulation pattern; prints `t_ms,force_n` at 1 ms to stdout.
    #[command(long_about = SIMULATE_HELP, allow_negative_numbers = true)]
    Simulate(SimulateArgs),
    /// Record a data set with the thesis protocol (or a richer one).
    #[command(long_about = RECORD_HELP, allow_negative_numbers = true)]
    Record(RecordArgs),
    /// Plot records of a data set as a PNG (pulses on top, force below).
    #[command(long_about = PLOT_HELP)]
    Plot(PlotArgs),
    /// Run the virtual stimulator with this muscle on a CAN bus (FORCE every 1 ms).
    #[command(long_about = STIMULATOR_HELP, allow_negative_numbers = true)]
    Stimulator(StimulatorCmd),
    /// Run a virtual Hasomed RehaStim 2 (ScienceMode 2) with this muscle on a pseudo-terminal.
    #[command(long_about = REHASTIM2_HELP)]
    Rehastim2(Rehastim2Cmd),
}

const REHASTIM2_HELP: &str = "\
Run a virtual Hasomed RehaStim 2 on a pseudo-terminal: the device side of ScienceMode 2
(docs/sciencemode.md) driving this muscle on one channel. Announces itself with Init until
the host answers, then serves GetStimulationMode, channel list mode (init, start / update,
stop) and single pulses within the device's limits (current 0..=126 mA, pulse width 0 or
20..=500 us, main interval 8..=1025 ms), answering out-of-range values with a parameter
error. Its watchdog stops channel list mode when the host sends nothing for --watchdog-ms.
Stops on SIGINT/SIGTERM.

The host opens the --pty-link path as it would /dev/ttyUSB0, e.g. with pyScienceMode:
  sim-muscle rehastim2 --pty-link /tmp/rehastim2 --pulse-log /tmp/pulses.csv --preset fast
  python3 -c 'from pysciencemode import Rehastim2; Rehastim2(\"/tmp/rehastim2\")'";

const STIMULATOR_HELP: &str = "\
Run the virtual stimulator on a CAN interface: the stimulator side of the FES protocol
(docs/can-protocol.md, crates/fes-can/dbc/fes.dbc) driving this muscle. NMT state machine,
CONFIG in pre-operational only, its own interlocks (minimum IPI, rate window, amplitude
and width ceilings, CRC and alive counter), EMCY on every rejection, a host-heartbeat
watchdog that stops output and waits for an explicit NMT start, FORCE every 1 ms and
STATUS every 10 ms. Stops on SIGINT/SIGTERM with output off and a final STATUS.

Without a kernel CAN driver, run it inside the vcan harness (docs/vcan.md):
  vcan-run -- sim-muscle stimulator --iface vcan0 --preset fast

Example (fatiguing fast muscle, measured force with the default sensor noise):
  sim-muscle stimulator --iface vcan0 --preset fast --fatigue --measured";

const SIMULATE_HELP: &str = "\
Simulate one stimulation pattern and print CSV `t_ms,force_n` on stdout, one line per
1 ms sample from t = 0 (muscle at rest) to duration - 1 ms. A pulse at t fires at the
start of that sample; with the default 7 ms electromechanical delay the first nonzero
force is 8 ms after the pulse.

The pattern is either a list of pulse times (--pulses 0,5,30) or a constant-frequency
train (--freq 40 --train-ms 300), optionally repeated (--repeat-ms 2000). By default the
output is the muscle's true force; --measured adds the force sensor (offset, noise,
low-pass) with the same defaults as `record`.

Examples:
  sim-muscle simulate --preset fast --pulses 0,5 --duration-ms 300
  sim-muscle simulate --preset slow --freq 40 --train-ms 300 --duration-ms 600
  sim-muscle simulate --preset fast --set tau1=0.04 --set r0=3 --pulses 0 --duration-ms 200
  sim-muscle simulate --preset fast --fatigue --freq 33 --train-ms 1000 --repeat-ms 2000 \\
      --duration-ms 60000";

const RECORD_HELP: &str = "\
Record a data set with the thesis protocol (5.1): supramaximal 200 us pulses, inter-pulse
intervals drawn at random from 1-70 ms, trains of at most 300 ms starting 10 ms into the
record, records of 590 ms (fast) / 600 ms (slow), 60 / 84 records, a constant 40 Hz
check record every 10th record (every 5 min with 30 s rests), 1 ms sampling, each record
from rest. The force is measured (offset + Gaussian noise, seeded), the offset removed
and the force normalised to [0, 1]; the scale and offset are stored. The first 30
records train, the rest test. Every protocol number below has the thesis value as
default.

--protocol rich adds constant-frequency trains spread over 5-100 Hz and doublet-led
trains, so the data cover the whole scheduling range.

The output directory gets dataset.json and record_NNN.csv files (format fes-dataset/1,
see docs/sim-muscle.md). A non-empty directory is refused unless --force is given. The
same seed gives a byte-identical data set.

Example:
  sim-muscle record --preset fast --seed 1 --out data/fast";

const PLOT_HELP: &str = "\
Plot records of a data set as a PNG like thesis Fig. 5.2: the selected records
concatenated (rests omitted), the pulses on top and the normalised force below. By
default the first three random records and the first constant-frequency record.

Example:
  sim-muscle plot --data data/fast --out fast.png --records 0,1,2,9";

/// Muscle preset names for clap.
#[derive(Clone, Copy, ValueEnum)]
enum PresetArg {
    /// Control muscle: fast twitch, strong catch-like effect.
    Fast,
    /// Chronically stimulated muscle: slower, no catch-like gain.
    Slow,
    /// Fast muscle whose identified local models have the thesis's Table 5.3 poles
    /// (-87..-256 and -8..-33 1/s): tau_c 3 ms, Ding 2003's tau_1, tau_2.
    ThesisFast,
}

impl From<PresetArg> for Preset {
    fn from(p: PresetArg) -> Self {
        match p {
            PresetArg::Fast => Preset::Fast,
            PresetArg::Slow => Preset::Slow,
            PresetArg::ThesisFast => Preset::ThesisFast,
        }
    }
}

/// Protocol names for clap.
#[derive(Clone, Copy, ValueEnum)]
enum ProtocolArg {
    /// Thesis 5.1: random IPI trains and the constant check record.
    Thesis,
    /// Thesis records plus constant trains over 5-100 Hz and doublet-led trains.
    Rich,
}

#[derive(Args)]
struct MuscleArgs {
    /// Muscle preset.
    #[arg(long, value_enum, required_unless_present = "model")]
    preset: Option<PresetArg>,
    /// Use an LMN model file (rt-core `fes-lmn/1`) as the muscle instead of a preset:
    /// force = model output x the file's force_scale_n. Pulses are binary (u = 1).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["preset", "set", "fatigue", "emd_ms"])]
    model: Option<PathBuf>,
    /// Change a model parameter, SI units, repeatable: tauc [s] (CN time constant), r0 [1]
    /// (catch-like enhancement, >= 1), km [1] (CN sensitivity), a [N/s] (force scale),
    /// tau1 [s] (force decay without cross-bridges), tau2 [s] (extra decay from
    /// cross-bridges); with --fatigue also alpha_a [1/s^2], alpha_km [1/(s N)],
    /// alpha_tau1 [1/N], tau_fat [s].
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = parse_assignment)]
    set: Vec<(String, f64)>,
    /// Enable the fatigue extension (Ding et al. 2003: A falls, Km and tau1 rise with
    /// force, recovering with tau_fat = 127 s).
    #[arg(long)]
    fatigue: bool,
    /// Electromechanical delay between a pulse and its force, ms (thesis: Td ~ 7 ms).
    #[arg(long, value_name = "MS", default_value_t = 7.0)]
    emd_ms: f64,
}

#[derive(Args)]
struct SensorArgs {
    /// Force-sensor noise standard deviation, N [default: 0.3 % of the muscle's maximal
    /// force, i.e. of the peak of a 1 s 100 Hz train].
    #[arg(long, value_name = "N")]
    noise_std_n: Option<f64>,
    /// Force-sensor offset, N [default: 1 % of the muscle's maximal force].
    #[arg(long, value_name = "N")]
    offset_n: Option<f64>,
    /// Time constant of a first-order force-sensor low-pass, ms (0 = none).
    #[arg(long, value_name = "MS", default_value_t = 0.0)]
    sensor_tau_ms: f64,
}

#[derive(Args)]
struct SimulateArgs {
    #[command(flatten)]
    muscle: MuscleArgs,
    /// Pulse times, ms, comma-separated, strictly increasing, whole samples.
    #[arg(long, value_name = "MS,MS,...", value_delimiter = ',', num_args = 1.., required_unless_present = "freq", conflicts_with = "freq")]
    pulses: Vec<f64>,
    /// Constant stimulation frequency, Hz (each pulse at the nearest 1 ms sample).
    #[arg(long, value_name = "HZ", requires = "train_ms")]
    freq: Option<f64>,
    /// Length of the constant-frequency train, ms (pulses at start .. start + N).
    #[arg(long, value_name = "MS", requires = "freq")]
    train_ms: Option<u32>,
    /// Time of the train's first pulse, ms.
    #[arg(long, value_name = "MS", default_value_t = 0, requires = "freq")]
    start_ms: u32,
    /// Repeat the pattern every N ms until the end of the run.
    #[arg(long, value_name = "MS")]
    repeat_ms: Option<u32>,
    /// Length of the run, ms (that many 1 ms samples are printed).
    #[arg(long, value_name = "MS")]
    duration_ms: u32,
    /// Pulse width, us. Turns on the pulse-width variant (Ding et al. 2007): widths
    /// below 200 us recruit fewer motor units; 200 us gives the base model.
    #[arg(long, value_name = "US", conflicts_with = "model")]
    pulse_width_us: Option<f64>,
    #[command(flatten)]
    force: ForceReading,
}

/// How a command reads the muscle's force: exact, or as the force sensor measures it.
#[derive(Args)]
struct ForceReading {
    /// Read the force as a force sensor measures it (offset, noise, low-pass) instead of
    /// the exact model force: what `simulate` prints, the stimulator's FORCE frames, the
    /// virtual RehaStim 2's `--force-prefix` samples.
    #[arg(long)]
    measured: bool,
    #[command(flatten)]
    sensor: SensorArgs,
    /// Seed of the sensor noise (with --measured).
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

impl ForceReading {
    /// Refuses sensor options given without `--measured` (they would be ignored).
    fn check(&self) -> Result<()> {
        let s = &self.sensor;
        if !self.measured
            && (s.noise_std_n.is_some() || s.offset_n.is_some() || s.sensor_tau_ms != 0.0)
        {
            bail!(
                "--noise-std-n, --offset-n and --sensor-tau-ms describe the sensor: add --measured"
            );
        }
        Ok(())
    }

    /// `plant` read this way, sampled every `ts_s`: as it is, or behind the sensor.
    fn read(&self, mut plant: Box<dyn MusclePlant>, ts_s: f64) -> Result<Box<dyn MusclePlant>> {
        if !self.measured {
            return Ok(plant);
        }
        let config = sensor_config(&self.sensor, plant.as_mut(), self.seed)?;
        Ok(Box::new(Measured::new(
            plant,
            ForceSensor::new(config, ts_s).context("sensor settings")?,
        )))
    }
}

#[derive(Args)]
struct RecordArgs {
    #[command(flatten)]
    muscle: MuscleArgs,
    /// Seed of the random patterns and the noise (the same seed gives the same bytes).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output directory (created; must be empty unless --force).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Replace the data set already in --out (only its dataset.json and record files).
    #[arg(long)]
    force: bool,
    /// Normalise the force by this data set's scale (its `scale_n`) instead of this
    /// recording's own peak, so that both share their units: a model's levels are
    /// fractions of its data's scale, and a richer protocol reaching a higher peak would
    /// otherwise make every level ask for more force. Records that exceed the reader's
    /// bound (1.1 of the scale) are left out, and their number reported.
    #[arg(long, value_name = "DIR")]
    scale_from: Option<PathBuf>,
    /// Pattern family.
    #[arg(long, value_enum, default_value = "thesis")]
    protocol: ProtocolArg,
    /// Number of records [default: 60 fast, 84 slow].
    #[arg(long, value_name = "N")]
    records: Option<usize>,
    /// Record length, ms [default: 590 fast, 600 slow].
    #[arg(long, value_name = "MS")]
    record_ms: Option<u32>,
    /// The first N records train, the rest test.
    #[arg(long, value_name = "N", default_value_t = 30)]
    train_records: usize,
    /// Sample period, ms.
    #[arg(long, value_name = "MS", default_value_t = 1.0)]
    ts_ms: f64,
    /// Time of each record's first pulse, ms.
    #[arg(long, value_name = "MS", default_value_t = 10)]
    train_start_ms: u32,
    /// Shortest train (first to last pulse), ms; lengths are drawn uniformly.
    #[arg(long, value_name = "MS", default_value_t = 100)]
    train_min_ms: u32,
    /// Longest train, ms.
    #[arg(long, value_name = "MS", default_value_t = 300)]
    train_max_ms: u32,
    /// Shortest random inter-pulse interval, ms (drawn uniformly, whole ms).
    #[arg(long, value_name = "MS", default_value_t = 1)]
    ipi_min_ms: u32,
    /// Longest random inter-pulse interval, ms.
    #[arg(long, value_name = "MS", default_value_t = 70)]
    ipi_max_ms: u32,
    /// Every Nth record is the constant check record (0 = none).
    #[arg(long, value_name = "N", default_value_t = 10)]
    const_every: usize,
    /// Inter-pulse interval of the constant check record, ms (25 ms = 40 Hz).
    #[arg(long, value_name = "MS", default_value_t = 25)]
    const_ipi_ms: u32,
    /// Rest before each record, s (recovery from fatigue with --fatigue).
    #[arg(long, value_name = "S", default_value_t = 30.0)]
    rest_s: f64,
    /// Rich protocol: lowest constant frequency, Hz.
    #[arg(long, value_name = "HZ", default_value_t = 5.0)]
    rich_min_hz: f64,
    /// Rich protocol: highest constant frequency, Hz.
    #[arg(long, value_name = "HZ", default_value_t = 100.0)]
    rich_max_hz: f64,
    /// Rich protocol: shortest doublet interval, ms.
    #[arg(long, value_name = "MS", default_value_t = 2)]
    doublet_min_ms: u32,
    /// Rich protocol: longest doublet interval, ms.
    #[arg(long, value_name = "MS", default_value_t = 10)]
    doublet_max_ms: u32,
    #[command(flatten)]
    sensor: SensorArgs,
}

#[derive(Args)]
struct PlotArgs {
    /// Data-set directory.
    #[arg(long, value_name = "DIR")]
    data: PathBuf,
    /// Output image: a .png (raster) or .svg (vector) file.
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    out: PathBuf,
    /// Record indices to show, comma-separated [default: three random records and the
    /// first constant-frequency record].
    #[arg(long, value_name = "I,J,...", value_delimiter = ',')]
    records: Vec<usize>,
    /// Image width, px.
    #[arg(long, default_value_t = 900)]
    width: u32,
    /// Image height, px.
    #[arg(long, default_value_t = 500)]
    height: u32,
    /// Title [default: the data set's preset and source].
    #[arg(long)]
    title: Option<String>,
}

/// Why a `--set NAME=VALUE` is refused.
#[derive(Debug, thiserror::Error)]
enum AssignmentError {
    #[error("`{0}` is not NAME=VALUE (e.g. tau1=0.04)")]
    NoEquals(String),
    #[error("`{0}` has no parameter name before `=`")]
    NoName(String),
    #[error("`{0}` is not a number")]
    NotANumber(String),
    #[error("`{0}` is not a finite number")]
    NotFinite(String),
}

/// Parses `NAME=VALUE` with a finite number.
fn parse_assignment(s: &str) -> Result<(String, f64), AssignmentError> {
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| AssignmentError::NoEquals(s.to_owned()))?;
    let name = name.trim();
    if name.is_empty() {
        return Err(AssignmentError::NoName(s.to_owned()));
    }
    let v: f64 = value
        .trim()
        .parse()
        .map_err(|_| AssignmentError::NotANumber(value.to_owned()))?;
    if !v.is_finite() {
        return Err(AssignmentError::NotFinite(value.to_owned()));
    }
    Ok((name.to_string(), v))
}

/// The Ding muscle described by the flags, sampled every `ts_s`.
fn muscle_config(args: &MuscleArgs, preset: Preset, ts_s: f64) -> Result<MuscleConfig> {
    let mut cfg = MuscleConfig {
        ts_s,
        emd_s: args.emd_ms * 1e-3,
        ..MuscleConfig::preset(preset)
    };
    // Force-model parameters first, so the fatigue coefficients are carried over to the
    // muscle actually simulated; then the fatigue coefficients themselves.
    let is_fatigue = |n: &str| FatigueParams::NAMES.iter().any(|(f, _)| *f == n);
    for (name, value) in args.set.iter().filter(|(n, _)| !is_fatigue(n)) {
        cfg.set(name, *value)
            .with_context(|| format!("--set {name}={value}"))?;
    }
    if args.fatigue {
        cfg.fatigue = Some(FatigueParams::for_muscle(&cfg.ding));
    }
    for (name, value) in args.set.iter().filter(|(n, _)| is_fatigue(n)) {
        cfg.set(name, *value)
            .with_context(|| format!("--set {name}={value}"))?;
    }
    cfg.validate().context("muscle settings")?;
    Ok(cfg)
}

/// The muscle chosen by the flags, and what a data set records about it.
struct Chosen {
    plant: Box<dyn MusclePlant>,
    preset: Option<Preset>,
    parameters: BTreeMap<String, f64>,
    source: String,
}

/// Builds the preset muscle (with `configure` applied) or the LMN plant.
fn choose_plant(
    args: &MuscleArgs,
    ts_s: f64,
    configure: impl FnOnce(&mut MuscleConfig) -> Result<()>,
) -> Result<Chosen> {
    let source = format!("sim-muscle {}", env!("CARGO_PKG_VERSION"));
    if let Some(path) = &args.model {
        let plant = LmnPlant::load(path).with_context(|| format!("--model {}", path.display()))?;
        if (plant.ts() - ts_s).abs() > 1e-9 * ts_s {
            bail!(
                "--model {}: the model samples every {} ms, the run every {} ms",
                path.display(),
                plant.ts() * 1e3,
                ts_s * 1e3
            );
        }
        let parameters = BTreeMap::from([("force_scale_n".to_string(), plant.scale_n())]);
        let source = format!("{source}, LMN model {}", path.display());
        return Ok(Chosen {
            plant: Box::new(plant),
            preset: None,
            parameters,
            source,
        });
    }
    let preset = args
        .preset
        .map(Preset::from)
        .context("--preset or --model is required")?;
    let mut cfg = muscle_config(args, preset, ts_s)?;
    configure(&mut cfg)?;
    let parameters = cfg.parameters();
    Ok(Chosen {
        plant: Box::new(Muscle::new(cfg)?),
        preset: Some(preset),
        parameters,
        source,
    })
}

/// The sensor described by the flags, defaults scaled to the muscle's maximal force.
fn sensor_config(
    args: &SensorArgs,
    plant: &mut dyn MusclePlant,
    seed: u64,
) -> Result<SensorConfig> {
    let fmax = max_force(plant);
    plant.reset();
    let defaults = SensorConfig::defaults_for(fmax, seed);
    let sensor = SensorConfig {
        offset_n: args.offset_n.unwrap_or(defaults.offset_n),
        noise_std_n: args.noise_std_n.unwrap_or(defaults.noise_std_n),
        lowpass_tau_s: args.sensor_tau_ms * 1e-3,
        seed,
    };
    sensor.validate().context("sensor settings")?;
    Ok(sensor)
}

fn simulate_cmd(args: SimulateArgs) -> Result<()> {
    let ts_s = 1e-3;
    args.force.check()?;
    if let Some(w) = args.pulse_width_us
        && !(w.is_finite() && w > 0.0)
    {
        bail!("--pulse-width-us {w}: must be a width > 0 us");
    }
    let chosen = choose_plant(&args.muscle, ts_s, |cfg| {
        if args.pulse_width_us.is_some() {
            cfg.pulse_width = Some(PulseWidthParams::DING_2007);
        }
        Ok(())
    })?;
    let pulse = Pulse {
        width_us: args.pulse_width_us.unwrap_or(200.0),
        ..Pulse::SUPRAMAXIMAL
    };
    let n = args.duration_ms as usize;
    if n == 0 {
        bail!("--duration-ms must be at least 1 ms");
    }
    let mut train = match args.freq {
        Some(hz) => {
            let len = args.train_ms.context("--freq needs --train-ms")? as usize + 1;
            let samples =
                constant_train(hz, args.start_ms as usize, len, ts_s).context("--freq")?;
            if samples.first().is_none_or(|&k| k >= n) {
                bail!(
                    "--start-ms {}: the train starts after the end of the {n} ms run",
                    args.start_ms
                );
            }
            from_samples(&samples, n)
        }
        None => from_times_ms(&args.pulses, ts_s, n).context("--pulses")?,
    };
    if let Some(period) = args.repeat_ms {
        let p = samples_on_grid(f64::from(period), ts_s).filter(|&p| p > 0);
        let Some(p) = p else {
            bail!("--repeat-ms {period}: must be at least 1 ms")
        };
        if let Some(last) = train.iter().rposition(|&x| x)
            && last >= p
        {
            bail!(
                "--repeat-ms {period}: the pattern is {} ms long; the period must be longer",
                last + 1
            );
        }
        let one: Vec<bool> = train[..p.min(n)].to_vec();
        for k in p..n {
            train[k] = one[k % p];
        }
    }
    let force = simulate(args.force.read(chosen.plant, ts_s)?.as_mut(), &train, pulse);
    let stdout = io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let result = (|| -> io::Result<()> {
        writeln!(out, "t_ms,force_n")?;
        for (k, f) in force.iter().enumerate() {
            writeln!(out, "{k},{f:.6}")?;
        }
        out.flush()
    })();
    match result {
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => Ok(()),
        other => other.context("writing to stdout"),
    }
}

fn record_cmd(args: RecordArgs) -> Result<()> {
    // An LMN model takes the fast muscle's protocol numbers unless given.
    let preset = args.muscle.preset.map(Preset::from).unwrap_or(Preset::Fast);
    let thesis = ProtocolConfig::thesis(preset);
    let protocol = ProtocolConfig {
        kind: match args.protocol {
            ProtocolArg::Thesis => ProtocolKind::Thesis,
            ProtocolArg::Rich => ProtocolKind::Rich,
        },
        records: args.records.unwrap_or(thesis.records),
        train_records: args.train_records,
        record_ms: args.record_ms.unwrap_or(thesis.record_ms),
        ts_ms: args.ts_ms,
        train_start_ms: args.train_start_ms,
        train_min_ms: args.train_min_ms,
        train_max_ms: args.train_max_ms,
        ipi_min_ms: args.ipi_min_ms,
        ipi_max_ms: args.ipi_max_ms,
        const_every: args.const_every,
        const_ipi_ms: args.const_ipi_ms,
        rest_s: args.rest_s,
        rich_min_hz: args.rich_min_hz,
        rich_max_hz: args.rich_max_hz,
        doublet_min_ms: args.doublet_min_ms,
        doublet_max_ms: args.doublet_max_ms,
    };
    protocol.validate()?;
    let mut chosen = choose_plant(&args.muscle, protocol.ts_ms * 1e-3, |_| Ok(()))?;
    let sensor = sensor_config(&args.sensor, chosen.plant.as_mut(), args.seed)?;
    let mode = WriteMode::from_force(args.force);
    if args.out.exists() && !args.out.is_dir() {
        bail!("{} exists and is not a directory", args.out.display());
    }
    if mode == WriteMode::CreateNew && args.out.read_dir().is_ok_and(|mut d| d.next().is_some()) {
        bail!(
            "{} exists and is not empty; choose another --out or add --force",
            args.out.display()
        );
    }
    let ts_s = chosen.plant.ts();
    let mut plant = Measured::new(chosen.plant, ForceSensor::new(sensor, ts_s)?);
    let origin = Origin {
        source: chosen.source,
        preset: chosen.preset.map(|p| p.name().to_string()),
        parameters: chosen.parameters,
        seed: args.seed,
        noise: serde_json::to_value(sensor)?,
    };
    let norm = match &args.scale_from {
        None => Normalise::Peak,
        Some(dir) => Normalise::Scale(
            DataSet::read(dir)
                .with_context(|| format!("--scale-from {}", dir.display()))?
                .header
                .scale_n,
        ),
    };
    let ds = record_normalised(&mut plant, &protocol, origin, norm)?;
    if ds.records.len() < protocol.records {
        eprintln!(
            "left out {} of {} records: they exceed {} of the scale {:.3} N",
            protocol.records - ds.records.len(),
            protocol.records,
            1.0 + FORCE_SLACK,
            ds.header.scale_n
        );
    }
    ds.write(&args.out, mode)?;
    eprintln!(
        "wrote {} records ({} train, {} test) to {}: scale {:.3} N, offset {:.3} N",
        ds.records.len(),
        ds.header.split.train.len(),
        ds.header.split.test.len(),
        args.out.display(),
        ds.header.scale_n,
        ds.header.offset_n
    );
    Ok(())
}

fn plot_cmd(args: PlotArgs) -> Result<()> {
    let ds = DataSet::read(&args.data)?;
    let records = if args.records.is_empty() {
        default_selection(&ds)
    } else {
        args.records
    };
    let title = args.title.unwrap_or_else(|| match &ds.header.preset {
        Some(p) => format!("{p} muscle ({}), records {records:?}", ds.header.source),
        None => format!("{}, records {records:?}", ds.header.source),
    });
    plot_records(&ds, &records, &title, &args.out, (args.width, args.height))?;
    Ok(())
}

/// The muscle under a virtual device and how its force is read: the options both device
/// commands share.
#[derive(Args)]
struct DevicePlantArgs {
    #[command(flatten)]
    muscle: MuscleArgs,
    #[command(flatten)]
    force: ForceReading,
}

#[derive(Args)]
struct StimulatorCmd {
    #[command(flatten)]
    plant: DevicePlantArgs,
    #[command(flatten)]
    stimulator: fes_virtual_stimulator::StimulatorArgs,
}

fn stimulator_cmd(args: StimulatorCmd) -> Result<()> {
    // A panicking thread aborts the virtual stimulator (its output ends with it), as a
    // real stimulator's firmware would reset.
    fes_rt::rt::panic::install("sim-muscle stimulator");
    let plant = device_plant(&args.plant)?;
    fes_virtual_stimulator::run(args.stimulator, Box::new(OnDevice(plant)))
}

#[derive(Args)]
struct Rehastim2Cmd {
    #[command(flatten)]
    plant: DevicePlantArgs,
    #[command(flatten)]
    device: fes_virtual_stimulator::rehastim2_pty::Rehastim2Args,
}

fn rehastim2_cmd(args: Rehastim2Cmd) -> Result<()> {
    fes_rt::rt::panic::install("sim-muscle rehastim2");
    let plant = device_plant(&args.plant)?;
    fes_virtual_stimulator::run_rehastim2(args.device, Box::new(OnDevice(plant)))
}

/// The muscle a virtual device drives at 1 ms: the model's force, or with `measured` the
/// force as the sensor measures it (the sensor options need `--measured`).
fn device_plant(args: &DevicePlantArgs) -> Result<Box<dyn MusclePlant>> {
    let ts_s = 1e-3;
    args.force.check()?;
    let chosen = choose_plant(&args.muscle, ts_s, |_| Ok(()))?;
    args.force.read(chosen.plant, ts_s)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(a) => simulate_cmd(a),
        Command::Record(a) => record_cmd(a),
        Command::Plot(a) => plot_cmd(a),
        Command::Stimulator(a) => stimulator_cmd(a),
        Command::Rehastim2(a) => rehastim2_cmd(a),
    };
    match result {
        Ok(()) => Exit::Done.into(),
        Err(e) => {
            eprintln!("sim-muscle: error: {e:#}");
            Exit::Failed.into()
        }
    }
}
