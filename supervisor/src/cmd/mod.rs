//! Subcommands of the daemon's binary: the daemon ([`run`]) and the operator client
//! ([`client`]: `set`, `profile`, `stop`, `arm`, `status`). The offline tools and the bench
//! are the workbench's (`fes`).

pub mod client;
pub mod run;
