//! CRC-8/SAE-J1850, the end-to-end checksum of PULSE frames.
//!
//! Parameters (Rocksoft model, as in the CRC catalogue and AUTOSAR's `Crc_CalculateCRC8`):
//! width 8, polynomial 0x1D (x^8 + x^4 + x^3 + x^2 + 1), init 0xFF, no reflection,
//! xorout 0xFF; check value ("123456789") 0x4B, residue 0xC4.
//!
//! A PULSE frame's CRC covers the frame's COB-ID (two bytes, little endian) followed by
//! payload bytes 0-6, so a frame copied onto another identifier fails the check (the
//! AUTOSAR E2E "data ID" idea).
//!
//! The arithmetic is the `crc` crate's, with its catalogue entry [`crc::CRC_8_SAE_J1850`]
//! and a lookup table it builds at compile time; this module only names the parameters and
//! keeps the register visible between updates.

use crc::{CRC_8_SAE_J1850, Crc};

/// The generator polynomial (normal notation, x^8 implicit): 0x1D.
pub const POLY: u8 = CRC_8_SAE_J1850.poly;
/// Initial register value: 0xFF.
pub const INIT: u8 = CRC_8_SAE_J1850.init;
/// Value XORed into the register before it is returned: 0xFF.
pub const XOR_OUT: u8 = CRC_8_SAE_J1850.xorout;

// The parameters the module doc and the wire format (docs/can-protocol.md) state.
const _: () = assert!(
    POLY == 0x1D
        && INIT == 0xFF
        && XOR_OUT == 0xFF
        && !CRC_8_SAE_J1850.refin
        && !CRC_8_SAE_J1850.refout
        && CRC_8_SAE_J1850.check == 0x4B
        && CRC_8_SAE_J1850.residue == 0xC4
);

/// The table-driven engine (one 256-byte table, built at compile time).
static J1850: Crc<u8> = Crc::<u8>::new(&CRC_8_SAE_J1850);

/// Incremental CRC-8/SAE-J1850 computation (no allocation, `const`-friendly state).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crc8 {
    register: u8,
}

impl Default for Crc8 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc8 {
    /// A fresh computation (register = [`INIT`]).
    pub const fn new() -> Self {
        Self { register: INIT }
    }

    /// Feeds `bytes` into the register.
    pub fn update(&mut self, bytes: &[u8]) -> &mut Self {
        // Width 8 and no reflection: the digest starts from the register as it is, and its
        // result is the register XOR `XOR_OUT`.
        let mut digest = J1850.digest_with_initial(self.register);
        digest.update(bytes);
        self.register = digest.finalize() ^ XOR_OUT;
        self
    }

    /// The register before the final XOR (compare with the catalogue's residue).
    pub const fn register(&self) -> u8 {
        self.register
    }

    /// The CRC value: the register XOR [`XOR_OUT`].
    pub const fn value(&self) -> u8 {
        self.register ^ XOR_OUT
    }
}

/// CRC-8/SAE-J1850 of `bytes`.
pub fn crc8(bytes: &[u8]) -> u8 {
    Crc8::new().update(bytes).value()
}

/// The PULSE frame CRC: CRC-8/SAE-J1850 over the COB-ID `id` (little endian, two bytes)
/// and the seven payload bytes that precede the CRC byte.
pub fn frame_crc(id: u16, payload: &[u8; 7]) -> u8 {
    Crc8::new()
        .update(&id.to_le_bytes())
        .update(payload)
        .value()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit-at-a-time reference (the textbook shift register), independent of the table.
    fn crc8_bitwise(bytes: &[u8]) -> u8 {
        let mut reg = INIT;
        for &b in bytes {
            reg ^= b;
            for _ in 0..8 {
                reg = if reg & 0x80 != 0 {
                    (reg << 1) ^ POLY
                } else {
                    reg << 1
                };
            }
        }
        reg ^ XOR_OUT
    }

    #[test]
    fn catalogue_check_value() {
        // CRC RevEng catalogue, CRC-8/SAE-J1850: check=0x4b residue=0xc4.
        assert_eq!(crc8(b"123456789"), 0x4B);
    }

    #[test]
    fn catalogue_residue() {
        // RevEng: the register after an error-free codeword (message then CRC), before
        // the final XOR, is the residue 0xC4 whatever the message.
        for msg in [&b"123456789"[..], &[0x00], &[0xDE, 0xAD, 0xBE, 0xEF]] {
            let crc = crc8(msg);
            let mut c = Crc8::new();
            c.update(msg).update(&[crc]);
            assert_eq!(c.register(), 0xC4, "message {msg:02X?}");
        }
    }

    #[test]
    fn autosar_crc_library_table() {
        // AUTOSAR SWS CRC Library, "8-bit SAE J1850 CRC Calculation" check table.
        let cases: [(&[u8], u8); 7] = [
            (&[0x00, 0x00, 0x00, 0x00], 0x59),
            (&[0xF2, 0x01, 0x83], 0x37),
            (&[0x0F, 0xAA, 0x00, 0x55], 0x79),
            (&[0x00, 0xFF, 0x55, 0x11], 0xB8),
            (
                &[0x33, 0x22, 0x55, 0xAA, 0xBB, 0xCC, 0xDD, 0xEE, 0xFF],
                0xCB,
            ),
            (&[0x92, 0x6B, 0x55], 0x8C),
            (&[0xFF, 0xFF, 0xFF, 0xFF], 0x74),
        ];
        for (data, expected) in cases {
            assert_eq!(crc8(data), expected, "data {data:02X?}");
        }
    }

    #[test]
    fn table_matches_bitwise_reference() {
        for n in 0..=255u8 {
            let data = [n, n.wrapping_mul(7), 0x5A ^ n];
            assert_eq!(crc8(&data), crc8_bitwise(&data));
        }
    }

    #[test]
    fn incremental_equals_one_shot() {
        let mut c = Crc8::new();
        c.update(b"1234").update(b"56789");
        assert_eq!(c.value(), crc8(b"123456789"));
    }

    #[test]
    fn frame_crc_covers_the_identifier() {
        let payload = [1, 2, 3, 4, 5, 6, 7];
        let mut all = [0u8; 9];
        all[..2].copy_from_slice(&0x110u16.to_le_bytes());
        all[2..].copy_from_slice(&payload);
        assert_eq!(frame_crc(0x110, &payload), crc8_bitwise(&all));
        assert_ne!(frame_crc(0x110, &payload), frame_crc(0x111, &payload));
    }
}
