//! `rt_core::rt::reference` (moved from its unit tests: the crate has one test binary).

use fes_model::control::preview::PreviewPoint;
use fes_rt::msg::{PreviewEdge, Reference, ReferencePreview};
use rt_core::rt::reference::*;

const MS: u64 = 1_000_000;

fn tracker() -> ReferenceTracker {
    ReferenceTracker::new(ReferencePolicy {
        stale_after_ns: 100 * MS,
        stale_ramp_per_s: 2.0,
        tick_ns: 1_000_000,
    })
}

#[test]
fn no_reference_means_zero_target() {
    let mut t = tracker();
    let target = t.advance(5 * MS);
    assert!(target.none);
    assert_eq!(target.value, 0.0);
}

#[test]
fn a_step_reference_applies_at_once_and_a_ramp_follows_its_rate() {
    let mut t = tracker();
    t.offer(&Reference::new(1, MS, 0.5), MS).unwrap();
    assert_eq!(t.advance(MS).value, 0.5);
    let mut r = Reference::new(2, 2 * MS, 1.0);
    r.max_rate_per_s = 10.0; // 0.01 per ms
    t.offer(&r, 2 * MS).unwrap();
    for k in 1..=50u64 {
        let v = t.advance(MS + k * MS).value;
        let expect = (0.5 + 0.01 * k as f64).min(1.0);
        assert!((v - expect).abs() < 1e-12, "k={k}: {v} vs {expect}");
    }
}

/// A reference of zero force reached by a ramp: the target is resting from the first
/// tick of the ramp down (the pattern generator then fires no pulse while the force is
/// to fall), and not while it ramps up.
#[test]
fn a_ramp_down_to_zero_is_resting_from_its_first_tick() {
    let mut t = tracker();
    let mut up = Reference::new(1, MS, 0.4);
    up.max_rate_per_s = 50.0;
    t.offer(&up, MS).unwrap();
    let first = t.advance(MS);
    assert!(!first.resting && first.value == 0.0, "{first:?}");
    let rising = t.advance(2 * MS);
    assert!(!rising.resting && rising.value > 0.0, "{rising:?}");
    for k in 3..20 {
        t.advance(k * MS);
    }
    let mut down = Reference::new(2, 20 * MS, 0.0);
    down.max_rate_per_s = 50.0;
    t.offer(&down, 20 * MS).unwrap();
    let ramp = t.advance(21 * MS);
    assert!(ramp.resting && ramp.value > 0.3, "{ramp:?}");
    assert!(Target::at(0.0).resting && !Target::at(0.2).resting);
}

#[test]
fn a_stale_reference_ramps_to_zero_at_the_configured_rate() {
    let mut t = tracker();
    t.offer(&Reference::new(1, 0, 0.8), 0).unwrap();
    assert_eq!(t.advance(0).value, 0.8);
    // Fresh until 100 ms.
    let at_100 = t.advance(100 * MS);
    assert!(!at_100.stale);
    assert_eq!(at_100.value, 0.8);
    // From 101 ms on: 2.0 per second = 0.002 per ms, measured from the last advance.
    let a = t.advance(101 * MS);
    assert!(a.stale);
    assert!((a.value - 0.798).abs() < 1e-12);
    let b = t.advance(201 * MS);
    assert!((b.value - 0.598).abs() < 1e-12);
    let c = t.advance(2_000 * MS);
    assert_eq!(c.value, 0.0);
    // A fresh reference revives it.
    t.offer(&Reference::new(2, 2_000 * MS, 0.3), 2_000 * MS)
        .unwrap();
    let d = t.advance(2_001 * MS);
    assert!(!d.stale);
    assert_eq!(d.value, 0.3);
}

#[test]
fn stop_drops_the_target_at_once() {
    let mut t = tracker();
    t.offer(&Reference::new(1, 0, 0.8), 0).unwrap();
    t.advance(0);
    let mut r = Reference::new(2, MS, 0.8);
    r.flags = Reference::FLAG_STOP;
    t.offer(&r, MS).unwrap();
    let s = t.advance(MS);
    assert!(s.stop);
    assert_eq!(s.value, 0.0);
}

#[test]
fn invalid_old_and_future_references_are_rejected_and_the_last_one_held() {
    let mut t = tracker();
    t.offer(&Reference::new(5, 10 * MS, 0.4), 10 * MS).unwrap();
    assert!(matches!(
        t.offer(&Reference::new(6, 10 * MS, 1.5), 10 * MS),
        Err(ReferenceRejection::Invalid(_))
    ));
    assert!(matches!(
        t.offer(&Reference::new(6, 10 * MS, f64::NAN), 10 * MS),
        Err(ReferenceRejection::Invalid(_))
    ));
    assert_eq!(
        t.offer(&Reference::new(5, 10 * MS, 0.1), 10 * MS),
        Err(ReferenceRejection::OutOfOrder {
            seq: 5,
            last_seq: 5
        })
    );
    assert!(matches!(
        t.offer(&Reference::new(7, 100 * MS, 0.1), 10 * MS),
        Err(ReferenceRejection::FromTheFuture { .. })
    ));
    let held = t.advance(11 * MS);
    assert_eq!((held.value, held.ref_seq), (0.4, 5));
}

/// The preview handed to the generator: the reference in use now, then each announced edge
/// still ahead at the tick it takes effect (rounded up to whole ticks); none while the
/// reference is stale or stopped, or once the preview itself is stale; a preview that fails
/// validation or comes out of order is refused.
#[test]
fn the_preview_is_the_reference_now_then_the_edges_ahead_in_ticks() {
    let mut t = tracker();
    let mut r = Reference::new(1, 10 * MS, 0.3);
    r.max_rate_per_s = 50.0;
    t.offer(&r, 10 * MS).unwrap();
    assert!(
        t.advance(10 * MS).preview.is_none(),
        "no preview received yet"
    );
    let edge = |ms: u64, force| PreviewEdge {
        t_ns: ms * MS,
        force,
        max_rate_per_s: 50.0,
    };
    let p = ReferencePreview::new(1, 10 * MS, 1, &[edge(330, 0.0), edge(810, 0.4)]);
    t.offer_preview(&p, 10 * MS).unwrap();
    let preview = t.advance(10 * MS + MS / 2).preview;
    let point = |at, force| PreviewPoint {
        at,
        force,
        rate_per_s: 50.0,
    };
    // 319.5 ms and 799.5 ms ahead: 320 and 800 ticks.
    assert_eq!(
        preview.points(),
        &[point(0, 0.3), point(320, 0.0), point(800, 0.4)]
    );
    // Past the first edge, only the second is ahead.
    let mut r2 = Reference::new(2, 330 * MS, 0.0);
    r2.max_rate_per_s = 50.0;
    t.offer(&r2, 330 * MS).unwrap();
    let p2 = ReferencePreview::new(2, 330 * MS, 2, &[edge(810, 0.4)]);
    t.offer_preview(&p2, 330 * MS).unwrap();
    let preview = t.advance(330 * MS).preview;
    assert_eq!(preview.points(), &[point(0, 0.0), point(480, 0.4)]);
    // A stale reference or preview (over 100 ms old) gives none.
    assert!(t.advance(431 * MS).preview.is_none());
    // Replayed or invalid previews are refused.
    assert!(t.offer_preview(&p2, 431 * MS).is_err());
    let mut bad = p2;
    bad.seq = 3;
    bad.edges[0].force = 2.0;
    assert!(t.offer_preview(&bad, 431 * MS).is_err());
    // An operator stop: no preview.
    let mut stop = Reference::new(3, 440 * MS, 0.0);
    stop.flags = Reference::FLAG_STOP;
    t.offer(&stop, 440 * MS).unwrap();
    let p3 = ReferencePreview::new(4, 440 * MS, 3, &[edge(810, 0.4), edge(900, 0.0)]);
    t.offer_preview(&p3, 440 * MS).unwrap();
    assert!(t.advance(440 * MS).preview.is_none());
}

/// At an edge the preview has passed but whose Reference has not arrived yet (the
/// supervisor publishes it after the edge, by milliseconds on a loaded host), the target
/// follows the announced schedule and the preview announces the edge's setpoint as in effect
/// now: a contraction starts and ends when announced. Once the Reference arrives it is the
/// reference again; a stop wins at once; a stale preview schedules nothing.
#[test]
fn an_edge_due_before_its_reference_arrives_is_the_setpoint_now() {
    let mut t = tracker();
    let reference = |seq, ms_ns: u64, force| {
        let mut r = Reference::new(seq, ms_ns, force);
        r.max_rate_per_s = 50.0;
        r
    };
    let edge = |ms: u64, force| PreviewEdge {
        t_ns: ms * MS,
        force,
        max_rate_per_s: 50.0,
    };
    let point = |at, force| PreviewPoint {
        at,
        force,
        rate_per_s: 50.0,
    };
    // The supervisor's keep-alive at 320 ms: at rest, the contraction 330-650 ms ahead.
    t.offer(&reference(1, 320 * MS, 0.0), 320 * MS).unwrap();
    let p = ReferencePreview::new(1, 320 * MS, 1, &[edge(330, 0.3), edge(650, 0.0)]);
    t.offer_preview(&p, 320 * MS).unwrap();
    // 200 us after the onset, the onset's Reference not yet received: the target follows
    // the schedule (no longer resting, ramping up) and the preview says so.
    let late = t.advance(330 * MS + 200_000);
    assert!(!late.resting);
    assert_eq!(late.preview.points(), &[point(0, 0.3), point(320, 0.0)]);
    let ramp = t.advance(331 * MS + 200_000);
    assert!((ramp.value - 0.05).abs() < 1e-9, "{}", ramp.value);
    // The Reference arrives (published 300 us after the edge): the reference again.
    t.offer(&reference(2, 330 * MS + 300_000, 0.3), 330 * MS + 400_000)
        .unwrap();
    let now = t.advance(330 * MS + 400_000).preview;
    assert_eq!(now.points(), &[point(0, 0.3), point(320, 0.0)]);
    // The same at the end: a keep-alive at 640 ms, the edge due at 650 ms, its Reference
    // of 0 not yet in.
    t.offer(&reference(3, 640 * MS, 0.3), 640 * MS).unwrap();
    let p2 = ReferencePreview::new(2, 640 * MS, 3, &[edge(650, 0.0), edge(1130, 0.3)]);
    t.offer_preview(&p2, 640 * MS).unwrap();
    let end = t.advance(650 * MS + 100_000);
    assert!(end.resting);
    assert_eq!(end.preview.points(), &[point(0, 0.0), point(480, 0.3)]);
    // A stop wins the moment it arrives, whatever the schedule says.
    let p3 = ReferencePreview::new(3, 1120 * MS, 3, &[edge(1130, 0.3)]);
    t.offer(&reference(4, 1120 * MS, 0.0), 1120 * MS).unwrap();
    t.offer_preview(&p3, 1120 * MS).unwrap();
    let mut stop = reference(5, 1125 * MS, 0.0);
    stop.flags = Reference::FLAG_STOP;
    t.offer(&stop, 1125 * MS).unwrap();
    let stopped = t.advance(1131 * MS);
    assert!(stopped.stop && stopped.resting && stopped.value == 0.0);
    assert!(stopped.preview.is_none());
    // A stale preview schedules nothing: 101 ms after it, its due edge is not applied.
    let mut t = tracker();
    t.offer(&reference(1, 320 * MS, 0.0), 320 * MS).unwrap();
    t.offer_preview(&p, 320 * MS).unwrap();
    t.offer(&reference(2, 400 * MS, 0.0), 400 * MS).unwrap();
    assert!(t.advance(421 * MS + 1).resting);
}

/// An edge is announced for the tick it takes effect, counted from the announcing tick's
/// grid point: a tick woken late within its period (after a stall) announces the same
/// tick as one woken on time. Counted from the wake-up time, a tick woken 0.5 ms late put
/// an onset 0.2 ms after a grid point one tick early; the planner kept that onset for the
/// whole contraction, and its opening pulse fell on the last tick at rest, where nothing
/// fires (the process bench, slow muscle at 0.5: a beat that lost its opening pulse,
/// docs/bench.md).
#[test]
fn an_edge_is_announced_for_the_tick_it_takes_effect_however_late_the_tick_woke() {
    let mut t = tracker();
    t.offer(&Reference::new(1, 10 * MS, 0.0), 10 * MS).unwrap();
    let onset = PreviewEdge {
        t_ns: 20 * MS + 200_000,
        force: 0.3,
        max_rate_per_s: 50.0,
    };
    let p = ReferencePreview::new(1, 10 * MS, 1, &[onset]);
    t.offer_preview(&p, 10 * MS).unwrap();
    for lateness in [20_000, 500_000, 900_000] {
        let mut t = t;
        let announced = t.advance_on_grid(12 * MS + lateness, 12 * MS).preview;
        let at = u64::from(announced.points()[1].at);
        // Every later tick woken 20 us after its grid point, as on a quiet host.
        let rises = (13..40)
            .find(|&k| !t.advance_on_grid(k * MS + 20_000, k * MS).resting)
            .unwrap();
        assert_eq!(
            12 + at,
            rises,
            "announced {at} ticks ahead, woken {lateness} ns late"
        );
    }
}
