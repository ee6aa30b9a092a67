//! [`TickSource`]: what the real-time loop runs once per tick.
//!
//! The loop is written against this small trait, so that it can be tested with the
//! deterministic [`TestPattern`] and run the thesis's pattern generator (LCN -> pulse shaper
//! -> LMN, Fig. 6.8) in production. A source is called exactly once per wake-up: after a
//! stall it is *not* called for the skipped periods, so it can never emit a catch-up burst.

/// The decision of one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickDecision {
    /// Fire one pulse now.
    pub pulse: bool,
    /// Continuous control signal u_cont (thesis 6.5.2).
    pub u_cont: f64,
    /// Pulse-shaper energy since the last pulse, E (eq. 6.8).
    pub energy: f64,
    /// Output of the simulated muscle model, normalised force.
    pub model_force: f64,
    /// Model force predicted over the input delay, normalised force.
    pub predicted_force: f64,
    /// Scheduling variable phi.
    pub phi: f64,
}

impl TickDecision {
    /// True when every number is finite.
    pub fn is_finite(&self) -> bool {
        [
            self.u_cont,
            self.energy,
            self.model_force,
            self.predicted_force,
            self.phi,
        ]
        .iter()
        .all(|v| v.is_finite())
    }
}

/// One step of a pattern generator, called once per tick from the real-time thread: it must
/// not allocate, lock, log or block.
pub trait TickSource {
    /// Decides this tick from the target `reference` (normalised force, [0, 1]) and, in
    /// feedback mode, the latest measured force.
    fn tick(&mut self, reference: f64, measured_force: Option<f64>) -> TickDecision;

    /// Returns to rest (all states zero), e.g. after a fault.
    fn reset(&mut self);

    /// Shortest spacing between two pulses, in ticks, that this source guarantees (the
    /// thesis's shaper: a pulse is always followed by at least one empty sample, so 2).
    fn min_pulse_gap_ticks(&self) -> u32;
}

/// Invalid [`TestPattern`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("test-pattern ipi_ticks = {0} must be at least 2 (a pulse is followed by an empty tick)")]
pub struct TestPatternError(pub u32);

/// A deterministic bench source with no muscle model: while the reference is above zero it
/// fires every `ipi_ticks` ticks, starting on the first such tick; a zero reference stops it
/// and restarts the count. `u_cont` echoes the reference; the model outputs are 0.
///
/// It exists to test and measure the real-time plumbing independently of the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TestPattern {
    ipi_ticks: u32,
    since_last: Option<u32>,
}

impl TestPattern {
    /// A pattern with a constant inter-pulse interval of `ipi_ticks` (>= 2).
    pub fn new(ipi_ticks: u32) -> Result<Self, TestPatternError> {
        if ipi_ticks < 2 {
            return Err(TestPatternError(ipi_ticks));
        }
        Ok(Self {
            ipi_ticks,
            since_last: None,
        })
    }
}

impl TickSource for TestPattern {
    fn tick(&mut self, reference: f64, _measured_force: Option<f64>) -> TickDecision {
        // `reference > 0.0` is false for NaN as well: no pulse on a bad input.
        let pulse = if reference > 0.0 {
            let fire = self.since_last.is_none_or(|n| n + 1 >= self.ipi_ticks);
            self.since_last = if fire {
                Some(0)
            } else {
                self.since_last.map(|n| n + 1)
            };
            fire
        } else {
            self.since_last = None;
            false
        };
        TickDecision {
            pulse,
            u_cont: if reference.is_finite() {
                reference
            } else {
                0.0
            },
            ..TickDecision::default()
        }
    }

    fn reset(&mut self) {
        self.since_last = None;
    }

    fn min_pulse_gap_ticks(&self) -> u32 {
        self.ipi_ticks
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fires_every_ipi_ticks_while_the_reference_is_positive() {
        let mut p = TestPattern::new(5).unwrap();
        let fired = (0..23).filter(|_| p.tick(0.4, None).pulse).count();
        assert_eq!(fired, 5); // ticks 0, 5, 10, 15, 20
        let mut p = TestPattern::new(5).unwrap();
        let pattern: Vec<bool> = (0..11).map(|_| p.tick(0.4, None).pulse).collect();
        let expect: Vec<bool> = (0..11).map(|k| k % 5 == 0).collect();
        assert_eq!(pattern, expect);
    }

    #[test]
    fn zero_reference_stops_and_restarts_the_count() {
        let mut p = TestPattern::new(3).unwrap();
        assert!(p.tick(1.0, None).pulse);
        assert!(!p.tick(1.0, None).pulse);
        assert!(!p.tick(0.0, None).pulse);
        assert!(p.tick(1.0, None).pulse);
        assert!(!p.tick(f64::NAN, None).pulse);
    }

    #[test]
    fn ipi_below_two_is_refused() {
        assert_eq!(TestPattern::new(1), Err(TestPatternError(1)));
    }
}
