//! `stim-driver` (being written).
fn main() {}
