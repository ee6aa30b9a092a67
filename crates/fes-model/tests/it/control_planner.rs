//! The receding-horizon planner (docs/control.md, section 11): planning off is the causal
//! loop bit for bit; with a preview the plan is never worse on the model than any
//! constant-frequency train with no more pulses; pulses stay inside the contraction and
//! the minimum interval; an expired deadline leaves the causal decisions; decisions are
//! deterministic; a changed preview replans.

use super::control_support::{TS, fast_muscle, table_6_1_specs};
use fes_model::control::file::{Controller, ControllerSettings};
use fes_model::control::pattern_generator::{PatternGenerator, TickInput, TickOutput};
use fes_model::control::planner::{
    Deadline, LambdaScale, PlanningConfig, PlanningConfigError, train_times,
};
use fes_model::control::preview::{Preview, PreviewPoint, slew};
use fes_model::model::AdvancedForm;

/// A cardiac reference: contractions of `on` ticks every `period`, at `level`, edges at
/// `rate` per second, as the supervisor schedules them and rt-core's tracker ramps them.
#[derive(Clone, Copy)]
struct Cardiac {
    period: usize,
    on: usize,
    level: f64,
    rate: f64,
}

impl Cardiac {
    fn setpoint(&self, k: usize) -> f64 {
        if k % self.period < self.on {
            self.level
        } else {
            0.0
        }
    }

    /// The preview at tick `k`: the setpoint now, then the next four edges.
    fn preview(&self, k: usize) -> Preview {
        let mut points = vec![PreviewPoint {
            at: 0,
            force: self.setpoint(k),
            rate_per_s: self.rate,
        }];
        let start = k - k % self.period;
        for edge in [
            start + self.on,
            start + self.period,
            start + self.period + self.on,
            start + 2 * self.period,
        ] {
            if edge > k {
                points.push(PreviewPoint {
                    at: (edge - k) as u32,
                    force: self.setpoint(edge),
                    rate_per_s: self.rate,
                });
            }
        }
        Preview::new(&points).unwrap()
    }

    /// The tracker's targets over `n` ticks.
    fn targets(&self, n: usize) -> Vec<f64> {
        let mut r = 0.0;
        (0..n)
            .map(|k| {
                r = slew(r, self.setpoint(k), self.rate, TS);
                r
            })
            .collect()
    }
}

const CARDIAC: Cardiac = Cardiac {
    period: 800,
    on: 320,
    level: 0.3,
    rate: 50.0,
};

fn controller(planning: PlanningConfig) -> Controller {
    let settings = ControllerSettings {
        planning,
        ..ControllerSettings::default()
    };
    Controller::design(fast_muscle(6), &table_6_1_specs(6), settings).unwrap()
}

fn planning() -> PlanningConfig {
    PlanningConfig::RECOMMENDED
}

/// Runs `n` ticks of the cardiac reference, with its preview when `preview` is set.
fn run(pg: &mut PatternGenerator, c: Cardiac, n: usize, preview: bool) -> Vec<TickOutput> {
    let r = c.targets(n);
    (0..n)
        .map(|k| {
            pg.tick(&TickInput {
                reference: r[k],
                measured_force: None,
                resting: c.setpoint(k) == 0.0,
                preview: if preview { c.preview(k) } else { Preview::NONE },
            })
        })
        .collect()
}

fn pulses(out: &[TickOutput]) -> Vec<usize> {
    out.iter()
        .enumerate()
        .filter(|(_, o)| o.pulse)
        .map(|(k, _)| k)
        .collect()
}

#[test]
fn planning_off_and_no_preview_are_the_causal_loop_bit_for_bit() {
    let causal = run(
        &mut controller(PlanningConfig::default())
            .pattern_generator()
            .unwrap(),
        CARDIAC,
        3000,
        true,
    );
    assert!(pulses(&causal).len() > 10);
    // Planning on, but nothing announced ahead: the planner never decides.
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let blind = run(&mut pg, CARDIAC, 3000, false);
    assert_eq!(causal, blind);
    assert_eq!(pg.stats().planner.planned_ticks, 0);
    // Planning off ignores the preview.
    let off = run(
        &mut controller(PlanningConfig::default())
            .pattern_generator()
            .unwrap(),
        CARDIAC,
        3000,
        false,
    );
    assert_eq!(causal, off);
}

/// The objective of docs/control.md section 11 over the second beat, computed here from
/// the model alone (not by the planner): the network runs the first beat's pulses as
/// fired, then `beat2` (ticks from the second onset); the core output against the
/// targets over the second beat, plus the plateau's mean error term.
fn objective(
    c: &Controller,
    r: &[f64],
    beat1: &[usize],
    beat2: &[usize],
    cfg: &PlanningConfig,
) -> f64 {
    let mut core = AdvancedForm::new(c.network).unwrap();
    let p = CARDIAC.period;
    let (a, b) = (p, p + CARDIAC.on);
    let pa = a + (cfg.plateau_start * (b - a) as f64) as usize;
    let (mut sq, mut plateau) = (0.0, 0.0);
    for (k, &rk) in r.iter().enumerate().take(2 * p) {
        let fire = if k < p {
            beat1.contains(&k)
        } else {
            beat2.contains(&(k - p))
        };
        let y = core.step(if fire { 1.0 } else { 0.0 }).y_ahead;
        if k >= p {
            let e = y - rk;
            sq += e * e;
            if k >= pa && k < b {
                plateau += e;
            }
        }
    }
    let np = (b - pa) as f64;
    sq + cfg.mean_weight * plateau * plateau / np + cfg.lambda * beat2.len() as f64
}

#[test]
fn the_plan_beats_every_train_with_no_more_pulses_on_the_model() {
    for level in [0.1, 0.3, 0.6] {
        let c = Cardiac { level, ..CARDIAC };
        let cfg = planning();
        let ctl = controller(cfg);
        let mut pg = ctl.pattern_generator().unwrap();
        // The second beat: planned in the rest after the first, from its preview.
        let p = c.period;
        let out = run(&mut pg, c, 2 * p, true);
        let fired = pulses(&out);
        let beat1: Vec<usize> = fired.iter().copied().filter(|&k| k < p).collect();
        let plan: Vec<usize> = fired.iter().filter(|&&k| k >= p).map(|k| k - p).collect();
        let r = c.targets(2 * p);
        let j_plan = objective(&ctl, &r, &beat1, &plan, &cfg);
        assert!(!plan.is_empty(), "level {level}: no pulse");
        let mut compared = 0;
        for hz in cfg.min_hz..=cfg.max_hz {
            let mut t = [0u16; 128];
            let all = train_times(hz, TS, 0, c.on, &mut t);
            for n in 1..=all {
                let train: Vec<usize> = t[..n].iter().map(|&x| x as usize).collect();
                let j = objective(&ctl, &r, &beat1, &train, &cfg);
                assert!(
                    j_plan <= j + 1e-9,
                    "level {level}: the plan {plan:?} (J {j_plan}) is worse on the model than \
                     {hz} Hz x {n} (J {j})"
                );
                compared += usize::from(n <= plan.len());
            }
        }
        assert!(compared > 50, "level {level}: {compared} trains compared");
        let stats = pg.stats().planner;
        assert!(
            stats.planned_ticks >= 2 * c.on as u64 - 100,
            "level {level}: {stats:?}"
        );
    }
}

#[test]
fn planned_pulses_stay_in_the_contraction_and_the_minimum_interval() {
    for level in [0.2, 0.5, 0.9] {
        let c = Cardiac { level, ..CARDIAC };
        let mut pg = controller(planning()).pattern_generator().unwrap();
        let out = run(&mut pg, c, 4000, true);
        let p = pulses(&out);
        assert!(p.len() > 8, "level {level}: {p:?}");
        for w in p.windows(2) {
            assert!(
                w[1] - w[0] >= 2,
                "level {level}: IPI {} ms at {}",
                w[1] - w[0],
                w[0]
            );
        }
        for &k in &p {
            assert!(
                c.setpoint(k) > 0.0,
                "level {level}: a pulse at rest, tick {k}"
            );
        }
        assert!(out.iter().skip(100).filter(|o| o.pulse).all(|o| o.planned));
        let s = pg.stats().planner;
        // Five contractions run, and the sixth (at 4000) already planned.
        assert_eq!(s.windows, 6, "{s:?}");
        assert_eq!(s.replans, 0, "{s:?}");
        assert!(s.converged >= 4, "{s:?}");
    }
}

#[test]
fn decisions_are_deterministic() {
    let a = run(
        &mut controller(planning()).pattern_generator().unwrap(),
        CARDIAC,
        2500,
        true,
    );
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let b = run(&mut pg, CARDIAC, 2500, true);
    assert_eq!(a, b);
    pg.reset();
    let c = run(&mut pg, CARDIAC, 2500, true);
    assert_eq!(a, c);
}

/// The price scaled by the level is the fixed price of the level's size, contraction by
/// contraction: at 0.3, `lambda` 1.0 by level decides every pulse as a fixed 0.3 does, and
/// differently from a fixed 1.0 (so the scale is applied, not ignored).
#[test]
fn a_price_by_level_is_the_fixed_price_of_that_level() {
    let with = |lambda, lambda_scale| {
        let cfg = PlanningConfig {
            lambda,
            lambda_scale,
            ..planning()
        };
        pulses(&run(
            &mut controller(cfg).pattern_generator().unwrap(),
            CARDIAC,
            2500,
            true,
        ))
    };
    let by_level = with(1.0, LambdaScale::Level);
    assert_eq!(by_level, with(CARDIAC.level, LambdaScale::Fixed));
    assert_ne!(by_level, with(1.0, LambdaScale::Fixed));
}

/// A deadline that has always expired.
struct Expired;

impl Deadline for Expired {
    fn expired(&mut self) -> bool {
        true
    }
}

#[test]
fn an_expired_deadline_leaves_every_decision_to_the_causal_loop() {
    let causal = run(
        &mut controller(PlanningConfig::default())
            .pattern_generator()
            .unwrap(),
        CARDIAC,
        2000,
        true,
    );
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let r = CARDIAC.targets(2000);
    let late: Vec<TickOutput> = (0..2000)
        .map(|k| {
            pg.tick_within(
                &TickInput {
                    reference: r[k],
                    measured_force: None,
                    resting: CARDIAC.setpoint(k) == 0.0,
                    preview: CARDIAC.preview(k),
                },
                &mut Expired,
            )
        })
        .collect();
    assert_eq!(pulses(&causal), pulses(&late));
    let s = pg.stats().planner;
    assert_eq!(s.planned_ticks, 0, "{s:?}");
    assert!(s.deadline_cuts > 1000, "{s:?}");
    assert!(s.causal_fallbacks > 500, "{s:?}");
}

#[test]
fn a_changed_level_replans_the_contraction() {
    // The beat at 1600 is announced at 0.3 until tick 1300, when the outer loop moves it
    // to 0.5 (in the rest before it).
    let (low, high) = (
        CARDIAC,
        Cardiac {
            level: 0.5,
            ..CARDIAC
        },
    );
    let (r_low, r_high) = (low.targets(2000), high.targets(2000));
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let out: Vec<TickOutput> = (0..2000)
        .map(|k| {
            let (c, r) = if k < 1300 {
                (low, &r_low)
            } else {
                (high, &r_high)
            };
            pg.tick(&TickInput {
                reference: r[k],
                measured_force: None,
                resting: c.setpoint(k) == 0.0,
                preview: c.preview(k),
            })
        })
        .collect();
    let s = pg.stats().planner;
    assert_eq!(s.replans, 1, "{s:?}");
    assert_eq!(s.causal_fallbacks, 0, "{s:?}");
    // The higher level gets more pulses than the beats before it.
    let count = |from: usize| out[from..from + 320].iter().filter(|o| o.pulse).count();
    assert!(
        count(1600) > count(800),
        "{} vs {}",
        count(1600),
        count(800)
    );
}

#[test]
fn an_edge_announced_a_tick_early_or_late_is_the_same_contraction() {
    // rt-core converts the supervisor's announced times to ticks on a clock that jitters
    // by tens of microseconds, so an edge may be announced a tick either way from one tick
    // to the next. That is the contraction already planned, not a new one: no replan.
    let c = CARDIAC;
    let r = c.targets(2400);
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let mut jitter = 0x2545_f491_u32;
    for (k, &rk) in r.iter().enumerate() {
        let exact = c.preview(k);
        let points: Vec<PreviewPoint> = exact
            .points()
            .iter()
            .map(|p| {
                jitter ^= jitter << 13;
                jitter ^= jitter >> 17;
                jitter ^= jitter << 5;
                let at = match (p.at, jitter % 3) {
                    (0, _) | (_, 0) => p.at,
                    (at, 1) => at + 1,
                    (at, _) if at > 1 => at - 1,
                    (at, _) => at,
                };
                PreviewPoint { at, ..*p }
            })
            .collect();
        let mut preview = Preview::new(&points);
        if preview.is_err() {
            preview = Ok(exact);
        }
        pg.tick(&TickInput {
            reference: rk,
            measured_force: None,
            resting: c.setpoint(k) == 0.0,
            preview: preview.unwrap(),
        });
    }
    // One window for the first contraction (unannounced, at tick 0), then one for each
    // next contraction, planned as the previous one ends: 4 in three beats, none replanned.
    let s = pg.stats().planner;
    assert_eq!(s.windows, 4, "{s:?}");
    assert_eq!(s.replans, 0, "{s:?}");
}

/// Runs `n` ticks of the cardiac reference with its preview; at tick `stall` the caller
/// stalls for `periods` periods (the ticks after it are not run: the next call is at
/// `stall + periods + 1`, told of the periods skipped), as rt-core does when its thread
/// wakes late. Returns the ticks that fired.
fn run_with_stall(
    pg: &mut PatternGenerator,
    c: Cardiac,
    n: usize,
    stall: usize,
    periods: usize,
) -> Vec<usize> {
    let r = c.targets(n);
    let input = |k: usize| TickInput {
        reference: r[k],
        measured_force: None,
        resting: c.setpoint(k) == 0.0,
        preview: c.preview(k),
    };
    let mut fired = Vec::new();
    let mut k = 0;
    while k < n {
        if k == stall + 1 {
            k += periods;
            pg.missed(periods as u32, &input(k));
        }
        if pg.tick(&input(k)).pulse {
            fired.push(k);
        }
        k += 1;
    }
    fired
}

#[test]
fn a_stall_at_rest_leaves_the_plan_on_the_schedule() {
    // A 6 ms stall 400 ms before an onset (rt-core's thread preempted on a loaded host).
    // The planner counts wall-clock ticks, so the contraction announced is still the one
    // planned: no replan, and every pulse after the stall is where it would have been.
    // (Counting calls put the plan six ticks late, the announced edges then moved by six
    // and each such stall restarted the search: on the process bench one beat in ten lost
    // its onset pulse and fired one at the contraction's end.)
    let c = CARDIAC;
    let n = 3 * c.period;
    let calm = run(
        &mut controller(planning()).pattern_generator().unwrap(),
        c,
        n,
        true,
    );
    let calm = pulses(&calm);
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let stalled = run_with_stall(&mut pg, c, n, c.period + 397, 6);
    assert_eq!(stalled, calm);
    let s = pg.stats().planner;
    assert_eq!((s.replans, s.skipped_ticks), (0, 6), "{s:?}");
}

/// The ticks that fired in `n` ticks of `c` with the shipped planning and no stall.
fn calm_pulses(c: Cardiac, n: usize) -> Vec<usize> {
    pulses(&run(
        &mut controller(planning()).pattern_generator().unwrap(),
        c,
        n,
        true,
    ))
}

#[test]
fn a_plateau_pulse_lost_in_a_stall_is_fired_late_not_left_out() {
    // A 6-period stall over a planned pulse in the middle of the third contraction's
    // plateau: the pulse is moved to the first tick after the stall (the plan's count is
    // kept), so the contraction gets as many pulses as the calm run's and its later pulses
    // are the calm run's within a few ticks. Left out, the contraction lost a pulse (on
    // the process bench a 5 ms stall took a beat to 5 of its 6 pulses and 38 % under the
    // level).
    let c = CARDIAC;
    let n = 4 * c.period;
    let onset = 2 * c.period;
    let calm = calm_pulses(c, n);
    let in_third = |v: &[usize]| {
        v.iter()
            .copied()
            .filter(|&k| (onset..onset + c.period).contains(&k))
            .collect::<Vec<_>>()
    };
    let third = in_third(&calm);
    let target = *third
        .iter()
        .find(|&&k| k > onset + 60 && k + 60 < onset + c.on)
        .expect("a plateau pulse");
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let stall = target - 3;
    let stalled = run_with_stall(&mut pg, c, n, stall, 6);
    let s = pg.stats().planner;
    assert_eq!((s.replans, s.skipped_ticks), (0, 6), "{s:?}");
    assert!(s.rebased >= 1, "{s:?}");
    let after = in_third(&stalled);
    assert_eq!(
        after.len(),
        third.len(),
        "calm {third:?}, stalled {after:?}"
    );
    let first_after = *after.iter().find(|&&k| k > stall).unwrap();
    assert!(
        first_after <= stall + 6 + 3,
        "the lost pulse at {target} came at {first_after}: {after:?}"
    );
}

#[test]
fn a_pulse_lost_in_a_stall_is_planned_around_without_a_replan() {
    // A stall over the onset of the third contraction swallows its planned first pulse:
    // no replan (the schedule has not moved), the plan goes on from the state reached
    // (a rebase), nothing fires in the stall, every tick of the contraction after it is
    // decided by the plan, and the next contraction is planned on schedule.
    let c = CARDIAC;
    let n = 4 * c.period;
    let onset = 2 * c.period;
    let calm = calm_pulses(c, n);
    assert!(
        calm.contains(&onset),
        "the calm plan fires at the onset: {calm:?}"
    );
    let mut pg = controller(planning()).pattern_generator().unwrap();
    let stall = onset - 3;
    let stalled = run_with_stall(&mut pg, c, n, stall, 6);
    let s = pg.stats().planner;
    assert_eq!(
        (s.replans, s.causal_fallbacks, s.skipped_ticks),
        (0, 0, 6),
        "{s:?}"
    );
    assert!(s.rebased >= 1, "{s:?}");
    assert!(
        !stalled.iter().any(|&k| k > stall && k <= stall + 6),
        "{stalled:?}"
    );
    let before = |v: &[usize]| {
        v.iter()
            .copied()
            .filter(|&k| k <= stall)
            .collect::<Vec<_>>()
    };
    assert_eq!(before(&stalled), before(&calm));
    let next = onset + c.period;
    assert!(stalled.contains(&next), "the next onset fires: {stalled:?}");
    assert!(stalled.iter().all(|&k| k % c.period < c.on), "{stalled:?}");
}

/// The burst settings out of range are refused, each with its own error: `burst_ipi_ms`
/// outside [0, 1000] ms (negative, not finite, longer than any horizon), `burst_min_level`
/// negative or not finite; 0 (no rule) and the shipped values are taken.
#[test]
fn burst_settings_out_of_range_are_refused() {
    type Set = fn(f64) -> PlanningConfig;
    type ItsError = fn(&PlanningConfigError) -> bool;
    let ipi: Set = |v| PlanningConfig {
        burst_ipi_ms: v,
        ..planning()
    };
    let level: Set = |v| PlanningConfig {
        burst_min_level: v,
        ..planning()
    };
    let cases: [(Set, &[f64], &[f64], ItsError); 2] = [
        (
            ipi,
            &[-1.0, f64::NAN, f64::INFINITY, 1000.5],
            &[0.0, 15.0],
            |e| matches!(e, PlanningConfigError::BurstIpi(_)),
        ),
        (
            level,
            &[-0.1, f64::NAN, f64::INFINITY],
            &[0.0, 0.35, 2.0],
            |e| matches!(e, PlanningConfigError::BurstMinLevel(_)),
        ),
    ];
    for (set, bad, good, its_error) in cases {
        for &v in bad {
            let e = set(v).validate().unwrap_err();
            assert!(its_error(&e), "{v}: {e}");
        }
        for &v in good {
            assert_eq!(set(v).validate(), Ok(()), "{v}");
        }
    }
}

/// The intervals of each planned contraction's pulses, ms (the first contraction, which
/// starts unannounced, left out).
fn planned_intervals(c: Cardiac, cfg: PlanningConfig) -> Vec<Vec<usize>> {
    let mut pg = controller(cfg).pattern_generator().unwrap();
    let p = pulses(&run(&mut pg, c, 4 * c.period, true));
    (1..4)
        .map(|beat| {
            let t: Vec<usize> = p.iter().copied().filter(|k| k / c.period == beat).collect();
            t.windows(2).map(|w| w[1] - w[0]).collect()
        })
        .collect()
}

/// `burst_min_level`: a contraction below it has no interval shorter than `burst_ipi_ms`
/// at all; at or above it the plan opens with its burst as without the key.
#[test]
fn only_contractions_at_the_burst_level_open_with_a_burst() {
    let high = Cardiac {
        level: 0.9,
        ..CARDIAC
    };
    let with = |min_level: f64| PlanningConfig {
        burst_ipi_ms: 15.0,
        burst_min_level: min_level,
        ..planning()
    };
    let free = planned_intervals(high, with(0.0));
    // On this model 0.9 opens with a doublet, then no interval under 15 ms.
    for beat in &free {
        assert!(beat[0] < 15, "{free:?}");
        assert!(beat[1..].iter().all(|&d| d >= 15), "{free:?}");
    }
    assert_eq!(planned_intervals(high, with(0.6)), free);
    assert_eq!(planned_intervals(high, with(0.9)), free);
    let even = planned_intervals(high, with(0.95));
    for beat in &even {
        assert!(beat.len() >= 10, "{even:?}");
        assert!(beat.iter().all(|&d| d >= 15), "{even:?}");
    }
}
