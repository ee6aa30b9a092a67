//! What the vector tests share: encode a packet, decode a byte stream, and check a vector
//! both ways.

use fes_sciencemode::{DecodeError, Decoder, MAX_PACKET_LEN, Packet};

/// The packet's bytes on the wire.
pub fn encode(p: &Packet) -> Vec<u8> {
    let mut buf = [0u8; MAX_PACKET_LEN];
    let n = p.encode(&mut buf).unwrap();
    buf[..n].to_vec()
}

/// Everything a fresh decoder yields for `bytes`.
pub fn decode_all(bytes: &[u8]) -> Vec<Result<Packet, DecodeError>> {
    Decoder::new().feed(bytes).collect()
}

/// `packet` encodes to exactly `wire`, and `wire` decodes to exactly `packet`.
#[track_caller]
pub fn check(packet: Packet, wire: &[u8]) {
    assert_eq!(encode(&packet), wire, "encoding {packet:?}");
    assert_eq!(decode_all(wire), [Ok(packet)], "decoding {wire:02X?}");
}
