//! The FES stimulator CAN protocol: the DBC file `dbc/fes.dbc`, its descriptor table, a
//! typed, allocation-free frame codec, the PULSE CRC and the freshness counters.
//!
//! The DBC is the single source of truth; [`table`] restates it for the codec and
//! `tests/it/dbc_consistency.rs` proves the two agree. The protocol borrows CANopen's
//! identifier layout and NMT / heartbeat / EMCY meanings (see `docs/can-protocol.md`).
//!
//! ```
//! use fes_can::{decode, Message, Pulse};
//! let pulse = Pulse { seq: 1, alive_counter: 0, channel: 0, amplitude_100ua: 200, width_us: 200 };
//! let frame = Message::Pulse(pulse).encode().unwrap();
//! assert_eq!(frame.id, 0x110);
//! assert_eq!(decode(u32::from(frame.id), frame.payload()), Ok(Message::Pulse(pulse)));
//! ```

pub mod candump;
pub mod config;
pub mod counter;
pub mod crc;
pub mod desc;
pub mod error;
pub mod ids;
pub mod message;
pub mod table;
pub mod values;

// The integration tests (tests/it) compile into this crate's one test binary: they use only
// the public API, through the crate's own name (docs/architecture.md, "Tests").
#[cfg(test)]
extern crate self as fes_can;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;

pub use config::{ConfigAssembler, LimitsError, StimLimits};
pub use counter::{AliveCheck, AliveCounter, AliveError, SequenceCheck, SequenceError};
pub use error::{DecodeError, EncodeError};
pub use ids::{MessageKind, NodeError, Nodes, Role, parse_node_id};
pub use message::{
    Config, ConfigPage, Emcy, Force, Frame, Heartbeat, INTERPHASE_GAP_US, Message, Nmt, Pulse,
    Status, decode,
};
pub use values::{ConfigPageId, ErrorCode, NmtCommand, NmtState, StimState};

/// The text of `dbc/fes.dbc`, for tools that want the protocol definition at run time.
pub const DBC: &str = include_str!("../dbc/fes.dbc");
