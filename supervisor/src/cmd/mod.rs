//! Subcommands, one module each, plus what the analysis commands share.

pub mod analyse;
pub mod design;
pub mod inputs;
pub mod modify;
pub mod osp;
pub mod plots;
