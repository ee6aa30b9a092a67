//! Reference validation: what the supervisor refuses to publish.
//!
//! "References outside [0, 1], NaN, too-fast changes (rate limit) are rejected with a clear
//! error and not published." The supervisor never steps the reference: every change it
//! publishes carries a ramp rate (`Reference::max_rate_per_s`, applied by rt-core), and
//! that rate may not exceed [`ReferenceLimits::max_rate_per_s`]. Only an operator stop or a
//! fault drops the reference to zero at once.

use serde::{Deserialize, Serialize};

/// Limits every published reference obeys. Read from the configuration, validated once.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReferenceLimits {
    /// Highest reference the operator may ask for, normalised force, in (0, 1]. Default 1.
    pub max_force: f64,
    /// Fastest change of the reference, normalised force per second, in (0, 1000].
    /// Default 50 /s (0 -> 1 in 20 ms, a fifth of the fast muscle's twitch).
    pub max_rate_per_s: f64,
    /// Rate of a `set` without an explicit rate, in (0, `max_rate_per_s`]. Default 5 /s.
    pub default_rate_per_s: f64,
}

impl Default for ReferenceLimits {
    fn default() -> Self {
        Self {
            max_force: 1.0,
            max_rate_per_s: 50.0,
            default_rate_per_s: 5.0,
        }
    }
}

/// Why a requested reference was refused. The text is what the operator reads.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Rejection {
    /// A value is NaN or infinite.
    #[error("{what} is {value}: must be a finite number")]
    NotFinite {
        /// Which value.
        what: String,
        /// The value.
        value: f64,
    },
    /// A force outside [0, max_force].
    #[error("{what} {value} is outside [0, {max}] (normalised force)")]
    OutOfRange {
        /// Which value.
        what: String,
        /// The value.
        value: f64,
        /// The ceiling in force.
        max: f64,
    },
    /// A change faster than the rate limit.
    #[error(
        "{what} {rate_per_s} /s is faster than the rate limit {max_per_s} /s (normalised force per second)"
    )]
    TooFast {
        /// Which change.
        what: String,
        /// Requested rate.
        rate_per_s: f64,
        /// Limit.
        max_per_s: f64,
    },
    /// A parameter outside its allowed interval.
    #[error("{what} {value}{unit} is outside {allowed}{why}")]
    Outside {
        /// Which parameter.
        what: String,
        /// Its value.
        value: f64,
        /// Its unit with a leading space, or "".
        unit: &'static str,
        /// The allowed interval, e.g. `[60, 200]`.
        allowed: String,
        /// Why that interval, with a leading space, or "".
        why: &'static str,
    },
    /// A time that does not increase from the previous point's.
    #[error("{what} {value} does not increase (previous {previous})")]
    NotIncreasing {
        /// Which time.
        what: String,
        /// Its value, s.
        value: f64,
        /// The previous point's, s.
        previous: f64,
    },
    /// A repeating ramp profile that does not end where it starts.
    #[error("a repeating ramp profile must end where it starts (first force {first}, last {last})")]
    RepeatGap {
        /// The first point's force.
        first: f64,
        /// The last point's force.
        last: f64,
    },
    /// A cardiac edge that takes longer than the shorter phase of the beat.
    #[error(
        "an edge of amplitude {amplitude} at {rate_per_s} /s takes {edge_ms:.1} ms, longer than the {phase} phase ({phase_ms:.1} ms): raise the edge rate or change the duty"
    )]
    EdgeTooLong {
        /// The amplitude.
        amplitude: f64,
        /// The edge rate.
        rate_per_s: f64,
        /// The edge's duration, ms.
        edge_ms: f64,
        /// The shorter phase: "contraction" or "rest".
        phase: &'static str,
        /// Its duration, ms.
        phase_ms: f64,
    },
}

/// The configuration's limits are inconsistent.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("reference.{field}: {problem}")]
pub struct LimitsError {
    /// Offending key.
    pub field: &'static str,
    /// What is wrong.
    pub problem: String,
}

impl ReferenceLimits {
    /// Checks the limits themselves.
    pub fn validate(&self) -> Result<(), LimitsError> {
        let bad = |field, problem: String| Err(LimitsError { field, problem });
        if !(self.max_force.is_finite() && self.max_force > 0.0 && self.max_force <= 1.0) {
            return bad("max_force", format!("{} must be in (0, 1]", self.max_force));
        }
        let top = fes_rt::msg::Reference::MAX_RATE_PER_S;
        if !(self.max_rate_per_s.is_finite()
            && self.max_rate_per_s > 0.0
            && self.max_rate_per_s <= top)
        {
            return bad(
                "max_rate_per_s",
                format!("{} must be in (0, {top}]", self.max_rate_per_s),
            );
        }
        if !(self.default_rate_per_s.is_finite()
            && self.default_rate_per_s > 0.0
            && self.default_rate_per_s <= self.max_rate_per_s)
        {
            return bad(
                "default_rate_per_s",
                format!(
                    "{} must be in (0, max_rate_per_s = {}]",
                    self.default_rate_per_s, self.max_rate_per_s
                ),
            );
        }
        Ok(())
    }

    /// Checks a force level `value` named `what`.
    pub fn check_force(&self, what: &str, value: f64) -> Result<(), Rejection> {
        if !value.is_finite() {
            return Err(Rejection::NotFinite {
                what: what.into(),
                value,
            });
        }
        if !(0.0..=self.max_force).contains(&value) {
            return Err(Rejection::OutOfRange {
                what: what.into(),
                value,
                max: self.max_force,
            });
        }
        Ok(())
    }

    /// Checks a ramp rate `rate` named `what` (must be > 0 and within the limit).
    pub fn check_rate(&self, what: &str, rate: f64) -> Result<(), Rejection> {
        if !rate.is_finite() {
            return Err(Rejection::NotFinite {
                what: what.into(),
                value: rate,
            });
        }
        if rate <= 0.0 {
            return Err(Rejection::Outside {
                what: what.into(),
                value: rate,
                unit: " /s",
                allowed: format!("(0, {}]", self.max_rate_per_s),
                why: " (the supervisor never steps the reference)",
            });
        }
        if rate > self.max_rate_per_s {
            return Err(Rejection::TooFast {
                what: what.into(),
                rate_per_s: rate,
                max_per_s: self.max_rate_per_s,
            });
        }
        Ok(())
    }

    /// Checks a duration in seconds (finite, > 0, at most a day).
    pub fn check_duration(what: &str, seconds: f64) -> Result<(), Rejection> {
        if !seconds.is_finite() {
            return Err(Rejection::NotFinite {
                what: what.into(),
                value: seconds,
            });
        }
        if !(seconds > 0.0 && seconds <= 86_400.0) {
            return Err(Rejection::Outside {
                what: what.into(),
                value: seconds,
                unit: " s",
                allowed: "(0, 86400]".into(),
                why: "",
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_checks_name_the_problem() {
        let l = ReferenceLimits::default();
        l.validate().unwrap();
        assert!(l.check_force("force", 0.0).is_ok());
        assert!(l.check_force("force", 1.0).is_ok());
        let e = l.check_force("force", 1.2).unwrap_err();
        assert_eq!(
            e.to_string(),
            "force 1.2 is outside [0, 1] (normalised force)"
        );
        let e = l.check_force("force", f64::NAN).unwrap_err();
        assert_eq!(e.to_string(), "force is NaN: must be a finite number");
        assert!(l.check_force("force", -0.01).is_err());
        let e = l.check_rate("rate", 51.0).unwrap_err();
        assert!(
            e.to_string().contains("faster than the rate limit 50"),
            "{e}"
        );
        assert!(l.check_rate("rate", 0.0).is_err());
        assert!(l.check_rate("rate", 50.0).is_ok());
    }

    #[test]
    fn inconsistent_limits_are_refused() {
        let l = ReferenceLimits {
            default_rate_per_s: 60.0,
            ..Default::default()
        };
        assert_eq!(l.validate().unwrap_err().field, "default_rate_per_s");
        let l = ReferenceLimits {
            max_force: 1.5,
            ..Default::default()
        };
        assert_eq!(l.validate().unwrap_err().field, "max_force");
    }
}
