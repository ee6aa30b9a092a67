//! The CAN decoder on any identifier and 0-16 bytes: a value or an error, never a panic;
//! an accepted frame re-encodes to exactly the bytes received (one meaning per frame).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((id, payload)) = data.split_first_chunk::<4>() else {
        return;
    };
    let id = u32::from_le_bytes(*id);
    let payload = &payload[..payload.len().min(16)];
    if let Ok(m) = fes_can::decode(id, payload) {
        let f = m.encode().expect("a decoded message re-encodes");
        assert_eq!(u32::from(f.id), id, "{m:?}");
        assert_eq!(f.payload(), payload, "{m:?}");
    }
});
