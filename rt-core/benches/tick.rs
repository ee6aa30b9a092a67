//! Criterion benchmark of the pattern-generator tick (to be written).
fn main() {}
