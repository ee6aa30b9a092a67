//! Codec errors. Both are `Copy` and allocation-free, so the real-time path can return
//! and inspect them.

use crate::values::ErrorCode;

/// A frame could not be decoded. Every variant is a reason to drop the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The identifier is not one of this protocol's COB-IDs for the configured nodes
    /// (or is an extended identifier).
    #[error("identifier {id:#x} is not a message of this protocol")]
    UnknownId {
        /// The identifier as received.
        id: u32,
    },
    /// The payload length differs from the message's DLC.
    #[error("{message}: {actual} data bytes, expected {expected}")]
    WrongLength {
        /// Message name.
        message: &'static str,
        /// The DLC the protocol defines.
        expected: u8,
        /// The number of bytes received.
        actual: usize,
    },
    /// The PULSE CRC does not match its contents (corrupt or forged frame).
    #[error("PULSE CRC {received:#04x}, computed {computed:#04x}")]
    BadCrc {
        /// CRC carried by the frame.
        received: u8,
        /// CRC computed over the frame.
        computed: u8,
    },
    /// A signal's raw value is outside its DBC range.
    #[error("{message}.{signal}: raw value {raw} outside its range")]
    OutOfRange {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// The raw value received.
        raw: i64,
    },
    /// An enumerated signal carries a value its value table does not define.
    #[error("{message}.{signal}: undefined value {raw}")]
    UnknownValue {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// The raw value received.
        raw: i64,
    },
    /// A bit that no signal of the message (or of its multiplexor page) occupies is set:
    /// unused bytes and bits must be zero, so that every accepted frame has one meaning
    /// and re-encodes to exactly the bytes received.
    #[error("{message}: reserved byte {byte} is {value:#04x}, must be 0")]
    ReservedNonZero {
        /// Message name.
        message: &'static str,
        /// Index (0-7) of the first payload byte with a reserved bit set.
        byte: usize,
        /// That byte as received.
        value: u8,
    },
}

impl DecodeError {
    /// The EMCY code a receiver reports for this error.
    pub const fn error_code(&self) -> ErrorCode {
        match self {
            DecodeError::UnknownId { .. } => ErrorCode::Communication,
            DecodeError::WrongLength { .. } => ErrorCode::LengthError,
            DecodeError::BadCrc { .. } => ErrorCode::BadCrc,
            DecodeError::OutOfRange { .. }
            | DecodeError::UnknownValue { .. }
            | DecodeError::ReservedNonZero { .. } => ErrorCode::ValueOutOfRange,
        }
    }
}

/// A message could not be encoded: a field is outside its signal's DBC range. The codec
/// never clamps or truncates a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// A field is outside its signal's range.
    #[error("{message}.{signal}: raw value {value} outside its range")]
    OutOfRange {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// The raw value that was refused.
        value: i64,
    },
}
