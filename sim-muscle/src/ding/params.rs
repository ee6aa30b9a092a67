//! Parameters of the Ding / Wexler / Binder-Macleod force model, in SI units.

use serde::{Deserialize, Serialize};

/// Why a parameter set or a parameter assignment was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// `--set NAME=VALUE` named a parameter the model does not have.
    #[error("unknown parameter `{name}`; known parameters: {known}")]
    Unknown {
        /// The name given.
        name: String,
        /// The accepted names, comma-separated.
        known: String,
    },
    /// A value is NaN or infinite.
    #[error("parameter `{name}` = {value} is not a finite number")]
    NotFinite {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
    },
    /// A value is outside its physical range.
    #[error("parameter `{name}` = {value} is out of range: {requirement}")]
    OutOfRange {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
        /// What the value must satisfy.
        requirement: &'static str,
    },
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<(), ParamError> {
    finite(name, value)?;
    if value > 0.0 {
        Ok(())
    } else {
        Err(ParamError::OutOfRange {
            name,
            value,
            requirement: "must be > 0",
        })
    }
}

/// Checks that `value` is finite and not negative.
pub(crate) fn non_negative(name: &'static str, value: f64) -> Result<(), ParamError> {
    finite(name, value)?;
    if value >= 0.0 {
        Ok(())
    } else {
        Err(ParamError::OutOfRange {
            name,
            value,
            requirement: "must be >= 0",
        })
    }
}

/// Checks that `value` is finite.
pub(crate) fn finite(name: &'static str, value: f64) -> Result<(), ParamError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ParamError::NotFinite { name, value })
    }
}

/// The six parameters of the Ding force model (Ding, Wexler & Binder-Macleod 2002, 2003),
/// named as in the papers, in SI units (the papers use ms; 1 ms = 1e-3 s, 1 N/ms = 1000 N/s).
///
/// CN is the normalised Ca2+-troponin complex, F the force:
/// - `dCN/dt = (1/tauc) sum_i R_i exp(-(t - t_i)/tauc) - CN/tauc`,
///   `R_i = 1 + (r0 - 1) exp(-(t_i - t_{i-1})/tauc)`;
/// - `dF/dt = a CN/(km + CN) - F/(tau1 + tau2 CN/(km + CN))`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DingParams {
    /// Time constant of the rise and decay of CN, s.
    pub tauc: f64,
    /// Magnitude of the enhancement of CN by a closely following pulse (the catch-like
    /// term); 1 means no enhancement. Dimensionless, >= 1.
    pub r0: f64,
    /// Sensitivity of strongly bound cross-bridges to CN. Dimensionless, > 0.
    pub km: f64,
    /// Scaling factor of the force, N/s.
    pub a: f64,
    /// Time constant of force decline without strongly bound cross-bridges, s.
    pub tau1: f64,
    /// Time constant of force decline due to the friction between actin and myosin, s.
    pub tau2: f64,
}

impl DingParams {
    /// Parameter names accepted by [`DingParams::get_mut`] and `--set`, with their units.
    pub const NAMES: [(&'static str, &'static str); 6] = [
        ("tauc", "s"),
        ("r0", "1"),
        ("km", "1"),
        ("a", "N/s"),
        ("tau1", "s"),
        ("tau2", "s"),
    ];

    /// Checks every parameter against its physical range.
    pub fn validate(&self) -> Result<(), ParamError> {
        positive("tauc", self.tauc)?;
        finite("r0", self.r0)?;
        if self.r0 < 1.0 {
            return Err(ParamError::OutOfRange {
                name: "r0",
                value: self.r0,
                requirement: "must be >= 1 (1 = no enhancement of CN)",
            });
        }
        positive("km", self.km)?;
        positive("a", self.a)?;
        positive("tau1", self.tau1)?;
        non_negative("tau2", self.tau2)?;
        Ok(())
    }

    /// Returns a mutable reference to the parameter called `name`, if there is one.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut f64> {
        match name {
            "tauc" => Some(&mut self.tauc),
            "r0" => Some(&mut self.r0),
            "km" => Some(&mut self.km),
            "a" => Some(&mut self.a),
            "tau1" => Some(&mut self.tau1),
            "tau2" => Some(&mut self.tau2),
            _ => None,
        }
    }

    /// The parameters as (name, value) pairs, in the order of [`DingParams::NAMES`].
    pub fn entries(&self) -> [(&'static str, f64); 6] {
        [
            ("tauc", self.tauc),
            ("r0", self.r0),
            ("km", self.km),
            ("a", self.a),
            ("tau1", self.tau1),
            ("tau2", self.tau2),
        ]
    }
}
