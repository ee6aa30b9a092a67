//! The scheduling variable phi (thesis 5.4.1).
//!
//! - **Input scheduling** (eq. 5.2-5.4): phi is the pulse train filtered by the critically
//!   damped low-pass G_pre(s) = K / (s^2 + 2 zeta w_n s + w_n^2), thesis values K = 25000,
//!   w_n = 50 rad/s, zeta = 1. It is discretised exactly with a zero-order hold at Ts
//!   ([`Prefilter`]); no Euler step. A pulse (u = 1 for one sample) then gives the samples
//!   s(kTs) - s((k-1)Ts) of the step response s(t), and a constant f Hz train gives a mean
//!   phi of (K / w_n^2) f Ts = f / 100 for the thesis values.
//! - **Output scheduling** (eq. 5.1): phi_k = y_{k-1}.
//!
//! Which input drives the prefilter is a property of the model class ([`SchedulingInput`]):
//! - [`SchedulingInput::Delayed`] (ours, the default): the DELAYED input u\[k-d\], the same
//!   input the local models see, so the whole network is an undelayed LPV core followed by a
//!   pure d-sample output delay (see [`super::network`]), and the controller can act on the
//!   state d samples ahead.
//! - [`SchedulingInput::Undelayed`] (eq. 5.2 as printed): phi(t) = Gamma{u(t)} filters the
//!   pulse train as it is applied, while the local models see u\[k-d\]. A pulse then reaches
//!   the local models when phi already carries its own contribution (a 2 ms doublet's second
//!   pulse lands at phi ~ 0.26 instead of ~ 0.035). The state d samples ahead depends on
//!   pulses not yet decided, so only the thesis's delayed loop runs on this class.

#[cfg(not(feature = "std"))]
use crate::num::math::FloatMath as _;
use serde::{Deserialize, Serialize};

/// The thesis's prefilter gain K (eq. 5.4).
pub const THESIS_PREFILTER_GAIN: f64 = 25_000.0;
/// The thesis's prefilter natural frequency w_n in rad/s (eq. 5.4).
pub const THESIS_PREFILTER_WN: f64 = 50.0;
/// The thesis's prefilter damping factor zeta (critically damped, eq. 5.3).
pub const THESIS_PREFILTER_ZETA: f64 = 1.0;

/// Why a scheduling specification was rejected.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SchedulingError {
    /// The prefilter gain K is zero, NaN or infinite.
    #[error("prefilter gain K = {0} must be finite and non-zero")]
    Gain(f64),
    /// The natural frequency is not a finite positive number.
    #[error("prefilter natural frequency w_n = {0} rad/s must be finite and > 0")]
    NaturalFrequency(f64),
    /// The damping factor is not a finite positive number.
    #[error("prefilter damping zeta = {0} must be finite and > 0")]
    Damping(f64),
    /// The sampling period is not a finite positive number.
    #[error("sampling period Ts = {0} s must be finite and > 0")]
    SamplingPeriod(f64),
    /// The discretised prefilter is not finite (parameters far outside any muscle's range).
    #[error(
        "prefilter w_n = {wn} rad/s, zeta = {zeta}, K = {gain} cannot be discretised at Ts = {ts} s: Phi or Gamma is not finite"
    )]
    Discretisation {
        /// K.
        gain: f64,
        /// w_n.
        wn: f64,
        /// zeta.
        zeta: f64,
        /// Ts.
        ts: f64,
    },
}

/// Which pulse train drives the prefilter (module docs). Stored in the model file as
/// `scheduling.scheduling_input`; a file without the field is [`SchedulingInput::Delayed`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SchedulingInput {
    /// phi filters u\[k-d\], the local models' input (ours; every file written before the
    /// choice was stored).
    #[default]
    Delayed,
    /// phi filters u\[k\] (eq. 5.2 read literally); the local models still see u\[k-d\].
    Undelayed,
}

impl SchedulingInput {
    /// The file's name of the choice.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Delayed => "delayed",
            Self::Undelayed => "undelayed",
        }
    }
}

/// How phi is obtained, as stored in the model file (`scheduling`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum SchedulingSpec {
    /// Input scheduling: phi = G_pre applied to the (delayed) pulse train (eq. 5.2-5.4).
    Input {
        /// K in G_pre(s) = K / (s^2 + 2 zeta w_n s + w_n^2).
        gain: f64,
        /// w_n in rad/s.
        natural_frequency_rad_s: f64,
        /// zeta (1 = critically damped).
        damping: f64,
        /// Which pulse train the prefilter filters.
        #[serde(default)]
        scheduling_input: SchedulingInput,
    },
    /// Output scheduling: phi_k = y_{k-1} (eq. 5.1).
    Output,
}

impl Default for SchedulingSpec {
    /// The thesis's prefilter (eq. 5.4).
    fn default() -> Self {
        Self::Input {
            gain: THESIS_PREFILTER_GAIN,
            natural_frequency_rad_s: THESIS_PREFILTER_WN,
            damping: THESIS_PREFILTER_ZETA,
            scheduling_input: SchedulingInput::Delayed,
        }
    }
}

impl SchedulingSpec {
    /// Which input drives phi ([`SchedulingInput::Delayed`] for output scheduling, whose
    /// phi_k = y_{k-1} is delayed with the output).
    pub fn scheduling_input(&self) -> SchedulingInput {
        match self {
            Self::Input {
                scheduling_input, ..
            } => *scheduling_input,
            Self::Output => SchedulingInput::Delayed,
        }
    }
}

/// The run-time scheduler: a discretised prefilter, or output feedback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Scheduler {
    /// Input scheduling through the exactly discretised prefilter, driven by the input the
    /// [`SchedulingInput`] names.
    Input(Prefilter, SchedulingInput),
    /// Output scheduling, phi_k = y_{k-1}.
    Output,
}

impl Scheduler {
    /// Builds the run-time scheduler for sampling period `ts`.
    pub fn new(spec: &SchedulingSpec, ts: f64) -> Result<Self, SchedulingError> {
        match *spec {
            SchedulingSpec::Input {
                gain,
                natural_frequency_rad_s,
                damping,
                scheduling_input,
            } => Ok(Self::Input(
                Prefilter::new(gain, natural_frequency_rad_s, damping, ts)?,
                scheduling_input,
            )),
            SchedulingSpec::Output => {
                if !(ts.is_finite() && ts > 0.0) {
                    return Err(SchedulingError::SamplingPeriod(ts));
                }
                Ok(Self::Output)
            }
        }
    }

    /// Which input drives phi.
    pub fn input(&self) -> SchedulingInput {
        match self {
            Self::Input(_, i) => *i,
            Self::Output => SchedulingInput::Delayed,
        }
    }
}

/// G_pre(s) = K / (s^2 + 2 zeta w_n s + w_n^2) discretised exactly with a zero-order hold:
/// w\[k+1\] = Phi w\[k\] + Gamma v\[k\], phi\[k\] = w_1\[k\], in the companion realisation
/// w_1' = w_2, w_2' = -w_n^2 w_1 - 2 zeta w_n w_2 + K v, with Phi = expm(A Ts) and
/// Gamma = A^-1 (Phi - I) B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prefilter {
    phi: [[f64; 2]; 2],
    gamma: [f64; 2],
    dc_gain: f64,
}

impl Prefilter {
    /// Discretises G_pre at sampling period `ts` (seconds).
    pub fn new(gain: f64, wn: f64, zeta: f64, ts: f64) -> Result<Self, SchedulingError> {
        if !(gain.is_finite() && gain != 0.0) {
            return Err(SchedulingError::Gain(gain));
        }
        if !(wn.is_finite() && wn > 0.0) {
            return Err(SchedulingError::NaturalFrequency(wn));
        }
        if !(zeta.is_finite() && zeta > 0.0) {
            return Err(SchedulingError::Damping(zeta));
        }
        if !(ts.is_finite() && ts > 0.0) {
            return Err(SchedulingError::SamplingPeriod(ts));
        }
        let a = [[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]];
        let phi = expm2(a, ts);
        // A^-1 = [[a11, -a01], [-a10, a00]] / det, det = w_n^2 > 0; B = [0, K].
        let det = wn * wn;
        let pm = [phi[0][1] * gain, (phi[1][1] - 1.0) * gain]; // (Phi - I) B
        let gamma = [
            (a[1][1] * pm[0] - a[0][1] * pm[1]) / det,
            (-a[1][0] * pm[0] + a[0][0] * pm[1]) / det,
        ];
        let dc_gain = gain / det;
        if !(phi.iter().flatten().chain(&gamma).all(|v| v.is_finite()) && dc_gain.is_finite()) {
            return Err(SchedulingError::Discretisation { gain, wn, zeta, ts });
        }
        Ok(Self {
            phi,
            gamma,
            dc_gain,
        })
    }

    /// The thesis prefilter (eq. 5.4) at sampling period `ts`.
    pub fn thesis(ts: f64) -> Result<Self, SchedulingError> {
        Self::new(
            THESIS_PREFILTER_GAIN,
            THESIS_PREFILTER_WN,
            THESIS_PREFILTER_ZETA,
            ts,
        )
    }

    /// The output phi\[k\] for filter state w\[k\].
    #[inline(always)]
    pub fn output(&self, w: &[f64; 2]) -> f64 {
        w[0]
    }

    /// w\[k+1\] = Phi w\[k\] + Gamma v\[k\].
    #[inline(always)]
    pub fn advance(&self, w: &mut [f64; 2], v: f64) {
        let w0 = self.phi[0][0] * w[0] + self.phi[0][1] * w[1] + self.gamma[0] * v;
        let w1 = self.phi[1][0] * w[0] + self.phi[1][1] * w[1] + self.gamma[1] * v;
        *w = [w0, w1];
    }

    /// Steady-state gain K / w_n^2 (the mean phi is this times the mean input).
    pub fn dc_gain(&self) -> f64 {
        self.dc_gain
    }

    /// Phi = expm(A Ts).
    pub fn transition(&self) -> [[f64; 2]; 2] {
        self.phi
    }

    /// Gamma = A^-1 (Phi - I) B.
    pub fn input_gain(&self) -> [f64; 2] {
        self.gamma
    }
}

/// Closed-form matrix exponential expm(A t) of a real 2x2 matrix.
///
/// With mu = tr(A)/2 and N = A - mu I, Cayley-Hamilton gives N^2 = q2 I, q2 = mu^2 - det A,
/// so expm(A t) = e^{mu t} (C(t) I + S(t) N) with C = cosh(sqrt(q2) t),
/// S = sinh(sqrt(q2) t)/sqrt(q2) (cos/sin for q2 < 0; a series near q2 t^2 = 0).
pub fn expm2(a: [[f64; 2]; 2], t: f64) -> [[f64; 2]; 2] {
    let mu = 0.5 * (a[0][0] + a[1][1]);
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    let q2 = mu * mu - det;
    let z = q2 * t * t;
    let (c, s) = if z.abs() < 1e-6 {
        // cosh(x) = sum z^k/(2k)!, sinh(x)/x * t = t sum z^k/(2k+1)!, x^2 = z; 4 terms give
        // a relative error below z^4/8! < 1e-27.
        (
            1.0 + z / 2.0 + z * z / 24.0 + z * z * z / 720.0,
            t * (1.0 + z / 6.0 + z * z / 120.0 + z * z * z / 5040.0),
        )
    } else if q2 > 0.0 {
        // e^{mu t} cosh(q t) as (e^{(mu+q)t} + e^{(mu-q)t})/2: the product form gives
        // 0 * inf = NaN for a heavily overdamped A (|mu| t in the hundreds).
        // The roots mu +- q, the smaller one from Vieta (r r' = det A) so that it keeps its
        // precision when |mu| >> q - |mu|.
        let q = q2.sqrt();
        let big = if mu <= 0.0 { mu - q } else { mu + q };
        let small = det / big;
        let (plus, minus) = if mu <= 0.0 {
            (small, big)
        } else {
            (big, small)
        };
        let (ep, em) = ((plus * t).exp(), (minus * t).exp());
        let (ec, es) = (0.5 * (ep + em), 0.5 * (ep - em) / q);
        return [
            [ec + es * (a[0][0] - mu), es * a[0][1]],
            [es * a[1][0], ec + es * (a[1][1] - mu)],
        ];
    } else {
        let q = (-q2).sqrt();
        ((q * t).cos(), (q * t).sin() / q)
    };
    let e = (mu * t).exp();
    [
        [e * (c + s * (a[0][0] - mu)), e * s * a[0][1]],
        [e * s * a[1][0], e * (c + s * (a[1][1] - mu))],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent truth: scaling and squaring, expm(A t) = expm(A t / 2^10)^(2^10), with
    /// the Taylor series (30 terms) for the scaled matrix.
    fn expm_series(a: [[f64; 2]; 2], t: f64) -> [[f64; 2]; 2] {
        let mul = |x: [[f64; 2]; 2], y: [[f64; 2]; 2]| {
            let mut r = [[0.0; 2]; 2];
            for i in 0..2 {
                for j in 0..2 {
                    r[i][j] = x[i][0] * y[0][j] + x[i][1] * y[1][j];
                }
            }
            r
        };
        let h = t / 1024.0;
        let ah = [[a[0][0] * h, a[0][1] * h], [a[1][0] * h, a[1][1] * h]];
        let mut term = [[1.0, 0.0], [0.0, 1.0]];
        let mut sum = term;
        for k in 1..30 {
            term = mul(term, ah);
            for row in term.iter_mut() {
                for x in row.iter_mut() {
                    *x /= k as f64;
                }
            }
            for i in 0..2 {
                for j in 0..2 {
                    sum[i][j] += term[i][j];
                }
            }
        }
        for _ in 0..10 {
            sum = mul(sum, sum);
        }
        sum
    }

    /// A heavily over-damped A (|mu| t = 800, beyond exp's range) gave 0 * inf = NaN.
    /// Independent truth: tr expm(A t) = e^{r1 t} + e^{r2 t} with the roots from Vieta
    /// (r1 = mu - q, r2 = det A / r1) and det expm(A t) = e^{tr(A) t} (Liouville).
    #[test]
    fn expm2_stays_finite_when_heavily_over_damped() {
        for (a, t) in [
            ([[0.0, 1.0], [-2500.0, -1.6e6]], 1e-3),
            ([[0.0, 1.0], [-2500.0, -4.3e11]], 1e-3),
        ] {
            let e = expm2(a, t);
            assert!(e.iter().flatten().all(|v| v.is_finite()), "{e:?}");
            let mu = 0.5 * a[1][1];
            let det = -a[1][0];
            let r1 = mu - (mu * mu - det).sqrt();
            let r2 = det / r1;
            let trace = (r1 * t).exp() + (r2 * t).exp();
            assert!(
                (e[0][0] + e[1][1] - trace).abs() < 1e-12,
                "{e:?} vs {trace}"
            );
            let d = e[0][0] * e[1][1] - e[0][1] * e[1][0];
            assert!(d.abs() < 1e-15, "{d}");
        }
        let p = Prefilter::new(25_000.0, 50.0, 4.294_967_296e9, 1e-3).unwrap();
        assert!(p.transition().iter().flatten().all(|v| v.is_finite()));
    }

    #[test]
    fn expm2_matches_series_in_all_three_regimes() {
        let cases = [
            [[0.0, 1.0], [-2500.0, -100.0]], // critically damped (q2 = 0)
            [[0.0, 1.0], [-2500.0, -30.0]],  // under-damped
            [[0.0, 1.0], [-2500.0, -180.0]], // over-damped
            [[-3.0, 2.0], [0.5, -7.0]],
        ];
        for a in cases {
            for &t in &[1e-3, 5e-3, 1e-2] {
                let e = expm2(a, t);
                let r = expm_series(a, t);
                for i in 0..2 {
                    for j in 0..2 {
                        assert!(
                            (e[i][j] - r[i][j]).abs() < 1e-12 * (1.0 + r[i][j].abs()),
                            "{a:?} t={t}: {e:?} vs {r:?}"
                        );
                    }
                }
            }
        }
    }
}
