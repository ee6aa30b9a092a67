//! The typed error every [`Contract::validate`](super::Contract::validate) returns, and the
//! small checks the message types share.

/// Declares a `#[repr(u8)]` enumeration that travels as a raw `u8` (module docs of
/// [`super`]) and its `TryFrom<u8>`: each value decodes to its variant, any other is
/// [`ValidationError::UnknownEnum`] naming `$field`. The codes stand once, in the
/// declaration (`code_enum!`).
macro_rules! u8_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident: $field:literal { $($body:tt)* }
    ) => {
        crate::code_enum::code_enum! {
            $(#[$meta])*
            pub enum $name { $($body)* }
        }

        impl TryFrom<u8> for $name {
            type Error = ValidationError;

            fn try_from(value: u8) -> Result<Self, Self::Error> {
                Self::from_code(value).ok_or(ValidationError::UnknownEnum {
                    field: $field,
                    value: u64::from(value),
                })
            }
        }
    };
}
pub(super) use u8_enum;

/// Why a received message was rejected. `Copy`, with the offending field named, so a
/// real-time receiver can count and report it without allocating.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ValidationError {
    /// A floating-point field is NaN or infinite.
    #[error("{field} is not a finite number ({value})")]
    NotFinite {
        /// Field name.
        field: &'static str,
        /// The value received.
        value: f64,
    },
    /// A floating-point field lies outside its documented range.
    #[error("{field} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        /// Field name.
        field: &'static str,
        /// The value received.
        value: f64,
        /// Smallest accepted value.
        min: f64,
        /// Largest accepted value.
        max: f64,
    },
    /// An integer field lies outside its documented range.
    #[error("{field} = {value} is outside [{min}, {max}]")]
    IntOutOfRange {
        /// Field name.
        field: &'static str,
        /// The value received.
        value: u64,
        /// Smallest accepted value.
        min: u64,
        /// Largest accepted value.
        max: u64,
    },
    /// A flag word has bits set that this version of the contract does not define.
    #[error("{field} has unknown bits set: {bits:#x}")]
    UnknownFlags {
        /// Field name.
        field: &'static str,
        /// The undefined bits that were set.
        bits: u64,
    },
    /// An enumeration field holds a value with no meaning.
    #[error("{field} = {value} is not a known value")]
    UnknownEnum {
        /// Field name.
        field: &'static str,
        /// The raw value received.
        value: u64,
    },
    /// Sequence number 0 is reserved for "none" and never sent.
    #[error("seq is 0 (reserved for \"none\")")]
    ZeroSequence,
    /// The timestamps of one message contradict each other (e.g. published before woken).
    #[error(
        "timestamps out of order: {earlier} ({earlier_ns} ns) is after {later} ({later_ns} ns)"
    )]
    TimestampOrder {
        /// Field that must be the earlier one.
        earlier: &'static str,
        /// Its value.
        earlier_ns: u64,
        /// Field that must be the later one.
        later: &'static str,
        /// Its value.
        later_ns: u64,
    },
    /// Two fields contradict each other (e.g. a pulse with zero amplitude).
    #[error("inconsistent message: {0}")]
    Inconsistent(&'static str),
    /// A reserved field is not zero (a sender using a newer layout under the old name).
    #[error("reserved field {field} is not zero")]
    ReservedNotZero {
        /// Field name.
        field: &'static str,
    },
}

/// `value` must be finite.
pub(crate) fn finite(field: &'static str, value: f64) -> Result<(), ValidationError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(ValidationError::NotFinite { field, value })
    }
}

/// `value` must be finite and within `[min, max]`.
pub(crate) fn in_range(
    field: &'static str,
    value: f64,
    min: f64,
    max: f64,
) -> Result<(), ValidationError> {
    finite(field, value)?;
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ValidationError::OutOfRange {
            field,
            value,
            min,
            max,
        })
    }
}

/// Integer `value` must be within `[min, max]`.
pub(crate) fn int_in_range(
    field: &'static str,
    value: u64,
    min: u64,
    max: u64,
) -> Result<(), ValidationError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ValidationError::IntOutOfRange {
            field,
            value,
            min,
            max,
        })
    }
}

/// `flags` must only use the bits in `known`.
pub(crate) fn known_flags(
    field: &'static str,
    flags: u64,
    known: u64,
) -> Result<(), ValidationError> {
    let unknown = flags & !known;
    if unknown == 0 {
        Ok(())
    } else {
        Err(ValidationError::UnknownFlags {
            field,
            bits: unknown,
        })
    }
}

/// `seq` must not be the reserved 0.
pub(crate) fn nonzero_seq(seq: u64) -> Result<(), ValidationError> {
    if seq == 0 {
        Err(ValidationError::ZeroSequence)
    } else {
        Ok(())
    }
}

/// `earlier_ns <= later_ns`.
pub(crate) fn ordered(
    earlier: &'static str,
    earlier_ns: u64,
    later: &'static str,
    later_ns: u64,
) -> Result<(), ValidationError> {
    if earlier_ns <= later_ns {
        Ok(())
    } else {
        Err(ValidationError::TimestampOrder {
            earlier,
            earlier_ns,
            later,
            later_ns,
        })
    }
}

/// A reserved byte field must be all zero.
pub(crate) fn reserved_zero(field: &'static str, bytes: &[u8]) -> Result<(), ValidationError> {
    if bytes.iter().all(|&b| b == 0) {
        Ok(())
    } else {
        Err(ValidationError::ReservedNotZero { field })
    }
}
