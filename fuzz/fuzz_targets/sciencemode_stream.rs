//! The ScienceMode 2 stream decoder on any bytes, fed in chunks whose sizes come from the
//! input: packets or errors, never a panic; every packet it yields has one meaning: it
//! re-encodes (in the description's stuffing, 2.2: only 0xF0, 0x0F and 0x81 escaped) to
//! bytes that decode to the same packet and are no longer than what was received (which
//! may escape other bytes too, as pyScienceMode does), whatever the chunking.
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
                assert!(consumed + i + 1 >= n, "{packet:?}");
                let again: Vec<_> = Decoder::new().feed(&buf[..n]).collect();
                assert_eq!(again, vec![Ok(packet)], "{packet:?}: {:02X?}", &buf[..n]);
            }
        }
        consumed += piece.len();
    }
});
