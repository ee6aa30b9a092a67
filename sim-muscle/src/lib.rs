//! Virtual muscle and stimulator (to be written).
pub mod stimulator;
