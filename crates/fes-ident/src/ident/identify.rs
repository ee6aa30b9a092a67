//! One identification run (thesis 5.3, 5.4): options, the estimation stages, metrics and
//! provenance. Used by `fes identify`, `sweep`, `compare` and the tests.
//!
//! Prediction mode (ARX only): least squares, global or local ([`super::regression`]).
//!
//! Simulation mode (every structure), Levenberg-Marquardt ([`super::lm`]) on the free-run
//! error over all training records, each from rest:
//! 1. **Linear fit** (a one-unit model of the same structure): for every choice of separated
//!    real poles from [`super::start::POLE_GRID`], the parameters that enter linearly for
//!    fixed poles are solved exactly by least squares; the best [`LINEAR_CANDIDATES`] (and,
//!    for ARX, the prediction-mode linear fit) are refined by LM; the best result is the
//!    linear model.
//! 2. **Starts for the network**: the linear fit copied into every unit (collapsed
//!    eigenvalues are separated first, pitfall (b)), its c/d^y (SS) or b/d (ARX) re-solved
//!    per unit by least squares; further starts from the next-best linear fits, the
//!    prediction-mode network (ARX) and seeded perturbations of the eigenvalues (SS).
//! 3. **LM from each start** (`starts` of them); the lowest training cost wins.
//! 4. Optionally, **knot optimisation** alternated with parameter estimation (5.4.2): LM on
//!    the interior knots with the parameters fixed, then LM on the parameters, until a round
//!    improves the training cost by less than 1e-4 (relative) or after [`KNOT_ROUNDS`].
//!
//! Time is passed in ([`Hooks::clock`]); rt-core never reads a clock itself.

use super::gauge::fix_gauge;
use super::knots::KnotMap;
use super::lm::{LmOptions, LmReport, StopReason, levenberg_marquardt};
use super::lsq::{self, DEFAULT_RCOND};
use super::metrics::{
    MIN_UNIT_SHARE, Metrics, UnitWeight, evaluate, unit_weights, validity_weights,
};
use super::problem::{Horizon, ModelData, ParamMap, Prior, Problem, ThetaMap};
use super::records::RecordSet;
use super::regression::{Learning, fit_prediction};
use super::resample::PulseShift;
use super::start;
use super::validation::{Validation, validate};
use super::{IdentError, PREDICTION_NEEDS_ARX};
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance, Structure};
use fes_model::model::network::MAX_DELAY;
use fes_model::model::params::ParamLayout;
use fes_model::model::scheduling::{
    SchedulingInput, SchedulingSpec, THESIS_PREFILTER_GAIN, THESIS_PREFILTER_WN,
    THESIS_PREFILTER_ZETA,
};
use fes_model::model::validity::{KnotLayout, MAX_UNITS, ValidityFunctions};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;

/// Linear fits refined by LM in stage 1.
pub const LINEAR_CANDIDATES: usize = 3;
/// LM iterations each linear candidate gets in stage 1 (the best one continues to
/// convergence when the linear model is the result). A real-eigenvalue fit whose best poles
/// are complex creeps towards a double pole (pitfall (b)) for hundreds of steps with little
/// gain; as a start for a network it needs no more.
pub const LINEAR_SCREEN_ITER: usize = 30;
/// Most knot-optimisation rounds.
pub const KNOT_ROUNDS: usize = 5;

/// Default [`IdentOptions::prior`].
pub const DEFAULT_PRIOR: f64 = 1e-3;

/// How the parameters are estimated (thesis B.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// One-step-ahead prediction, linear least squares (ARX only).
    Prediction,
    /// Free-run simulation, Levenberg-Marquardt.
    Simulation,
}

/// The scheduling variable (5.4.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SchedulingKind {
    /// The prefiltered pulse train (eq. 5.4).
    Input,
    /// The output one sample earlier (eq. 5.1).
    Output,
}

/// Options of one identification run.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentOptions {
    /// Local model structure.
    pub structure: Structure,
    /// Number of units M (1 = a single linear model).
    pub units: usize,
    /// ARX order n (ARX structures; 1..=3).
    pub arx_order: usize,
    /// Model period in base samples (1 = the data's period; 5, 10 for the shift models of
    /// 5.3 at 5 and 10 ms).
    pub ts_factor: usize,
    /// Input delay in model samples; `None`: 7 ms at the base period, 10 ms at a longer one
    /// (Fig. 5.6), rounded to model samples.
    pub delay: Option<usize>,
    /// Scheduling variable.
    pub scheduling: SchedulingKind,
    /// Input scheduling: which pulse train the prefilter filters (eq. 5.2 as printed:
    /// [`SchedulingInput::Undelayed`]; ours: [`SchedulingInput::Delayed`]).
    pub scheduling_input: SchedulingInput,
    /// Offsets fixed at zero (6.5.3).
    pub zero_offsets: bool,
    /// Estimation mode.
    pub mode: Mode,
    /// Global or local learning (prediction mode only).
    pub learning: Learning,
    /// Alternate knot optimisation with parameter estimation (simulation mode).
    pub optimise_knots: bool,
    /// Number of network starts for LM (>= 1).
    pub starts: usize,
    /// LM iteration limit per run.
    pub max_iter: usize,
    /// Seed of the perturbed starts.
    pub seed: u64,
    /// Scheduling range [lo, hi] of the uniform validity functions.
    pub range: (f64, f64),
    /// Knot layout of the validity functions: clamped (ours, the default) or the thesis's
    /// evenly spaced knots extended beyond the range (docs/model.md).
    pub knots: KnotLayout,
    /// Strength of the prior that keeps units the training data barely reach near the
    /// start (pitfall (d)); 0 disables it (the thesis's pure error criterion). Every
    /// parameter of a unit with less than [`MIN_UNIT_SHARE`] of the training data's
    /// validity weight gets the penalty w (theta - theta_start)^2 with w = prior x the
    /// largest Gauss-Newton diagonal of the same parameter in any unit at the start (so it
    /// acts like data worth a fraction `prior` of the best-covered unit's); the other units
    /// are free.
    pub prior: f64,
}

impl Default for IdentOptions {
    /// ss-eig-common, 4 units, input scheduling, simulation mode at the data's period,
    /// 1 start, 200 iterations, seed 1, range [0, 1].
    fn default() -> Self {
        Self {
            structure: Structure::SsEigCommon,
            units: 4,
            arx_order: 2,
            ts_factor: 1,
            delay: None,
            scheduling: SchedulingKind::Input,
            scheduling_input: SchedulingInput::Delayed,
            zero_offsets: false,
            mode: Mode::Simulation,
            learning: Learning::Local,
            optimise_knots: false,
            knots: KnotLayout::Clamped,
            starts: 1,
            max_iter: 200,
            seed: 1,
            range: (0.0, 1.0),
            prior: DEFAULT_PRIOR,
        }
    }
}

impl IdentOptions {
    /// Checks every option; the error names it.
    pub fn validate(&self) -> Result<(), IdentError> {
        let bad = |option, value: &dyn std::fmt::Display, allowed: String| {
            Err(IdentError::Option {
                option,
                value: value.to_string(),
                allowed,
            })
        };
        let conflict = |option, value: &str, with: String, rule| {
            Err(IdentError::Conflict {
                option,
                value: value.into(),
                with,
                rule,
            })
        };
        if self.units == 0 || self.units > MAX_UNITS {
            let allowed = format!("in 1..={MAX_UNITS} (1 = a single linear model)");
            return bad("units", &self.units, allowed);
        }
        if !(1..=3).contains(&self.arx_order) {
            return bad("ARX order", &self.arx_order, "in 1..=3".into());
        }
        if self.ts_factor == 0 {
            let allowed = "a positive multiple of the data's period".into();
            return bad("the model period factor", &self.ts_factor, allowed);
        }
        if let Some(d) = self.delay
            && d > MAX_DELAY
        {
            return bad("delay", &d, format!("at most {MAX_DELAY} samples"));
        }
        if self.starts == 0 {
            return bad("starts", &self.starts, "at least 1".into());
        }
        if self.mode == Mode::Prediction {
            if self.structure.is_state_space() {
                let with = format!("structure {}", self.structure);
                return conflict("mode", "prediction", with, PREDICTION_NEEDS_ARX);
            }
            if self.optimise_knots {
                let rule = "knot optimisation runs in simulation mode";
                return conflict("optimise_knots", "true", "mode prediction".into(), rule);
            }
        }
        if self.optimise_knots && self.knots == KnotLayout::Uniform {
            let rule = "knot optimisation moves the interior knots between clamped end knots: \
                        use the clamped layout";
            return conflict("optimise_knots", "true", "knots uniform".into(), rule);
        }
        if !(self.prior.is_finite() && self.prior >= 0.0) {
            return bad("prior", &self.prior, "finite and >= 0".into());
        }
        let (lo, hi) = self.range;
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            let range = format!("[{lo}, {hi}]");
            return bad("scheduling range", &range, "finite with lo < hi".into());
        }
        Ok(())
    }

    /// The input delay in model samples at model period `ts` (see [`Self::delay`]).
    pub fn delay_samples(&self, ts: f64) -> usize {
        self.delay.unwrap_or_else(|| {
            let ms = if self.ts_factor == 1 { 7.0 } else { 10.0 };
            ((ms * 1e-3 / ts).round() as usize).max(1)
        })
    }

    /// A JSON summary for the model's provenance.
    pub fn to_json(&self) -> serde_json::Value {
        json!({
            "structure": self.structure.name(),
            "units": self.units,
            "arx_order": self.arx_order,
            "ts_factor": self.ts_factor,
            "delay_samples": self.delay,
            "scheduling": match self.scheduling { SchedulingKind::Input => "input", SchedulingKind::Output => "output" },
            "scheduling_input": self.scheduling_input.name(),
            "zero_offsets": self.zero_offsets,
            "mode": match self.mode { Mode::Prediction => "prediction", Mode::Simulation => "simulation" },
            "learning": match self.learning { Learning::Global => "global", Learning::Local => "local" },
            "optimise_knots": self.optimise_knots,
            "knots": match self.knots { KnotLayout::Clamped => "clamped", KnotLayout::Uniform => "uniform" },
            "starts": self.starts,
            "max_iter": self.max_iter,
            "seed": self.seed,
            "range": [self.range.0, self.range.1],
            "prior": self.prior,
        })
    }
}

/// What a run reports while it works.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Progress<'a> {
    /// A new stage begins.
    Stage(&'a str),
    /// An accepted LM step.
    Step {
        /// Step number in this LM run.
        iteration: usize,
        /// The limit.
        max_iter: usize,
        /// Training MSE after the step.
        mse: f64,
    },
}

/// Callbacks of a run: progress and a clock (seconds, any origin).
pub struct Hooks<'a> {
    /// Called at every stage and accepted step.
    pub progress: &'a (dyn Fn(Progress<'_>) + Sync),
    /// Wall-clock seconds.
    pub clock: &'a (dyn Fn() -> f64 + Sync),
}

impl Hooks<'static> {
    /// No progress output and no clock (times are 0).
    pub fn silent() -> Self {
        Hooks {
            progress: &|_| {},
            clock: &|| 0.0,
        }
    }
}

/// The result of [`identify`].
#[derive(Debug, Clone)]
pub struct Identified {
    /// The model, with metrics and options in its provenance.
    pub lmn: Lmn,
    /// The error measures.
    pub metrics: Metrics,
    /// Accepted LM steps over all stages.
    pub iterations: usize,
    /// Accepted LM steps of the final network fit (the winning start).
    pub final_iterations: usize,
    /// Why the final LM run stopped (simulation mode).
    pub stop: Option<StopReason>,
    /// Training MSSE (data only, without the prior) reached from each network start.
    pub start_msse: Vec<f64>,
    /// Wall-clock seconds (from [`Hooks::clock`]).
    pub seconds: f64,
    /// Each unit's validity weight in the training data (pitfall (d)).
    pub unit_weights: Vec<UnitWeight>,
    /// How far down-sampling moved pulses.
    pub pulse_shift: PulseShift,
    /// Things the user should know (small units, collapsed eigenvalues, ...).
    pub warnings: Vec<String>,
    /// The field's validation figures: fit %, RRSE, residual tests, traces.
    pub validation: Validation,
}

/// Runs one identification (module docs).
pub fn identify(
    records: &RecordSet,
    opts: &IdentOptions,
    hooks: &Hooks<'_>,
) -> Result<Identified, IdentError> {
    opts.validate()?;
    let t0 = (hooks.clock)();
    let ts = records.ts * opts.ts_factor as f64;
    let train = ModelData::new(&records.train, opts.ts_factor)?;
    let test = ModelData::new(&records.test, opts.ts_factor)?;
    let mut run = Run {
        opts,
        hooks,
        train: &train,
        n_rows: train.base_samples() as f64,
        iterations: 0,
        warnings: Vec::new(),
        reference: 0,
        unit_weights: Vec::new(),
    };
    let mut template = run.template(ts, records.force_scale_n)?;
    let weights = unit_weights(&validity_weights(&template, &train)?);
    for w in &weights {
        if w.share < MIN_UNIT_SHARE && opts.units > 1 {
            run.warnings.push(format!(
                "unit {} gets only {:.2} % of the training data's validity weight (peak activation {:.2}): the data barely reach it, so it is fitted to little information (pitfall d); consider fewer units or data that reach it",
                w.unit,
                100.0 * w.share,
                w.peak
            ));
        }
    }
    // The gauge's reference unit: the one the data cover most.
    run.reference = weights
        .iter()
        .max_by(|a, b| a.share.total_cmp(&b.share))
        .map_or(0, |w| w.unit);
    if let LocalModelSet::SsEigCommon { reference_unit, .. } = &mut template.local {
        *reference_unit = run.reference;
    }
    run.unit_weights = weights;
    let mut outcome = match opts.mode {
        Mode::Prediction => {
            (hooks.progress)(Progress::Stage("least squares (prediction mode)"));
            let (theta, fallback) = fit_prediction(&template, &train, opts.learning)?;
            for u in fallback {
                run.warnings.push(format!(
                    "unit {u}: no training data activate it; it was given the linear fit"
                ));
            }
            Outcome {
                lmn: ParamLayout::new(&template).apply(&template, &theta)?,
                final_iterations: 0,
                stop: None,
                start_msse: Vec::new(),
                fixed: Vec::new(),
                prior: None,
            }
        }
        Mode::Simulation => run.simulation(&template)?,
    };
    if opts.optimise_knots {
        run.optimise_knots(&mut outcome)?;
    }
    let metrics = evaluate(&outcome.lmn, &train, &test)?;
    let validation = validate(&outcome.lmn, &train, &test);
    let seconds = (hooks.clock)() - t0;
    let mut lmn = outcome.lmn;
    lmn.provenance = provenance(
        records,
        opts,
        &run,
        (outcome.final_iterations, outcome.stop),
        (&metrics, &validation),
        seconds,
        (&train, &test),
    );
    Ok(Identified {
        lmn,
        metrics,
        iterations: run.iterations,
        final_iterations: outcome.final_iterations,
        stop: outcome.stop,
        start_msse: outcome.start_msse,
        seconds,
        unit_weights: run.unit_weights,
        pulse_shift: train.shift.merge(test.shift),
        warnings: run.warnings,
        validation,
    })
}

/// The model file's provenance of a run (docs/identification.md, "Errors and provenance").
fn provenance(
    records: &RecordSet,
    opts: &IdentOptions,
    run: &Run<'_>,
    (final_iterations, stop): (usize, Option<StopReason>),
    (metrics, validation): (&Metrics, &Validation),
    seconds: f64,
    (train, test): (&ModelData, &ModelData),
) -> Provenance {
    let finite = |v: f64| v.is_finite().then_some(v);
    let mut extra = std::collections::BTreeMap::new();
    extra.insert("data_set".into(), json!(records.source));
    extra.insert("seed".into(), json!(opts.seed));
    extra.insert("structure".into(), json!(opts.structure.name()));
    extra.insert("options".into(), opts.to_json());
    extra.insert(
        "tool".into(),
        json!(format!("rt-core ident {}", env!("CARGO_PKG_VERSION"))),
    );
    extra.insert("iterations".into(), json!(run.iterations));
    extra.insert("final_iterations".into(), json!(final_iterations));
    if let Some(s) = stop {
        extra.insert("stop".into(), json!(s.to_string()));
    }
    extra.insert(
        "unit_validity_share".into(),
        json!(run.unit_weights.iter().map(|w| w.share).collect::<Vec<_>>()),
    );
    if opts.ts_factor > 1 {
        let s = train.shift.merge(test.shift);
        extra.insert(
            "pulse_shift".into(),
            json!({"pulses": s.pulses, "collisions": s.collisions,
                   "max_displacement_ms": s.max_displacement as f64 * records.ts * 1e3}),
        );
    }
    if !metrics.train_msse.is_finite() || !metrics.test_msse.is_finite() {
        extra.insert("diverges".into(), json!(true));
    }
    if !run.warnings.is_empty() {
        extra.insert("warnings".into(), json!(run.warnings));
    }
    // The field's figures beside the thesis's MSSE (docs/identification.md, "Validation").
    for (key, v) in [
        ("train_fit_percent", validation.train_fit_percent),
        ("test_fit_percent", validation.test_fit_percent),
        ("test_rrse", validation.test_rrse),
    ] {
        if let Some(v) = v.filter(|v| v.is_finite()) {
            extra.insert(key.into(), json!(v));
        }
    }
    if let Some(r) = &validation.resid {
        extra.insert(
            "test_resid".into(),
            json!({"lags": super::validation::RESID_LAGS, "band_99": r.band,
                   "autocorr_outside": r.autocorr_outside, "xcorr_outside": r.xcorr_outside}),
        );
    }
    Provenance {
        train_mspe: metrics.train_mspe.and_then(finite),
        train_msse: finite(metrics.train_msse),
        test_msse: finite(metrics.test_msse),
        fit_seconds: finite(seconds),
        extra,
    }
}

/// A fitted network before metrics.
struct Outcome {
    lmn: Lmn,
    final_iterations: usize,
    stop: Option<StopReason>,
    start_msse: Vec<f64>,
    /// Parameters held fixed by the gauge ([`super::gauge`]).
    fixed: Vec<usize>,
    /// The prior of the winning start.
    prior: Option<Prior>,
}

/// The state of one run.
struct Run<'a> {
    opts: &'a IdentOptions,
    hooks: &'a Hooks<'a>,
    train: &'a ModelData,
    n_rows: f64,
    iterations: usize,
    warnings: Vec<String>,
    /// The gauge's reference unit.
    reference: usize,
    /// Each unit's validity weight in the training data.
    unit_weights: Vec<UnitWeight>,
}

impl Run<'_> {
    /// The M-unit model with uniform validity functions and a placeholder linear unit.
    fn template(&self, ts: f64, force_scale_n: f64) -> Result<Lmn, IdentError> {
        let o = self.opts;
        let scheduling = match o.scheduling {
            // A pulse is one model sample long: scale K so that a pulse still has the
            // thesis's area of 1 ms (the same phi at every period).
            SchedulingKind::Input => SchedulingSpec::Input {
                gain: THESIS_PREFILTER_GAIN * 1e-3 / ts,
                natural_frequency_rad_s: THESIS_PREFILTER_WN,
                damping: THESIS_PREFILTER_ZETA,
                scheduling_input: o.scheduling_input,
            },
            SchedulingKind::Output => SchedulingSpec::Output,
        };
        let one = start::linear_set(o.structure, &[-20.0, -120.0, -300.0], ts, o.arx_order);
        Ok(Lmn {
            ts,
            delay: o.delay_samples(ts),
            scheduling,
            validity: ValidityFunctions::with_layout(o.knots, o.units, o.range.0, o.range.1)
                .map_err(fes_model::model::params::ParamError::from)?,
            local: start::replicate(&one, o.units, 0),
            zero_offsets: o.zero_offsets,
            force_scale_n,
            provenance: Provenance::default(),
        })
    }

    /// LM over the parameters of `map` except `fixed` on the training data.
    fn lm<M: ParamMap>(
        &mut self,
        map: M,
        p0: &[f64],
        fixed: &[usize],
        max_iter: usize,
        prior: Option<Prior>,
    ) -> Result<LmReport, IdentError> {
        let mut problem = Problem::new(map, self.train, Horizon::Simulation);
        problem.prior = prior;
        let free: Vec<usize> = (0..p0.len()).filter(|i| !fixed.contains(i)).collect();
        let opts = LmOptions {
            max_iter,
            ..LmOptions::default()
        };
        let n = self.n_rows;
        let progress = self.hooks.progress;
        let rep = levenberg_marquardt(&problem, p0, &free, &opts, &mut |iteration, cost| {
            progress(Progress::Step {
                iteration,
                max_iter: opts.max_iter,
                mse: cost / n,
            })
        })?;
        self.iterations += rep.iterations;
        Ok(rep)
    }

    /// theta with the parameters `cols` replaced by their least-squares solution for the
    /// others fixed (exact when the output is affine in them), kept only if it lowers the
    /// cost.
    fn solve_linear_part(&self, template: &Lmn, theta: &[f64]) -> Result<Vec<f64>, IdentError> {
        let layout = ParamLayout::new(template);
        // Units the data barely reach keep their values: least squares would fit their few
        // samples' noise (pitfall (d)).
        let sparse: Vec<usize> = if template.units() > 1 {
            self.unit_weights
                .iter()
                .filter(|w| w.share < MIN_UNIT_SHARE)
                .map(|w| w.unit)
                .collect()
        } else {
            Vec::new()
        };
        let cols: Vec<usize> = linear_columns(&layout, template.structure())
            .into_iter()
            .filter(|&i| !sparse.iter().any(|&u| layout.unit_range(u).contains(&i)))
            .collect();
        let problem = Problem::new(
            ThetaMap {
                template,
                layout: &layout,
            },
            self.train,
            Horizon::Simulation,
        );
        let before = problem.cost(theta).unwrap_or(f64::INFINITY);
        let Ok((r, j)) = problem.jacobian(theta, &cols) else {
            return Ok(theta.to_vec());
        };
        let Ok(sol) = lsq::solve(&j, &(-r), DEFAULT_RCOND) else {
            return Ok(theta.to_vec());
        };
        let mut out = theta.to_vec();
        for (k, &i) in cols.iter().enumerate() {
            out[i] += sol.x[k];
        }
        match problem.cost(&out) {
            Ok(c) if c < before => Ok(out),
            _ => Ok(theta.to_vec()),
        }
    }

    /// The prior of pitfall (d) for a network start theta (see [`IdentOptions::prior`]):
    /// on the parameters of units with less than [`MIN_UNIT_SHARE`] of the training data's
    /// validity weight, w_i = prior x the largest Gauss-Newton diagonal J'J of the same
    /// parameter in any unit, centred on the start; other parameters are free.
    fn prior<M: ParamMap>(
        &self,
        map: M,
        theta: &[f64],
        fixed: &[usize],
    ) -> Result<Option<Prior>, IdentError> {
        let alpha = self.opts.prior;
        let sparse: Vec<usize> = self
            .unit_weights
            .iter()
            .filter(|w| w.share < MIN_UNIT_SHARE)
            .map(|w| w.unit)
            .collect();
        if alpha <= 0.0 || sparse.is_empty() {
            return Ok(None);
        }
        let Some(names) = map.names() else {
            return Ok(None);
        };
        let free: Vec<usize> = (0..theta.len()).filter(|i| !fixed.contains(i)).collect();
        let normal = Problem::new(map, self.train, Horizon::Simulation).normal(theta, &free)?;
        let field = |n: &str| n.rsplit('.').next().unwrap_or("").to_string();
        let unit_of = |n: &str| {
            n.strip_prefix("units[")
                .and_then(|r| r.split(']').next())
                .and_then(|u| u.parse::<usize>().ok())
        };
        let mut scale = std::collections::BTreeMap::<String, f64>::new();
        for (k, &i) in free.iter().enumerate() {
            let e = scale.entry(field(&names[i])).or_insert(0.0);
            *e = e.max(normal.h[(k, k)]);
        }
        let weight = names
            .iter()
            .map(|n| match unit_of(n) {
                Some(u) if sparse.contains(&u) => {
                    alpha * scale.get(&field(n)).copied().unwrap_or(0.0)
                }
                _ => 0.0,
            })
            .collect();
        Ok(Some(Prior {
            center: theta.to_vec(),
            weight,
        }))
    }

    /// Stage 1: linear (one-unit) fits, best first: (one-unit local set, training cost).
    fn linear_fits(&mut self, template: &Lmn) -> Result<Vec<(LocalModelSet, f64)>, IdentError> {
        let o = self.opts;
        let mut single = template.clone();
        single.validity = ValidityFunctions::uniform(1, 0.0, 1.0)
            .map_err(fes_model::model::params::ParamError::from)?;
        let n_poles = if o.structure.is_state_space() {
            2
        } else {
            o.arx_order
        };
        let mut candidates: Vec<(Vec<f64>, f64)> = Vec::new();
        for poles in start::pole_sets(n_poles) {
            single.local = start::linear_set(o.structure, &poles, template.ts, o.arx_order);
            let layout = ParamLayout::new(&single);
            let theta = self.solve_linear_part(&single, &layout.theta(&single)?)?;
            let cost = self.cost_of(&single, &layout, &theta);
            candidates.push((theta, cost));
        }
        let layout = ParamLayout::new(&single);
        if !o.structure.is_state_space() {
            // The prediction-mode linear fit as another candidate (good at 5-10 ms, 5.3.1).
            single.local = start::linear_set(
                o.structure,
                &[-20.0, -120.0, -300.0],
                template.ts,
                o.arx_order,
            );
            if let Ok((theta, _)) = fit_prediction(&single, self.train, Learning::Global) {
                let cost = self.cost_of(&single, &layout, &theta);
                candidates.push((theta, cost));
            }
        }
        candidates.retain(|c| c.1.is_finite());
        candidates.sort_by(|a, b| a.1.total_cmp(&b.1));
        let mut fits = Vec::new();
        let k = LINEAR_CANDIDATES.max(o.starts).min(candidates.len());
        let screen = LINEAR_SCREEN_ITER.min(o.max_iter);
        for (i, (theta, _)) in candidates.iter().take(k).enumerate() {
            (self.hooks.progress)(Progress::Stage(&format!("linear fit {}/{k}", i + 1)));
            let (theta, fixed) = gauged(&single, theta, 0)?;
            let map = ThetaMap {
                template: &single,
                layout: &layout,
            };
            let rep = self.lm(map, &theta, &fixed, screen, None)?;
            fits.push((rep.p, fixed, rep.cost, rep.stop));
        }
        fits.sort_by(|a, b| a.2.total_cmp(&b.2));
        let Some(best) = fits.first_mut() else {
            return Err(IdentError::NoStart);
        };
        if o.units == 1 && best.3 == StopReason::MaxIterations && o.max_iter > screen {
            // The linear model is the result: continue the best candidate to convergence.
            (self.hooks.progress)(Progress::Stage("linear fit, refining"));
            let map = ThetaMap {
                template: &single,
                layout: &layout,
            };
            let (p, fixed) = (best.0.clone(), best.1.clone());
            let rep = self.lm(map, &p, &fixed, o.max_iter - screen, None)?;
            best.0 = rep.p;
            best.2 = rep.cost;
        }
        let fits = fits
            .into_iter()
            .map(|(p, _, cost, _)| Ok((layout.apply(&single, &p)?.local, cost)))
            .collect::<Result<Vec<_>, IdentError>>()?;
        if let Some(e) = start::eigenvalues(&fits[0].0)
            && start::collapsed(e)
        {
            self.warnings.push(format!(
                "the linear fit's two real eigenvalues collapsed onto a double pole ({:.1}, {:.1}): the best linear poles are probably complex (pitfall b); the network starts from separated eigenvalues",
                e[0], e[1]
            ));
        }
        Ok(fits)
    }

    fn cost_of(&self, template: &Lmn, layout: &ParamLayout, theta: &[f64]) -> f64 {
        Problem::new(
            ThetaMap { template, layout },
            self.train,
            Horizon::Simulation,
        )
        .cost(theta)
        .unwrap_or(f64::INFINITY)
    }

    /// Stages 2-3 (module docs).
    fn simulation(&mut self, template: &Lmn) -> Result<Outcome, IdentError> {
        let o = self.opts;
        let linear = self.linear_fits(template)?;
        let layout = ParamLayout::new(template);
        let reference = self.reference;
        if o.units == 1 {
            let mut lmn = template.clone();
            lmn.local = linear[0].0.clone();
            let msse = linear[0].1 / self.n_rows;
            let fixed = gauged(&lmn, &layout.theta(&lmn)?, 0)?.1;
            return Ok(Outcome {
                lmn,
                final_iterations: 0,
                stop: None,
                start_msse: vec![msse],
                fixed,
                prior: None,
            });
        }
        // Starts, best-first candidates.
        let mut starts: Vec<Vec<f64>> = Vec::new();
        let mut rng = ChaCha8Rng::seed_from_u64(o.seed);
        for (set, _) in &linear {
            let mut m = template.clone();
            m.local = start::replicate(set, o.units, reference);
            if let Some(e) = start::eigenvalues(set)
                && start::collapsed(e)
            {
                start::set_eigenvalues(&mut m.local, start::separate(e, template.ts));
            }
            let theta = layout.theta(&m)?;
            starts.push(self.solve_linear_part(&m, &theta)?);
        }
        if !o.structure.is_state_space() {
            let mut m = template.clone();
            m.local = start::replicate(&linear[0].0, o.units, 0);
            if let Ok((theta, _)) = fit_prediction(&m, self.train, Learning::Local)
                && self.cost_of(&m, &layout, &theta).is_finite()
            {
                starts.insert(1.min(starts.len()), theta);
            }
        }
        while starts.len() < o.starts && o.structure.is_state_space() {
            // Seeded perturbation of every unit's eigenvalue parameters (eta) around the
            // best linear fit.
            let mut theta = starts[0].clone();
            for (i, name) in layout.names().iter().enumerate() {
                if name.ends_with(".eta0") || name.ends_with(".eta1") {
                    theta[i] += 0.8 * (rng.random::<f64>() * 2.0 - 1.0);
                }
                if o.structure == Structure::SsDirect
                    && (name.ends_with(".a00") || name.ends_with(".a11"))
                {
                    theta[i] *= 1.0 + 0.5 * (rng.random::<f64>() * 2.0 - 1.0);
                }
            }
            starts.push(self.solve_linear_part(template, &theta)?);
        }
        starts.truncate(o.starts);
        let mut best: Option<(LmReport, usize)> = None;
        let mut start_msse = Vec::new();
        let count = starts.len();
        let mut fixed_best = Vec::new();
        let mut prior_best = None;
        for (i, theta) in starts.iter().enumerate() {
            (self.hooks.progress)(Progress::Stage(&format!("network start {}/{count}", i + 1)));
            let (theta, fixed) = gauged(template, theta, reference)?;
            let map = ThetaMap {
                template,
                layout: &layout,
            };
            let prior = self.prior(map.clone(), &theta, &fixed)?;
            let prior_kept = prior.clone();
            let rep = self.lm(map, &theta, &fixed, o.max_iter, prior)?;
            start_msse.push(self.cost_of(template, &layout, &rep.p) / self.n_rows);
            if best.as_ref().is_none_or(|(b, _)| rep.cost < b.cost) {
                best = Some((rep, i));
                fixed_best = fixed;
                prior_best = prior_kept;
            }
        }
        let (rep, _) = best.ok_or(IdentError::NoStart)?;
        Ok(Outcome {
            lmn: layout.apply(template, &rep.p)?,
            final_iterations: rep.iterations,
            stop: Some(rep.stop),
            start_msse,
            fixed: fixed_best,
            prior: prior_best,
        })
    }

    /// Stage 4 (module docs).
    fn optimise_knots(&mut self, out: &mut Outcome) -> Result<(), IdentError> {
        let order = out.lmn.validity.order();
        if out.lmn.units() <= order {
            self.warnings.push(format!(
                "knot optimisation skipped: {} units of order {order} have no interior knots",
                out.lmn.units()
            ));
            return Ok(());
        }
        let layout = ParamLayout::new(&out.lmn);
        let mut theta = layout.theta(&out.lmn)?;
        let mut cost = self.cost_of(&out.lmn, &layout, &theta);
        for round in 1..=KNOT_ROUNDS {
            (self.hooks.progress)(Progress::Stage(&format!("knots, round {round}")));
            let before = cost;
            let knots = {
                let map = KnotMap {
                    template: &out.lmn,
                    layout: &layout,
                    theta: &theta,
                };
                let Some(s0) = map.params() else { break };
                let rep = self.lm(map.clone(), &s0, &[], self.opts.max_iter, None)?;
                map.knots(&rep.p)
            };
            out.lmn.validity = ValidityFunctions::from_knots(&knots, order)
                .map_err(fes_model::model::params::ParamError::from)?;
            (self.hooks.progress)(Progress::Stage(&format!("parameters, round {round}")));
            let rep = self.lm(
                ThetaMap {
                    template: &out.lmn,
                    layout: &layout,
                },
                &theta,
                &out.fixed,
                self.opts.max_iter,
                out.prior.clone(),
            )?;
            theta = rep.p;
            cost = rep.cost;
            out.final_iterations += rep.iterations;
            out.stop = Some(rep.stop);
            if (before - cost) < 1e-4 * before {
                break;
            }
        }
        out.lmn = layout.apply(&out.lmn, &theta)?;
        Ok(())
    }
}

/// theta mapped into the gauge with reference unit r ([`super::gauge`]) and the parameters
/// to hold fixed.
fn gauged(template: &Lmn, theta: &[f64], r: usize) -> Result<(Vec<f64>, Vec<usize>), IdentError> {
    let layout = ParamLayout::new(template);
    let mut m = layout.apply(template, theta)?;
    let fixed = fix_gauge(&mut m, r);
    Ok((layout.theta(&m)?, fixed))
}

/// The parameters that enter the output linearly when the others are fixed: c and d^y of
/// state-space units (x does not depend on them), b and d of ARX units (for fixed A the
/// free-run output is linear in them; exactly so with input scheduling).
fn linear_columns(layout: &ParamLayout, structure: Structure) -> Vec<usize> {
    let keep = |n: &str| {
        let field = n.rsplit('.').next().unwrap_or("");
        if structure.is_state_space() {
            matches!(field, "c0" | "c1" | "dy")
        } else {
            field == "d" || (field.starts_with('b') && field[1..].parse::<usize>().is_ok())
        }
    };
    layout
        .names()
        .iter()
        .enumerate()
        .filter(|(_, n)| keep(n))
        .map(|(i, _)| i)
        .collect()
}
