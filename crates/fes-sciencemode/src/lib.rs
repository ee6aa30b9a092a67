//! Hasomed RehaStim 2's ScienceMode 2 serial protocol: packet framing with byte stuffing
//! and a CRC-8 checksum, the typed stimulation commands and their acknowledgements, and a
//! streaming decoder. Firmware-free and allocation-free, like `fes-can`: it links only
//! `thiserror`.
//!
//! Written from "ScienceMode2 – Description and Protocol" (HASOMED GmbH / TU Berlin; the
//! section numbers below are those of its 2012 edition, which pyScienceMode also cites) and
//! checked byte for byte against pyScienceMode, an implementation that shares no code with
//! this one (`tests/tests/it/sciencemode_peer.rs` in the workspace). `docs/sciencemode.md`
//! says which features the controller uses and what the serial line allows.
//!
//! * [`frame`]: packet framing (§2.2): start byte, stuffed checksum and length, stuffed
//!   packet data, stop byte; [`Decoder`], the byte-at-a-time decoder;
//! * [`message`]: packet numbers, command identifiers and the typed [`Message`]s;
//! * [`limits`]: the device's value ranges.
//!
//! ```
//! use fes_sciencemode::{Decoder, Message, Packet, SinglePulse, MAX_PACKET_LEN};
//! let pulse = Packet::new(7, Message::SinglePulse(SinglePulse {
//!     channel: 0,
//!     pulse_width_us: 250,
//!     current_ma: 40,
//! }));
//! let mut buf = [0u8; MAX_PACKET_LEN];
//! let n = pulse.encode(&mut buf).unwrap();
//! assert_eq!(&buf[..n], &[0xF0, 0x81, 0x2F, 0x81, 0x53, 0x07, 0x24, 0x00, 0x00, 0xFA, 0x28, 0x0F]);
//! let mut decoder = Decoder::new();
//! let decoded: Vec<_> = decoder.feed(&buf[..n]).collect();
//! assert_eq!(decoded, [Ok(pulse)]);
//! ```

pub mod error;
pub mod frame;
pub mod limits;
pub mod message;

// The integration tests (tests/it) compile into this crate's one test binary: they use only
// the public API, through the crate's own name (docs/architecture.md, "Tests").
#[cfg(test)]
extern crate self as fes_sciencemode;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;

pub use error::{DecodeError, EncodeError};
pub use frame::{
    Decoder, Feed, HEADER_LEN, MAX_DATA_LEN, MAX_PACKET_LEN, START_BYTE, STOP_BYTE, STUFFING_BYTE,
    STUFFING_KEY, crc8, is_special, stuffed_len,
};
pub use message::{
    AckResult, ChannelListInit, ChannelListUpdate, ChannelPulse, Command, Message, Packet,
    PhaseResult, PulseMode, SinglePulse, StimulationError, StimulationMode,
};

/// The serial line's baud rate (§2.1): 460 800 baud, 8 data bits, even parity, one stop bit,
/// no flow control.
pub const BAUD_RATE: u32 = 460_800;

/// Bits on the line per byte at the protocol's settings (§2.1): start bit, 8 data bits,
/// even parity, one stop bit.
pub const BITS_PER_BYTE: u32 = 11;

/// The protocol version a RehaStim 2 announces in [`Message::Init`] and the host accepts.
pub const PROTOCOL_VERSION: u8 = 1;
