//! [`DriverCommand`]: the supervisor's orders to the stimulator driver (supervisor ->
//! stim-driver): arm, disarm, safe stop.

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_DRIVER_COMMAND};
use super::validate::{ValidationError, int_in_range, nonzero_seq, reserved_zero, u8_enum};

u8_enum! {
    /// What the supervisor asks the driver to do.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum DriverCommandKind: "command" {
        /// Start forwarding pulses: NMT start to the stimulator. The driver checks its own
        /// preconditions (link up, stimulator configured, StimTicks flowing) and refuses (and
        /// reports) when one is missing. The only way out of the driver's safe state.
        Arm = 1,
        /// Stop forwarding pulses: NMT stop to the stimulator; not a fault.
        Disarm = 2,
        /// Emergency stop ordered by the supervisor: NMT stop, the driver enters its safe state
        /// and reports it as a fault until re-armed.
        SafeStop = 3,
    }
}

/// One order to the stimulator driver.
///
/// The service keeps no history (a subscriber that connects late never sees an old Arm), and
/// the driver additionally refuses a command whose `t_ns` is older than its configured age
/// limit or whose `seq` does not increase.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("fes::DriverCommand::v1")]
pub struct DriverCommand {
    /// Sequence number, 1, 2, ... per publisher; must increase.
    pub seq: u64,
    /// CLOCK_MONOTONIC time the command was issued, ns (its age is checked by the driver).
    pub t_ns: u64,
    /// A [`DriverCommandKind`] as `u8`.
    pub command: u8,
    /// Zero.
    pub reserved: [u8; 7],
}

impl DriverCommand {
    /// `seq` must be below this (2^56): the driver's acknowledgement packs it with its
    /// result into one word. The supervisor counts from its start time in µs.
    pub const MAX_SEQ: u64 = 1 << 56;

    /// A command of `kind`.
    pub fn new(seq: u64, t_ns: u64, kind: DriverCommandKind) -> Self {
        Self {
            seq,
            t_ns,
            command: kind as u8,
            reserved: [0; 7],
        }
    }

    /// The command, decoded.
    pub fn kind(&self) -> Result<DriverCommandKind, ValidationError> {
        DriverCommandKind::try_from(self.command)
    }
}

impl Contract for DriverCommand {
    const TOPIC: &'static str = TOPIC_DRIVER_COMMAND;
    const QOS: PubSubQos = PubSubQos {
        // One commander: a second publisher (another process of the same user) is refused
        // at creation, so only the supervisor sends DriverCommands.
        max_publishers: 1,
        max_subscribers: 4,
        subscriber_buffer: 8,
        history: 0,
        max_loaned_samples: 2,
    };

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        int_in_range("seq", self.seq, 1, Self::MAX_SEQ - 1)?;
        self.kind()?;
        reserved_zero("reserved", &self.reserved)?;
        if self.t_ns == 0 {
            return Err(ValidationError::Inconsistent(
                "t_ns is 0 (a command must carry its issue time)",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn layout_is_pinned() {
        assert_eq!(
            (size_of::<DriverCommand>(), align_of::<DriverCommand>()),
            (24, 8)
        );
        assert_eq!(offset_of!(DriverCommand, t_ns), 8);
        assert_eq!(offset_of!(DriverCommand, command), 16);
        // SAFETY: only reads the constant name string of the derive.
        let name = unsafe { <DriverCommand as ZeroCopySend>::type_name() };
        assert_eq!(name, "fes::DriverCommand::v1");
    }

    #[test]
    fn validation_names_the_problem() {
        let ok = DriverCommand::new(1, 5, DriverCommandKind::Arm);
        assert_eq!(ok.validate(), Ok(()));
        assert_eq!(ok.kind(), Ok(DriverCommandKind::Arm));
        assert_eq!(
            DriverCommand { seq: 0, ..ok }.validate(),
            Err(ValidationError::ZeroSequence)
        );
        assert_eq!(
            DriverCommand { command: 9, ..ok }.validate(),
            Err(ValidationError::UnknownEnum {
                field: "command",
                value: 9
            })
        );
        assert_eq!(
            DriverCommand {
                reserved: [0, 0, 1, 0, 0, 0, 0],
                ..ok
            }
            .validate(),
            Err(ValidationError::ReservedNotZero { field: "reserved" })
        );
        assert!(matches!(
            DriverCommand { t_ns: 0, ..ok }.validate(),
            Err(ValidationError::Inconsistent(_))
        ));
        for k in [
            DriverCommandKind::Arm,
            DriverCommandKind::Disarm,
            DriverCommandKind::SafeStop,
        ] {
            assert_eq!(DriverCommandKind::try_from(k as u8), Ok(k));
        }
        assert_eq!(
            DriverCommand::QOS.history,
            0,
            "an old Arm must never replay"
        );
    }
}
