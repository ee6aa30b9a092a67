//! Subcommands, one module each, plus what they share: the structure / mode flags of an
//! identification, a progress bar, table formatting (and, in [`plots`] and [`inputs`], what
//! the analysis commands share).
//!
//! Data: [`dataset`] (import). Offline model work: [`identify`], [`sweep`], [`compare`], [`analyse`], [`modify`],
//! [`design`], [`lcn_variants`], [`osp`]; and the end-to-end [`mod@bench`].

pub mod analyse;
pub mod bench;
pub mod compare;
pub mod dataset;
pub mod design;
pub mod identify;
pub mod inputs;
pub mod lcn_variants;
pub mod modify;
pub mod osp;
pub mod plots;
pub mod sweep;
pub mod validation;

use clap::ValueEnum;
use fes_ident::ident::{Hooks, Learning, Mode, Progress, SchedulingKind};
use fes_model::model::Structure;
use indicatif::{ProgressBar, ProgressStyle};
use std::time::Instant;

/// `--structure` values (the model file's names).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StructureArg {
    /// ARX local models in shift form, at Ts = 1/5/10 ms (eq. 2.20-2.24; 5.3.1).
    ArxShift,
    /// ARX local models with delta-domain parameters at 1 ms (D.2.2; 5.3.2).
    ArxDelta,
    /// State space, A, b, c, dx, dy free: 11 per unit (5.4.2, Fig. 5.18).
    SsDirect,
    /// State space, real eigensystems, local eigenvectors (eq. 5.5, Fig. 5.19).
    SsEigLocal,
    /// State space, real eigensystems, common eigenvectors (eq. 5.6, Fig. 5.21): stable by
    /// construction.
    SsEigCommon,
}

impl From<StructureArg> for Structure {
    fn from(s: StructureArg) -> Self {
        match s {
            StructureArg::ArxShift => Structure::ArxShift,
            StructureArg::ArxDelta => Structure::ArxDelta,
            StructureArg::SsDirect => Structure::SsDirect,
            StructureArg::SsEigLocal => Structure::SsEigLocal,
            StructureArg::SsEigCommon => Structure::SsEigCommon,
        }
    }
}

/// `--mode` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// One-step-ahead prediction, linear least squares (B.2, B.4); ARX structures only.
    Prediction,
    /// Free-run simulation from rest, Levenberg-Marquardt (B.3.2, B.6/B.7).
    Simulation,
}

impl From<ModeArg> for Mode {
    fn from(m: ModeArg) -> Self {
        match m {
            ModeArg::Prediction => Mode::Prediction,
            ModeArg::Simulation => Mode::Simulation,
        }
    }
}

/// `--learning` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LearningArg {
    /// One criterion for all local models (eq. 2.33).
    Global,
    /// One weighted criterion per local model (eq. 2.35).
    Local,
}

impl From<LearningArg> for Learning {
    fn from(l: LearningArg) -> Self {
        match l {
            LearningArg::Global => Learning::Global,
            LearningArg::Local => Learning::Local,
        }
    }
}

/// `--scheduling` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SchedulingArg {
    /// phi = the pulse train through G_pre(s) = 25000/(s^2 + 100 s + 2500) (eq. 5.4).
    Input,
    /// phi = the model output one sample earlier (eq. 5.1).
    Output,
}

/// Which pulse train drives the input-scheduling prefilter (eq. 5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SchedulingInputArg {
    /// u(t - Td), the input of the local models (ours).
    Delayed,
    /// u(t) as applied (eq. 5.2 as printed).
    Undelayed,
}

impl From<SchedulingInputArg> for fes_model::model::scheduling::SchedulingInput {
    fn from(s: SchedulingInputArg) -> Self {
        match s {
            SchedulingInputArg::Delayed => Self::Delayed,
            SchedulingInputArg::Undelayed => Self::Undelayed,
        }
    }
}

impl From<SchedulingArg> for SchedulingKind {
    fn from(s: SchedulingArg) -> Self {
        match s {
            SchedulingArg::Input => SchedulingKind::Input,
            SchedulingArg::Output => SchedulingKind::Output,
        }
    }
}

/// A progress bar on stderr (hidden when stderr is not a terminal) driven by a run's
/// progress reports, and a wall clock.
pub struct Feedback {
    bar: ProgressBar,
    start: Instant,
    prefix: String,
    verbose: bool,
}

impl Feedback {
    /// A bar whose messages start with `prefix`.
    pub fn new(prefix: impl Into<String>, verbose: bool) -> Self {
        let bar = ProgressBar::new(1);
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} {elapsed:>4} {msg} [{bar:24}] {pos}/{len} {prefix}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        Self {
            bar,
            start: Instant::now(),
            prefix: prefix.into(),
            verbose,
        }
    }

    /// Changes the message prefix (e.g. the run being swept).
    pub fn set_prefix(&mut self, prefix: impl Into<String>) {
        self.prefix = prefix.into();
    }

    /// Runs `f` with hooks that drive this bar.
    pub fn with_hooks<T>(&self, f: impl FnOnce(&Hooks<'_>) -> T) -> T {
        let bar = &self.bar;
        let prefix = &self.prefix;
        let start = self.start;
        let verbose = self.verbose;
        let progress = move |p: Progress<'_>| {
            if verbose {
                let t = start.elapsed().as_secs_f64();
                match p {
                    Progress::Stage(s) => bar.suspend(|| eprintln!("[{t:7.2} s] {prefix}{s}")),
                    Progress::Step { iteration, mse, .. } => bar.suspend(|| {
                        eprintln!("[{t:7.2} s]   step {iteration:4}  training MSE {mse:.6e}")
                    }),
                }
            }
            match p {
                Progress::Stage(s) => {
                    bar.set_position(0);
                    bar.set_prefix("");
                    bar.set_message(format!("{prefix}{s}"));
                }
                Progress::Step {
                    iteration,
                    max_iter,
                    mse,
                } => {
                    bar.set_length(max_iter as u64);
                    bar.set_position(iteration as u64);
                    bar.set_prefix(format!("training MSE {mse:.3e}"));
                }
            }
        };
        let clock = move || start.elapsed().as_secs_f64();
        f(&Hooks {
            progress: &progress,
            clock: &clock,
        })
    }

    /// Removes the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// A number for tables: 3 significant digits in scientific notation, `diverges` for
/// infinity, `-` for none.
pub fn fmt_err(v: Option<f64>) -> String {
    match v {
        None => "-".into(),
        Some(x) if !x.is_finite() => "diverges".into(),
        Some(x) => format!("{x:.3e}"),
    }
}

/// Records the command that made a model in its provenance (`tool`).
pub fn stamp_tool(lmn: &mut fes_model::model::Lmn, command: &str) {
    lmn.provenance.extra.insert(
        "tool".into(),
        serde_json::json!(format!("fes {command} {}", env!("CARGO_PKG_VERSION"))),
    );
}
