//! `fes dataset`: data sets from elsewhere. `fes dataset import` turns a table of force and
//! stimulation recorded on another rig (any rate, units, column names and record layout)
//! into a `fes-dataset/1` directory (`fes_dataset::import` does the work; this is its
//! command line). `fes dataset merge` joins recordings of one muscle into one data set
//! (`fes_dataset::merge`). `fes dataset inspect` describes a data set of either version
//! (`workbench::data::describe`).

use std::path::PathBuf;

use anyhow::{Context, Result};
use fes_dataset::import::{
    ColumnRef, Delimiter, ImportOptions, Level, Pulses, SplitSpec, TimeSource, TimeUnit, import,
    parse_pulse_times,
};
use fes_dataset::{DataSet, WriteMode};

/// `fes dataset` arguments.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: Command,
}

/// `fes dataset` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Import a CSV (or whitespace-separated) table of force and stimulation into a data
    /// set: columns mapped, force scaled, resampled to the 1 ms grid, records and split.
    #[command(after_long_help = IMPORT_HELP)]
    Import(Box<ImportArgs>),
    /// Describe a data set of either version (fes-dataset/1: pulses and force;
    /// fes-dataset/2: named continuous channels): period, records, split, channels.
    Inspect(InspectArgs),
    /// Merge recordings of one muscle into one data set, to identify a model from all of
    /// them: records in order, the union of the splits, one force scale.
    #[command(after_long_help = MERGE_HELP)]
    Merge(MergeArgs),
}

/// `fes dataset merge` arguments.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The data-set directories (fes-dataset/1), two or more, in the order their records
    /// take.
    #[arg(required = true, num_args = 2..)]
    pub dirs: Vec<PathBuf>,
    /// Output data-set directory (must be empty or new, unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace the data set in --out.
    #[arg(long)]
    pub force: bool,
}

const MERGE_HELP: &str = "\
WHAT IT DOES
  Reads every data set, checks that they share the sample period and the force scale
  (scale_n: normalised forces on different scales cannot be fitted together; record a
  later set with `sim-muscle record --scale-from FIRST`), and writes one data set: the
  records in order, renamed record_000.csv on; a training record stays a training record
  and a test record a test record. Origin fields all sets share are kept; each set's own
  (source, preset, seed, protocol, offset, first record) are under protocol.sets.

  Why: a second recording adds what the first one lacks (close pulse pairs from rest, a
  frequency band). docs/sim-muscle.md, \"fes dataset merge\".

EXAMPLE
  sim-muscle record --preset slow --seed 1 --out data/slow
  sim-muscle record --preset slow --seed 3 --protocol rich --records 60 \\
      --train-records 30 --rich-min-hz 4 --rich-max-hz 12 --doublet-min-ms 2 \\
      --doublet-max-ms 6 --scale-from data/slow --out data/slow-pairs
  fes dataset merge data/slow data/slow-pairs --out data/slow-all
  fes identify --data data/slow-all --structure ss-eig-common --units 6 --range 0,0.5 \\
      --zero-offsets --starts 8 --out slow.lmn.json  (the shipped slow model's recipe)";

/// `fes dataset inspect` arguments.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// The data-set directory.
    pub dir: PathBuf,
}

const IMPORT_HELP: &str = "\
WHAT IT DOES
  1. Reads the table: `,` `;` or tab separated with optional \"quoting\" (or whitespace
     columns), `#` comment lines, an optional preamble (--skip-lines). The first line
     names the columns unless it holds a number (then name columns by number, from 1).
  2. Time from --time-col (in --time-unit) or, without a time column, --rate-hz.
  3. Records: a new record where the time jumps by more than --split-gap (s) and/or
     where the --record-col value changes (that value becomes the record's kind).
  4. Force in newtons = --force-gain x the column; resampled onto the grid t0 + k ts of
     each record (--ts-ms, 1 ms) by linear interpolation; normalised as
     (F - offset) / scale with --force-offset / --force-scale in N, or `auto`: the
     offset is the mean force up to each record's first pulse, the scale the largest
     offset-free sample (as sim-muscle record does).
  5. Pulses from --pulse-col (a pulse in every sample > 0: 1, or an amplitude; with
     --pulse-edges one pulse per run of non-zero samples) or from --pulse-times FILE (one
     time per line, same clock and unit as the time column); each goes to the nearest
     grid tick of its record. Two pulses on one tick are refused (the grid holds one
     pulse per sample).
  6. The first half of the records trains, the rest test (--train-records N, or
     --test-records 3,7,...).
  Any problem is an error naming the file, line and column. Data-set format and reader:
  docs/sim-muscle.md, \"Importing data and reading it elsewhere\"; README, \"Use your own
  data\".

EXAMPLES
  Time in seconds at 2 kHz, a 0/1 stimulation column, force in mN, trials separated by
  rests of a second or more:
    fes dataset import trials.csv --out data/mine --time-col time_s --force-col force_mN \\
        --force-gain 0.001 --pulse-col stim --split-gap 0.5

  Whitespace columns without a header (1: force in N, 2: stimulator current), 10 kHz, one
  trial number per line in column 3, calibrated offset and scale, trials 0-9 train:
    fes dataset import rig.txt --out data/rig --rate-hz 10000 --force-col 1 \\
        --pulse-col 2 --pulse-edges --record-col 3 --force-offset 4.8 --force-scale 364 \\
        --train-records 10

  Pulse times in ms in a file of their own:
    fes dataset import force.csv --out data/f --time-col t --time-unit ms --force-col F \\
        --pulse-times pulses.txt --split-gap 1

  Then: fes identify --data data/mine --structure ss-eig-common --units 4 --out mine.lmn.json";

/// `fes dataset import` arguments.
#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    /// The table to import (CSV with a header line, or whitespace-separated columns).
    pub input: PathBuf,
    /// Output data-set directory (must be empty or new, unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace the data set in --out (its dataset.json and listed records only).
    #[arg(long)]
    pub force: bool,
    /// Field separator.
    #[arg(long, value_enum, default_value_t = DelimiterArg::Auto)]
    pub delimiter: DelimiterArg,
    /// Lines to skip before the header (an instrument's preamble).
    #[arg(long, default_value_t = 0)]
    pub skip_lines: usize,
    /// The first line is data, not column names (default: it is data if it holds a number).
    #[arg(long)]
    pub no_header: bool,
    /// Time column (header name, or number from 1).
    #[arg(long, required_unless_present = "rate_hz", conflicts_with = "rate_hz")]
    pub time_col: Option<String>,
    /// Unit of the time column and of --pulse-times.
    #[arg(long, value_enum, default_value_t = TimeUnitArg::S)]
    pub time_unit: TimeUnitArg,
    /// No time column: the input's sample rate, Hz (line k at k / rate).
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// Force column (header name, or number from 1).
    #[arg(long)]
    pub force_col: String,
    /// Newtons per unit of the force column (e.g. 0.001 for mN, a load cell's N/V).
    #[arg(long, default_value_t = 1.0)]
    pub force_gain: f64,
    /// Force offset removed, N, or `auto` (mean force up to each record's first pulse).
    #[arg(long, default_value = "auto")]
    pub force_offset: String,
    /// Newtons per normalised unit (the force that counts as 1), or `auto` (the largest
    /// offset-free sample).
    #[arg(long, default_value = "auto")]
    pub force_scale: String,
    /// Pulse column: 0 = no pulse, > 0 (1, or an amplitude) = a pulse in that sample.
    #[arg(
        long,
        required_unless_present = "pulse_times",
        conflicts_with = "pulse_times"
    )]
    pub pulse_col: Option<String>,
    /// With --pulse-col: a run of consecutive non-zero samples is one pulse (at its first
    /// sample), for a stimulator output sampled faster than a pulse lasts.
    #[arg(long, requires = "pulse_col")]
    pub pulse_edges: bool,
    /// File of pulse times, one per line (first field), on the time column's clock and
    /// in --time-unit.
    #[arg(long)]
    pub pulse_times: Option<PathBuf>,
    /// Sample period of the data set's grid, ms (identification works at 1 ms).
    #[arg(long, default_value_t = 1.0)]
    pub ts_ms: f64,
    /// Start a new record where consecutive samples are more than this apart, s.
    #[arg(long)]
    pub split_gap: Option<f64>,
    /// Start a new record where this column's value changes (the value is its kind).
    #[arg(long)]
    pub record_col: Option<String>,
    /// The first N records train, the rest test (default: the first half, rounded up).
    #[arg(long, conflicts_with = "test_records")]
    pub train_records: Option<usize>,
    /// These records test (comma-separated, numbered from 0), the rest train.
    #[arg(long, value_delimiter = ',')]
    pub test_records: Option<Vec<usize>>,
    /// `kind` of every record when there is no --record-col.
    #[arg(long, default_value = "imported")]
    pub kind: String,
    /// `source` of the data set (who recorded it; default: the input's name).
    #[arg(long)]
    pub source: Option<String>,
}

/// `--delimiter`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DelimiterArg {
    /// From the first line: `,` if it has one, else `;`, else a tab, else whitespace.
    Auto,
    /// Comma.
    Comma,
    /// Semicolon.
    Semicolon,
    /// Tab.
    Tab,
    /// Runs of spaces and tabs.
    Whitespace,
}

/// `--time-unit`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TimeUnitArg {
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
}

fn level(flag: &str, text: &str) -> Result<Level> {
    if text.trim().eq_ignore_ascii_case("auto") {
        return Ok(Level::Auto);
    }
    let v: f64 = text
        .trim()
        .parse()
        .with_context(|| format!("{flag} `{text}`: neither a number (N) nor `auto`"))?;
    Ok(Level::Given(v))
}

impl ImportArgs {
    /// The library's options (reads --pulse-times).
    pub fn options(&self) -> Result<ImportOptions> {
        let time = match (&self.time_col, self.rate_hz) {
            (Some(c), _) => TimeSource::Column(ColumnRef::parse(c)),
            (None, Some(hz)) => TimeSource::Rate { hz },
            (None, None) => anyhow::bail!("give --time-col or --rate-hz"),
        };
        let pulses = match (&self.pulse_col, &self.pulse_times) {
            (Some(c), _) => Pulses::Column {
                column: ColumnRef::parse(c),
                edges: self.pulse_edges,
            },
            (None, Some(p)) => {
                let bytes =
                    std::fs::read(p).with_context(|| format!("--pulse-times {}", p.display()))?;
                Pulses::Times {
                    path: p.clone(),
                    times: parse_pulse_times(p, &bytes)?,
                }
            }
            (None, None) => anyhow::bail!("give --pulse-col or --pulse-times"),
        };
        let mut o = ImportOptions::new(time, ColumnRef::parse(&self.force_col), pulses);
        o.delimiter = match self.delimiter {
            DelimiterArg::Auto => Delimiter::Auto,
            DelimiterArg::Comma => Delimiter::Comma,
            DelimiterArg::Semicolon => Delimiter::Semicolon,
            DelimiterArg::Tab => Delimiter::Tab,
            DelimiterArg::Whitespace => Delimiter::Whitespace,
        };
        o.skip_lines = self.skip_lines;
        o.header = self.no_header.then_some(false);
        o.time_unit = match self.time_unit {
            TimeUnitArg::S => TimeUnit::S,
            TimeUnitArg::Ms => TimeUnit::Ms,
            TimeUnitArg::Us => TimeUnit::Us,
        };
        o.force_gain = self.force_gain;
        o.force_offset = level("--force-offset", &self.force_offset)?;
        o.force_scale = level("--force-scale", &self.force_scale)?;
        o.ts_s = self.ts_ms * 1e-3;
        o.split_gap_s = self.split_gap;
        o.record_column = self.record_col.as_deref().map(ColumnRef::parse);
        o.split = match (self.train_records, &self.test_records) {
            (Some(n), _) => SplitSpec::TrainFirst(n),
            (None, Some(t)) => SplitSpec::Test(t.clone()),
            (None, None) => SplitSpec::Half,
        };
        o.kind = self.kind.clone();
        o.source = self.source.clone().unwrap_or_else(|| {
            format!(
                "fes dataset import {} ({})",
                env!("CARGO_PKG_VERSION"),
                self.input
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
            )
        });
        Ok(o)
    }
}

/// Runs `fes dataset`.
pub fn run(args: Args) -> Result<()> {
    match args.command {
        Command::Import(a) => run_import(*a),
        Command::Merge(a) => run_merge(a),
        Command::Inspect(a) => {
            let text = workbench::data::describe(&a.dir)
                .with_context(|| format!("cannot read data set {}", a.dir.display()))?;
            print!("{text}");
            Ok(())
        }
    }
}

fn run_merge(a: MergeArgs) -> Result<()> {
    let mut sets = Vec::with_capacity(a.dirs.len());
    for dir in &a.dirs {
        workbench::data::require_pulses(dir)?;
        let set = DataSet::read(dir)
            .with_context(|| format!("cannot read data set {}", dir.display()))?;
        sets.push((dir.display().to_string(), set));
    }
    let merged = fes_dataset::merge::merge(&sets)?;
    let mode = WriteMode::from_force(a.force);
    merged
        .write(&a.out, mode)
        .with_context(|| format!("cannot write the data set to {}", a.out.display()))?;
    for (name, set) in &sets {
        println!(
            "{name:<30} {} records ({} train, {} test)",
            set.records.len(),
            set.header.split.train.len(),
            set.header.split.test.len()
        );
    }
    println!(
        "{:<30} {} records ({} train, {} test), scale {} N",
        a.out.display(),
        merged.records.len(),
        merged.header.split.train.len(),
        merged.header.split.test.len(),
        merged.header.scale_n
    );
    Ok(())
}

fn run_import(a: ImportArgs) -> Result<()> {
    let opts = a.options()?;
    let bytes = std::fs::read(&a.input).with_context(|| format!("{}", a.input.display()))?;
    let imported = import(&a.input, &bytes, &opts)?;
    let ds: &DataSet = &imported.dataset;
    let mode = WriteMode::from_force(a.force);
    ds.write(&a.out, mode)
        .with_context(|| format!("cannot write the data set to {}", a.out.display()))?;
    let r = &imported.report;
    let samples: usize = ds.records.iter().map(|r| r.len()).sum();
    println!(
        "input          {} lines, median step {} ms",
        r.lines, r.input_step_ms
    );
    println!(
        "records        {} ({} train, {} test), {} samples at {} ms",
        ds.records.len(),
        ds.header.split.train.len(),
        ds.header.split.test.len(),
        samples,
        ds.header.ts_s * 1e3
    );
    println!(
        "pulses         {} (moved at most {:.3} ms onto the grid)",
        r.pulses, r.max_pulse_shift_ms
    );
    println!(
        "force          offset {} N, scale {} N",
        r.offset_n, r.scale_n
    );
    println!("data set       {}", a.out.display());
    Ok(())
}
