//! [`DriverStatus`]: health of the stimulator driver and the stimulator (stim-driver ->
//! supervisor).

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_DRIVER_STATUS};
use super::validate::{ValidationError, nonzero_seq};

/// Life-cycle state of the driver or the stimulator (the stimulator's STATUS frame states).
#[repr(u8)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DeviceState {
    /// Starting up; no output.
    Boot = 0,
    /// Configurable, not armed; no output.
    PreOperational = 1,
    /// Armed: will stimulate on the next pulse command.
    Armed = 2,
    /// Delivering pulses.
    Stimulating = 3,
    /// Safe state after a fault; output off until explicitly re-armed.
    Fault = 4,
    /// Stopped on command (NMT stop, a disarm): output off until explicitly re-armed, but
    /// nothing went wrong. Only the stimulator reports it.
    Stopped = 5,
    /// Not known (e.g. no STATUS frame received from the stimulator yet).
    Unknown = 255,
}

impl TryFrom<u8> for DeviceState {
    type Error = ValidationError;

    fn try_from(value: u8) -> Result<Self, Self::Error> {
        Ok(match value {
            0 => Self::Boot,
            1 => Self::PreOperational,
            2 => Self::Armed,
            3 => Self::Stimulating,
            4 => Self::Fault,
            5 => Self::Stopped,
            255 => Self::Unknown,
            other => {
                return Err(ValidationError::UnknownEnum {
                    field: "state",
                    value: other.into(),
                });
            }
        })
    }
}

/// Periodic status of the stimulator driver, with counters since it started.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("fes::DriverStatus::v1")]
pub struct DriverStatus {
    /// Sequence number, 1, 2, ... per publisher.
    pub seq: u64,
    /// CLOCK_MONOTONIC time of this status, ns.
    pub t_ns: u64,
    /// StimTicks received.
    pub ticks_received: u64,
    /// StimTicks lost (gaps in their `seq`).
    pub ticks_lost: u64,
    /// Pulses forwarded to the stimulator.
    pub pulses_sent: u64,
    /// Pulse commands refused by the driver's interlocks (never silently changed).
    pub pulses_rejected: u64,
    /// CAN transmit errors.
    pub can_tx_errors: u64,
    /// Watchdog trips (no StimTick in time, or stimulator heartbeat lost).
    pub watchdog_trips: u32,
    /// Last fault, as a CANopen EMCY error code; 0 = none.
    pub fault_code: u16,
    /// Driver state, a [`DeviceState`] as `u8`.
    pub state: u8,
    /// Stimulator state from its STATUS frames, a [`DeviceState`] as `u8`.
    pub stimulator_state: u8,
}

impl DriverStatus {
    /// `fault_code` of a safe state the supervisor ordered (DriverCommand SafeStop): the
    /// driver is in its safe state because it was told to be, not because of a fault it
    /// found.
    pub const FAULT_CODE_SAFE_STOP_ORDERED: u16 = 0xFF2B;

    /// The driver's state, decoded.
    pub fn state(&self) -> Result<DeviceState, ValidationError> {
        DeviceState::try_from(self.state)
    }

    /// The stimulator's state, decoded.
    pub fn stimulator_state(&self) -> Result<DeviceState, ValidationError> {
        DeviceState::try_from(self.stimulator_state).map_err(|_| ValidationError::UnknownEnum {
            field: "stimulator_state",
            value: self.stimulator_state.into(),
        })
    }
}

impl Contract for DriverStatus {
    const TOPIC: &'static str = TOPIC_DRIVER_STATUS;
    const QOS: PubSubQos = PubSubQos {
        max_publishers: 1,
        max_subscribers: 8,
        subscriber_buffer: 16,
        history: 1,
    };

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        self.state()?;
        self.stimulator_state()?;
        if self.pulses_sent > self.ticks_received {
            return Err(ValidationError::Inconsistent(
                "more pulses sent than StimTicks received",
            ));
        }
        Ok(())
    }
}
