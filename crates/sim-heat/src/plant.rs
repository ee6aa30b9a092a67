//! The air heater (thesis App. E.1, Fig. E.1) from first principles, in the spirit of the
//! thesis's rig and of Johansen & Foss (1995).
//!
//! A fan pulls air through an inlet valve (angle alpha) and a tube; a resistor at the tube
//! input heats it and a temperature sensor at the outlet measures it. Between two samples
//! the plant is integrated exactly (every stage is linear with constant coefficients over a
//! sub-step of `Ts / substeps`, inputs held):
//!
//! 1. **Voltage to heat** (E.1, "non-linear in the voltage"): Joule heating,
//!    p(u) = (u / u_max)^2 in [0, 1] (P = u^2 / R normalised by the full-scale power).
//! 2. **Heat conduction inside the resistor**: a pure delay of `conduction_delay_s`
//!    between the voltage and the heat reaching the air. The valve acts on the air
//!    directly, so this is the ~0.1 s by which the u -> y delay exceeds the alpha -> y
//!    delay (Table E.1).
//! 3. **Air heating** (E.1, "a larger angle increases the volume of air ... the
//!    temperature will decrease"): the air leaving the heater, theta (K above ambient),
//!    follows tau_e(alpha) theta' = K(alpha) p - theta. The energy balance gives
//!    K(alpha) = `gain_k` / q(alpha) with the relative mass flow
//!    q(alpha) = 1 + (`flow_ratio` - 1)(alpha - 20 deg) / 100 deg (q = 1 at 20 deg,
//!    `flow_ratio` at 120 deg): the gain falls as the valve opens (Fig. E.4a). Convective
//!    heat transfer grows with the flow (King's law, h ~ q^0.5), so
//!    tau_e(alpha) = `tau_heater_s` / sqrt(q(alpha)): the plant is faster with the valve
//!    open (Fig. E.7, bottom: the pole moves inwards as alpha grows).
//! 4. **Transport along the tube**: plug flow at speed v(alpha); the outlet sees the air
//!    that left the heater when it had travelled one tube length since. The transit time
//!    at constant angle is T_t(alpha) = `transport_s` (beta - alpha) / (beta - 20 deg)
//!    with beta = `valve_beta_deg` (the speed in the tube grows hyperbolically as the
//!    valve's resistance vanishes). With the conduction delay this reproduces Table E.1:
//!    the dead time u -> y, 0.1 s + T_t, falls from 0.24 s at 20 deg to 0.11 s at 120 deg,
//!    and alpha -> y (T_t alone) is 0.1 s shorter. Read off the step responses as the
//!    thesis read Fig. E.4(b) ([`step_delay`]; the sensor's lag adds a little), the delays
//!    are 6, 5, 5, 4, 3 samples u -> y and 4, 4, 3, 2, 1 alpha -> y at 20, 40, 60, 90, 120
//!    deg, against Table E.1's 6, 5, 5, 4, 2 and 4, 3, 3, 2, < 1.
//! 5. **Sensor**: a first-order lag `sensor_tau_s` (the thermistor's mass; together with
//!    step 3 the 1st/2nd-order step responses of Fig. E.4-E.5) plus seeded Gaussian
//!    measurement noise of `noise_std_k` (E.2: "the recorded data contain noise").
//!
//! The output is the outlet temperature in degrees Celsius (the thesis's y is the sensor's
//! voltage; with a linear sensor they differ by a scale). Sampling convention: [`HeatPlant::step`]
//! returns the measurement y\[k\] at t = k Ts, then holds alpha\[k\], u\[k\] over
//! \[k Ts, (k + 1) Ts) (a DAC), so a dead time T shows as a delay of about T / Ts samples.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The thesis's sample period (E.2: "The sampling period was chosen at Ts = 0.05 s").
pub const TS_S: f64 = 0.05;
/// The test angles of the test-voltage experiment and of Table E.1, in degrees.
pub const TEST_ANGLES_DEG: [f64; 5] = [20.0, 40.0, 60.0, 90.0, 120.0];
/// Table E.1: T_d,u / Ts at [`TEST_ANGLES_DEG`].
pub const TABLE_E1_DELAY_U: [usize; 5] = [6, 5, 5, 4, 2];
/// Table E.1: T_d,alpha / Ts at [`TEST_ANGLES_DEG`] (the thesis's "< 1" at 120 deg as 0).
pub const TABLE_E1_DELAY_ALPHA: [usize; 5] = [4, 3, 3, 2, 0];

/// Why a parameter set was rejected.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum HeatParamError {
    /// A parameter is not finite or out of its range.
    #[error("heat plant parameter `{name}` = {value} is invalid: {problem}")]
    Invalid {
        /// The field name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is required.
        problem: &'static str,
    },
}

/// The plant's physical parameters. [`Default`] gives the thesis's rig as read from App. E:
/// each field's doc names the table or figure it reproduces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeatParams {
    /// Sample period, s (E.2: 0.05 s).
    pub ts_s: f64,
    /// Integration sub-steps per sample (10: 5 ms, fine against every time constant).
    pub substeps: usize,
    /// Ambient (inlet air) temperature, deg C.
    pub ambient_c: f64,
    /// Full-scale heater voltage, V (the 4 V steps of Fig. E.4 are 40 % of it).
    pub u_max_v: f64,
    /// Steady outlet temperature rise at alpha = 20 deg and full voltage, K (sets the scale
    /// that E.2's normalisation maps to 1).
    pub gain_k: f64,
    /// Relative mass flow at 120 deg against 20 deg (Fig. E.4a: the gain u -> y at 120 deg
    /// is 1 / `flow_ratio` of the gain at 20 deg). 5 is the variation at which a linear
    /// controller designed at mid angle overshoots nearly closed, as in Fig. E.8 (at 2.5
    /// it does not: docs/heat-transfer.md).
    pub flow_ratio: f64,
    /// Time constant of the air heating at 20 deg, s (Table E.2: the 1st-order ARX poles
    /// 0.91-0.95 at Ts = 50 ms; with `flow_ratio` 5 the heater's time constant runs from
    /// 0.5 s at 20 deg to 0.22 s at 120 deg, and the identified poles are 0.89-0.97).
    pub tau_heater_s: f64,
    /// Heat conduction delay in the resistor, s (Table E.1: T_d,alpha is about 0.1 s
    /// smaller than T_d,u).
    pub conduction_delay_s: f64,
    /// Transit time through the tube at 20 deg, s (Table E.1: T_d,alpha = 0.20 s at 20
    /// deg; 0.14 s plus the sensor's lag reads as 4 samples).
    pub transport_s: f64,
    /// Angle at which the valve would offer no resistance, deg (> 120; Table E.1's fall of
    /// the delay to 0.10 s at 120 deg).
    pub valve_beta_deg: f64,
    /// Sensor time constant, s (the gently curved start of the responses of Fig. E.4b).
    pub sensor_tau_s: f64,
    /// Standard deviation of the measurement noise, K (E.2: noise, removed by the mean
    /// filter).
    pub noise_std_k: f64,
}

impl Default for HeatParams {
    fn default() -> Self {
        Self {
            ts_s: TS_S,
            substeps: 10,
            ambient_c: 20.0,
            u_max_v: 10.0,
            gain_k: 40.0,
            flow_ratio: 5.0,
            tau_heater_s: 0.5,
            conduction_delay_s: 0.1,
            transport_s: 0.14,
            valve_beta_deg: 125.0,
            sensor_tau_s: 0.03,
            noise_std_k: 0.25,
        }
    }
}

impl HeatParams {
    /// Checks every parameter's range.
    pub fn validate(&self) -> Result<(), HeatParamError> {
        let positive = [
            ("ts_s", self.ts_s),
            ("u_max_v", self.u_max_v),
            ("gain_k", self.gain_k),
            ("flow_ratio", self.flow_ratio),
            ("tau_heater_s", self.tau_heater_s),
            ("transport_s", self.transport_s),
            ("sensor_tau_s", self.sensor_tau_s),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(HeatParamError::Invalid {
                    name,
                    value,
                    problem: "must be finite and > 0",
                });
            }
        }
        for (name, value) in [
            ("conduction_delay_s", self.conduction_delay_s),
            ("noise_std_k", self.noise_std_k),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(HeatParamError::Invalid {
                    name,
                    value,
                    problem: "must be finite and >= 0",
                });
            }
        }
        if !(self.ambient_c.is_finite()) {
            return Err(HeatParamError::Invalid {
                name: "ambient_c",
                value: self.ambient_c,
                problem: "must be finite",
            });
        }
        if !(self.valve_beta_deg.is_finite() && self.valve_beta_deg > MAX_ANGLE_DEG) {
            return Err(HeatParamError::Invalid {
                name: "valve_beta_deg",
                value: self.valve_beta_deg,
                problem: "must be finite and above the largest angle, 120 deg",
            });
        }
        if self.substeps == 0 || self.substeps > 1000 {
            return Err(HeatParamError::Invalid {
                name: "substeps",
                value: self.substeps as f64,
                problem: "must be in 1..=1000",
            });
        }
        Ok(())
    }

    /// Sub-step length h = Ts / substeps, s.
    pub fn h(&self) -> f64 {
        self.ts_s / self.substeps as f64
    }

    /// Relative mass flow q(alpha) (1 at 20 deg, `flow_ratio` at 120 deg).
    pub fn flow(&self, alpha_deg: f64) -> f64 {
        let a = alpha_deg.clamp(MIN_ANGLE_DEG, MAX_ANGLE_DEG);
        1.0 + (self.flow_ratio - 1.0) * (a - MIN_ANGLE_DEG) / (MAX_ANGLE_DEG - MIN_ANGLE_DEG)
    }

    /// Steady air temperature rise per unit of normalised heat, K(alpha), K.
    pub fn heating_gain(&self, alpha_deg: f64) -> f64 {
        self.gain_k / self.flow(alpha_deg)
    }

    /// Air heating time constant tau_e(alpha), s.
    pub fn heating_tau(&self, alpha_deg: f64) -> f64 {
        self.tau_heater_s / self.flow(alpha_deg).sqrt()
    }

    /// Tube transit time at a constant angle, T_t(alpha), s.
    pub fn transit(&self, alpha_deg: f64) -> f64 {
        let a = alpha_deg.clamp(MIN_ANGLE_DEG, MAX_ANGLE_DEG);
        self.transport_s * (self.valve_beta_deg - a) / (self.valve_beta_deg - MIN_ANGLE_DEG)
    }

    /// Normalised heat of a voltage, p(u) = (u / u_max)^2 (u clamped into [0, u_max]).
    pub fn heat(&self, u_v: f64) -> f64 {
        let r = u_v.clamp(0.0, self.u_max_v) / self.u_max_v;
        r * r
    }

    /// The steady outlet temperature at constant inputs, deg C (no noise).
    pub fn steady_output(&self, alpha_deg: f64, u_v: f64) -> f64 {
        self.ambient_c + self.heating_gain(alpha_deg) * self.heat(u_v)
    }
}

/// Smallest valve angle of the rig's range, deg (E.2's smallest test angle).
pub const MIN_ANGLE_DEG: f64 = 20.0;
/// Largest valve angle of the rig's range, deg (E.2's largest test angle).
pub const MAX_ANGLE_DEG: f64 = 120.0;

/// Capacity of the tube history in sub-steps: the longest transit (`transport_s` scaled to
/// 20 deg) must fit; 4096 sub-steps are 20 s at the default 5 ms.
const HISTORY: usize = 4096;

/// The simulated heater: state and seeded noise.
#[derive(Debug, Clone)]
pub struct HeatPlant {
    p: HeatParams,
    alpha: f64,
    /// Heat entering the air, a FIFO of the conduction delay (sub-steps).
    conduction: Vec<f64>,
    conduction_at: usize,
    /// Air temperature rise leaving the heater, K.
    theta: f64,
    /// Distance travelled by the air since the start, in tube lengths, per sub-step (ring),
    /// with theta at that instant.
    hist_x: Vec<f64>,
    hist_theta: Vec<f64>,
    hist_at: usize,
    hist_len: usize,
    x: f64,
    /// Sensor state, K above ambient.
    sensor: f64,
    rng: ChaCha8Rng,
    noise: Option<Normal<f64>>,
}

impl HeatPlant {
    /// A plant at rest (no heat, ambient temperature everywhere) at angle `alpha_deg`, its
    /// noise drawn from `seed`.
    pub fn new(params: HeatParams, seed: u64, alpha_deg: f64) -> Result<Self, HeatParamError> {
        params.validate()?;
        let noise = if params.noise_std_k > 0.0 {
            Some(
                Normal::new(0.0, params.noise_std_k).map_err(|_| HeatParamError::Invalid {
                    name: "noise_std_k",
                    value: params.noise_std_k,
                    problem: "must be a standard deviation",
                })?,
            )
        } else {
            None
        };
        let nc = (params.conduction_delay_s / params.h()).round() as usize;
        let mut plant = Self {
            p: params,
            alpha: alpha_deg,
            conduction: vec![0.0; nc.max(1)],
            conduction_at: 0,
            theta: 0.0,
            hist_x: vec![0.0; HISTORY],
            hist_theta: vec![0.0; HISTORY],
            hist_at: 0,
            hist_len: 0,
            x: 0.0,
            sensor: 0.0,
            rng: ChaCha8Rng::seed_from_u64(seed),
            noise,
        };
        plant.settle(alpha_deg, 0.0);
        Ok(plant)
    }

    /// The parameters.
    pub fn params(&self) -> &HeatParams {
        &self.p
    }

    /// Puts the plant into its steady state at constant inputs (every stage at
    /// equilibrium, the tube filled with equally warm air).
    pub fn settle(&mut self, alpha_deg: f64, u_v: f64) {
        let heat = self.p.heat(u_v);
        self.alpha = alpha_deg;
        self.conduction.iter_mut().for_each(|c| *c = heat);
        self.theta = self.p.heating_gain(alpha_deg) * heat;
        self.hist_theta.iter_mut().for_each(|t| *t = self.theta);
        // A uniform history at the current speed: sub-step j back is at x - j h / T_t.
        let dx = self.p.h() / self.p.transit(alpha_deg);
        self.x = HISTORY as f64 * dx;
        self.hist_at = HISTORY - 1;
        for j in 0..HISTORY {
            self.hist_x[(self.hist_at + HISTORY - j) % HISTORY] = self.x - j as f64 * dx;
        }
        self.hist_len = HISTORY;
        self.sensor = self.theta;
    }

    /// The noise-free outlet temperature now, deg C.
    pub fn clean_output(&self) -> f64 {
        self.p.ambient_c + self.sensor
    }

    /// One sample: returns the measurement y\[k\] (deg C, noisy) at t = k Ts, then holds
    /// `alpha_deg` and `u_v` for one sample period.
    pub fn step(&mut self, alpha_deg: f64, u_v: f64) -> f64 {
        let noise = match &self.noise {
            Some(n) => n.sample(&mut self.rng),
            None => 0.0,
        };
        let y = self.clean_output() + noise;
        self.advance(alpha_deg, u_v);
        y
    }

    /// Advances one sample period with the inputs held (module docs, stages 1-5).
    pub fn advance(&mut self, alpha_deg: f64, u_v: f64) {
        let p = self.p;
        let h = p.h();
        self.alpha = alpha_deg.clamp(MIN_ANGLE_DEG, MAX_ANGLE_DEG);
        let heat = p.heat(u_v);
        let gain = p.heating_gain(self.alpha);
        let e_heat = (-h / p.heating_tau(self.alpha)).exp();
        let e_sensor = (-h / p.sensor_tau_s).exp();
        let dx = h / p.transit(self.alpha);
        for _ in 0..p.substeps {
            // 2. conduction delay (FIFO)
            let delayed = self.conduction[self.conduction_at];
            self.conduction[self.conduction_at] = heat;
            self.conduction_at = (self.conduction_at + 1) % self.conduction.len();
            // 3. air heating, exact for the held input
            self.theta = gain * delayed + (self.theta - gain * delayed) * e_heat;
            // 4. plug flow: record (x, theta), read theta at x - 1
            self.x += dx;
            self.hist_at = (self.hist_at + 1) % HISTORY;
            self.hist_x[self.hist_at] = self.x;
            self.hist_theta[self.hist_at] = self.theta;
            self.hist_len = (self.hist_len + 1).min(HISTORY);
            let outlet = self.outlet(self.x - 1.0);
            // 5. sensor lag
            self.sensor = outlet + (self.sensor - outlet) * e_sensor;
        }
    }

    /// theta of the air parcel that was at the heater when the travelled distance was
    /// `x_back` (linear interpolation between sub-steps; the oldest value if it is older
    /// than the history).
    fn outlet(&self, x_back: f64) -> f64 {
        let mut newer = self.hist_at;
        for j in 1..self.hist_len {
            let older = (self.hist_at + HISTORY - j) % HISTORY;
            let (xo, xn) = (self.hist_x[older], self.hist_x[newer]);
            if xo <= x_back {
                let f = if xn > xo {
                    (x_back - xo) / (xn - xo)
                } else {
                    1.0
                };
                return self.hist_theta[older]
                    + f * (self.hist_theta[newer] - self.hist_theta[older]);
            }
            newer = older;
        }
        self.hist_theta[newer]
    }
}

/// Which input a step is applied to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepInput {
    /// The heater voltage (Fig. E.4: 4 V steps).
    Voltage,
    /// The valve angle (Fig. E.5).
    Angle,
}

/// The delay in samples read off a noise-free step response at `alpha_deg`, as one reads it
/// off Fig. E.4(b): the plant settled, the step applied at sample k0, the delay is the
/// number of samples until the response first exceeds 2 % of its final change.
///
/// Voltage: from 3 V to 7 V (a 4 V step, Fig. E.4). Angle: by 10 deg at 7 V, downwards
/// (closing) except at the smallest angle, where it opens.
pub fn step_delay(
    params: &HeatParams,
    alpha_deg: f64,
    input: StepInput,
) -> Result<usize, HeatParamError> {
    let mut p = *params;
    p.noise_std_k = 0.0;
    let (a0, u0, a1, u1) = match input {
        StepInput::Voltage => (alpha_deg, 3.0, alpha_deg, 7.0),
        StepInput::Angle if alpha_deg - 10.0 >= MIN_ANGLE_DEG => {
            (alpha_deg, 7.0, alpha_deg - 10.0, 7.0)
        }
        StepInput::Angle => (alpha_deg, 7.0, alpha_deg + 10.0, 7.0),
    };
    let mut plant = HeatPlant::new(p, 0, a0)?;
    plant.settle(a0, u0);
    let y0 = plant.clean_output();
    let n = (30.0 / p.ts_s) as usize;
    let ys: Vec<f64> = (0..n).map(|_| plant.step(a1, u1)).collect();
    let change = ys[n - 1] - y0;
    let k = ys
        .iter()
        .position(|y| (y - y0).abs() > 0.02 * change.abs())
        .unwrap_or(n);
    Ok(k)
}
