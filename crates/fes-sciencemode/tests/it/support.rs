//! What the vector tests share: encode a packet, wrap forged packet data, decode a byte
//! stream, and check a vector both ways.

use fes_sciencemode::{DecodeError, Decoder, MAX_PACKET_LEN, Packet, crc8};

/// The packet's bytes on the wire.
pub fn encode(p: &Packet) -> Vec<u8> {
    let mut buf = [0u8; MAX_PACKET_LEN];
    let n = p.encode(&mut buf).unwrap();
    buf[..n].to_vec()
}

/// The packet around packet data `stuffed` as sent (§2.2): start byte, the checksum and
/// the length (each always stuffed), the data, stop byte. Tests that forge a stream build
/// it with this, stuffing the data themselves.
pub fn wrap(stuffed: &[u8]) -> Vec<u8> {
    let mut out = vec![
        0xF0,
        0x81,
        crc8(stuffed) ^ 0x55,
        0x81,
        u8::try_from(stuffed.len()).unwrap() ^ 0x55,
    ];
    out.extend(stuffed);
    out.push(0x0F);
    out
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
