//! Enumerated signal values: one Rust enum per DBC value table (`VAL_`).
//!
//! Each enum lists its `(raw value, DBC name)` pairs in `VALUES`, which the DBC
//! consistency test compares with the file, so the two cannot drift.

/// Defines a `#[repr]` enum with its raw values and DBC names, `raw()`, `name()`,
/// `VALUES` and a fallible `from_raw()`.
macro_rules! value_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident: $repr:ty {
            $( $(#[$vmeta:meta])* $variant:ident = $value:expr => $text:literal, )+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr($repr)]
        pub enum $name {
            $( $(#[$vmeta])* $variant = $value, )+
        }

        impl $name {
            /// Every value with its DBC name, in declaration order.
            pub const VALUES: &'static [(u64, &'static str)] = &[ $( ($value as u64, $text), )+ ];

            /// Every variant, in declaration order.
            pub const ALL: &'static [$name] = &[ $( $name::$variant, )+ ];

            /// The raw value on the bus.
            pub const fn raw(self) -> $repr {
                self as $repr
            }

            /// The DBC value-table name.
            pub const fn name(self) -> &'static str {
                match self { $( $name::$variant => $text, )+ }
            }

            /// The variant with raw value `raw`, if there is one.
            pub const fn from_raw(raw: u64) -> Option<Self> {
                $( if raw == $value as u64 { return Some($name::$variant); } )+
                None
            }
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str(self.name())
            }
        }
    };
}

value_enum! {
    /// CANopen NMT command (NMT frame, `command`).
    pub enum NmtCommand: u8 {
        /// Enter operational.
        Start = 0x01 => "start",
        /// Enter stopped.
        Stop = 0x02 => "stop",
        /// Enter pre-operational.
        EnterPreOperational = 0x80 => "enter_pre_operational",
        /// Reset the application: defaults, counters and boot-up message.
        ResetNode = 0x81 => "reset_node",
        /// Reset communication state (counters, freshness) and enter pre-operational.
        ResetCommunication = 0x82 => "reset_communication",
    }
}

value_enum! {
    /// CANopen NMT state as carried by heartbeats.
    pub enum NmtState: u8 {
        /// The boot-up message: the node has just (re)started.
        BootUp = 0x00 => "boot_up",
        /// Stopped: only NMT is served.
        Stopped = 0x04 => "stopped",
        /// Operational.
        Operational = 0x05 => "operational",
        /// Pre-operational: configuration allowed, no output.
        PreOperational = 0x7F => "pre_operational",
    }
}

value_enum! {
    /// The stimulator's own state (STATUS and EMCY `state`), finer than its NMT state.
    pub enum StimState: u8 {
        /// Starting up (NMT boot-up).
        Boot = 0 => "boot",
        /// NMT pre-operational: CONFIG accepted, no output.
        PreOperational = 1 => "pre_operational",
        /// NMT operational, no pulse applied in the last 100 ms.
        Armed = 2 => "armed",
        /// NMT operational, a pulse applied in the last 100 ms.
        Stimulating = 3 => "stimulating",
        /// NMT stopped on command: output off.
        Stopped = 4 => "stopped",
        /// NMT stopped by a fault (watchdog): output off until an explicit NMT command.
        Fault = 5 => "fault",
    }
}

impl StimState {
    /// The NMT state this stimulator state reports in its heartbeat.
    pub const fn nmt(self) -> NmtState {
        match self {
            StimState::Boot => NmtState::BootUp,
            StimState::PreOperational => NmtState::PreOperational,
            StimState::Armed | StimState::Stimulating => NmtState::Operational,
            StimState::Stopped | StimState::Fault => NmtState::Stopped,
        }
    }
}

value_enum! {
    /// Emergency error codes (EMCY `error_code`, STATUS `last_error`).
    ///
    /// 0x0000-0x8FFF are CANopen (CiA 301) codes; 0xFF00-0xFFFF is CANopen's
    /// manufacturer-specific range, used for this project's interlocks.
    pub enum ErrorCode: u16 {
        /// Error reset or no error (sent when a fault is cleared).
        NoError = 0x0000 => "no_error",
        /// Generic error.
        Generic = 0x1000 => "generic",
        /// Communication error, not classified further (bus error frame).
        Communication = 0x8100 => "communication",
        /// CAN overrun: frames lost (receive or transmit queue full).
        CanOverrun = 0x8110 => "can_overrun",
        /// CAN controller in error-passive mode.
        CanErrorPassive = 0x8120 => "can_error_passive",
        /// Life guard / heartbeat error: no host heartbeat within the watchdog time.
        HeartbeatLost = 0x8130 => "heartbeat_lost",
        /// Recovered from bus-off.
        BusOffRecovered = 0x8140 => "bus_off_recovered",
        /// Frame not processed because of its length (wrong DLC).
        LengthError = 0x8210 => "length_error",
        /// PULSE closer to the previous one than the minimum inter-pulse interval.
        MinIpiViolation = 0xFF01 => "min_ipi_violation",
        /// PULSE over the maximum number of pulses in the rate window.
        RateViolation = 0xFF02 => "rate_violation",
        /// PULSE amplitude above the amplitude ceiling.
        AmplitudeCeiling = 0xFF03 => "amplitude_ceiling",
        /// PULSE width above the width ceiling.
        WidthCeiling = 0xFF04 => "width_ceiling",
        /// PULSE with a wrong CRC.
        BadCrc = 0xFF05 => "bad_crc",
        /// PULSE with an unexpected alive counter (stale, repeated or lost frame).
        BadAliveCounter = 0xFF06 => "bad_alive_counter",
        /// PULSE whose sequence number is not newer than the last one.
        SequenceError = 0xFF07 => "sequence_error",
        /// Command not allowed in the current state (PULSE outside operational,
        /// CONFIG outside pre-operational); also an accepted pulse cancelled by a stop.
        WrongState = 0xFF08 => "wrong_state",
        /// CONFIG with invalid limits.
        ConfigInvalid = 0xFF09 => "config_invalid",
        /// PULSE for a channel the stimulator does not have.
        ChannelInvalid = 0xFF0A => "channel_invalid",
        /// A signal outside its range, or an undefined enumerated value.
        ValueOutOfRange = 0xFF0B => "value_out_of_range",
        /// PULSE charge per phase (amplitude x width) above the charge ceiling.
        ChargeCeiling = 0xFF0C => "charge_ceiling",
    }
}

/// CANopen error register bits (object 1001h) carried by EMCY.
pub mod error_register {
    /// Generic error (set in every EMCY except "no error").
    pub const GENERIC: u8 = 1 << 0;
    /// Current (amplitude) error.
    pub const CURRENT: u8 = 1 << 1;
    /// Communication error (overrun, error state, freshness).
    pub const COMMUNICATION: u8 = 1 << 4;
    /// Device-profile-specific error (interlocks on timing and width).
    pub const DEVICE_PROFILE: u8 = 1 << 5;
    /// Manufacturer-specific error.
    pub const MANUFACTURER: u8 = 1 << 7;
}

impl ErrorCode {
    /// The CANopen error register value that accompanies this code in an EMCY.
    pub const fn error_register(self) -> u8 {
        use error_register::*;
        match self {
            ErrorCode::NoError => 0,
            ErrorCode::Generic => GENERIC,
            ErrorCode::Communication
            | ErrorCode::CanOverrun
            | ErrorCode::CanErrorPassive
            | ErrorCode::HeartbeatLost
            | ErrorCode::BusOffRecovered
            | ErrorCode::LengthError => GENERIC | COMMUNICATION,
            ErrorCode::BadCrc | ErrorCode::BadAliveCounter | ErrorCode::SequenceError => {
                GENERIC | COMMUNICATION | MANUFACTURER
            }
            ErrorCode::AmplitudeCeiling | ErrorCode::ChargeCeiling => {
                GENERIC | CURRENT | MANUFACTURER
            }
            ErrorCode::MinIpiViolation
            | ErrorCode::RateViolation
            | ErrorCode::WidthCeiling
            | ErrorCode::ChannelInvalid => GENERIC | DEVICE_PROFILE | MANUFACTURER,
            ErrorCode::WrongState | ErrorCode::ConfigInvalid | ErrorCode::ValueOutOfRange => {
                GENERIC | MANUFACTURER
            }
        }
    }
}

value_enum! {
    /// CONFIG page (the multiplexor).
    pub enum ConfigPageId: u8 {
        /// Page 0: amplitude and width ceilings, minimum IPI.
        OutputLimits = 0 => "output_limits",
        /// Page 1: rate limit and watchdog.
        RateAndWatchdog = 1 => "rate_and_watchdog",
        /// Page 2: charge-per-phase ceiling.
        Charge = 2 => "charge",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_raw_inverts_raw() {
        for &c in ErrorCode::ALL {
            assert_eq!(ErrorCode::from_raw(u64::from(c.raw())), Some(c));
        }
        for &s in StimState::ALL {
            assert_eq!(StimState::from_raw(u64::from(s.raw())), Some(s));
        }
        assert_eq!(NmtCommand::from_raw(3), None);
        assert_eq!(NmtState::from_raw(1), None);
    }

    #[test]
    fn values_list_is_complete_and_unique() {
        assert_eq!(ErrorCode::VALUES.len(), ErrorCode::ALL.len());
        let mut raws: Vec<u64> = ErrorCode::VALUES.iter().map(|v| v.0).collect();
        raws.dedup();
        assert_eq!(raws.len(), ErrorCode::ALL.len());
    }

    #[test]
    fn error_register_has_generic_bit_for_errors_only() {
        for &c in ErrorCode::ALL {
            let generic = c.error_register() & error_register::GENERIC != 0;
            assert_eq!(generic, c != ErrorCode::NoError, "{c}");
        }
    }

    #[test]
    fn nmt_mapping_matches_canopen() {
        assert_eq!(StimState::Stimulating.nmt().raw(), 0x05);
        assert_eq!(StimState::Fault.nmt().raw(), 0x04);
        assert_eq!(StimState::PreOperational.nmt().raw(), 0x7F);
    }
}
