//! The runtime's subcommands: the daemon (`run`), the operator client (`set`, `profile`,
//! `stop`, `arm`, `status`) and the end-to-end bench (`bench`).

pub mod bench;
pub mod client;
pub mod run;
