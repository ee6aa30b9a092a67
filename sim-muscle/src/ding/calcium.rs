//! The Ca2+-troponin complex CN (Ding et al. 2002), discretised exactly.
//!
//! Each pulse i adds `(R_i/tauc) (t - t_i) exp(-(t - t_i)/tauc)` to CN. Written as the
//! linear system `du/dt = -u/tauc + sum_i R_i delta(t - t_i)`, `dCN/dt = (u - CN)/tauc`
//! (u is the sum `sum_i R_i exp(-(t - t_i)/tauc)` of the CN equation), it has the exact
//! solution between pulses used here, so CN carries no integration error.

/// The CN state: `u` (the exponentially weighted pulse sum) and `cn`, plus the time since
/// the last pulse for the catch-like term `R_i`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calcium {
    u: f64,
    cn: f64,
    since_pulse: f64,
}

impl Default for Calcium {
    fn default() -> Self {
        Self::REST
    }
}

impl Calcium {
    /// No CN and no stimulation history (the previous pulse infinitely long ago).
    pub const REST: Calcium = Calcium {
        u: 0.0,
        cn: 0.0,
        since_pulse: f64::INFINITY,
    };

    /// The catch-like enhancement of the next pulse,
    /// `R_i = 1 + (r0 - 1) exp(-(t_i - t_{i-1})/tauc)` (Ding et al. 2002); 1 for the first
    /// pulse after rest.
    pub fn enhancement(&self, r0: f64, tauc: f64) -> f64 {
        1.0 + (r0 - 1.0) * (-self.since_pulse / tauc).exp()
    }

    /// Delivers a pulse now with enhancement `r` (see [`Calcium::enhancement`]).
    pub fn fire(&mut self, r: f64) {
        self.u += r;
        self.since_pulse = 0.0;
    }

    /// CN `tau` seconds from now if no pulse comes: `(cn + u tau/tauc) exp(-tau/tauc)`.
    pub fn cn_after(&self, tau: f64, tauc: f64) -> f64 {
        (self.cn + self.u * tau / tauc) * (-tau / tauc).exp()
    }

    /// Advances the state `h` seconds without a pulse (exact).
    pub fn advance(&mut self, h: f64, tauc: f64) {
        let decay = (-h / tauc).exp();
        self.cn = (self.cn + self.u * h / tauc) * decay;
        self.u *= decay;
        self.since_pulse += h;
    }

    /// Current CN (dimensionless).
    pub fn cn(&self) -> f64 {
        self.cn
    }

    /// Whether CN and its driving sum have decayed below `eps`.
    pub fn is_below(&self, eps: f64) -> bool {
        self.u.abs() < eps && self.cn.abs() < eps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The exact step agrees with the closed-form single-pulse response
    /// `(t/tauc) exp(-t/tauc)` after many small steps (identity, 1e-12).
    #[test]
    fn single_pulse_matches_closed_form() {
        let tauc = 0.02;
        let mut c = Calcium::REST;
        assert_eq!(c.enhancement(5.0, tauc), 1.0);
        c.fire(1.0);
        let h = 1e-3;
        for k in 1..=200 {
            c.advance(h, tauc);
            let t = k as f64 * h;
            let exact = t / tauc * (-t / tauc).exp();
            assert!((c.cn() - exact).abs() < 1e-12, "k = {k}");
        }
    }

    /// The catch-like term of a pulse 5 ms after another equals its formula.
    #[test]
    fn enhancement_after_short_interval() {
        let tauc = 0.01;
        let mut c = Calcium::REST;
        c.fire(1.0);
        c.advance(0.005, tauc);
        let expected = 1.0 + 4.0 * (-0.5f64).exp();
        assert!((c.enhancement(5.0, tauc) - expected).abs() < 1e-15);
    }
}
