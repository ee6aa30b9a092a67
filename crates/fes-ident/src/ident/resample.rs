//! Down-sampling for models at a longer sampling period (thesis 5.2.2) and the way back to
//! the base period for the error measures (5.3: "the outputs of the models for sub-sampled
//! data are interpolated for the original sampling period of 1 ms").
//!
//! The coarse period is `factor` base samples; coarse sample j is base sample j * factor,
//! and a record of N base samples has (N - 1) / factor + 1 coarse samples.
//!
//! - **Input (pulse-preserving, 5.2.2 a/b).** Each pulse moves to the nearest coarse sample
//!   (a pulse exactly half-way goes to the later one). Pulses are placed in time order; a
//!   pulse whose nearest coarse sample is taken moves to the nearest *free* coarse sample
//!   (distance measured in base samples, ties to the later), so the pulse count never
//!   changes. The displacement is bounded: no pulse moves more than [`MAX_PULSE_SHIFT`]
//!   coarse samples beyond its nearest one, otherwise the record is refused as too dense
//!   for that period. The largest displacement is reported ([`PulseShift`]).
//! - **Output.** Low-pass filtered by a centred (zero-phase, so no delay is added)
//!   triangular FIR of half-width `factor` (weights factor - |m|, normalised over the
//!   samples inside the record; its response is sinc^2 with the first zero at the coarse
//!   sampling frequency) and decimated.
//! - **Back to the base period.** The coarse model output is interpolated linearly between
//!   coarse samples (held after the last one). The map is linear, so it is applied to
//!   `Dual` outputs too (exact Jacobians of the base-period error).

use fes_model::num::Scalar;

/// Largest extra displacement, in coarse samples beyond the nearest one, of a pulse that
/// collides with another (module docs).
pub const MAX_PULSE_SHIFT: usize = 4;

/// Why a record could not be down-sampled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ResampleError {
    /// The factor is zero.
    #[error("down-sampling factor must be >= 1")]
    Factor,
    /// Pulses are too dense to keep them all within the displacement bound.
    #[error(
        "the pulse at base sample {sample} cannot be placed within {MAX_PULSE_SHIFT} coarse samples of its nearest one at {factor} base samples per coarse sample (pulses too dense for this period)"
    )]
    TooDense {
        /// Base sample of the pulse.
        sample: usize,
        /// Down-sampling factor.
        factor: usize,
    },
}

/// How far pulses were moved by [`downsample_pulses`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PulseShift {
    /// Number of pulses.
    pub pulses: usize,
    /// Pulses that did not land on their nearest coarse sample (collisions).
    pub collisions: usize,
    /// Largest |coarse time - original time| in base samples.
    pub max_displacement: usize,
}

impl PulseShift {
    /// Combines the figures of two records.
    pub fn merge(self, o: Self) -> Self {
        Self {
            pulses: self.pulses + o.pulses,
            collisions: self.collisions + o.collisions,
            max_displacement: self.max_displacement.max(o.max_displacement),
        }
    }
}

/// Number of coarse samples for `n` base samples.
pub fn coarse_len(n: usize, factor: usize) -> usize {
    if n == 0 { 0 } else { (n - 1) / factor + 1 }
}

/// Pulse-preserving down-sampling of a 0/1 pulse train (module docs).
pub fn downsample_pulses(
    u: &[f64],
    factor: usize,
) -> Result<(Vec<f64>, PulseShift), ResampleError> {
    if factor == 0 {
        return Err(ResampleError::Factor);
    }
    let nc = coarse_len(u.len(), factor);
    let mut out = vec![0.0; nc];
    let mut shift = PulseShift::default();
    for (k, _) in u.iter().enumerate().filter(|(_, v)| **v != 0.0) {
        shift.pulses += 1;
        let nearest = ((k + factor / 2) / factor).min(nc - 1);
        let dist = |j: usize| (j * factor).abs_diff(k);
        // Candidates within the bound, nearest first (ties: the later one, as the rounding).
        let lo = nearest.saturating_sub(MAX_PULSE_SHIFT);
        let hi = (nearest + MAX_PULSE_SHIFT).min(nc - 1);
        let best = (lo..=hi)
            .filter(|&j| out[j] == 0.0)
            .min_by_key(|&j| (dist(j), core::cmp::Reverse(j)))
            .ok_or(ResampleError::TooDense { sample: k, factor })?;
        if best != nearest {
            shift.collisions += 1;
        }
        shift.max_displacement = shift.max_displacement.max(dist(best));
        out[best] = 1.0;
    }
    Ok((out, shift))
}

/// Low-pass (centred triangular FIR, half-width `factor`) and decimation of an output.
pub fn downsample_output(y: &[f64], factor: usize) -> Vec<f64> {
    let n = y.len();
    let f = factor.max(1) as isize;
    (0..coarse_len(n, factor.max(1)))
        .map(|j| {
            let c = j as isize * f;
            let (mut acc, mut wsum) = (0.0, 0.0);
            for m in (1 - f)..f {
                let k = c + m;
                if k >= 0 && (k as usize) < n {
                    let w = (f - m.abs()) as f64;
                    acc += w * y[k as usize];
                    wsum += w;
                }
            }
            acc / wsum
        })
        .collect()
}

/// Linear interpolation of coarse outputs back to `out.len()` base samples (held after the
/// last coarse sample). `out.len()` must map onto `y_coarse` ([`coarse_len`]).
pub fn interpolate<S: Scalar>(y_coarse: &[S], factor: usize, out: &mut [S]) {
    let f = factor.max(1);
    let nc = y_coarse.len();
    for (k, o) in out.iter_mut().enumerate() {
        let j = k / f;
        let r = k % f;
        *o = if r == 0 || j + 1 >= nc {
            y_coarse[j.min(nc.saturating_sub(1))]
        } else {
            let w = r as f64 / f as f64;
            y_coarse[j] * (1.0 - w) + y_coarse[j + 1] * w
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factor_one_is_identity() {
        let u = [0.0, 1.0, 1.0, 0.0, 1.0];
        let (c, s) = downsample_pulses(&u, 1).unwrap();
        assert_eq!(c, u);
        assert_eq!(s.collisions, 0);
        let y = [0.1, 0.5, 0.2];
        assert_eq!(downsample_output(&y, 1), y);
        let mut back = [0.0; 3];
        interpolate(&y, 1, &mut back);
        assert_eq!(back, y);
    }

    #[test]
    fn pulses_move_to_nearest_and_collisions_to_nearest_free() {
        // factor 10: pulses at 14 -> 10, 15 -> 20 (tie goes later), 16 -> 20 taken -> 10
        // taken -> 30 (dist 14) vs 0 (dist 16): 30.
        let mut u = vec![0.0; 50];
        for k in [14, 15, 16] {
            u[k] = 1.0;
        }
        let (c, s) = downsample_pulses(&u, 10).unwrap();
        assert_eq!(c, vec![0.0, 1.0, 1.0, 1.0, 0.0]);
        assert_eq!(s.pulses, 3);
        assert_eq!(s.collisions, 1);
        assert_eq!(s.max_displacement, 14);
    }

    #[test]
    fn too_dense_is_refused() {
        let u = vec![1.0; 100];
        assert!(matches!(
            downsample_pulses(&u, 10),
            Err(ResampleError::TooDense { .. })
        ));
    }

    #[test]
    fn output_filter_keeps_constants_and_lines() {
        // The normalised symmetric kernel reproduces constants everywhere and straight lines
        // away from the record edges.
        let y: Vec<f64> = (0..41).map(|k| 0.3 + 0.01 * k as f64).collect();
        let c = downsample_output(&y, 5);
        assert_eq!(c.len(), 9);
        for (j, v) in c.iter().enumerate().skip(1).take(7) {
            assert!((v - y[5 * j]).abs() < 1e-12);
        }
        let mut back = vec![0.0; 41];
        interpolate(&c, 5, &mut back);
        for k in 5..36 {
            assert!((back[k] - y[k]).abs() < 1e-12, "k {k}");
        }
    }
}
