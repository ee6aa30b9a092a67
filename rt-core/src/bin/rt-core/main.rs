//! `rt-core`: the 1 ms real-time pattern generator process (to be written).
fn main() {
    eprintln!("rt-core: the real-time pattern generator is not built yet");
    std::process::exit(2);
}
