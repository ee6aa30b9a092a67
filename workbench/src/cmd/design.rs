//! `fes design`: the Local Controller Network of a model by pole placement (thesis
//! 6.5.3, App. C.2), one local controller per unit from a rise time and a damping factor;
//! prints the layout of Tables 6.1 / 6.2 and writes the controller file `fes-lcn/1`.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use fes_model::control::design::EstimatorPoles;
use fes_model::control::file::Controller;
use fes_model::control::lcn_design::{THESIS_DAMPING, UnitSpec};
use fes_model::control::pattern_generator::{FeedbackMode, FeedbackState};
use fes_model::control::planner::{LambdaScale, PlanningConfig};
use fes_model::control::poles::{Pole, dominant_pair, third_pole};
use fes_model::model::file;

use super::inputs::{md_table, parse_list};
use workbench::variant_args::VariantArgs;

/// `--rise-ms auto` spreads the rise times evenly over this interval, ms (Table 6.2).
pub const AUTO_RISE_MS: (f64, f64) = (30.0, 200.0);

/// Arguments of `fes design`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model file (fes-lmn/1; every local model must be stable).
    #[arg(long)]
    pub model: PathBuf,
    /// Closed-loop rise time per unit, ms, comma-separated in unit order (Table 6.1:
    /// 100,30,30,10,20,30), or `auto`: evenly spaced from 30 to 200 ms over the units, as
    /// Table 6.2, or `auto:LO-HI`: evenly spaced from LO to HI ms (the shipped controllers:
    /// auto:12-160 fast, auto:80-200 slow; models/README.md).
    #[arg(long)]
    pub rise_ms: String,
    /// Damping factor xi of the dominant pair (1.2: no overshoot, thesis 6.5.3).
    #[arg(long, default_value_t = THESIS_DAMPING)]
    pub damping: f64,
    /// Third (integrator) pole, delta domain, 1/s (default: --third-pole-rule).
    #[arg(long, allow_negative_numbers = true)]
    pub third_pole: Option<f64>,
    /// The loop variant.
    #[command(flatten)]
    pub variant: VariantArgs,
    /// Design even for units with a negative local steady-state gain (thesis 6.5.3 explains
    /// why the loop then switches between neighbouring controllers).
    #[arg(long)]
    pub allow_negative_gain: bool,
    /// Shortest interval between two pulses, ms (the pulse shaper's `min_gap` + 1 samples;
    /// thesis: 2 at Ts = 1 ms). A transport that delivers one command at a time needs its
    /// answer time here: a RehaStim 2 over ScienceMode 2 answers in under 20 ms on average
    /// (its driver's `[transport] min_interval_ms`, which refuses to arm a generator with a
    /// shorter interval). The plan and the causal loop both keep it.
    #[arg(long, default_value_t = 2.0, value_name = "MS")]
    pub min_interval_ms: f64,
    /// Pulse decisions: `receding-horizon` plans each contraction the reference preview
    /// announces over the model (docs/control.md, section 11), `off` leaves every pulse to
    /// the causal LCN + shaper. Default: receding-horizon with --feedback-state advanced,
    /// off with delayed (the plan's warm start runs the advanced loop).
    #[arg(long, value_enum)]
    pub planning: Option<PlanningArg>,
    /// Price of a pulse in the plan's objective, in summed squared error (normalised force
    /// squared over 1 ms ticks): higher, fewer pulses.
    #[arg(long, default_value_t = PlanningConfig::RECOMMENDED.lambda)]
    pub plan_lambda: f64,
    /// How --plan-lambda prices a pulse: `level` (times the contraction's level, the
    /// default: measured to beat every constant train at 0.1-0.9 on the fast muscle) or
    /// `fixed` (the same at every level, eq. 6.4's constant weight).
    #[arg(long, value_enum, default_value_t = LambdaScaleArg::Level)]
    pub plan_lambda_scale: LambdaScaleArg,
    /// Weight of the plateau's mean error in the plan's objective (0: none; the outer loop
    /// then hunts between pulse counts).
    #[arg(long, default_value_t = PlanningConfig::RECOMMENDED.mean_weight)]
    pub plan_mean_weight: f64,
    /// Price of each pulse a contraction has more or fewer than the last one (0: none).
    #[arg(long, default_value_t = PlanningConfig::RECOMMENDED.count_change)]
    pub plan_count_change: f64,
    /// Shortest interval between two planned pulses after the opening burst, ms (0: no
    /// such rule). The thesis's patterns open with a doublet or triplet and go on evenly;
    /// on a muscle with a catch-like effect a close pair later in the contraction is where
    /// a fatiguing muscle departs most from the model (docs/control.md, section 11: the
    /// shipped fast controller uses 15).
    #[arg(long, default_value_t = PlanningConfig::RECOMMENDED.burst_ipi_ms, value_name = "MS")]
    pub plan_burst_ipi_ms: f64,
    /// Lowest contraction level that may open with a burst (0: every level); below it no
    /// two planned pulses come closer than --plan-burst-ipi-ms at all. The opening doublet
    /// buys a high level's fast rise; at low levels a fatiguing muscle answers it above the
    /// model (docs/control.md, section 11, "Bursts by level": the shipped fast controller
    /// uses 0.35).
    #[arg(long, default_value_t = PlanningConfig::RECOMMENDED.burst_min_level, value_name = "LEVEL")]
    pub plan_burst_min_level: f64,
    /// Wall-clock planning budget per tick in rt-core, us.
    #[arg(long, default_value_t = PlanningConfig::RECOMMENDED.budget_us)]
    pub plan_budget_us: f64,
    /// Which signal closes the loop: `model` (Fig. 6.6(b): the model alone, no sensor) or
    /// `measured-force` (Fig. 6.6(a): a force sensor corrects the model state through a
    /// local estimator, eq. C.18, and drives the integral action; plans start from the
    /// corrected state).
    #[arg(long, value_enum, default_value_t = FeedbackArg::Model)]
    pub feedback: FeedbackArg,
    /// Rise time of the estimator's pole pair (damping 1.2), ms; with --feedback
    /// measured-force. Faster corrects the model sooner and passes more sensor noise (C.2.2).
    #[arg(long, default_value_t = 5.0, value_name = "MS")]
    pub estimator_rise_ms: f64,
    /// The controller file to write.
    #[arg(long)]
    pub out: PathBuf,
}

/// `--feedback`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FeedbackArg {
    /// The model closes the loop (thesis Fig. 6.6(b)).
    Model,
    /// The measured force corrects the model through the estimator (thesis Fig. 6.6(a)).
    MeasuredForce,
}

/// `--planning`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PlanningArg {
    /// The causal LCN + shaper decide every pulse.
    Off,
    /// Receding-horizon pulse decisions over the reference preview.
    RecedingHorizon,
}

/// `--plan-lambda-scale`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LambdaScaleArg {
    /// The same price at every level (eq. 6.4's constant weight).
    Fixed,
    /// The price times the contraction's level.
    Level,
}

/// The planner's settings from the `--plan-*` options, the rest as recommended.
fn planning_config(args: &Args) -> PlanningConfig {
    PlanningConfig {
        lambda: args.plan_lambda,
        lambda_scale: match args.plan_lambda_scale {
            LambdaScaleArg::Fixed => LambdaScale::Fixed,
            LambdaScaleArg::Level => LambdaScale::Level,
        },
        mean_weight: args.plan_mean_weight,
        count_change: args.plan_count_change,
        burst_ipi_ms: args.plan_burst_ipi_ms,
        burst_min_level: args.plan_burst_min_level,
        budget_us: args.plan_budget_us,
        ..PlanningConfig::RECOMMENDED
    }
}

/// Rise times in seconds, one per unit, from `--rise-ms` (a list or `auto`).
pub fn rise_times(text: &str, units: usize) -> Result<Vec<f64>> {
    let text = text.trim();
    if let Some(range) = text.strip_prefix("auto") {
        let (lo, hi) = if range.is_empty() {
            AUTO_RISE_MS
        } else {
            let bad = || {
                anyhow::anyhow!(
                    "--rise-ms {text}: write auto, or auto:LO-HI with 0 < LO <= HI in ms (e.g. auto:12-160)"
                )
            };
            let (a, b) = range
                .strip_prefix(':')
                .and_then(|r| r.split_once('-'))
                .ok_or_else(bad)?;
            let (lo, hi): (f64, f64) = (
                a.trim().parse().map_err(|_| bad())?,
                b.trim().parse().map_err(|_| bad())?,
            );
            if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
                return Err(bad());
            }
            (lo, hi)
        };
        return Ok((0..units)
            .map(|i| {
                let f = if units > 1 {
                    i as f64 / (units - 1) as f64
                } else {
                    0.0
                };
                (lo + (hi - lo) * f) * 1e-3
            })
            .collect());
    }
    let ms = parse_list("--rise-ms", text)?;
    if ms.len() != units {
        bail!(
            "--rise-ms gives {} rise time(s) but the model has {units} units: give one per unit, in unit order",
            ms.len()
        );
    }
    if let Some((i, v)) = ms.iter().enumerate().find(|(_, v)| **v <= 0.0) {
        bail!("--rise-ms: rise time of unit {i} is {v} ms; rise times must be > 0");
    }
    Ok(ms.iter().map(|v| v * 1e-3).collect())
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let lmn = match file::load(&args.model) {
        Ok(lmn) => lmn,
        Err(e) => {
            // Say so when only the stability requirement fails.
            if let Ok((_, st)) = file::load_allow_unstable(&args.model) {
                let bad: Vec<usize> = st.iter().filter(|s| !s.stable).map(|s| s.unit).collect();
                if bad.is_empty() {
                    return Err(e).with_context(|| format!("model file {}", args.model.display()));
                }
                bail!(
                    "model file {}: {e}\nthe model is unstable (units {bad:?}); a controller needs every local model stable: repair it with `fes modify --stabilise`",
                    args.model.display()
                );
            }
            return Err(e).with_context(|| format!("model file {}", args.model.display()));
        }
    };
    let units = lmn.units();
    let Some(local) = lmn.ss_units() else {
        bail!(
            "model {}: structure {} has ARX local models; the LCN needs state-space local models (ss-direct, ss-eig-local, ss-eig-common)",
            args.model.display(),
            lmn.structure()
        );
    };
    let tr = rise_times(&args.rise_ms, units)?;
    if !(args.damping.is_finite() && args.damping > 0.0) {
        bail!("--damping {}: must be a finite number > 0", args.damping);
    }
    let p3 = match args.third_pole {
        Some(p) => Pole::real(p),
        None => third_pole(args.variant.third_pole_rule.into(), lmn.ts),
    };
    // Every negative local gain at once (the library reports the first only).
    let negative: Vec<String> = local
        .iter()
        .enumerate()
        .filter_map(|(i, m)| {
            m.gain()
                .filter(|g| *g < 0.0)
                .map(|g| format!("unit {i}: G = {g:.4}"))
        })
        .collect();
    if !negative.is_empty() && !args.allow_negative_gain {
        bail!(
            "the model's offsets give negative local steady-state gains G = -c'A^-1 b ({}). \
             An LCN whose units mix negative- and positive-gain controllers switches back and \
             forth between them and never settles (thesis 6.5.3). Identify the model with the \
             offsets fixed at zero (`fes identify --zero-offsets`), which keeps every \
             local gain non-negative, or pass --allow-negative-gain to design anyway",
            negative.join(", ")
        );
    }
    let specs = UnitSpec::for_rise_times(&tr, args.damping, p3);
    let mut settings = args.variant.settings();
    settings.shaper.min_gap = min_gap(args.min_interval_ms, lmn.ts)?;
    settings.design.allow_negative_gain = args.allow_negative_gain;
    if args.feedback == FeedbackArg::MeasuredForce {
        let tr = args.estimator_rise_ms;
        if !(tr.is_finite() && tr > 0.0) {
            bail!("--estimator-rise-ms {tr}: must be a finite number > 0");
        }
        let [p1, p2] = dominant_pair(tr * 1e-3, THESIS_DAMPING, lmn.ts)
            .with_context(|| format!("estimator poles for a {tr} ms rise time"))?;
        settings.mode = FeedbackMode::MeasuredForce;
        settings.estimator_poles = Some(EstimatorPoles { p1, p2 });
    }
    let planning = args.planning.unwrap_or(match settings.feedback_state {
        FeedbackState::Advanced => PlanningArg::RecedingHorizon,
        FeedbackState::Delayed => PlanningArg::Off,
    });
    if planning == PlanningArg::RecedingHorizon {
        settings.planning = planning_config(&args);
    }
    let ts = lmn.ts;
    let controller = Controller::design(lmn, &specs, settings)
        .with_context(|| format!("designing the LCN for {}", args.model.display()))?;
    println!("{}", table(&controller, ts));
    if !negative.is_empty() {
        eprintln!(
            "WARNING: designed with negative local gains ({}), as --allow-negative-gain asked",
            negative.join(", ")
        );
    }
    controller
        .save(&args.out)
        .with_context(|| format!("writing {}", args.out.display()))?;
    println!("controller written to {}", args.out.display());
    Ok(())
}

/// The pulse shaper's `min_gap` (empty samples after a pulse) for pulses at least
/// `interval_ms` apart at the model's period `ts` (s): the interval in whole samples, less
/// the pulse's own.
pub fn min_gap(interval_ms: f64, ts: f64) -> Result<u32> {
    // (Less a rounding error's worth, so that 20 ms at 1 ms is 20 samples, not 21.)
    let samples = (interval_ms * 1e-3 / ts - 1e-9).ceil();
    if !(interval_ms.is_finite() && (2.0..=1000.0).contains(&samples)) {
        bail!(
            "--min-interval-ms {interval_ms}: must span 2 to 1000 model samples of {} ms (a pulse and at least one empty sample)",
            ts * 1e3
        );
    }
    Ok(samples as u32 - 1)
}

/// Tables 6.1 / 6.2: one column per unit.
fn table(c: &Controller, ts: f64) -> String {
    let mut header = vec!["unit".to_string()];
    header.extend((1..=c.units.len()).map(|i| i.to_string()));
    let row = |name: &str, f: &dyn Fn(usize) -> String| {
        let mut r = vec![name.to_string()];
        r.extend((0..c.units.len()).map(f));
        r
    };
    let pole = |p: Pole| {
        if p.im == 0.0 {
            format!("{:.1}", p.re)
        } else {
            format!("{:.1}{:+.1}i", p.re, p.im)
        }
    };
    let u = &c.units;
    let rows = vec![
        row("t_r [ms]", &|i| {
            format!("{:.1}", u[i].spec.rise_time_s * 1e3)
        }),
        row("p_1", &|i| pole(u[i].poles.p1)),
        row("p_2", &|i| pole(u[i].poles.p2)),
        row("p_3", &|i| pole(u[i].poles.p3)),
        row("K_x,1", &|i| format!("{:.4}", u[i].gains.k_x[0])),
        row("K_x,2", &|i| format!("{:.4}", u[i].gains.k_x[1])),
        row("K_I", &|i| format!("{:.2}", u[i].gains.k_i)),
    ];
    let h: Vec<&str> = header.iter().map(String::as_str).collect();
    format!(
        "LCN design (delta domain, Ts = {} ms, damping {}; poles in 1/s)\n\n{}",
        ts * 1e3,
        u.first().map_or(0.0, |x| x.spec.damping),
        md_table(&h, &rows)
    )
}
