//! `fes osp`: optimal stimulation patterns (thesis ch. 6) on a model, on the Ding
//! muscle of sim-muscle, or on both side by side (the thesis compared its models with
//! Kwende's experiments on the real muscles):
//!
//! - `random` (6.2, Figs. 6.1-6.2): FTIpP of random patterns (the thesis protocol, 5.1)
//!   against their average frequency; best and worst patterns;
//! - `trains` (6.3, Fig. 6.3): FTIpP of constant-IPI trains, 1-10 pulses x IPI 2-100 ms,
//!   as heat maps;
//! - `iterative` (6.4, Fig. 6.4): pulses added one at a time at the best IPI;
//! - `lcn` (6.5, Figs. 6.9 / 6.11): the pattern generator of `--controller` driven by step
//!   references; its pattern also drives `--model` and/or the Ding muscle (Fig. 6.6(b)).
//!
//! FTI (eq. 6.2) is summed over one window of `--window-ms` from the pattern's start (the
//! twitch included), with the rest force removed (`fes_ident::analysis::osp`).
//!
//! One module per method: its `compute` returns a plain result and its `report` draws the
//! figure, writes the CSV and appends the report's section from that result. This module
//! holds the arguments, the subjects and what the methods share.

mod iterative;
mod lcn;
mod random;
mod trains;

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use fes_ident::analysis::osp::{Evaluator, ForceResponse, ModelResponse};
use fes_model::control::file::Controller;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::preset::Preset;
use sim_muscle::simulate::MuscleResponse;

use super::inputs::{md_table, open_model, out_dir, parse_list, write_csv};
use super::plots::{self, Figure, Panel};

/// The methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Random patterns: FTIpP vs average frequency (6.2).
    Random,
    /// Constant-IPI trains: the FTIpP surface (6.3).
    Trains,
    /// The iterative method (6.4).
    Iterative,
    /// The LCN pattern generator on step references (6.5); needs --controller.
    Lcn,
}

/// `--muscle` presets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MuscleArg {
    /// Fast muscle with the catch-like effect.
    Fast,
    /// Slow (chronically stimulated) muscle.
    Slow,
    /// Fast muscle whose identified local models have the thesis's Table 5.3 poles.
    ThesisFast,
}

impl From<MuscleArg> for Preset {
    fn from(m: MuscleArg) -> Self {
        match m {
            MuscleArg::Fast => Preset::Fast,
            MuscleArg::Slow => Preset::Slow,
            MuscleArg::ThesisFast => Preset::ThesisFast,
        }
    }
}

/// Arguments of `fes osp`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A model file (fes-lmn/1): the methods run on its output.
    #[arg(long, required_unless_present_any = ["muscle", "controller"])]
    pub model: Option<PathBuf>,
    /// A controller file (fes-lcn/1), for `--method lcn`.
    #[arg(long)]
    pub controller: Option<PathBuf>,
    /// The Ding muscle of sim-muscle (no fatigue, 7 ms delay): the methods run on it too.
    #[arg(long, value_enum)]
    pub muscle: Option<MuscleArg>,
    /// Methods, comma-separated (random, trains, iterative, lcn).
    #[arg(long, value_enum, value_delimiter = ',', required = true)]
    pub method: Vec<Method>,
    /// Output directory (created if needed).
    #[arg(long)]
    pub out: PathBuf,
    /// FTI window from the pattern's start, ms (the twitch's too).
    #[arg(long, default_value_t = 2000)]
    pub window_ms: u32,
    /// Shortest IPI of the trains and iterative sweeps, ms.
    #[arg(long, default_value_t = 2)]
    pub ipi_min_ms: u32,
    /// Longest IPI of the trains and iterative sweeps, ms.
    #[arg(long, default_value_t = 100)]
    pub ipi_max_ms: u32,
    /// Largest pulse count of the train surface.
    #[arg(long, default_value_t = 10)]
    pub train_pulses: usize,
    /// Pulses of the iterative method.
    #[arg(long, default_value_t = 5)]
    pub iterative_pulses: usize,
    /// Random patterns (thesis protocol 5.1: IPI 1-70 ms, trains <= 300 ms).
    #[arg(long, default_value_t = 300)]
    pub patterns: usize,
    /// Seed of the random patterns.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Step reference levels for `lcn` (normalised force), comma-separated.
    #[arg(long, default_value = "0.15,0.3,0.5,0.7")]
    pub levels: String,
    /// Length of each `lcn` run, ms (the step comes at 50 ms).
    #[arg(long, default_value_t = 800)]
    pub lcn_ms: u32,
    /// Format of the figures: png (raster) or svg (vector, for papers).
    #[arg(long, value_enum, default_value_t = workbench::plots::FigureFormat::Png)]
    pub format: workbench::plots::FigureFormat,
}

/// One muscle or model the methods run on.
struct Subject {
    name: String,
    unit: &'static str,
    response: Box<dyn ForceResponse>,
    /// Multiplies this subject's force into the controller model's normalised units.
    to_normalised: f64,
}

impl Subject {
    /// What a method's result keeps of its subject for the report.
    fn info(&self) -> SubjectInfo {
        SubjectInfo {
            name: self.name.clone(),
            unit: self.unit,
            ts: self.response.ts(),
        }
    }
}

/// A subject as the reports name it: its name, force unit and sample time (s).
#[derive(Debug, Clone)]
struct SubjectInfo {
    name: String,
    unit: &'static str,
    ts: f64,
}

/// Samples of `ms` milliseconds at `ts`, which must be a whole number.
fn samples(flag: &str, ms: f64, ts: f64) -> Result<usize> {
    let k = ms * 1e-3 / ts;
    if (k - k.round()).abs() > 1e-9 * k.max(1.0) {
        bail!(
            "{flag} {ms} ms is not a whole number of {} ms samples",
            ts * 1e3
        );
    }
    Ok(k.round() as usize)
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    check_ipi_range(&args)?;
    if args.method.contains(&Method::Lcn) && args.controller.is_none() {
        bail!("--method lcn needs --controller (a fes-lcn/1 file from `fes design`)");
    }
    let controller = args
        .controller
        .as_deref()
        .map(|p| Controller::load(p).with_context(|| format!("controller file {}", p.display())))
        .transpose()?;
    let subjects = subjects(&args, controller.as_ref())?;
    let levels = parse_list("--levels", &args.levels)?;
    if let Some(l) = levels.iter().find(|l| !(0.0..=1.0).contains(*l)) {
        bail!("--levels: {l} is outside [0, 1] (normalised force)");
    }
    out_dir(&args.out)?;
    let mut md = report_header(&args, &subjects);
    let mut methods = args.method.clone();
    methods.dedup();
    for m in methods {
        match m {
            Method::Random => random::run(&args, &subjects, &mut md)?,
            Method::Trains => trains::run(&args, &subjects, &mut md)?,
            Method::Iterative => iterative::run(&args, &subjects, &mut md)?,
            Method::Lcn => {
                let c = controller
                    .as_ref()
                    .context("--method lcn needs --controller")?;
                lcn::run(&args, c, &subjects, &levels, &mut md)?
            }
        }
    }
    let path = args.out.join("report.md");
    std::fs::write(&path, md).with_context(|| format!("writing {}", path.display()))?;
    println!("report written to {}", path.display());
    Ok(())
}

fn check_ipi_range(args: &Args) -> Result<()> {
    if args.ipi_min_ms == 0 || args.ipi_min_ms > args.ipi_max_ms {
        bail!(
            "--ipi-min-ms {} / --ipi-max-ms {}: need 1 <= min <= max",
            args.ipi_min_ms,
            args.ipi_max_ms
        );
    }
    Ok(())
}

/// The subjects of `--model` and `--muscle`, in that order, scaled to the controller
/// model's normalised units when there is a controller.
fn subjects(args: &Args, controller: Option<&Controller>) -> Result<Vec<Subject>> {
    let mut subjects = Vec::new();
    if let Some(path) = &args.model {
        let m = open_model(path)?;
        let scale = controller.map_or(1.0, |c| m.lmn.force_scale_n / c.lmn.force_scale_n);
        subjects.push(Subject {
            name: format!(
                "model {}",
                path.file_name().map_or_else(
                    || path.display().to_string(),
                    |s| s.to_string_lossy().into()
                )
            ),
            unit: "normalised",
            response: Box::new(ModelResponse::new(&m.lmn).context("model")?),
            to_normalised: scale,
        });
    }
    if let Some(p) = args.muscle {
        let preset = Preset::from(p);
        let muscle = Muscle::new(MuscleConfig::preset(preset)).context("Ding muscle")?;
        subjects.push(Subject {
            name: format!("Ding {} muscle", preset.name()),
            unit: "N",
            response: Box::new(MuscleResponse::new(muscle)),
            to_normalised: controller.map_or(1.0, |c| 1.0 / c.lmn.force_scale_n),
        });
    }
    Ok(subjects)
}

/// The report's title and the paragraph on subjects and FTI.
fn report_header(args: &Args, subjects: &[Subject]) -> String {
    let mut md = String::new();
    let names: Vec<String> = subjects.iter().map(|s| s.name.clone()).collect();
    let _ = writeln!(md, "# Optimal stimulation patterns (thesis ch. 6)\n");
    let _ = writeln!(
        md,
        "Subjects: {}. FTI (eq. 6.2) over {} ms from the start of each pattern, rest force removed; FTIpP = FTI_p / (FTI_1 p) (eq. 6.3), FTI_1 the twitch's over the same window.\n",
        if names.is_empty() {
            "(none: only the controller's loop)".into()
        } else {
            names.join(", ")
        },
        args.window_ms
    );
    md
}

fn need_subjects(subjects: &[Subject], method: &str) -> Result<()> {
    if subjects.is_empty() {
        bail!("--method {method} needs --model and/or --muscle");
    }
    Ok(())
}

/// An evaluator whose window covers patterns ending at `last_ms` plus 200 ms.
fn evaluator<'a>(
    args: &Args,
    s: &'a Subject,
    last_ms: f64,
) -> Result<Evaluator<'a, dyn ForceResponse>> {
    if (args.window_ms as f64) < last_ms + 200.0 {
        bail!(
            "--window-ms {} is too short: the longest pattern ends at {last_ms} ms and the force needs time to return to rest (give at least {} ms)",
            args.window_ms,
            last_ms + 200.0
        );
    }
    let ts = s.response.ts();
    let window = samples("--window-ms", args.window_ms as f64, ts)?;
    Evaluator::new(s.response.as_ref(), window).with_context(|| format!("{}: twitch", s.name))
}

/// The IPI range of the sweeps in samples of `ts`.
fn ipi_samples(args: &Args, ts: f64) -> Result<(usize, usize)> {
    let lo = samples("--ipi-min-ms", args.ipi_min_ms as f64, ts)?;
    let hi = samples("--ipi-max-ms", args.ipi_max_ms as f64, ts)?;
    Ok((lo, hi))
}

fn pulses_ms(p: &[usize], ts: f64) -> String {
    p.iter()
        .map(|&k| format!("{}", (k as f64 * ts * 1e6).round() / 1e3))
        .collect::<Vec<_>>()
        .join(";")
}

/// A method's figure `<stem>` (PNG or SVG by `--format`): one column of panels per
/// subject, 560 px wide each, `height` px high.
fn save_subject_columns(
    args: &Args,
    stem: &str,
    title: String,
    columns: Vec<Vec<(u32, Panel)>>,
    height: u32,
) -> Result<()> {
    let width = 560 * columns.len() as u32 + 80;
    plots::save(
        &Figure { title, columns },
        &args.format.file(&args.out, stem),
        (width, height),
    )
}

/// A method's table of every run, written as `<stem>.csv`, and its report section:
/// `heading`, `intro`, the figures (description, file stem of the PNG), the summary table
/// and the note on responses cut by the window (every method ends its section so).
struct Section<'a> {
    stem: &'a str,
    csv_header: &'a [&'a str],
    csv_rows: Vec<Vec<String>>,
    heading: &'a str,
    intro: String,
    figures: &'a [(&'a str, &'a str)],
    summary_header: &'a [&'a str],
    summary: Vec<Vec<String>>,
    worst_end: f64,
}

impl Section<'_> {
    fn write(&self, args: &Args, md: &mut String) -> Result<()> {
        let csv = args.out.join(format!("{}.csv", self.stem));
        write_csv(&csv, self.csv_header, &self.csv_rows)?;
        let _ = writeln!(md, "## {}\n", self.heading);
        let _ = writeln!(md, "{}\n", self.intro);
        for (description, stem) in self.figures {
            let _ = writeln!(md, "![{description}]({stem}.png)\n");
        }
        md.push_str(&md_table(self.summary_header, &self.summary));
        md.push('\n');
        truncation_note(md, self.worst_end);
        Ok(())
    }
}

fn truncation_note(md: &mut String, worst: f64) {
    if worst > 0.01 {
        let _ = writeln!(
            md,
            "**Note:** some responses had not returned to rest at the end of the window (largest remaining force {:.1} % of the peak); lengthen `--window-ms`.\n",
            100.0 * worst
        );
    }
}
