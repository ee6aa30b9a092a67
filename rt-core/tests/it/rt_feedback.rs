//! `rt_core::rt::feedback` (moved from its unit tests: the crate has one test binary).

use fes_rt::msg::ForceSample;
use rt_core::rt::feedback::*;

fn sample(seq: u64, t_ns: u64, force: f64) -> ForceSample {
    ForceSample {
        seq,
        t_ns,
        stim_seq: 0,
        force_n: force * 10.0,
        force,
    }
}

#[test]
fn fresh_samples_are_used_and_old_ones_expire() {
    let mut f = FeedbackTracker::new(5_000_000);
    assert_eq!(f.measured(0), None);
    f.offer(&sample(1, 1_000_000, 0.25)).unwrap();
    assert_eq!(f.measured(6_000_000), Some(0.25));
    assert_eq!(f.measured(6_000_001), None);
    assert!(f.offer(&sample(1, 2_000_000, 0.3)).is_err());
    assert!(f.offer(&sample(2, 2_000_000, f64::INFINITY)).is_err());
    assert_eq!(f.measured(2_000_000), Some(0.25));
}
