//! `rt_core::rt::generator` (moved from its unit tests: the crate has one test binary).

use core::time::Duration;
use fes_rt::msg::Contract;
use fes_rt::msg::{Reference, StimTick};
use fes_rt::rt::clock::PeriodicSchedule;
use rt_core::rt::generator::*;
use rt_core::rt::reference::ReferencePolicy;
use rt_core::rt::reference::Target;
use rt_core::rt::source::TestPattern;
use rt_core::rt::source::{TickDecision, TickSource};

const MS: u64 = 1_000_000;

/// A loop around `source` with the tests' reference policy (stale after 100 ms, ramping
/// down at 1 per second, 1 ms ticks) and pulse settings `pulse`.
fn loop_of<S: TickSource>(source: S, pulse: PulseSettings, degraded: bool) -> PatternLoop<S> {
    PatternLoop::new(
        source,
        ReferencePolicy {
            stale_after_ns: 100 * MS,
            stale_ramp_per_s: 1.0,
            tick_ns: 1_000_000,
        },
        None,
        pulse,
        degraded,
    )
}

/// The least pulse: channel 0, 1 uA, 1 us.
const TINY: PulseSettings = PulseSettings {
    channel: 0,
    amplitude_ua: 1,
    width_us: 1,
};

fn pattern_loop(ipi: u32) -> PatternLoop<TestPattern> {
    loop_of(
        TestPattern::new(ipi).unwrap(),
        PulseSettings {
            channel: 2,
            amplitude_ua: 20_000,
            width_us: 200,
        },
        false,
    )
}

/// A source that returns NaN on its third call.
struct Faulty(u32);
impl TickSource for Faulty {
    fn tick(&mut self, _r: &Target, _m: Option<f64>) -> TickDecision {
        self.0 += 1;
        TickDecision {
            pulse: true,
            phi: if self.0 == 3 { f64::NAN } else { 0.0 },
            ..TickDecision::default()
        }
    }
    fn missed(&mut self, _periods: u32, _r: &Target) {}
    fn reset(&mut self) {}
    fn min_pulse_gap_ticks(&self) -> u32 {
        1
    }
}

#[test]
fn ticks_are_valid_gap_free_and_carry_the_pulse_settings() {
    let mut l = pattern_loop(4);
    let mut sched = PeriodicSchedule::new(Duration::from_millis(1), MS).unwrap();
    l.offer_reference(&Reference::new(1, MS, 0.5), MS).unwrap();
    for k in 0..20u64 {
        let w = sched.advance(MS + k * MS + 30_000);
        let (t, ev) = l.step(&w);
        assert!(!ev.source_fault);
        t.validate().unwrap();
        assert_eq!(t.seq, k + 1);
        assert_eq!(t.t_ns, MS + k * MS);
        assert_eq!(t.fires(), k % 4 == 0);
        if t.fires() {
            assert_eq!((t.amplitude_ua, t.width_us, t.channel), (20_000, 200, 2));
        }
        assert_eq!(t.ref_seq, 1);
    }
    let f = l.final_tick(30 * MS);
    f.validate().unwrap();
    assert_eq!(f.seq, 21);
    assert!(f.has(StimTick::FLAG_FINAL) && !f.fires());
}

#[test]
fn a_stall_yields_one_tick_with_the_misses_and_no_burst() {
    let mut l = pattern_loop(2);
    let mut sched = PeriodicSchedule::new(Duration::from_millis(1), MS).unwrap();
    l.offer_reference(&Reference::new(1, MS, 0.5), MS).unwrap();
    let (a, _) = l.step(&sched.advance(MS));
    assert!(a.fires());
    // 100 ms stall.
    let (b, _) = l.step(&sched.advance(2 * MS + 100 * MS));
    assert_eq!(b.seq, a.seq + 1);
    assert_eq!(b.missed_periods, 100);
    assert!(b.has(StimTick::FLAG_OVERRUN));
    // The source decides once: one pulse at most, however long the stall. Its interval
    // counts wall-clock ticks (the skipped periods fired nothing), so 101 ms after the last
    // pulse it fires, and the tick after keeps the 2-tick gap.
    assert!(b.fires());
    let (c, _) = l.step(&sched.advance(103 * MS));
    assert!(!c.fires() && c.missed_periods == 0);
    let (d, _) = l.step(&sched.advance(104 * MS));
    assert!(d.fires());
}

#[test]
fn a_non_finite_decision_is_a_fault_without_a_pulse() {
    let mut l = loop_of(Faulty(0), TINY, true);
    let mut sched = PeriodicSchedule::new(Duration::from_millis(1), 0).unwrap();
    let faults: Vec<bool> = (0..4)
        .map(|k| {
            let (t, ev) = l.step(&sched.advance(k * MS));
            t.validate().unwrap();
            assert!(t.has(StimTick::FLAG_DEGRADED));
            assert_eq!(ev.source_fault, t.has(StimTick::FLAG_SOURCE_FAULT));
            assert_eq!(t.fires(), !ev.source_fault);
            ev.source_fault
        })
        .collect();
    assert_eq!(faults, [false, false, true, false]);
}

#[test]
fn a_rejected_reference_flags_the_next_tick_only() {
    let mut l = pattern_loop(2);
    let mut sched = PeriodicSchedule::new(Duration::from_millis(1), 0).unwrap();
    assert!(l.offer_reference(&Reference::new(1, 0, 2.0), 0).is_err());
    let (a, _) = l.step(&sched.advance(0));
    assert!(a.has(StimTick::FLAG_REFERENCE_REJECTED) && a.has(StimTick::FLAG_NO_REFERENCE));
    let (b, _) = l.step(&sched.advance(MS));
    assert!(!b.has(StimTick::FLAG_REFERENCE_REJECTED));
}

/// A source that logs what it is told: (missed periods reported, ticks decided).
#[derive(Default)]
struct Told(Vec<(u32, u32)>);
impl TickSource for Told {
    fn tick(&mut self, _r: &Target, _m: Option<f64>) -> TickDecision {
        self.0.push((0, 1));
        TickDecision::default()
    }
    fn missed(&mut self, periods: u32, _r: &Target) {
        self.0.push((periods, 0));
    }
    fn reset(&mut self) {}
    fn min_pulse_gap_ticks(&self) -> u32 {
        2
    }
}

#[test]
fn skipped_periods_are_told_to_the_source_before_its_one_decision() {
    // A wake-up 3.5 periods late skips 3: the source hears of them first (a model or a
    // plan keeps wall-clock time by them) and then decides once; an on-time tick tells
    // nothing.
    let mut l = loop_of(Told::default(), TINY, false);
    let mut sched = PeriodicSchedule::new(Duration::from_millis(1), MS).unwrap();
    let (t, _) = l.step(&sched.advance(MS + 10_000));
    assert_eq!(t.missed_periods, 0);
    let (t, _) = l.step(&sched.advance(5 * MS + 500_000));
    assert_eq!(t.missed_periods, 3);
    assert_eq!(l.source().0, [(0, 1), (3, 0), (0, 1)]);
}

/// `FLAG_CONTRACTION_AHEAD`: set while the target contracts and from
/// `CONTRACTION_AHEAD_MS` before a contraction the preview announces, clear at rest
/// otherwise (a transport carrying one command at a time keeps its line free meanwhile).
#[test]
fn contraction_ahead_is_flagged_from_the_preview_and_while_contracting() {
    use fes_rt::msg::{PreviewEdge, ReferencePreview};
    let mut l = loop_of(TestPattern::new(1000).unwrap(), TINY, false);
    let mut sched = PeriodicSchedule::new(Duration::from_millis(1), MS).unwrap();
    let edge = |ms: u64, force| PreviewEdge {
        t_ns: ms * MS,
        force,
        max_rate_per_s: 0.0,
    };
    l.offer_reference(&Reference::new(1, MS, 0.0), MS).unwrap();
    l.offer_preview(
        &ReferencePreview::new(1, MS, 1, &[edge(500, 0.4), edge(700, 0.0)]),
        MS,
    )
    .unwrap();
    let ahead = u64::from(StimTick::CONTRACTION_AHEAD_MS);
    let mut flagged = Vec::new();
    for k in 1..=650u64 {
        let now = k * MS;
        if k % 50 == 0 {
            // The supervisor's periodic reference: the schedule's setpoint now.
            let force = if (500..700).contains(&k) { 0.4 } else { 0.0 };
            l.offer_reference(&Reference::new(1 + k, now, force), now)
                .unwrap();
            let edges: Vec<_> = [edge(500, 0.4), edge(700, 0.0)]
                .into_iter()
                .filter(|e| e.t_ns > now)
                .collect();
            l.offer_preview(&ReferencePreview::new(1 + k, now, 1 + k, &edges), now)
                .unwrap();
        }
        let (t, _) = l.step(&sched.advance(now + 20_000));
        t.validate().unwrap();
        if t.has(StimTick::FLAG_CONTRACTION_AHEAD) {
            flagged.push(k);
        }
    }
    // From 120 ms before the onset (the edge at 500 ms is `ceil` ticks ahead) through
    // the contraction.
    assert_eq!(flagged.first(), Some(&(500 - ahead)), "{flagged:?}");
    assert!(flagged.windows(2).all(|w| w[1] == w[0] + 1), "{flagged:?}");
    assert_eq!(flagged.last(), Some(&650));
    // Without a preview only a running contraction is flagged.
    let mut l = loop_of(TestPattern::new(1000).unwrap(), TINY, false);
    l.offer_reference(&Reference::new(1, MS, 0.0), MS).unwrap();
    let (t, _) = l.step(&sched.advance(700 * MS));
    assert!(!t.has(StimTick::FLAG_CONTRACTION_AHEAD));
    l.offer_reference(&Reference::new(2, 701 * MS, 0.3), 701 * MS)
        .unwrap();
    let (t, _) = l.step(&sched.advance(701 * MS + 20_000));
    assert!(t.has(StimTick::FLAG_CONTRACTION_AHEAD));
}
