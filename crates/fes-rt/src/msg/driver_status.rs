//! [`DriverStatus`]: health of the stimulator driver and the stimulator (stim-driver ->
//! supervisor).

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_DRIVER_STATUS};
use super::validate::{ValidationError, nonzero_seq, reserved_zero, u8_enum};

u8_enum! {
    /// Life-cycle state of the driver or the stimulator (the stimulator's STATUS frame states).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum DeviceState: "state" {
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
}

/// What the driver did with a [`super::DriverCommand`] (the acknowledgement a
/// [`DriverStatus`] carries).
#[repr(u8)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CommandResult {
    /// No command handled yet (`command_seq` is 0).
    None = 0,
    /// Carried out (an Arm: armed, or armed already; a Disarm or SafeStop: stopped).
    Accepted = 1,
    /// Refused, for the [`CommandRefusal`] in `command_reason`.
    Refused = 2,
}

u8_enum! {
    /// Why the driver refused a command (`command_reason` of a [`DriverStatus`]).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum CommandRefusal: "command_reason" {
        /// The stimulator is not configured yet (or refused the configuration).
        NotConfigured = 1,
        /// The bus link is down, or a stop is still waiting to be written.
        LinkDown = 2,
        /// No recent STATUS from the stimulator.
        StimulatorSilent = 3,
        /// The stimulator does not report the driver's configuration.
        StimulatorConfigMismatch = 4,
        /// No valid StimTick within the watchdog time.
        NoTicks = 5,
        /// The StimTick publisher is not alive.
        PublisherNotAlive = 6,
        /// The supervisor's node was last seen dead.
        SupervisorDead = 7,
        /// The pattern generator has published its final tick.
        GeneratorStopped = 8,
        /// The command was too old, from the future, or not newer than the last one.
        StaleCommand = 9,
        /// The NMT start could not be written.
        TxFailed = 10,
        /// The command did not validate.
        InvalidCommand = 11,
        /// The stimulator does not read back the limits the driver configured (or read back
        /// none).
        StimulatorLimitsMismatch = 12,
        /// The pattern generator's minimum pulse interval (StimTick `min_gap_ticks`) is
        /// shorter than the transport can deliver (a RehaStim 2 answers one command at a
        /// time): its pulses would wait and be dropped.
        GeneratorGapTooShort = 13,
    }
}

impl CommandRefusal {
    /// Every reason, in code order.
    pub const ALL: [CommandRefusal; 13] = [
        Self::NotConfigured,
        Self::LinkDown,
        Self::StimulatorSilent,
        Self::StimulatorConfigMismatch,
        Self::NoTicks,
        Self::PublisherNotAlive,
        Self::SupervisorDead,
        Self::GeneratorStopped,
        Self::StaleCommand,
        Self::TxFailed,
        Self::InvalidCommand,
        Self::StimulatorLimitsMismatch,
        Self::GeneratorGapTooShort,
    ];

    /// The reason's name (logs, `supervisor status`).
    pub const fn name(self) -> &'static str {
        match self {
            Self::NotConfigured => "the stimulator is not configured",
            Self::LinkDown => "the bus link is down",
            Self::StimulatorSilent => "no recent STATUS from the stimulator",
            Self::StimulatorConfigMismatch => "the stimulator reports another configuration",
            Self::NoTicks => "no valid StimTick within the watchdog time",
            Self::PublisherNotAlive => "the StimTick publisher is not alive",
            Self::SupervisorDead => "the supervisor was seen dead",
            Self::GeneratorStopped => "the pattern generator has stopped",
            Self::StaleCommand => "the command was stale",
            Self::TxFailed => "the NMT start could not be written",
            Self::InvalidCommand => "the command was invalid",
            Self::StimulatorLimitsMismatch => "the stimulator reports other limits",
            Self::GeneratorGapTooShort => {
                "the pattern generator's minimum pulse interval is shorter than the transport delivers"
            }
        }
    }
}

/// The acknowledgement of the last command, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CommandAck {
    /// No command handled yet.
    None,
    /// Command `seq` was carried out.
    Accepted {
        /// The command's `seq`.
        seq: u64,
    },
    /// Command `seq` was refused.
    Refused {
        /// The command's `seq`.
        seq: u64,
        /// Why.
        reason: CommandRefusal,
    },
}

/// Periodic status of the stimulator driver, with counters since it started, and the
/// acknowledgement of the last DriverCommand it handled.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("fes::DriverStatus::v3")]
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
    /// `seq` of the last DriverCommand the driver handled; 0 = none.
    pub command_seq: u64,
    /// What it did with it, a [`CommandResult`] as `u8`.
    pub command_result: u8,
    /// Why it refused it, a [`CommandRefusal`] as `u8`; 0 unless refused.
    pub command_reason: u8,
    /// Reserved, zero.
    pub reserved: [u8; 6],
}

impl DriverStatus {
    /// `fault_code` of a safe state the supervisor ordered (DriverCommand SafeStop): the
    /// driver is in its safe state because it was told to be, not because of a fault it
    /// found.
    pub const FAULT_CODE_SAFE_STOP_ORDERED: u16 = 0xFF2B;

    /// Driver fault: no StimTick within the watchdog time.
    pub const FAULT_TICK_TIMEOUT: u16 = 0xFF21;
    /// Driver fault: the StimTick publisher's node is dead.
    pub const FAULT_GENERATOR_DEAD: u16 = 0xFF22;
    /// Driver fault: the StimTick service has no publisher.
    pub const FAULT_GENERATOR_GONE: u16 = 0xFF23;
    /// Driver fault: a StimTick older than allowed.
    pub const FAULT_STALE_TICK: u16 = 0xFF24;
    /// Driver fault: rt-core published its final tick.
    pub const FAULT_GENERATOR_STOPPED: u16 = 0xFF25;
    /// Driver fault: the CAN link went down.
    pub const FAULT_LINK_DOWN: u16 = 0xFF26;
    /// Driver fault: the CAN controller went bus-off.
    pub const FAULT_BUS_OFF: u16 = 0xFF27;
    /// Driver fault: no heartbeat or STATUS from the stimulator in time.
    pub const FAULT_STIMULATOR_SILENT: u16 = 0xFF28;
    /// Driver fault: the stimulator booted again.
    pub const FAULT_STIMULATOR_RESET: u16 = 0xFF29;
    /// Driver fault: the stimulator left or never reached operational.
    pub const FAULT_STIMULATOR_NOT_OPERATIONAL: u16 = 0xFF2A;
    /// Driver fault: bus events were lost between the driver's threads.
    pub const FAULT_BUS_EVENTS_LOST: u16 = 0xFF2C;
    /// Driver fault: a frame could not be written.
    pub const FAULT_TX_FAILED: u16 = 0xFF2D;
    /// Driver fault: the supervisor's node is dead.
    pub const FAULT_SUPERVISOR_DEAD: u16 = 0xFF2E;
    /// Driver fault: the DriverCommand service has no publisher.
    pub const FAULT_SUPERVISOR_GONE: u16 = 0xFF2F;
    /// Driver fault: a frame on one of the driver's own transmit identifiers (NMT, PULSE,
    /// CONFIG, host heartbeat) that the driver did not send: someone else is on the bus.
    pub const FAULT_INTRUSION: u16 = 0xFF30;
    /// Driver fault: the stimulator's delivered-pulse count (STATUS) does not match the
    /// PULSE frames the driver wrote, beyond the pulses in flight.
    pub const FAULT_DELIVERY_MISMATCH: u16 = 0xFF31;
    /// Driver fault: while armed, the stimulator read back (CONFIG_APPLIED) limits other
    /// than the ones checked at the Arm: what it enforces changed under the driver.
    pub const FAULT_LIMITS_CHANGED: u16 = 0xFF32;
    /// Driver fault: the StimTick or DriverCommand publisher's process runs outside the
    /// systemd unit the driver's configuration names (a squatter of the same user).
    pub const FAULT_FOREIGN_PUBLISHER: u16 = 0xFF33;

    /// The driver's own fault codes (manufacturer-specific EMCY range 0xFF21..=0xFF3F),
    /// with their names: the contract between stim-driver, which reports them, and the
    /// supervisor, which names them (docs/stim-driver.md).
    pub const DRIVER_FAULTS: [(u16, &'static str); 19] = [
        (Self::FAULT_TICK_TIMEOUT, "tick_timeout"),
        (Self::FAULT_GENERATOR_DEAD, "generator_dead"),
        (Self::FAULT_GENERATOR_GONE, "generator_gone"),
        (Self::FAULT_STALE_TICK, "stale_tick"),
        (Self::FAULT_GENERATOR_STOPPED, "generator_stopped"),
        (Self::FAULT_LINK_DOWN, "link_down"),
        (Self::FAULT_BUS_OFF, "bus_off"),
        (Self::FAULT_STIMULATOR_SILENT, "stimulator_silent"),
        (Self::FAULT_STIMULATOR_RESET, "stimulator_reset"),
        (
            Self::FAULT_STIMULATOR_NOT_OPERATIONAL,
            "stimulator_not_operational",
        ),
        (Self::FAULT_CODE_SAFE_STOP_ORDERED, "safe_stop_ordered"),
        (Self::FAULT_BUS_EVENTS_LOST, "bus_events_lost"),
        (Self::FAULT_TX_FAILED, "tx_failed"),
        (Self::FAULT_SUPERVISOR_DEAD, "supervisor_dead"),
        (Self::FAULT_SUPERVISOR_GONE, "supervisor_gone"),
        (Self::FAULT_INTRUSION, "intrusion"),
        (Self::FAULT_DELIVERY_MISMATCH, "delivery_mismatch"),
        (Self::FAULT_LIMITS_CHANGED, "limits_changed"),
        (Self::FAULT_FOREIGN_PUBLISHER, "foreign_publisher"),
    ];

    /// The name of a driver fault code, if it is one.
    pub fn driver_fault_name(code: u16) -> Option<&'static str> {
        Self::DRIVER_FAULTS
            .iter()
            .find(|(c, _)| *c == code)
            .map(|(_, n)| *n)
    }

    /// True for the driver faults of its StimTick watchdog (no tick in time, a tick too
    /// old on arrival): rt-core silent, or the driver itself too late to read it.
    pub fn is_tick_loss(code: u16) -> bool {
        matches!(code, Self::FAULT_TICK_TIMEOUT | Self::FAULT_STALE_TICK)
    }

    /// True for the driver faults that say the stimulator stopped answering or left
    /// operation (silent, reset, not operational): the stimulator is the cause.
    pub fn is_stimulator_loss(code: u16) -> bool {
        matches!(
            code,
            Self::FAULT_STIMULATOR_SILENT
                | Self::FAULT_STIMULATOR_RESET
                | Self::FAULT_STIMULATOR_NOT_OPERATIONAL
        )
    }

    /// The acknowledgement of the last command, decoded.
    pub fn command_ack(&self) -> Result<CommandAck, ValidationError> {
        let seq = self.command_seq;
        match (self.command_result, self.command_reason) {
            (0, 0) if seq == 0 => Ok(CommandAck::None),
            (1, 0) if seq != 0 => Ok(CommandAck::Accepted { seq }),
            (2, r) if seq != 0 => Ok(CommandAck::Refused {
                seq,
                reason: CommandRefusal::try_from(r)?,
            }),
            _ => Err(ValidationError::Inconsistent(
                "command_seq, command_result and command_reason disagree",
            )),
        }
    }

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
    const QOS: PubSubQos = PubSubQos::status_report(1);

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        self.state()?;
        self.stimulator_state()?;
        self.command_ack()?;
        reserved_zero("reserved", &self.reserved)?;
        if self.pulses_sent > self.ticks_received {
            return Err(ValidationError::Inconsistent(
                "more pulses sent than StimTicks received",
            ));
        }
        Ok(())
    }
}
