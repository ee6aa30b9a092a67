//! # sim-muscle: a physiological muscle for the FES controller
//!
//! Stands in for the thesis's rabbit muscles (Gollee, ch. 5) with the Ding / Wexler /
//! Binder-Macleod force model, which shows the catch-like effect (4.2.3), a
//! force-frequency curve and, optionally, fatigue:
//!
//! - [`ding`]: the continuous-time model (CN exactly, force by RK4), fatigue (Ding 2003)
//!   and the pulse-width variant (Ding 2007).
//! - [`muscle`]: that model sampled at `ts` with an electromechanical delay, as a
//!   [`plant::MusclePlant`].
//! - [`preset`]: the `fast` (catch-like) and `slow` (chronically stimulated) muscles.
//! - [`sensor`]: force measurement: offset, seeded Gaussian noise, sensor low-pass.
//! - [`pattern`], [`simulate`]: pulse trains and the loop that runs a plant over one.
//! - [`metrics`]: FTI and FTIpP (eq. 6.1-6.3).
//! - [`protocol`], [`recorder`]: the thesis recording protocol (5.1) producing data sets in
//!   the `fes_dataset` format.
//! - [`plot`]: records drawn like thesis Fig. 5.2.

pub mod ding;
pub mod lmn_plant;
pub mod metrics;
pub mod muscle;
pub mod pattern;
pub mod plant;
pub mod plot;
pub mod preset;
pub mod protocol;
pub mod recorder;
pub mod sensor;
pub mod simulate;
