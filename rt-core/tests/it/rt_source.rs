//! `rt_core::rt::source` (moved from its unit tests: the crate has one test binary).

use rt_core::rt::reference::Target;
use rt_core::rt::source::*;

#[test]
fn fires_every_ipi_ticks_while_the_reference_is_positive() {
    let mut p = TestPattern::new(5).unwrap();
    let fired = (0..23)
        .filter(|_| p.tick(&Target::at(0.4), None).pulse)
        .count();
    assert_eq!(fired, 5); // ticks 0, 5, 10, 15, 20
    let mut p = TestPattern::new(5).unwrap();
    let pattern: Vec<bool> = (0..11)
        .map(|_| p.tick(&Target::at(0.4), None).pulse)
        .collect();
    let expect: Vec<bool> = (0..11).map(|k| k % 5 == 0).collect();
    assert_eq!(pattern, expect);
}

#[test]
fn zero_reference_stops_and_restarts_the_count() {
    let mut p = TestPattern::new(3).unwrap();
    assert!(p.tick(&Target::at(1.0), None).pulse);
    assert!(!p.tick(&Target::at(1.0), None).pulse);
    assert!(!p.tick(&Target::at(0.0), None).pulse);
    assert!(p.tick(&Target::at(1.0), None).pulse);
    assert!(!p.tick(&Target::at(f64::NAN), None).pulse);
}

#[test]
fn ipi_below_two_is_refused() {
    assert_eq!(TestPattern::new(1), Err(TestPatternError(1)));
}
