//! Stimulation patterns: the binary pulse input u\[k\] (1 = a pulse fires at the start of
//! sample k), built from pulse times or as constant-frequency trains.

/// Why a pulse pattern was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PatternError {
    /// No pulse times were given.
    #[error("the pulse list is empty; give at least one pulse time in ms")]
    Empty,
    /// A pulse time is NaN, infinite or negative.
    #[error("pulse time #{index} = {value} ms is not a finite time >= 0")]
    BadTime {
        /// Position in the list (0-based).
        index: usize,
        /// The value given.
        value: f64,
    },
    /// A pulse time is not on the sampling grid.
    #[error("pulse time #{index} = {value} ms is not a multiple of the {ts_ms} ms sample period")]
    OffGrid {
        /// Position in the list (0-based).
        index: usize,
        /// The value given.
        value: f64,
        /// Sample period, ms.
        ts_ms: f64,
    },
    /// Pulse times do not strictly increase (one pulse per sample at most).
    #[error("pulse times must strictly increase: #{index} = {value} ms follows {previous} ms")]
    NotIncreasing {
        /// Position in the list (0-based).
        index: usize,
        /// The value given.
        value: f64,
        /// The time before it.
        previous: f64,
    },
    /// A pulse falls outside the simulated duration.
    #[error("pulse time #{index} = {value} ms is not before the end of the {duration_ms} ms run")]
    AfterEnd {
        /// Position in the list (0-based).
        index: usize,
        /// The value given.
        value: f64,
        /// Duration, ms.
        duration_ms: f64,
    },
    /// A frequency is NaN, infinite, not positive, or faster than one pulse per sample.
    #[error(
        "frequency {hz} Hz is not usable: it must be > 0 and at most {max_hz} Hz (one pulse per sample)"
    )]
    BadFrequency {
        /// The value given.
        hz: f64,
        /// One pulse per sample.
        max_hz: f64,
    },
}

/// Number of samples of period `ts_s` in `ms` milliseconds, if `ms` lies on the grid.
pub fn samples_on_grid(ms: f64, ts_s: f64) -> Option<usize> {
    let k = ms * 1e-3 / ts_s;
    let r = k.round();
    if ms.is_finite() && ms >= 0.0 && (k - r).abs() <= 1e-6 * r.max(1.0) {
        Some(r as usize)
    } else {
        None
    }
}

/// A pattern of `n` samples with pulses at the given times (ms, on the sample grid,
/// strictly increasing, before `n ts`).
pub fn from_times_ms(times_ms: &[f64], ts_s: f64, n: usize) -> Result<Vec<bool>, PatternError> {
    if times_ms.is_empty() {
        return Err(PatternError::Empty);
    }
    let ts_ms = ts_s * 1e3;
    let mut train = vec![false; n];
    let mut previous: Option<f64> = None;
    for (index, &value) in times_ms.iter().enumerate() {
        if !value.is_finite() || value < 0.0 {
            return Err(PatternError::BadTime { index, value });
        }
        let k = samples_on_grid(value, ts_s).ok_or(PatternError::OffGrid {
            index,
            value,
            ts_ms,
        })?;
        if let Some(previous) = previous
            && value <= previous
        {
            return Err(PatternError::NotIncreasing {
                index,
                value,
                previous,
            });
        }
        if k >= n {
            return Err(PatternError::AfterEnd {
                index,
                value,
                duration_ms: n as f64 * ts_ms,
            });
        }
        train[k] = true;
        previous = Some(value);
    }
    Ok(train)
}

/// Sample indices of a constant-frequency train: pulse j at `start + round(j / (f ts))`
/// while before `start + len`. Each pulse goes to the nearest sample (as thesis 5.2.2
/// moves pulses when resampling), so the mean frequency is exact even when `1/f` is not a
/// whole number of samples.
pub fn constant_train(
    freq_hz: f64,
    start: usize,
    len: usize,
    ts_s: f64,
) -> Result<Vec<usize>, PatternError> {
    let max_hz = 1.0 / ts_s;
    if !freq_hz.is_finite() || freq_hz <= 0.0 || freq_hz > max_hz * (1.0 + 1e-9) {
        return Err(PatternError::BadFrequency {
            hz: freq_hz,
            max_hz,
        });
    }
    let per = 1.0 / (freq_hz * ts_s);
    let mut out = Vec::new();
    for j in 0.. {
        let k = (j as f64 * per).round() as usize;
        if k >= len {
            break;
        }
        out.push(start + k);
    }
    Ok(out)
}

/// A pattern of `n` samples with pulses at the given sample indices (those >= n dropped).
pub fn from_samples(samples: &[usize], n: usize) -> Vec<bool> {
    let mut train = vec![false; n];
    for &k in samples {
        if k < n {
            train[k] = true;
        }
    }
    train
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 33 Hz at 1 ms: 33 pulses in 1000 samples, intervals 30 or 31 samples.
    #[test]
    fn constant_train_keeps_mean_frequency() {
        let k = constant_train(33.0, 0, 1000, 1e-3).expect("valid");
        assert_eq!(k.len(), 33);
        assert!(k.windows(2).all(|w| w[1] - w[0] == 30 || w[1] - w[0] == 31));
        let k = constant_train(40.0, 10, 300, 1e-3).expect("valid");
        assert_eq!(k, (0..12).map(|j| 10 + 25 * j).collect::<Vec<_>>());
    }

    /// Times are validated in order: empty, negative, off grid, repeated, too late.
    #[test]
    fn bad_times_are_refused() {
        assert_eq!(from_times_ms(&[], 1e-3, 10), Err(PatternError::Empty));
        assert!(matches!(
            from_times_ms(&[-1.0], 1e-3, 10),
            Err(PatternError::BadTime { .. })
        ));
        assert!(matches!(
            from_times_ms(&[f64::NAN], 1e-3, 10),
            Err(PatternError::BadTime { .. })
        ));
        assert!(matches!(
            from_times_ms(&[0.5], 1e-3, 10),
            Err(PatternError::OffGrid { .. })
        ));
        assert!(matches!(
            from_times_ms(&[3.0, 3.0], 1e-3, 10),
            Err(PatternError::NotIncreasing { .. })
        ));
        assert!(matches!(
            from_times_ms(&[10.0], 1e-3, 10),
            Err(PatternError::AfterEnd { .. })
        ));
        assert_eq!(
            from_times_ms(&[0.0, 5.0], 1e-3, 6).expect("valid"),
            vec![true, false, false, false, false, true]
        );
    }
}
