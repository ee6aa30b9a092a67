//! `sim-muscle` (to be written).
fn main() {
    eprintln!("sim-muscle: not built yet");
    std::process::exit(2);
}
