//! A setting outside its range, typed: the key, the value and the interval it must be in
//! (the supervisor's configuration checks; `config::SupervisorConfig::validate` prefixes the
//! section).

use std::fmt;

/// An interval of accepted values; every bound is finite and so must the value be.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
    /// The lower bound itself is excluded.
    pub lo_open: bool,
    /// The upper bound itself is excluded.
    pub hi_open: bool,
}

impl Interval {
    /// `[lo, hi]`.
    pub const fn closed(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            hi,
            lo_open: false,
            hi_open: false,
        }
    }
    /// `(lo, hi]`.
    pub const fn left_open(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            hi,
            lo_open: true,
            hi_open: false,
        }
    }
    /// `[lo, hi)`.
    pub const fn right_open(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            hi,
            lo_open: false,
            hi_open: true,
        }
    }

    /// Whether `v` is finite and inside.
    pub fn contains(&self, v: f64) -> bool {
        v.is_finite()
            && (if self.lo_open {
                v > self.lo
            } else {
                v >= self.lo
            })
            && (if self.hi_open {
                v < self.hi
            } else {
                v <= self.hi
            })
    }
}

impl fmt::Display for Interval {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (l, r) = (
            if self.lo_open { '(' } else { '[' },
            if self.hi_open { ')' } else { ']' },
        );
        write!(f, "{l}{}, {}{r}", self.lo, self.hi)
    }
}

/// A value outside its interval.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key} {}", self.problem())]
pub struct RangeError {
    /// The key within its section (`gain`, `self_stall_ms`).
    pub key: &'static str,
    /// The value found.
    pub value: f64,
    /// Where it must be.
    pub interval: Interval,
}

impl RangeError {
    /// `<value> must be in <interval>`, without the key.
    pub fn problem(&self) -> String {
        format!("{} must be in {}", self.value, self.interval)
    }
}

/// `Ok` when `value` is in `interval`, else the [`RangeError`] naming `key`.
pub fn check(key: &'static str, value: f64, interval: Interval) -> Result<(), RangeError> {
    if interval.contains(value) {
        Ok(())
    } else {
        Err(RangeError {
            key,
            value,
            interval,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_open_and_closed_and_the_message_names_key_value_and_interval() {
        let i = Interval::left_open(0.0, 1.0);
        assert!(!i.contains(0.0) && i.contains(1.0) && !i.contains(f64::NAN));
        assert!(Interval::right_open(0.0, 1.0).contains(0.0));
        assert!(!Interval::right_open(0.0, 1.0).contains(1.0));
        let e = check("gain", 1.5, i).unwrap_err();
        assert_eq!(e.to_string(), "gain 1.5 must be in (0, 1]");
        assert_eq!(e.problem(), "1.5 must be in (0, 1]");
        let e = check("self_stall_ms", 10.0, Interval::closed(20.0, 60_000.0)).unwrap_err();
        assert_eq!(e.to_string(), "self_stall_ms 10 must be in [20, 60000]");
    }
}
