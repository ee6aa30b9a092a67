//! Virtual muscle and stimulator (to be written).
pub mod plant;
pub mod stimulator;
