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
