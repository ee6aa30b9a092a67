//! Desired closed-loop poles from a time-domain specification (thesis 6.5.3, C.1.1).
//!
//! The thesis selects, per local controller, a rise time `t_r` and a damping factor `xi`
//! "for which the corresponding pair of poles can be directly set using standard
//! time-domain formulae" (C.1.1), and adds a third, faster pole `p3 = -1.9/Ts` for the
//! integrator (6.5.3). The rule that reproduces all 16 poles of Tables 6.1 and 6.2 to the
//! printed digit ([`RiseTimeRule::Thesis`]) is
//!
//! ```text
//! w_n t_r = 3.2,     s_{1,2} = w_n (-xi ± sqrt(xi² - 1)),
//! ```
//!
//! mapped exactly (zero-order hold) into the delta domain, `p = (exp(s Ts) - 1) / Ts`
//! (App. D.2.2, eq. D.7). The project first used the rise-time approximation
//! `w_n = (2.16 xi + 0.60) / t_r` ([`RiseTimeRule::Approximation`], 3.192 / t_r at
//! xi = 1.2: within 0.83 % of the tables, not their rule); it is kept so that controller
//! files designed with it still load and for comparison.

#[cfg(not(feature = "std"))]
use crate::num::math::{ComplexMath as _, FloatMath as _};
use nalgebra::Complex;
use serde::{Deserialize, Serialize};

/// A pole in the delta domain, in 1/s. Real poles have `im == 0`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pole {
    /// Real part, 1/s.
    pub re: f64,
    /// Imaginary part, 1/s.
    pub im: f64,
}

impl Pole {
    /// A real pole.
    pub const fn real(re: f64) -> Self {
        Self { re, im: 0.0 }
    }

    /// As a complex number.
    pub fn to_complex(self) -> Complex<f64> {
        Complex::new(self.re, self.im)
    }

    /// From a complex number.
    pub fn from_complex(c: Complex<f64>) -> Self {
        Self { re: c.re, im: c.im }
    }

    /// `true` when the pole lies strictly inside the delta-domain stability region, the
    /// circle of radius `1/Ts` centred at `-1/Ts` (App. D.2.2, Fig. D.4), i.e. the
    /// shift-domain pole `1 + p Ts` lies inside the unit circle.
    pub fn is_stable(self, ts: f64) -> bool {
        let z = Complex::new(1.0 + self.re * ts, self.im * ts);
        self.re.is_finite() && self.im.is_finite() && z.norm() < 1.0
    }
}

/// Why a time-domain specification cannot be turned into poles.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// The rise time must be finite and positive (seconds).
    #[error("rise time t_r = {0} s is not a finite positive number")]
    RiseTime(f64),
    /// The damping factor must be finite and positive (1.2 gives no overshoot, thesis 6.5.3).
    #[error("damping factor xi = {0} is not a finite positive number")]
    Damping(f64),
    /// The sampling period must be finite and positive (seconds).
    #[error("sampling period Ts = {0} s is not a finite positive number")]
    SamplingPeriod(f64),
}

/// How a rise time becomes a natural frequency (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RiseTimeRule {
    /// `w_n t_r = 3.2`: reproduces every pole of thesis Tables 6.1 and 6.2 to the printed
    /// digit (the default).
    #[default]
    Thesis,
    /// `w_n = (2.16 xi + 0.60) / t_r`, the common rise-time approximation; within 0.83 % of
    /// the tables at xi = 1.2. The rule of controller files written before the rule was
    /// stored.
    Approximation,
}

impl RiseTimeRule {
    /// The rule of a controller file that does not name one (written before the rule was
    /// stored): [`RiseTimeRule::Approximation`].
    pub const fn legacy() -> Self {
        Self::Approximation
    }
}

/// `w_n t_r` of [`RiseTimeRule::Thesis`].
pub const THESIS_WN_TR: f64 = 3.2;

/// Natural frequency `w_n` in rad/s for a rise time `t_r` (s) and damping `xi` by `rule`.
pub fn natural_frequency(
    rule: RiseTimeRule,
    rise_time: f64,
    damping: f64,
) -> Result<f64, SpecError> {
    if !(rise_time.is_finite() && rise_time > 0.0) {
        return Err(SpecError::RiseTime(rise_time));
    }
    if !(damping.is_finite() && damping > 0.0) {
        return Err(SpecError::Damping(damping));
    }
    Ok(match rule {
        RiseTimeRule::Thesis => THESIS_WN_TR / rise_time,
        RiseTimeRule::Approximation => (2.16 * damping + 0.60) / rise_time,
    })
}

/// Continuous-time dominant pair `s = w_n (-xi ± sqrt(xi² - 1))`, the faster first.
/// For `xi < 1` the pair is complex conjugate (positive imaginary part first).
pub fn continuous_dominant_pair(
    rule: RiseTimeRule,
    rise_time: f64,
    damping: f64,
) -> Result<[Complex<f64>; 2], SpecError> {
    let wn = natural_frequency(rule, rise_time, damping)?;
    let disc = damping * damping - 1.0;
    Ok(if disc >= 0.0 {
        let r = disc.sqrt();
        [
            Complex::new(wn * (-damping - r), 0.0),
            Complex::new(wn * (-damping + r), 0.0),
        ]
    } else {
        let w = (-disc).sqrt();
        [
            Complex::new(-wn * damping, wn * w),
            Complex::new(-wn * damping, -wn * w),
        ]
    })
}

/// Exact map of a continuous pole into the delta domain, `(exp(s Ts) - 1) / Ts`
/// (App. D.2.2: the delta operator `(q - 1)/Ts` applied to the zero-order-hold pole `exp(s Ts)`).
pub fn continuous_to_delta(s: Complex<f64>, ts: f64) -> Complex<f64> {
    // exp_m1 keeps full precision for |s Ts| << 1 on the real part.
    let (re, im) = (s.re * ts, s.im * ts);
    let em1 = re.exp_m1();
    let (sin, cos) = im.sin_cos();
    // exp(re + i im) - 1 = (e^re cos - 1) + i e^re sin, with e^re cos - 1 = em1 cos + (cos - 1).
    let cos_m1 = -2.0 * (im / 2.0).sin().powi(2);
    Complex::new((em1 * cos + cos_m1) / ts, (em1 + 1.0) * sin / ts)
}

/// Delta-domain dominant pair `p1, p2` for a rise time and damping by the thesis's rule
/// (6.5.3, Tables 6.1 and 6.2), the faster first.
pub fn dominant_pair(rise_time: f64, damping: f64, ts: f64) -> Result<[Pole; 2], SpecError> {
    dominant_pair_by(RiseTimeRule::Thesis, rise_time, damping, ts)
}

/// [`dominant_pair`] by a chosen [`RiseTimeRule`].
pub fn dominant_pair_by(
    rule: RiseTimeRule,
    rise_time: f64,
    damping: f64,
    ts: f64,
) -> Result<[Pole; 2], SpecError> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(SpecError::SamplingPeriod(ts));
    }
    let [s1, s2] = continuous_dominant_pair(rule, rise_time, damping)?;
    Ok([
        Pole::from_complex(continuous_to_delta(s1, ts)),
        Pole::from_complex(continuous_to_delta(s2, ts)),
    ])
}

/// How the thesis's third (integrator) pole "`p3 = -1.9/Ts`" (6.5.3) is read. The thesis
/// does not say; the controller file stores the resulting `p3` per unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThirdPoleRule {
    /// Literally, as a delta-domain pole: `p3 = -1.9/Ts`. In the shift domain that is
    /// `z = 1 - 1.9 = -0.9`, a mode that flips sign every sample and decays by only 10 %
    /// per sample.
    #[default]
    Delta,
    /// As a continuous pole `s3 = -1.9/Ts` mapped like the dominant pair,
    /// `p3 = (exp(-1.9) - 1)/Ts = -850.4` 1/s at 1 ms (`z = 0.150`, monotone, 85 % per
    /// sample).
    Mapped,
}

/// `p3` by `rule` at sampling period `ts` (6.5.3).
pub fn third_pole(rule: ThirdPoleRule, ts: f64) -> Pole {
    match rule {
        ThirdPoleRule::Delta => Pole::real(-1.9 / ts),
        ThirdPoleRule::Mapped => {
            Pole::from_complex(continuous_to_delta(Complex::new(-1.9 / ts, 0.0), ts))
        }
    }
}

/// The thesis's third (integrator) pole read literally, `p3 = -1.9/Ts` (6.5.3,
/// [`ThirdPoleRule::Delta`]).
pub fn default_third_pole(ts: f64) -> Pole {
    third_pole(ThirdPoleRule::Delta, ts)
}
