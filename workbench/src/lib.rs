//! The workbench library: what the offline tools of `fes` share, the data sets they read
//! ([`data`]), the options of the controller variants ([`variant_args`]) and the figures
//! ([`plots`], the bench's among them). The bench itself (the four processes, the chain in
//! simulated time, the summary, the CFT front) is the crate `fes_bench`.

pub mod data;
pub mod plots;
pub mod variant_args;
