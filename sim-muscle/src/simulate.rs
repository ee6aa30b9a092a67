//! Running a plant over a stimulation pattern: the one loop the CLI, the recorder and
//! the metrics share.

use crate::plant::{MusclePlant, Pulse};

/// Force samples (N) of `plant` driven by `train` (1 = `pulse` at that sample's start).
///
/// Sample 0 is [`MusclePlant::initial_force`]; sample k+1 is the force after the step
/// that fires `train[k]`, so the result has `train.len()` samples at `t = k ts` and the
/// pulse of the last sample has no visible effect. The plant is not reset first.
pub fn simulate(plant: &mut dyn MusclePlant, train: &[bool], pulse: Pulse) -> Vec<f64> {
    let mut force = Vec::with_capacity(train.len());
    if train.is_empty() {
        return force;
    }
    force.push(plant.initial_force());
    for &fire in &train[..train.len() - 1] {
        force.push(plant.step(fire.then_some(pulse)));
    }
    force
}

/// The Ding muscle as a pattern-to-force map for the optimal-stimulation-pattern methods
/// of rt-core (`fes_ident::analysis::osp`): each pattern runs from rest, the rest force
/// removed, in newtons.
#[derive(Debug, Clone)]
pub struct MuscleResponse {
    muscle: crate::muscle::Muscle,
}

impl MuscleResponse {
    /// The response of `muscle` (reset before every pattern).
    pub fn new(muscle: crate::muscle::Muscle) -> Self {
        Self { muscle }
    }
}

impl fes_ident::analysis::osp::ForceResponse for MuscleResponse {
    fn ts(&self) -> f64 {
        self.muscle.ts()
    }

    fn force(&self, train: &[bool]) -> Result<Vec<f64>, fes_ident::analysis::osp::OspError> {
        let mut m = self.muscle.clone();
        m.reset();
        let rest = m.initial_force();
        let mut f = simulate(&mut m, train, Pulse::SUPRAMAXIMAL);
        for v in &mut f {
            *v -= rest;
        }
        Ok(f)
    }
}
