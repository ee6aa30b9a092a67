//! The workbench library: the end-to-end bench ([`mod@bench`]: the four processes on one
//! bus), the chain in simulated time ([`simulation`]), the run's summary and verdicts
//! ([`summary`], [`baseline`], [`cft`]) and their figures ([`plots`]). It builds on the
//! supervisor's pure parts (profiles, outer loop, protocol) and links the muscle simulator
//! and plotting, which the safety daemon does not.

pub mod baseline;
pub mod bench;
pub mod canlog;
pub mod cft;
pub mod data;
pub mod plots;
pub mod simulation;
pub mod summary;
pub mod variant_args;
