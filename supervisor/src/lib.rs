//! The supervisor runtime: the slow side of the FES controller (thesis 1.1, 6.6).
//!
//! It publishes the force reference r(t) that rt-core's pattern generator follows, from
//! operator commands and profiles (constant, steps, ramps and the cardiac-assist square
//! wave of thesis 1.1); closes the slow outer loop ("Controller 1") on the measured
//! contraction of each beat; watches the health of every process of the stimulation
//! chain and stops stimulation on any fault; records every message of a run as a
//! `fes-dataset/1` data set. It is the safety daemon and its operator client; it links
//! neither plotting nor the muscle simulator (the offline tools and the bench are the
//! workbench, `fes`).
//!
//! The pure parts (profiles, outer loop, contraction estimate, reference limits, the
//! control protocol, the health rules, the supervisor state machine) take time as an
//! argument and do no I/O, so they are tested without processes. The I/O parts are
//! [`control`] (Unix socket), [`recording`] (files) and [`daemon`] (iceoryx2).

pub mod cli;
pub mod command_link;
pub mod config;
pub mod contraction;
pub mod control;
pub mod core;
pub mod daemon;
pub mod health;
pub mod limits;
pub mod outer_loop;
pub mod pass;
pub mod profile;
pub mod protocol;
pub mod range;
pub mod recording;
pub mod recording_thread;
