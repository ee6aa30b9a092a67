//! The end-to-end bench: the four processes on one bus ([`mod@bench`]: starting, watching and
//! stopping them), the chain in simulated time ([`simulation`], `fes bench --in-process`),
//! the bus's CAN log ([`canlog`]), the run's summary and verdicts ([`summary`],
//! [`baseline`], [`cft`]). `fes bench` (the workbench's binary) is its command line and
//! draws its figures. It builds on the supervisor's pure parts (profiles, outer loop,
//! protocol) and links the muscle simulator, which the safety daemon does not.

pub mod baseline;
pub mod bench;
pub mod canlog;
pub mod cft;
pub mod simulation;
pub mod summary;
