//! Codec errors. Both are `Copy` and allocation-free, so the real-time path can return and
//! inspect them.

/// Bytes from the line could not be decoded into a packet. Every variant drops the packet
/// being received; the decoder then waits for the next start byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// A header position that must hold the stuffing byte 0x81 (§2.2) held another byte.
    #[error("packet header byte {position} is {byte:#04x}, expected the stuffing byte 0x81")]
    BadHeader {
        /// Position in the packet (1 or 3).
        position: u8,
        /// The byte received.
        byte: u8,
    },
    /// A start byte arrived inside a packet: the packet before it was cut short (lost
    /// bytes, or the device restarted). The new packet is being received.
    #[error("start byte inside a packet after {received} data bytes: the packet was cut short")]
    Truncated {
        /// Stuffed data bytes received before the start byte.
        received: u8,
    },
    /// More packet data than a packet can carry (§2.2: at most 69 bytes per packet) and no
    /// stop byte.
    #[error("packet data exceeds {max} bytes without a stop byte")]
    TooLong {
        /// The most stuffed data bytes a packet carries.
        max: u8,
    },
    /// The length field disagrees with the stuffed data bytes received.
    #[error("length field says {declared} data bytes, {actual} received")]
    BadLength {
        /// The length field (unstuffed).
        declared: u8,
        /// Stuffed data bytes between the header and the stop byte.
        actual: u8,
    },
    /// The checksum (CRC-8 over the stuffed packet data, §2.2) does not match.
    #[error("checksum {received:#04x}, computed {computed:#04x}")]
    BadChecksum {
        /// The checksum field (unstuffed).
        received: u8,
        /// CRC-8 of the data received.
        computed: u8,
    },
    /// Byte stuffing is violated (§2.2): a stuffing byte at the end of the packet data, with
    /// no byte after it to un-stuff.
    #[error("bad byte stuffing at data byte {position} ({byte:#04x})")]
    BadStuffing {
        /// Position among the stuffed data bytes.
        position: u8,
        /// The offending byte.
        byte: u8,
    },
    /// The packet data holds no packet number and command.
    #[error("packet data of {len} bytes has no packet number and command")]
    Empty {
        /// Unstuffed data bytes.
        len: u8,
    },
    /// The command identifier is not one this codec decodes (the MOTOmed commands and
    /// their acknowledgements, §3.4, other than the information packets, and any number
    /// the protocol does not define).
    #[error("packet {number}: unknown command {command}")]
    UnknownCommand {
        /// The packet number (a device answers an unknown command with UnknownCommand
        /// echoing it, §4.1).
        number: u8,
        /// The command byte.
        command: u8,
    },
    /// The command's data has the wrong number of bytes.
    #[error("{command:?}: {actual} data bytes, expected {expected}")]
    WrongDataLength {
        /// The command.
        command: crate::Command,
        /// The number the protocol defines (for a channel list: a multiple of 4, 4..=32).
        expected: u8,
        /// The number received.
        actual: u8,
    },
    /// An enumerated field carries a value the protocol does not define.
    #[error("{command:?}.{field}: undefined value {value}")]
    BadField {
        /// The command.
        command: crate::Command,
        /// The field's name.
        field: &'static str,
        /// The value received.
        value: u8,
    },
}

/// A packet could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// The caller's buffer is shorter than the encoded packet.
    #[error("the packet needs {needed} bytes, the buffer has {available}")]
    BufferTooSmall {
        /// Bytes the encoded packet takes.
        needed: usize,
        /// Bytes the buffer has.
        available: usize,
    },
    /// After stuffing, the packet would exceed the protocol's 69 bytes (§2.2).
    #[error("the stuffed packet data is {len} bytes, more than the {max} a packet carries")]
    TooLong {
        /// Stuffed data bytes.
        len: usize,
        /// The most stuffed data bytes a packet carries.
        max: usize,
    },
    /// A channel list holds no entry or more than eight.
    #[error("a channel list has 1..=8 entries, not {len}")]
    ChannelCount {
        /// The entries given.
        len: usize,
    },
}
