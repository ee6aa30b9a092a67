//! `supervisor` (to be written).
fn main() {
    eprintln!("supervisor: not built yet");
    std::process::exit(2);
}
