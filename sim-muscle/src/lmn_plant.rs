//! An LMN model file as the muscle (the thesis's own test setup, 6.5): the model's
//! normalised output times its force scale, in newtons, through rt-core's model code.

use std::path::Path;

use fes_model::model::file::{self, FileError};
use fes_model::model::{Lmn, NetworkError, ThesisForm, lmn::LmnError};

use crate::plant::{MusclePlant, Pulse};

/// Why an LMN plant could not be built.
#[derive(Debug, thiserror::Error)]
pub enum LmnPlantError {
    /// The model file could not be loaded (the message names the field).
    #[error("model file: {0}")]
    File(#[from] FileError),
    /// The model is invalid.
    #[error("model: {0}")]
    Model(#[from] LmnError),
    /// The network could not be started.
    #[error("model network: {0}")]
    Network(#[from] NetworkError),
    /// The model has no input delay, so its output at the end of a sample could depend
    /// on the pulse of the next one.
    #[error(
        "the model has delay_samples = 0; a plant needs d >= 1 (the thesis's models use d = 7)"
    )]
    NoDelay,
}

/// An LMN as a [`MusclePlant`].
///
/// `MusclePlant::step` fires the pulse of sample k and returns the force at the end of it,
/// y\[k+1\]; rt-core's thesis form returns y\[k\]. The network is an undelayed core followed
/// by a pure d-sample delay (rt-core `docs/model.md`, convention 4), so running it with
/// d - 1 gives y\[k+1\] exactly; a pulse at sample k then first shows at k + d + 1, as in
/// the data sets the model was identified from.
#[derive(Debug, Clone)]
pub struct LmnPlant {
    form: ThesisForm<f64>,
    at_rest: ThesisForm<f64>,
    scale_n: f64,
    rest_n: f64,
    ts: f64,
}

impl LmnPlant {
    /// The plant of a validated model; force = output x `lmn.force_scale_n`.
    pub fn new(lmn: &Lmn) -> Result<Self, LmnPlantError> {
        if lmn.delay == 0 {
            return Err(LmnPlantError::NoDelay);
        }
        let shifted = Lmn {
            delay: lmn.delay - 1,
            ..lmn.clone()
        };
        let at_rest = ThesisForm::new(shifted.network()?)?;
        // With no pulse the output from rest stays constant: that value is the rest force.
        let rest_n = at_rest.clone().step(0.0) * lmn.force_scale_n;
        Ok(Self {
            form: at_rest.clone(),
            at_rest,
            scale_n: lmn.force_scale_n,
            rest_n,
            ts: lmn.ts,
        })
    }

    /// Loads a model file (every local model must be stable) and builds the plant.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LmnPlantError> {
        Self::new(&file::load(path)?)
    }

    /// Newtons per unit of model output.
    pub fn scale_n(&self) -> f64 {
        self.scale_n
    }
}

impl MusclePlant for LmnPlant {
    fn ts(&self) -> f64 {
        self.ts
    }

    fn step(&mut self, pulse: Option<Pulse>) -> f64 {
        // Supramaximal stimulation: a pulse with charge is u = 1 (thesis 5.1.1).
        let delivered = pulse.is_some_and(|p| p.amplitude_ma > 0.0 && p.width_us > 0.0);
        self.form.step(if delivered { 1.0 } else { 0.0 }) * self.scale_n
    }

    fn reset(&mut self) {
        self.form.clone_from(&self.at_rest);
    }

    fn initial_force(&mut self) -> f64 {
        self.rest_n
    }
}
