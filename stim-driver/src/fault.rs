//! Why the driver entered its safe state ([`Fault`]) and why it refused to arm
//! ([`ArmRefusal`]), with the codes `DriverStatus.fault_code` carries.
//!
//! Codes: a stimulator EMCY is reported with the stimulator's own CANopen code; the
//! driver's own conditions use the manufacturer-specific range 0xFF21..=0xFF3F (the bus
//! protocol's own codes stop at 0xFF0B; these never appear on the bus).

use fes_can::{ErrorCode, MessageKind};
use fes_rt::msg::DriverStatus;

/// A condition that stops stimulation: NMT stop on the bus, the driver's safe state, and
/// nothing forwarded until an explicit re-arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// No StimTick for the watchdog time.
    TickTimeout {
        /// Time since the last valid tick, ns.
        silent_ns: u64,
    },
    /// The StimTick publisher's iceoryx2 node is dead (its process died).
    PublisherDead,
    /// The StimTick service has no publisher any more.
    PublisherGone,
    /// A StimTick arrived older than the staleness limit.
    StaleTick {
        /// Its age on arrival (publish to receive), ns.
        age_ns: u64,
    },
    /// rt-core published its final tick (it is stopping).
    GeneratorStopped,
    /// The CAN interface is down (or gone).
    LinkDown,
    /// The CAN controller went bus-off.
    BusOff,
    /// The stimulator raised an emergency.
    StimulatorEmcy {
        /// Its code.
        code: ErrorCode,
        /// Its detail field.
        detail: u16,
    },
    /// No STATUS from the stimulator for its timeout.
    StimulatorSilent {
        /// Time since the last STATUS, ns.
        silent_ns: u64,
    },
    /// The stimulator restarted (boot-up heartbeat) or lost our configuration.
    StimulatorReset,
    /// After NMT start the stimulator did not report operational in time, or it left
    /// operational by itself.
    StimulatorNotOperational,
    /// The supervisor ordered a safe stop.
    SafeStopCommand,
    /// The supervisor's iceoryx2 node (the DriverCommand publisher) is dead: nobody is
    /// left to stop the stimulation, watch health, or record.
    SupervisorDead,
    /// The DriverCommand service has no publisher any more (the supervisor left).
    SupervisorGone,
    /// A bus event was lost (the queue from the receive thread overflowed).
    BusEventsLost,
    /// A frame could not be written for a reason other than a full queue or a down link.
    TxFailed {
        /// errno.
        errno: i32,
    },
    /// The stimulator refused our CONFIG (its EMCY detail names the limit).
    ConfigRefused {
        /// Index of the offending limit (see docs/can-protocol.md).
        detail: u16,
    },
    /// A frame on one of the driver's own transmit identifiers (NMT, PULSE, CONFIG, host
    /// heartbeat) that the driver did not write: another sender is on the bus
    /// ([`crate::intrusion`]). Trips in every mode, not only while armed.
    Intrusion {
        /// The frame's COB-ID.
        cob_id: u16,
        /// The message kind that identifier carries.
        kind: MessageKind,
    },
    /// A STATUS whose delivered-pulse count does not match the PULSE frames the driver
    /// wrote since the Arm, beyond the pulses in flight ([`crate::forward`],
    /// "Reconciliation"). Counts are modulo 2^24, as STATUS carries them.
    DeliveryMismatch {
        /// PULSE frames the driver wrote since the Arm.
        sent: u32,
        /// Pulses the stimulator reports applied since the Arm.
        delivered: u32,
        /// The allowance: pulses written within the in-flight window (fewer delivered)
        /// or just before the Arm (more delivered).
        allowed: u32,
    },
    /// While armed, the stimulator read back (CONFIG_APPLIED) limits other than the ones
    /// checked at the Arm: a CONFIG the driver did not send, or a stimulator that changed
    /// what it enforces.
    LimitsChanged {
        /// The first limit that differs.
        field: &'static str,
    },
    /// A publisher the driver follows runs outside the systemd unit its configuration
    /// names ([`fes_rt::rt::liveness`]): a process of the same user that took the service.
    ForeignPublisher {
        /// The DriverCommand publisher (else the StimTick publisher).
        supervisor: bool,
    },
}

impl Fault {
    /// The code reported in `DriverStatus.fault_code`.
    pub const fn code(&self) -> u16 {
        match self {
            Fault::StimulatorEmcy { code, .. } => code.raw(),
            Fault::ConfigRefused { .. } => ErrorCode::ConfigInvalid.raw(),
            Fault::TickTimeout { .. } => DriverStatus::FAULT_TICK_TIMEOUT,
            Fault::PublisherDead => DriverStatus::FAULT_GENERATOR_DEAD,
            Fault::PublisherGone => DriverStatus::FAULT_GENERATOR_GONE,
            Fault::StaleTick { .. } => DriverStatus::FAULT_STALE_TICK,
            Fault::GeneratorStopped => DriverStatus::FAULT_GENERATOR_STOPPED,
            Fault::LinkDown => DriverStatus::FAULT_LINK_DOWN,
            Fault::BusOff => DriverStatus::FAULT_BUS_OFF,
            Fault::StimulatorSilent { .. } => DriverStatus::FAULT_STIMULATOR_SILENT,
            Fault::StimulatorReset => DriverStatus::FAULT_STIMULATOR_RESET,
            Fault::StimulatorNotOperational => DriverStatus::FAULT_STIMULATOR_NOT_OPERATIONAL,
            Fault::SafeStopCommand => DriverStatus::FAULT_CODE_SAFE_STOP_ORDERED,
            Fault::BusEventsLost => DriverStatus::FAULT_BUS_EVENTS_LOST,
            Fault::TxFailed { .. } => DriverStatus::FAULT_TX_FAILED,
            Fault::SupervisorDead => DriverStatus::FAULT_SUPERVISOR_DEAD,
            Fault::SupervisorGone => DriverStatus::FAULT_SUPERVISOR_GONE,
            Fault::Intrusion { .. } => DriverStatus::FAULT_INTRUSION,
            Fault::DeliveryMismatch { .. } => DriverStatus::FAULT_DELIVERY_MISMATCH,
            Fault::LimitsChanged { .. } => DriverStatus::FAULT_LIMITS_CHANGED,
            Fault::ForeignPublisher { .. } => DriverStatus::FAULT_FOREIGN_PUBLISHER,
        }
    }

    /// True for the watchdog conditions counted in `DriverStatus.watchdog_trips`: the
    /// generator side (ticks missing, stale, its node dead or gone), the supervisor's node
    /// dead or gone, and the stimulator side (silent).
    pub const fn is_watchdog(&self) -> bool {
        matches!(
            self,
            Fault::TickTimeout { .. }
                | Fault::PublisherDead
                | Fault::PublisherGone
                | Fault::SupervisorDead
                | Fault::SupervisorGone
                | Fault::StaleTick { .. }
                | Fault::StimulatorSilent { .. }
        )
    }
}

impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let ms = |ns: u64| ns as f64 / 1e6;
        match *self {
            Fault::TickTimeout { silent_ns } => {
                write!(f, "watchdog: no StimTick for {:.3} ms", ms(silent_ns))
            }
            Fault::PublisherDead => f.write_str("watchdog: the StimTick publisher's node is dead"),
            Fault::PublisherGone => f.write_str("watchdog: the StimTick publisher is gone"),
            Fault::StaleTick { age_ns } => {
                write!(f, "watchdog: StimTick {:.3} ms old on arrival", ms(age_ns))
            }
            Fault::GeneratorStopped => f.write_str("the generator published its final tick"),
            Fault::LinkDown => f.write_str("CAN interface down"),
            Fault::BusOff => f.write_str("CAN controller bus-off"),
            Fault::StimulatorEmcy { code, detail } => write!(
                f,
                "stimulator emergency {code} ({:#06x}), detail {detail}",
                code.raw()
            ),
            Fault::StimulatorSilent { silent_ns } => {
                write!(
                    f,
                    "no STATUS from the stimulator for {:.1} ms",
                    ms(silent_ns)
                )
            }
            Fault::StimulatorReset => {
                f.write_str("the stimulator restarted or lost its configuration")
            }
            Fault::StimulatorNotOperational => f.write_str(
                "the stimulator is not operational (NMT start not confirmed, or it left)",
            ),
            Fault::SafeStopCommand => f.write_str("safe stop ordered by the supervisor"),
            Fault::SupervisorDead => {
                f.write_str("watchdog: the supervisor's node (DriverCommand publisher) is dead")
            }
            Fault::SupervisorGone => {
                f.write_str("watchdog: the supervisor left (no DriverCommand publisher)")
            }
            Fault::BusEventsLost => f.write_str("bus events lost (receive queue overflow)"),
            Fault::TxFailed { errno } => write!(f, "CAN write failed (errno {errno})"),
            Fault::ConfigRefused { detail } => {
                write!(
                    f,
                    "the stimulator refused the CONFIG (limit index {detail})"
                )
            }
            Fault::Intrusion { cob_id, kind } if crate::intrusion::OWN_KINDS.contains(&kind) => {
                write!(
                    f,
                    "intrusion: a {} frame (COB-ID {cob_id:#05x}) the driver did not send",
                    kind.name()
                )
            }
            Fault::Intrusion { cob_id, kind } => write!(
                f,
                "intrusion: a {} frame (COB-ID {cob_id:#05x}) out of the stimulator's numbering (repeated or stepping back): a second sender",
                kind.name()
            ),
            Fault::DeliveryMismatch {
                sent,
                delivered,
                allowed,
            } => write!(
                f,
                "delivery mismatch: the stimulator applied {delivered} pulses since the Arm, the driver wrote {sent} (allowance {allowed})"
            ),
            Fault::LimitsChanged { field } => write!(
                f,
                "the stimulator now applies another {field} than the limits checked at the Arm (CONFIG_APPLIED)"
            ),
            Fault::ForeignPublisher { supervisor } => write!(
                f,
                "a foreign {} publisher: its process runs outside watchdog.{}_unit",
                if supervisor {
                    "DriverCommand"
                } else {
                    "StimTick"
                },
                if supervisor {
                    "supervisor"
                } else {
                    "generator"
                }
            ),
        }
    }
}

/// Why an Arm command was refused (the driver stays as it was).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmRefusal {
    /// The stimulator is still being brought up (or refused the configuration).
    NotConfigured,
    /// The CAN interface is down, or a stop is still waiting to be sent.
    LinkDown,
    /// No STATUS from the stimulator recently.
    StimulatorSilent,
    /// The stimulator's STATUS does not show our configuration.
    StimulatorConfigMismatch {
        /// The configuration id the stimulator reports.
        reported: u8,
        /// Ours.
        expected: u8,
    },
    /// No valid StimTick within the watchdog time.
    NoTicks,
    /// The StimTick publisher is not alive.
    PublisherNotAlive,
    /// The supervisor's node was last seen dead (the command came from a stale sample).
    SupervisorDead,
    /// The generator has published its final tick.
    GeneratorStopped,
    /// The command was older than the age limit, from the future, or not newer than the
    /// last one.
    StaleCommand,
    /// The NMT start could not be written.
    TxFailed,
    /// The stimulator has not read back the limits it applied for our configuration
    /// (CONFIG_APPLIED), so what it enforces is unknown.
    LimitsNotReadBack,
    /// The stimulator read back other limits than the driver sent: it enforces something
    /// else than the configuration (e.g. a looser ceiling).
    StimulatorLimitsDiffer {
        /// The first differing limit (CONFIG signal name).
        field: &'static str,
    },
    /// The pattern generator's minimum pulse interval (StimTick `min_gap_ticks`, not
    /// stated: 0) is shorter than the transport delivers (`[transport] min_interval_ms`):
    /// its closer pulses would wait for the device and be dropped.
    GeneratorGapTooShort {
        /// The generator's minimum interval, us.
        generator_us: u64,
        /// The transport's shortest interval, us.
        transport_us: u64,
    },
}

impl ArmRefusal {
    /// The reason as the DriverStatus acknowledgement carries it.
    pub const fn reason(&self) -> fes_rt::msg::CommandRefusal {
        use fes_rt::msg::CommandRefusal as R;
        match self {
            ArmRefusal::NotConfigured => R::NotConfigured,
            ArmRefusal::LinkDown => R::LinkDown,
            ArmRefusal::StimulatorSilent => R::StimulatorSilent,
            ArmRefusal::StimulatorConfigMismatch { .. } => R::StimulatorConfigMismatch,
            ArmRefusal::NoTicks => R::NoTicks,
            ArmRefusal::PublisherNotAlive => R::PublisherNotAlive,
            ArmRefusal::SupervisorDead => R::SupervisorDead,
            ArmRefusal::GeneratorStopped => R::GeneratorStopped,
            ArmRefusal::StaleCommand => R::StaleCommand,
            ArmRefusal::TxFailed => R::TxFailed,
            ArmRefusal::StimulatorLimitsDiffer { .. } | ArmRefusal::LimitsNotReadBack => {
                R::StimulatorLimitsMismatch
            }
            ArmRefusal::GeneratorGapTooShort { .. } => R::GeneratorGapTooShort,
        }
    }
}

impl core::fmt::Display for ArmRefusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ArmRefusal::NotConfigured => f.write_str("the stimulator is not configured yet"),
            ArmRefusal::LinkDown => f.write_str("the CAN link is down"),
            ArmRefusal::StimulatorSilent => f.write_str("no recent STATUS from the stimulator"),
            ArmRefusal::StimulatorConfigMismatch { reported, expected } => write!(
                f,
                "the stimulator reports configuration {reported}, expected {expected}"
            ),
            ArmRefusal::NoTicks => f.write_str("no valid StimTick within the watchdog time"),
            ArmRefusal::PublisherNotAlive => f.write_str("the StimTick publisher is not alive"),
            ArmRefusal::SupervisorDead => f.write_str("the supervisor's node is dead"),
            ArmRefusal::GeneratorStopped => f.write_str("the generator has stopped (final tick)"),
            ArmRefusal::StaleCommand => {
                f.write_str("the command is stale, from the future, or not newer than the last")
            }
            ArmRefusal::TxFailed => f.write_str("NMT start could not be written"),
            ArmRefusal::LimitsNotReadBack => {
                f.write_str("the stimulator has not read back the limits it applied")
            }
            ArmRefusal::StimulatorLimitsDiffer { field } => write!(
                f,
                "the stimulator applied another {field} than the configuration sent"
            ),
            ArmRefusal::GeneratorGapTooShort {
                generator_us,
                transport_us,
            } => write!(
                f,
                "the pattern generator may fire pulses {} ms apart, the transport delivers \
                 them at least {} ms apart ([transport] min_interval_ms): design the \
                 controller with `fes design --min-interval-ms {}` or more",
                generator_us as f64 / 1000.0,
                transport_us as f64 / 1000.0,
                transport_us.div_ceil(1000)
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_distinct_and_in_the_driver_range() {
        let faults = [
            Fault::TickTimeout { silent_ns: 0 },
            Fault::PublisherDead,
            Fault::PublisherGone,
            Fault::StaleTick { age_ns: 0 },
            Fault::GeneratorStopped,
            Fault::LinkDown,
            Fault::BusOff,
            Fault::StimulatorSilent { silent_ns: 0 },
            Fault::StimulatorReset,
            Fault::StimulatorNotOperational,
            Fault::SafeStopCommand,
            Fault::BusEventsLost,
            Fault::TxFailed { errno: 5 },
            Fault::SupervisorDead,
            Fault::SupervisorGone,
            Fault::Intrusion {
                cob_id: 0x110,
                kind: MessageKind::Pulse,
            },
            Fault::DeliveryMismatch {
                sent: 1,
                delivered: 2,
                allowed: 0,
            },
            Fault::LimitsChanged {
                field: "max_amplitude",
            },
            Fault::ForeignPublisher { supervisor: true },
        ];
        let mut codes: Vec<u16> = faults.iter().map(Fault::code).collect();
        assert!(codes.iter().all(|c| (0xFF21..=0xFF3F).contains(c)));
        codes.sort_unstable();
        codes.dedup();
        assert_eq!(codes.len(), faults.len());
        // None collides with a bus protocol code, and each is in the contract's table
        // the supervisor names them by.
        assert_eq!(codes.len(), DriverStatus::DRIVER_FAULTS.len());
        for c in codes {
            assert_eq!(ErrorCode::from_raw(u64::from(c)), None);
            assert!(DriverStatus::driver_fault_name(c).is_some(), "{c:#06x}");
        }
        assert_eq!(
            Fault::StimulatorEmcy {
                code: ErrorCode::HeartbeatLost,
                detail: 3
            }
            .code(),
            0x8130
        );
    }
}
