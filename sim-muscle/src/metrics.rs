//! Force-time integral of a plant's response (thesis 6.1). FTI and FTIpP themselves
//! (eq. 6.2-6.3) live in `fes_ident::analysis::osp`.

use crate::pattern::from_samples;
use crate::plant::{MusclePlant, Pulse};
use crate::simulate::simulate;

use fes_ident::analysis::osp::fti;

/// FTI (eq. 6.2) of the response of `plant`, from rest, to supramaximal pulses at the
/// sample indices `pulses`, over the window `[0, window ts)`. Choose `window` long enough
/// for the force to return to rest after the last pulse, or eq. (6.3) compares truncated
/// responses.
pub fn response_fti(plant: &mut dyn MusclePlant, pulses: &[usize], window: usize) -> f64 {
    plant.reset();
    let force = simulate(plant, &from_samples(pulses, window), Pulse::SUPRAMAXIMAL);
    fti(&force, plant.ts())
}
