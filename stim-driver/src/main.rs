//! `stim-driver` (to be written).
fn main() {
    eprintln!("stim-driver: not built yet");
    std::process::exit(2);
}
