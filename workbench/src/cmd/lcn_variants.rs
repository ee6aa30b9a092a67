//! `fes lcn-variants`: the pattern generator's loop variants side by side
//! (docs/control.md "Variants"). Every candidate reading of the thesis's loop (rise-time
//! rule, p3, the shaper's sum, the anti-windup rule, the state fed back) is a named
//! variant of the default; each is designed on the same model with the same rise times,
//! run on step references from rest, and its pattern drives the Ding muscle (and, with
//! `--plant-model`, a second model) outside the loop, as in Fig. 6.6(b). The table reports
//! per variant and level: pulses, the pattern's shape (convention 9), the mean force over
//! the second half in whole inter-pulse intervals (convention 11) in the loop, the plant
//! model and the muscle, and the RMS tracking error.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use fes_ident::analysis::osp::lcn::{StepScore, StepSettings, evaluate_step};
use fes_ident::analysis::osp::{ForceResponse, ModelResponse};
use fes_model::control::file::Controller;
use fes_model::control::lcn_design::UnitSpec;
use fes_model::control::poles::third_pole;
use fes_model::model::file;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::preset::Preset;
use sim_muscle::simulate::MuscleResponse;

use workbench::variant_args::{
    AntiWindupArg, FeedbackStateArg, RiseRuleArg, ShaperSumArg, ThirdPoleArg, VariantArgs,
};

use super::design::rise_times;
use super::inputs::{md_table, out_dir, parse_list, progress, write_csv};
use super::osp::MuscleArg;

/// One named variant: a change to the default loop.
struct Variant {
    name: &'static str,
    what: &'static str,
    apply: fn(&mut VariantArgs),
}

/// The variants, one candidate cause each, plus the thesis's and the previous default's
/// combinations.
const VARIANTS: &[Variant] = &[
    Variant {
        name: "default",
        what: "anti-windup none, clamped sum, advanced state, w_n t_r = 3.2, p3 = -1.9/Ts",
        apply: |_| {},
    },
    Variant {
        name: "legacy",
        what: "the default until 2026-12: anti-windup integral_sign, rise-time approximation",
        apply: |v| {
            v.anti_windup = AntiWindupArg::IntegralSign;
            v.rise_rule = RiseRuleArg::Approximation;
        },
    },
    Variant {
        name: "integral-sign",
        what: "anti-windup integral_sign",
        apply: |v| v.anti_windup = AntiWindupArg::IntegralSign,
    },
    Variant {
        name: "output-clamp",
        what: "anti-windup output_clamp (textbook conditional integration)",
        apply: |v| v.anti_windup = AntiWindupArg::OutputClamp,
    },
    Variant {
        name: "signed-sum",
        what: "the shaper sums the signed control signal, unbounded (eq. 6.8)",
        apply: |v| {
            v.shaper_sum = ShaperSumArg::Signed;
            v.e_min = None;
        },
    },
    Variant {
        name: "signed-sum-floor",
        what: "the signed sum with its energy floored at -eta",
        apply: |v| {
            v.shaper_sum = ShaperSumArg::Signed;
            v.e_min = Some(-1.0);
        },
    },
    Variant {
        name: "p3-mapped",
        what: "p3 = (exp(-1.9) - 1)/Ts (a continuous pole mapped)",
        apply: |v| v.third_pole_rule = ThirdPoleArg::Mapped,
    },
    Variant {
        name: "rise-approximation",
        what: "w_n = (2.16 xi + 0.6)/t_r",
        apply: |v| v.rise_rule = RiseRuleArg::Approximation,
    },
    Variant {
        name: "delayed-state",
        what: "the LCN feeds back x[k] (the delay in the loop)",
        apply: |v| v.feedback_state = FeedbackStateArg::Delayed,
    },
    Variant {
        name: "thesis",
        what: "every thesis reading: signed unbounded sum, no anti-windup, delayed state, p3 = -1.9/Ts",
        apply: thesis_loop,
    },
    Variant {
        name: "thesis-p3-mapped",
        what: "the thesis's loop with p3 = (exp(-1.9) - 1)/Ts (a continuous pole mapped)",
        apply: |v| {
            thesis_loop(v);
            v.third_pole_rule = ThirdPoleArg::Mapped;
        },
    },
];

/// The thesis's loop (6.5, C.2): plain integral action, the signed shaper sum (eq. 6.8),
/// the model state now fed back (Td = 0 assumed in the design), w_n t_r = 3.2 and
/// p3 = -1.9/Ts read in the delta domain. On a model of the undelayed scheduling class
/// (eq. 5.2) its gains are scheduled on phi(t) = Gamma{u(t)}.
fn thesis_loop(v: &mut VariantArgs) {
    v.shaper_sum = ShaperSumArg::Signed;
    v.e_min = None;
    v.anti_windup = AntiWindupArg::None;
    v.feedback_state = FeedbackStateArg::Delayed;
    v.rise_rule = RiseRuleArg::Thesis;
    v.third_pole_rule = ThirdPoleArg::Delta;
}

/// Arguments of `fes lcn-variants`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "Variants: default, legacy, integral-sign, output-clamp, signed-sum, \
    signed-sum-floor, p3-mapped, rise-approximation, delayed-state, thesis, \
    thesis-p3-mapped (see docs/control.md, \"Variants\"). On a model of the undelayed \
    scheduling class (eq. 5.2) only the delayed-state variants run; the others are listed \
    as not run.\n\nExamples:\n  fes lcn-variants --model models/slow.lmn.json --muscle \
    slow --rise-ms auto --out target/variants/slow\n  fes lcn-variants --model \
    models/thesis-fast.lmn.json --muscle thesis-fast --rise-ms 100,30,30,10,20,30 \
    --variants thesis,thesis-p3-mapped --out target/variants/thesis-fast"
)]
pub struct Args {
    /// The design model (fes-lmn/1, state space, every local model stable).
    #[arg(long)]
    pub model: PathBuf,
    /// The Ding muscle the patterns drive outside the loop (no fatigue, 7 ms delay).
    #[arg(long, value_enum)]
    pub muscle: MuscleArg,
    /// A second model the patterns drive outside the loop (thesis Fig. 6.11: the LMN with
    /// offsets in place of the muscle).
    #[arg(long)]
    pub plant_model: Option<PathBuf>,
    /// Rise time per unit, ms, comma-separated, or `auto` (as `fes design`).
    #[arg(long, default_value = "auto")]
    pub rise_ms: String,
    /// Damping factor xi of the dominant pair.
    #[arg(long, default_value_t = fes_model::control::lcn_design::THESIS_DAMPING)]
    pub damping: f64,
    /// Step reference levels (normalised force), comma-separated.
    #[arg(long, default_value = "0.1,0.15,0.2,0.3,0.5,0.7,0.9")]
    pub levels: String,
    /// Variants to run, comma-separated (default: all).
    #[arg(long, value_delimiter = ',')]
    pub variants: Vec<String>,
    /// Output directory: variants.md (the tables) and variants.csv (one row per variant and level).
    #[arg(long)]
    pub out: PathBuf,
}

/// A scored variant.
struct Scored {
    variant: &'static Variant,
    scores: Vec<StepScore>,
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    let lmn =
        file::load(&args.model).with_context(|| format!("model file {}", args.model.display()))?;
    let ts = lmn.ts;
    let tr = rise_times(&args.rise_ms, lmn.units())?;
    if !(args.damping.is_finite() && args.damping > 0.0) {
        bail!("--damping {}: must be a finite number > 0", args.damping);
    }
    let levels = parse_list("--levels", &args.levels)?;
    if let Some(l) = levels.iter().find(|l| !(**l > 0.0 && **l <= 1.0)) {
        bail!("--levels: {l} is outside (0, 1] (normalised force)");
    }
    let chosen: Vec<&'static Variant> = if args.variants.is_empty() {
        VARIANTS.iter().collect()
    } else {
        args.variants
            .iter()
            .map(|n| {
                VARIANTS
                    .iter()
                    .find(|v| v.name == n.trim())
                    .with_context(|| {
                        format!(
                            "--variants: unknown variant {n:?} (known: {})",
                            VARIANTS
                                .iter()
                                .map(|v| v.name)
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    })
            })
            .collect::<Result<_>>()?
    };
    let preset = Preset::from(args.muscle);
    let muscle =
        MuscleResponse::new(Muscle::new(MuscleConfig::preset(preset)).context("Ding muscle")?);
    let mut subjects: Vec<(String, Box<dyn ForceResponse>, f64)> = Vec::new();
    if let Some(p) = &args.plant_model {
        let m = file::load(p).with_context(|| format!("--plant-model {}", p.display()))?;
        let scale = m.force_scale_n / lmn.force_scale_n;
        subjects.push((
            "plant model".into(),
            Box::new(ModelResponse::new(&m)?),
            scale,
        ));
    }
    subjects.push((
        format!("Ding {}", preset.name()),
        Box::new(muscle),
        1.0 / lmn.force_scale_n,
    ));
    let settings = StepSettings::variant_table(ts);
    out_dir(&args.out)?;
    // The undelayed class (eq. 5.2) cannot be run ahead: only the delayed loop runs on it.
    let runs_ahead = lmn
        .network()
        .context("the model's network")?
        .can_run_ahead();
    let (chosen, not_run): (Vec<_>, Vec<_>) = chosen.into_iter().partition(|v| {
        let mut opts = VariantArgs::default();
        (v.apply)(&mut opts);
        runs_ahead || opts.feedback_state == FeedbackStateArg::Delayed
    });
    if chosen.is_empty() {
        bail!(
            "{}: the model's scheduling_input is undelayed (eq. 5.2); of the variants asked for, none feeds back the delayed state (try --variants thesis,delayed-state)",
            args.model.display()
        );
    }
    let bar = progress(chosen.len() * levels.len(), "LCN variants");
    let mut scored = Vec::new();
    for v in chosen {
        let mut opts = VariantArgs::default();
        (v.apply)(&mut opts);
        let p3 = third_pole(opts.third_pole_rule.into(), ts);
        let specs = UnitSpec::for_rise_times(&tr, args.damping, p3);
        let c = Controller::design(lmn.clone(), &specs, opts.settings())
            .with_context(|| format!("variant {}: design", v.name))?;
        let mut pg = c.pattern_generator().context("pattern generator")?;
        let refs: Vec<(&dyn ForceResponse, f64)> =
            subjects.iter().map(|(_, r, s)| (r.as_ref(), *s)).collect();
        let mut scores = Vec::new();
        for &level in &levels {
            let (_, score) = evaluate_step(&mut pg, level, &settings, &refs)
                .with_context(|| format!("variant {}, r = {level}", v.name))?;
            scores.push(score);
            bar.inc(1);
        }
        scored.push(Scored { variant: v, scores });
    }
    bar.finish_and_clear();
    let names: Vec<String> = subjects.iter().map(|(n, _, _)| n.clone()).collect();
    write_outputs(&args, &names, &settings, ts, &scored, &not_run)
}

/// Shape of a pattern in a few words (convention 9).
fn shape_words(s: &StepScore) -> String {
    match &s.shape {
        None => format!("{} pulse(s)", s.pulses.len()),
        Some(sh) if sh.is_doublet_pause_even() => {
            if sh.burst_pulses == 2 {
                "doublet, pause, even".into()
            } else {
                format!("{}-burst, pause, even", sh.burst_pulses)
            }
        }
        Some(sh) => {
            let open = if sh.has_burst {
                format!("{}-burst", sh.burst_pulses)
            } else {
                "single".into()
            };
            let limit = if s.short_ipis_after_opening(10) > 0 {
                ", burst limit cycle"
            } else {
                ""
            };
            let even = if sh.is_even { ", even" } else { ", not even" };
            format!("{open}{even}{limit}")
        }
    }
}

fn write_outputs(
    args: &Args,
    subjects: &[String],
    settings: &StepSettings,
    ts: f64,
    scored: &[Scored],
    not_run: &[&Variant],
) -> Result<()> {
    let ms = ts * 1e3;
    let half = settings.second_half();
    let last = subjects.len() - 1;
    let mut md = String::new();
    let _ = writeln!(md, "# LCN variants on {}\n", args.model.display());
    let _ = writeln!(
        md,
        "Step references from rest (step at {} ms, {} ms in all); means over the second half in whole inter-pulse intervals (convention 11), error of the {} against r; RMS of ({} - r) from the step on. Rise times {}, damping {}.\n",
        settings.onset as f64 * ms,
        settings.samples as f64 * ms,
        subjects[last],
        subjects[last],
        args.rise_ms,
        args.damping
    );
    if !not_run.is_empty() {
        let _ = writeln!(
            md,
            "Not run: {} (they act on the state d samples ahead, which a model of the undelayed scheduling class, eq. 5.2, cannot predict).\n",
            not_run
                .iter()
                .map(|v| format!("`{}`", v.name))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let mut csv = Vec::new();
    let mut summary = Vec::new();
    for s in scored {
        let _ = writeln!(md, "## `{}`: {}\n", s.variant.name, s.variant.what);
        let mut rows = Vec::new();
        let mut within = 0;
        for sc in &s.scores {
            let target = sc.subjects[last].mean;
            let err = (target - sc.level) / sc.level;
            if err.abs() <= 0.05 {
                within += 1;
            }
            rows.push(table_row(sc, err, ms, last));
            csv.push(csv_row(s.variant.name, sc, half, ms, last));
        }
        let mut header = vec!["r", "pulses", "first IPI (ms)", "shape"];
        let mean_head = format!("mean 2nd half: loop / {}", subjects.join(" / "));
        header.push(&mean_head);
        let err_head = format!("{} - r", subjects[last]);
        header.push(&err_head);
        header.push("RMS");
        header.push("min E");
        md.push_str(&md_table(&header, &rows));
        md.push('\n');
        summary.push(vec![
            format!("`{}`", s.variant.name),
            format!("{within} of {}", s.scores.len()),
            s.scores
                .iter()
                .filter(|x| x.short_ipis_after_opening(10) > 0)
                .map(|x| format!("{}", x.level))
                .collect::<Vec<_>>()
                .join(", "),
        ]);
    }
    let mut top = String::new();
    let _ = writeln!(top, "## Summary\n");
    top.push_str(&md_table(
        &["variant", "levels within 5 %", "burst limit cycle at r ="],
        &summary,
    ));
    top.push('\n');
    let text = {
        let split = md.find("## `").unwrap_or(md.len());
        format!("{}{}{}", &md[..split], top, &md[split..])
    };
    let path = args.out.join("variants.md");
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    write_csv(&args.out.join("variants.csv"), &CSV_HEADER, &csv)?;
    println!("variant table written to {}", path.display());
    Ok(())
}

/// The columns of `variants.csv`, one row per variant and level ([`csv_row`]).
const CSV_HEADER: [&str; 17] = [
    "variant",
    "reference",
    "pulses",
    "pulses_second_half",
    "first_ipi_ms",
    "burst_pulses",
    "pause_ms",
    "later_ipi_median_ms",
    "later_ipi_cv",
    "doublet_pause_even",
    "short_ipis_after_opening",
    "loop_mean",
    "plant_model_mean",
    "muscle_mean",
    "loop_rms",
    "muscle_rms",
    "min_energy",
];

/// One level's row of a variant's Markdown table; `err` is the last subject's relative
/// error against the level.
fn table_row(sc: &StepScore, err: f64, ms: f64, last: usize) -> Vec<String> {
    let means: Vec<String> = std::iter::once(format!("{:.3}", sc.loop_mean))
        .chain(sc.subjects.iter().map(|x| format!("{:.3}", x.mean)))
        .collect();
    vec![
        format!("{}", sc.level),
        sc.pulses.len().to_string(),
        sc.first_ipi()
            .map_or("-".into(), |i| format!("{}", i as f64 * ms)),
        shape_words(sc),
        means.join(" / "),
        format!("{:+.1} %", 100.0 * err),
        format!("{:.3}", sc.subjects[last].rms),
        format!("{:.2}", sc.min_energy),
    ]
}

/// One level's row of `variants.csv` ([`CSV_HEADER`]).
fn csv_row(variant: &str, sc: &StepScore, half: usize, ms: f64, last: usize) -> Vec<String> {
    let sh = sc.shape.as_ref();
    let or_empty = |v: Option<String>| v.unwrap_or_default();
    vec![
        variant.to_string(),
        format!("{}", sc.level),
        sc.pulses.len().to_string(),
        sc.pulses_from(half).to_string(),
        or_empty(sc.first_ipi().map(|i| format!("{}", i as f64 * ms))),
        or_empty(sh.map(|x| x.burst_pulses.to_string())),
        or_empty(
            sh.and_then(|x| x.pause)
                .map(|p| format!("{}", p as f64 * ms)),
        ),
        or_empty(
            sh.and_then(|x| x.steady_median)
                .map(|m| format!("{}", m * ms)),
        ),
        or_empty(sh.and_then(|x| x.steady_cv).map(|c| format!("{c}"))),
        sh.is_some_and(|x| x.is_doublet_pause_even()).to_string(),
        sc.short_ipis_after_opening(10).to_string(),
        format!("{}", sc.loop_mean),
        or_empty(
            sc.subjects
                .first()
                .filter(|_| last > 0)
                .map(|x| format!("{}", x.mean)),
        ),
        format!("{}", sc.subjects[last].mean),
        format!("{}", sc.loop_rms),
        format!("{}", sc.subjects[last].rms),
        format!("{}", sc.min_energy),
    ]
}
