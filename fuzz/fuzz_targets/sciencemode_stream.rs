//! The ScienceMode 2 stream decoder on any bytes, fed in chunks whose sizes come from the
//! input: packets or errors, never a panic; every packet it yields re-encodes to exactly
//! the bytes it came from (one meaning per packet), whatever the chunking.
#![no_main]

use fes_sciencemode::{Decoder, MAX_PACKET_LEN};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, stream)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);
    let mut decoder = Decoder::new();
    let mut consumed = 0;
    for piece in stream.chunks(chunk) {
        for (i, &b) in piece.iter().enumerate() {
            if let Some(Ok(packet)) = decoder.push(b) {
                let mut buf = [0u8; MAX_PACKET_LEN];
                let n = packet
                    .encode(&mut buf)
                    .expect("a decoded packet re-encodes");
                let end = consumed + i + 1;
                assert!(end >= n, "{packet:?}");
                assert_eq!(&buf[..n], &stream[end - n..end], "{packet:?}");
            }
        }
        consumed += piece.len();
    }
});
