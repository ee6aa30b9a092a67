//! `fes identify`: one identification run, the model file and its metrics.

use super::{
    Feedback, LearningArg, ModeArg, SchedulingArg, SchedulingInputArg, StructureArg, fmt_err,
};
use anyhow::{Context, Result, bail};
use fes_ident::ident::{IdentOptions, Identified, Learning, RecordSet, Undelivered, identify};
use fes_model::model::{KnotLayout, file};
use std::path::{Path, PathBuf};

const AFTER_HELP: &str = "\
STRUCTURES (local models; thesis 5.3, 5.4.2)
  arx-shift      ARX, shift-operator parameters (eq. 2.20-2.24). At Ts = 1 ms prediction
                 mode only learns to repeat the last sample (5.3.1); use --ts-ms 5 or 10
                 (pulse-preserving down-sampling, 5.2.2; delay 10 ms, Fig. 5.6).
  arx-delta      ARX with delta-operator parameters (D.2.2), Ts = 1 ms, delay 7 ms (5.3.2).
  ss-direct      2nd-order delta-domain state space, A b c dx dy free, 11 per unit (Fig. 5.18).
  ss-eig-local   real eigensystem per unit, A_i = V_i diag(e_i) V_i^-1 (eq. 5.5, Fig. 5.19).
  ss-eig-common  common eigenvectors, A_i = V diag(e_i) V^-1 (eq. 5.6, Fig. 5.21), gauge
                 V = I, b = (1, 1) for the best-covered unit; every eigenvalue inside
                 (-1/Ts, 0) by construction, so the network is stable (2.4.1).
  --units 1 is the single linear model; --order sets the ARX order (state space: 2).

ESTIMATION (App. B)
  simulation     free run from rest, Levenberg-Marquardt with exact (dual-number)
                 Jacobians; starts from the best linear fit copied into every unit.
  prediction     one-step-ahead least squares by SVD; ARX only; --learning global
                 (eq. 2.33) or local (eq. 2.35, default).

ERRORS (5.3, eq. B.8, normalised force, always at the data's 1 ms)
  train MSPE (ARX), train MSSE, test MSSE; stored in the model file's provenance with the
  options, the data set, the seed and the fit time. Beside them, as the field reports a
  model: NRMSE fit % (MATLAB compare; 100 = perfect, 0 = the mean), RRSE (sysidentpy),
  and the residual tests of MATLAB resid (autocorrelation of the test residuals, their
  cross-correlation with the input, +-25 lags, 99 % band): train_fit_percent,
  test_fit_percent, test_rrse, test_resid in the provenance; --validation DIR writes the
  traces and the tests as CSV and a figure.

EXAMPLES
  fes identify --data data/fast --structure ss-eig-common --units 4 --out fast.lmn.json
  fes identify --data data/fast --structure arx-shift --ts-ms 5 --mode prediction \\
      --units 10 --out fast-arx.lmn.json
  See docs/identification.md.";

/// `fes identify` arguments.
#[derive(Debug, clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    #[command(flatten)]
    pub fit: FitArgs,
    /// Number of units M (validity functions / local models), 1..=16; 1 = linear model.
    #[arg(long)]
    pub units: usize,
    /// Output model file (fes-lmn/1 JSON).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the validation as the field reports it into this directory: measured
    /// and simulated traces per record (`traces_train.csv`, `traces_test.csv`) and the
    /// residual tests of MATLAB's `resid` (`resid.csv`, `resid.png`).
    #[arg(long)]
    pub validation: Option<PathBuf>,
    /// Format of the figures: png (raster) or svg (vector, for papers).
    #[arg(long, value_enum, default_value_t = workbench::plots::FigureFormat::Png)]
    pub format: workbench::plots::FigureFormat,
}

/// What `fes identify` and `fes sweep` fit, and how: the data, the structure and the
/// estimation options (every network size of a sweep is fitted as identify would).
#[derive(Debug, Clone, clap::Args)]
pub struct FitArgs {
    /// Data-set directory (fes-dataset/1, e.g. from `sim-muscle record`).
    #[arg(long)]
    pub data: PathBuf,
    /// Local model structure.
    #[arg(long, value_enum)]
    pub structure: StructureArg,
    /// ARX order n (1..=3; ARX structures).
    #[arg(long, default_value_t = 2)]
    pub order: usize,
    /// Model sampling period in ms, a multiple of the data's (1; 5 or 10 for arx-shift).
    #[arg(long, default_value_t = 1)]
    pub ts_ms: usize,
    /// Input delay in ms (default 7 ms at the data's period, 10 ms at a longer one).
    #[arg(long)]
    pub delay_ms: Option<usize>,
    /// Fix every offset dx, dy (ARX: d) at zero (thesis 6.5.3).
    #[arg(long)]
    pub zero_offsets: bool,
    /// Scheduling variable.
    #[arg(long, value_enum, default_value_t = SchedulingArg::Input)]
    pub scheduling: SchedulingArg,
    /// Input scheduling: which pulse train the prefilter filters. `delayed` (ours): u(t - Td),
    /// the input the local models see, so the controller can act on the state d samples
    /// ahead. `undelayed` (eq. 5.2 as printed): u(t) as applied, the local models still
    /// seeing u(t - Td); only the thesis's delayed loop runs on such a model
    /// (docs/model.md, "Scheduling classes").
    #[arg(long, value_enum, default_value_t = SchedulingInputArg::Delayed)]
    pub scheduling_input: SchedulingInputArg,
    /// Estimation mode.
    #[arg(long, value_enum, default_value_t = ModeArg::Simulation)]
    pub mode: ModeArg,
    /// Global or local learning (prediction mode; default local).
    #[arg(long, value_enum)]
    pub learning: Option<LearningArg>,
    /// Alternate interior-knot optimisation with parameter estimation (5.4.2).
    #[arg(long)]
    pub optimise_knots: bool,
    /// Knot layout of the validity functions: `clamped` (p-fold end knots, edge units peak
    /// at the range ends) or `uniform` (the thesis's evenly spaced knots, extended beyond
    /// [0, 1]; every unit the same shifted spline). docs/model.md.
    #[arg(long, value_enum, default_value_t = KnotsArg::Clamped)]
    pub knots: KnotsArg,
    /// Scheduling range LO,HI the validity functions span (phi; a constant f Hz train
    /// has mean phi f/100). Units beyond the range the data reach are fitted to little
    /// information (pitfall d): put them where the data are; outside the range phi is
    /// clamped into it, so the edge units extrapolate. docs/model.md.
    #[arg(long, value_parser = parse_range, default_value = "0,1")]
    pub range: (f64, f64),
    /// Number of network starts for Levenberg-Marquardt (best training error wins).
    #[arg(long, default_value_t = 1)]
    pub starts: usize,
    /// Levenberg-Marquardt iteration limit per run.
    #[arg(long, default_value_t = 200)]
    pub max_iter: usize,
    /// Seed of the perturbed starts.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Strength of the prior keeping units the data barely reach near the start (pitfall
    /// d; 0 = the thesis's pure error criterion). See docs/identification.md.
    #[arg(long, default_value_t = fes_ident::ident::identify::DEFAULT_PRIOR)]
    pub prior: f64,
    /// Print every stage and accepted step on stderr.
    #[arg(long, short)]
    pub verbose: bool,
    /// Fit a recording whose delivered pulses differ from the decided ones (pulses the
    /// driver refused or sent while not armed): by default such a data set is refused. The
    /// model's provenance then records how many differed (`undelivered_pulses`).
    #[arg(long)]
    pub allow_undelivered: bool,
}

/// `--range LO,HI`: two finite numbers (their order is checked with the other options).
fn parse_range(s: &str) -> std::result::Result<(f64, f64), String> {
    let (lo, hi) = s
        .split_once(',')
        .ok_or_else(|| format!("`{s}`: expected LO,HI (e.g. 0,0.7)"))?;
    let num = |t: &str| {
        t.trim()
            .parse::<f64>()
            .map_err(|e| format!("`{t}` in `{s}`: {e}"))
    };
    Ok((num(lo)?, num(hi)?))
}

/// `--knots`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum KnotsArg {
    /// Open uniform knots with p-fold ends (ours).
    Clamped,
    /// Evenly spaced knots extended beyond the range (thesis 5.4.1).
    Uniform,
}

impl FitArgs {
    /// Library options for `units`, checked against the data's period.
    pub fn options(&self, units: usize, data_ts_s: f64) -> Result<IdentOptions> {
        let data_ms = data_ts_s * 1e3;
        let factor = self.ts_ms as f64 / data_ms;
        if self.ts_ms == 0 || (factor - factor.round()).abs() > 1e-9 || factor.round() < 1.0 {
            bail!(
                "--ts-ms {}: the model period must be a positive multiple of the data's {data_ms} ms",
                self.ts_ms
            );
        }
        let ts_model_ms = factor.round() * data_ms;
        let delay = match self.delay_ms {
            None => None,
            Some(d) => {
                let k = d as f64 / ts_model_ms;
                if (k - k.round()).abs() > 1e-9 {
                    bail!(
                        "--delay-ms {d}: the delay must be a multiple of the model period {ts_model_ms} ms"
                    );
                }
                Some(k.round() as usize)
            }
        };
        if self.learning.is_some() && self.mode == ModeArg::Simulation {
            bail!(
                "--learning applies to prediction mode only (local learning, eq. 2.35, fits one-step predictors)"
            );
        }
        if self.scheduling == SchedulingArg::Output
            && self.scheduling_input == SchedulingInputArg::Undelayed
        {
            bail!(
                "--scheduling-input undelayed applies to input scheduling only (output scheduling has no prefilter)"
            );
        }
        let opts = IdentOptions {
            structure: self.structure.into(),
            units,
            arx_order: self.order,
            ts_factor: factor.round() as usize,
            delay,
            scheduling: self.scheduling.into(),
            scheduling_input: self.scheduling_input.into(),
            zero_offsets: self.zero_offsets,
            mode: self.mode.into(),
            learning: self.learning.map_or(Learning::Local, Into::into),
            optimise_knots: self.optimise_knots,
            knots: match self.knots {
                KnotsArg::Clamped => KnotLayout::Clamped,
                KnotsArg::Uniform => KnotLayout::Uniform,
            },
            starts: self.starts,
            max_iter: self.max_iter,
            seed: self.seed,
            prior: self.prior,
            range: self.range,
        };
        opts.validate()?;
        Ok(opts)
    }
}

/// Loads a data set with a message naming the directory; a `fes-dataset/2` data set is
/// refused saying what reads it ([`workbench::data::require_pulses`]).
pub fn load_records(dir: &Path) -> Result<RecordSet> {
    workbench::data::require_pulses(dir)?;
    RecordSet::load(dir).with_context(|| format!("cannot use data set {}", dir.display()))
}

/// [`load_records`], refusing a recording whose deliveries differ from its decisions
/// unless `--allow-undelivered`; returns the differences to stamp into the model.
pub fn load_delivered(fit: &FitArgs) -> Result<(RecordSet, Undelivered)> {
    let dir = &fit.data;
    let records = load_records(dir)?;
    let undelivered = records
        .check_deliveries(fit.allow_undelivered)
        .with_context(|| format!("cannot use data set {}", dir.display()))?;
    Ok((records, undelivered))
}

/// Says in the model's provenance how many pulses of its data were not as decided (only
/// when some were: `--allow-undelivered`).
pub fn stamp_undelivered(lmn: &mut fes_model::model::Lmn, undelivered: Undelivered) {
    if !undelivered.is_none() {
        lmn.provenance
            .extra
            .insert("undelivered_pulses".into(), serde_json::json!(undelivered));
    }
}

/// Prints the run's figures (`data_ts_s`: the data's sampling period).
pub fn print_summary(r: &Identified, data_ts_s: f64) {
    let m = &r.metrics;
    println!(
        "structure      {} ({} units)",
        r.lmn.structure(),
        r.lmn.units()
    );
    println!("train MSPE     {}", fmt_err(m.train_mspe));
    println!("train MSSE     {}", fmt_err(Some(m.train_msse)));
    println!("test MSSE      {}", fmt_err(Some(m.test_msse)));
    let v = &r.validation;
    let pct = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{x:.1} %"));
    println!(
        "fit (NRMSE)    train {}, test {}; test RRSE {}",
        pct(v.train_fit_percent),
        pct(v.test_fit_percent),
        v.test_rrse.map_or("-".to_owned(), |x| format!("{x:.4}"))
    );
    if let Some(res) = &v.resid {
        println!(
            "resid (99 %)   {} of {} autocorrelation lags, {} of {} input cross-correlation lags outside the band",
            res.autocorr_outside,
            fes_ident::ident::validation::RESID_LAGS,
            res.xcorr_outside,
            2 * fes_ident::ident::validation::RESID_LAGS + 1
        );
    }
    println!(
        "iterations     {} (final fit {}{})",
        r.iterations,
        r.final_iterations,
        r.stop.map_or(String::new(), |s| format!(", {s}"))
    );
    println!("fit time       {:.2} s", r.seconds);
    let shares: Vec<String> = r
        .unit_weights
        .iter()
        .map(|w| format!("{:.1}%", 100.0 * w.share))
        .collect();
    println!("unit weights   {}", shares.join(" "));
    if r.pulse_shift.collisions > 0 {
        println!(
            "down-sampling  {} of {} pulses moved past their nearest sample, at most {} ms",
            r.pulse_shift.collisions,
            r.pulse_shift.pulses,
            r.pulse_shift.max_displacement as f64 * data_ts_s * 1e3
        );
    }
    let stab = r.lmn.stability();
    if let Some(u) = stab.iter().find(|s| !s.stable) {
        println!(
            "stability      unit {} is unstable (max |1 + Ts p| = {:.4})",
            u.unit, u.radius
        );
    }
    for w in &r.warnings {
        eprintln!("warning: {w}");
    }
}

/// Runs `fes identify`.
pub fn run(args: Args) -> Result<()> {
    let (records, undelivered) = load_delivered(&args.fit)?;
    let opts = args.fit.options(args.units, records.ts)?;
    let fb = Feedback::new("", args.fit.verbose);
    let result = fb.with_hooks(|h| identify(&records, &opts, h));
    fb.finish();
    let mut result = result.context("identification failed")?;
    super::stamp_tool(&mut result.lmn, "identify");
    stamp_undelivered(&mut result.lmn, undelivered);
    file::save(&result.lmn, &args.out)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    print_summary(&result, records.ts);
    println!("model          {}", args.out.display());
    if let Some(dir) = &args.validation {
        let name = args.out.file_name().map_or_else(
            || args.out.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        super::validation::write(dir, &result.validation, records.ts, &name, args.format)?;
        println!("validation     {}", dir.display());
    }
    Ok(())
}
