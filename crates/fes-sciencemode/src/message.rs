//! Packet numbers, command identifiers and the typed messages (§4 of the protocol
//! description; the stimulation commands are §4.3).
//!
//! A packet's data (§2.2) is its packet number, its command identifier and the command's
//! data bytes. Multi-byte values are most significant byte first. Result and error codes
//! are signed bytes.

use crate::error::{DecodeError, EncodeError};

/// The most data bytes (unstuffed) any command here carries: a channel list of eight.
pub const MAX_COMMAND_DATA: usize = 32;

/// Declares a `#[repr(u8)]` enumeration of the protocol with its `ALL` (every value, in
/// declaration order) and `from_byte` (the value of a byte, if any): the variants and
/// their codes stand once, in the declaration.
macro_rules! byte_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal,)+
        }
    ) => {
        $(#[$meta])*
        #[repr(u8)]
        pub enum $name {
            $($(#[$vmeta])* $variant = $code,)+
        }

        impl $name {
            /// Every value, in declaration order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];

            fn from_byte(b: u8) -> Option<$name> {
                $name::ALL.iter().copied().find(|v| *v as u8 == b)
            }
        }
    };
}

/// Declares an enumeration of a signed code byte (§4.3's result and error codes), with
/// `Other` keeping any code it does not name, and its `from_code` and `code`: the named
/// codes stand once, in the declaration, so the two directions cannot disagree.
macro_rules! signed_code_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal,)+
        }
    ) => {
        $(#[$meta])*
        pub enum $name {
            $($(#[$vmeta])* $variant,)+
            /// Any other code, kept as received.
            Other(i8),
        }

        impl $name {
            /// The value of the signed byte `code` (every byte has one).
            pub const fn from_code(code: i8) -> $name {
                match code {
                    $($code => $name::$variant,)+
                    other => $name::Other(other),
                }
            }

            /// The signed byte on the wire.
            pub const fn code(self) -> i8 {
                match self {
                    $($name::$variant => $code,)+
                    $name::Other(c) => c,
                }
            }
        }
    };
}

byte_enum! {
    /// Command identifiers (the command byte of §2.2), for the commands this codec implements.
    ///
    /// The MOTOmed commands (50..=90, §3.4) are not used by the controller. The ones a device
    /// sends unasked with a MOTOmed attached (the information packets of §3.5: PhaseResult,
    /// ActualValues every 20 ms, MotomedCommandDone, MotomedError) are decoded, so that a host
    /// can skip them; the decoder reports the others as [`DecodeError::UnknownCommand`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum Command {
        /// Device → host: the device is ready and announces its protocol version.
        Init = 1,
        /// Host → device: answer to [`Command::Init`].
        InitAck = 2,
        /// Device → host: the device did not recognise a command.
        UnknownCommand = 3,
        /// Host → device: keep-alive (see [`Message::Watchdog`]).
        Watchdog = 4,
        /// Host → device: ask for the stimulation mode.
        GetStimulationMode = 10,
        /// Device → host: answer to [`Command::GetStimulationMode`].
        GetStimulationModeAck = 11,
        /// Host → device: initialise channel list mode (§4.3).
        InitChannelListMode = 30,
        /// Device → host: answer to [`Command::InitChannelListMode`].
        InitChannelListModeAck = 31,
        /// Host → device: start, or update, channel list mode (§4.3).
        StartChannelListMode = 32,
        /// Device → host: answer to [`Command::StartChannelListMode`].
        StartChannelListModeAck = 33,
        /// Host → device: stop channel list mode (§4.3).
        StopChannelListMode = 34,
        /// Device → host: answer to [`Command::StopChannelListMode`].
        StopChannelListModeAck = 35,
        /// Host → device: one pulse, now (§4.3).
        SinglePulse = 36,
        /// Device → host: answer to [`Command::SinglePulse`].
        SinglePulseAck = 37,
        /// Device → host, unsolicited: the stimulation failed (§4.3).
        StimulationError = 38,
        /// Device → host, unsolicited: the results of the last MOTOmed phase (§4.4).
        PhaseResult = 58,
        /// Device → host, unsolicited, every 20 ms with a MOTOmed (§2.3 ActualValuesInterval,
        /// §4.4): crank angle, speed and torque.
        ActualValues = 60,
        /// Device → host, unsolicited: the last MOTOmed command is done (§4.4).
        MotomedCommandDone = 89,
        /// Device → host, unsolicited: a MOTOmed error (§4.4).
        MotomedError = 90,
    }
}

impl Command {
    /// The command with identifier `id`, if this codec implements it.
    pub fn from_id(id: u8) -> Option<Command> {
        Command::from_byte(id)
    }

    /// The identifier byte.
    pub const fn id(self) -> u8 {
        self as u8
    }
}

signed_code_enum! {
    /// The result byte of an acknowledgement (§4.3): 0 for success, a negative error code
    /// otherwise.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum AckResult {
        /// 0: the command was executed.
        Ok = 0,
        /// -1: transfer error (the device received a damaged packet).
        TransferError = -1,
        /// -2: parameter error (a value outside the device's range).
        ParameterError = -2,
        /// -3: wrong mode error (the command is not allowed in the current mode, e.g.
        /// StartChannelListMode before InitChannelListMode).
        WrongModeError = -3,
        /// -5: InitAck only: the host does not support the device's protocol version.
        VersionError = -5,
        /// -8: busy error (the device is still executing the previous command).
        BusyError = -8,
    }
}

impl AckResult {
    /// Whether the command was executed.
    pub const fn is_ok(self) -> bool {
        matches!(self, AckResult::Ok)
    }
}

signed_code_enum! {
    /// The error a device reports unsolicited in [`Message::StimulationError`] (§4.3). Each
    /// stops the stimulation.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum StimulationError {
        /// -1: the emergency switch was pressed, or is not connected.
        EmergencySwitch = -1,
        /// -2: electrode error (an electrode came off or its cable is broken).
        Electrode = -2,
        /// -3: a stimulation module failed.
        StimulationModule = -3,
    }
}

byte_enum! {
    /// The device's stimulation mode, as [`Message::GetStimulationModeAck`] reports it.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum StimulationMode {
        /// 0: start mode (nothing initialised).
        Start = 0,
        /// 1: channel list mode initialised, not stimulating.
        Initialised = 1,
        /// 2: channel list mode stimulating.
        Started = 2,
    }
}

impl StimulationMode {}

byte_enum! {
    /// How many pulses a channel list entry fires per main stimulation interval (§4.3).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub enum PulseMode {
        /// 0: one pulse.
        #[default]
        Single = 0,
        /// 1: two pulses, the inter-pulse interval apart.
        Doublet = 1,
        /// 2: three pulses, the inter-pulse interval apart.
        Triplet = 2,
    }
}

impl PulseMode {
    /// Pulses per main stimulation interval.
    pub const fn pulses(self) -> u8 {
        self as u8 + 1
    }
}

/// InitChannelListMode's data (§4.3): which channels the list holds and its timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ChannelListInit {
    /// Low-frequency factor, 0..=7: channels in `low_frequency_channels` fire only every
    /// (factor + 1)-th main interval.
    pub low_frequency_factor: u8,
    /// Active channels, bit 0 = channel 1 ... bit 7 = channel 8.
    pub active_channels: u8,
    /// Channels stimulated at the low frequency (same bit layout).
    pub low_frequency_channels: u8,
    /// Inter-pulse interval (between the pulses of a doublet or triplet and between
    /// channels) coded as (interval / ms - 1.5) x 2, i.e. 1.5 ms + code x 0.5 ms.
    pub inter_pulse_interval_code: u8,
    /// Main stimulation interval coded as (interval / ms - 1) x 2, i.e. 1 ms + code x
    /// 0.5 ms, 0..=2048 (the device requires at least 8 ms, code 14).
    pub main_interval_code: u16,
    /// Channel execution; pyScienceMode sends 0 (sequential).
    pub channel_execution: u8,
}

impl ChannelListInit {
    /// The inter-pulse interval in microseconds.
    pub const fn inter_pulse_interval_us(&self) -> u32 {
        1500 + 500 * self.inter_pulse_interval_code as u32
    }

    /// The main stimulation interval in microseconds.
    pub const fn main_interval_us(&self) -> u32 {
        1000 + 500 * self.main_interval_code as u32
    }
}

/// One channel's entry in StartChannelListMode (§4.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct ChannelPulse {
    /// Single, doublet or triplet.
    pub mode: PulseMode,
    /// Pulse width, us (the device: 0 or 20..=500).
    pub pulse_width_us: u16,
    /// Current, mA (the device: 0..=126).
    pub current_ma: u8,
}

/// StartChannelListMode's data (§4.3): one entry per active channel, in channel order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ChannelListUpdate {
    entries: [ChannelPulse; 8],
    len: u8,
}

impl ChannelListUpdate {
    /// A list of 1..=8 entries (one per active channel, lowest channel first).
    pub fn new(entries: &[ChannelPulse]) -> Result<Self, EncodeError> {
        if entries.is_empty() || entries.len() > 8 {
            return Err(EncodeError::ChannelCount { len: entries.len() });
        }
        let mut list = ChannelListUpdate {
            entries: [ChannelPulse::default(); 8],
            len: 0,
        };
        for (slot, e) in list.entries.iter_mut().zip(entries) {
            *slot = *e;
            list.len += 1;
        }
        Ok(list)
    }

    /// The entries.
    pub fn entries(&self) -> &[ChannelPulse] {
        &self.entries[..usize::from(self.len)]
    }
}

/// SinglePulse's data (§4.3): one pulse on one channel, now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SinglePulse {
    /// Channel, 0..=7 (channel 1 is 0).
    pub channel: u8,
    /// Pulse width, us (the device: 0 or 20..=500).
    pub pulse_width_us: u16,
    /// Current, mA (the device: 0..=126).
    pub current_ma: u8,
}

/// A command with its data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Message {
    /// Device → host: ready, protocol `version`. Sent until the host answers with InitAck.
    Init {
        /// The device's protocol version ([`crate::PROTOCOL_VERSION`]).
        version: u8,
    },
    /// Host → device: the connection is accepted (`Ok`) or the version is not supported
    /// (`VersionError`). Carries the packet number of the Init it answers.
    InitAck {
        /// The host's verdict.
        result: AckResult,
    },
    /// Device → host: a command was not recognised (§4.1). Carries the packet number of
    /// the packet it answers, like any acknowledgement.
    UnknownCommand {
        /// The command byte the device did not recognise, echoed.
        command: u8,
    },
    /// Host → device: keep-alive. The device stops stimulating when the host sends nothing
    /// for too long (`docs/sciencemode.md`, "Watchdog").
    Watchdog,
    /// Host → device: ask for the stimulation mode.
    GetStimulationMode,
    /// Device → host: the stimulation mode. §4.2: when the result is not 0 (transfer
    /// error, busy) the acknowledgement carries the result only, and no mode.
    GetStimulationModeAck {
        /// Whether the request was served.
        result: AckResult,
        /// The mode; `None` in an error acknowledgement.
        mode: Option<StimulationMode>,
    },
    /// Host → device: initialise channel list mode.
    InitChannelListMode(ChannelListInit),
    /// Device → host: answer to InitChannelListMode.
    InitChannelListModeAck {
        /// The device's verdict.
        result: AckResult,
    },
    /// Host → device: start channel list mode, or update its pulses while it runs.
    StartChannelListMode(ChannelListUpdate),
    /// Device → host: answer to StartChannelListMode.
    StartChannelListModeAck {
        /// The device's verdict.
        result: AckResult,
    },
    /// Host → device: stop channel list mode (back to start mode).
    StopChannelListMode,
    /// Device → host: answer to StopChannelListMode.
    StopChannelListModeAck {
        /// The device's verdict.
        result: AckResult,
    },
    /// Host → device: one pulse.
    SinglePulse(SinglePulse),
    /// Device → host: answer to SinglePulse.
    SinglePulseAck {
        /// The device's verdict.
        result: AckResult,
    },
    /// Device → host, unsolicited: stimulation failed and stopped.
    StimulationError {
        /// What failed.
        error: StimulationError,
    },
    /// Device → host, unsolicited (MOTOmed): the results of the last phase (§4.4).
    PhaseResult(PhaseResult),
    /// Device → host, unsolicited every 20 ms (MOTOmed, §4.4). Values MSB first.
    ActualValues {
        /// Crank angle, degrees from the 12 o'clock position of the left crank.
        angle_deg: u16,
        /// Speed, rpm; positive forward, negative backward.
        speed_rpm: i16,
        /// Torque, dNm; positive active, negative passive.
        torque_dnm: i16,
    },
    /// Device → host, unsolicited (MOTOmed, §4.4): the last MOTOmed command is done.
    MotomedCommandDone {
        /// The result (0: done).
        result: AckResult,
    },
    /// Device → host, unsolicited (MOTOmed, §4.4): -4 MOTOmed connection error, -6 invalid
    /// MOTOmed trainer.
    MotomedError {
        /// The error code.
        code: i8,
    },
}

/// PhaseResult's data (§4.4): the results of the last MOTOmed phase. Values MSB first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct PhaseResult {
    /// Phase counter.
    pub phase_counter: u8,
    /// Passive distance, in units of 10 m.
    pub passive_distance_10m: u16,
    /// Active distance, in units of 10 m.
    pub active_distance_10m: u16,
    /// Average power, W.
    pub average_power_w: u8,
    /// Maximum power, W.
    pub maximum_power_w: u8,
    /// Phase duration, s.
    pub phase_duration_s: u16,
    /// Active phase duration, s.
    pub active_phase_duration_s: u16,
    /// Phase work, J.
    pub phase_work_j: u16,
    /// Success value, %.
    pub success_percent: u8,
    /// Symmetry (left), %.
    pub symmetry_left_percent: u8,
    /// Average muscle tone, dNm.
    pub average_muscle_tone_dnm: u8,
}

/// Writes command data into a small stack buffer.
struct DataWriter {
    buf: [u8; MAX_COMMAND_DATA],
    len: usize,
}

impl DataWriter {
    fn new() -> Self {
        DataWriter {
            buf: [0; MAX_COMMAND_DATA],
            len: 0,
        }
    }

    fn push(&mut self, b: u8) {
        // A message never carries more than MAX_COMMAND_DATA bytes (ChannelListUpdate
        // holds at most eight 4-byte entries); a longer write would be a bug, and is cut.
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = b;
            self.len += 1;
        }
    }

    fn push_u16(&mut self, v: u16) {
        let [hi, lo] = v.to_be_bytes();
        self.push(hi);
        self.push(lo);
    }

    fn push_i16(&mut self, v: i16) {
        let [hi, lo] = v.to_be_bytes();
        self.push(hi);
        self.push(lo);
    }

    fn push_i8(&mut self, v: i8) {
        self.push(v.to_be_bytes()[0]);
    }
}

impl Message {
    /// The command identifier.
    pub const fn command(&self) -> Command {
        match self {
            Message::Init { .. } => Command::Init,
            Message::InitAck { .. } => Command::InitAck,
            Message::UnknownCommand { .. } => Command::UnknownCommand,
            Message::Watchdog => Command::Watchdog,
            Message::GetStimulationMode => Command::GetStimulationMode,
            Message::GetStimulationModeAck { .. } => Command::GetStimulationModeAck,
            Message::InitChannelListMode(_) => Command::InitChannelListMode,
            Message::InitChannelListModeAck { .. } => Command::InitChannelListModeAck,
            Message::StartChannelListMode(_) => Command::StartChannelListMode,
            Message::StartChannelListModeAck { .. } => Command::StartChannelListModeAck,
            Message::StopChannelListMode => Command::StopChannelListMode,
            Message::StopChannelListModeAck { .. } => Command::StopChannelListModeAck,
            Message::SinglePulse(_) => Command::SinglePulse,
            Message::SinglePulseAck { .. } => Command::SinglePulseAck,
            Message::StimulationError { .. } => Command::StimulationError,
            Message::PhaseResult(_) => Command::PhaseResult,
            Message::ActualValues { .. } => Command::ActualValues,
            Message::MotomedCommandDone { .. } => Command::MotomedCommandDone,
            Message::MotomedError { .. } => Command::MotomedError,
        }
    }

    /// Whether this is one of the information packets a device sends unasked with a
    /// MOTOmed attached (§3.5: PhaseResult, ActualValues, MotomedCommandDone,
    /// MotomedError). They carry the device's own packet number and answer no command.
    pub const fn is_motomed_information(&self) -> bool {
        matches!(
            self,
            Message::PhaseResult(_)
                | Message::ActualValues { .. }
                | Message::MotomedCommandDone { .. }
                | Message::MotomedError { .. }
        )
    }

    /// Whether the device answers this host command (§2.3, §5.1: every command but
    /// Watchdog and InitAck has a response packet carrying its packet number). The host
    /// sends its next such command only after that answer: one arriving while the device
    /// still processes the last is answered -8 busy and not executed.
    pub const fn expects_answer(&self) -> bool {
        matches!(
            self,
            Message::GetStimulationMode
                | Message::InitChannelListMode(_)
                | Message::StartChannelListMode(_)
                | Message::StopChannelListMode
                | Message::SinglePulse(_)
        )
    }

    /// Whether this device packet answers a host command ([`Self::expects_answer`]): an
    /// acknowledgement, or UnknownCommand (§4.1), both with the command's packet number.
    pub const fn is_answer(&self) -> bool {
        matches!(
            self,
            Message::GetStimulationModeAck { .. }
                | Message::InitChannelListModeAck { .. }
                | Message::StartChannelListModeAck { .. }
                | Message::StopChannelListModeAck { .. }
                | Message::SinglePulseAck { .. }
                | Message::UnknownCommand { .. }
        )
    }

    /// The acknowledgement's result, for the device's answers that carry one.
    pub const fn ack_result(&self) -> Option<AckResult> {
        match *self {
            Message::InitAck { result }
            | Message::GetStimulationModeAck { result, .. }
            | Message::InitChannelListModeAck { result }
            | Message::StartChannelListModeAck { result }
            | Message::StopChannelListModeAck { result }
            | Message::SinglePulseAck { result } => Some(result),
            _ => None,
        }
    }

    fn write_data(&self, w: &mut DataWriter) {
        match *self {
            Message::Init { version } => w.push(version),
            Message::UnknownCommand { command } => w.push(command),
            Message::InitAck { result }
            | Message::InitChannelListModeAck { result }
            | Message::StartChannelListModeAck { result }
            | Message::StopChannelListModeAck { result }
            | Message::SinglePulseAck { result } => w.push_i8(result.code()),
            Message::GetStimulationModeAck { result, mode } => {
                w.push_i8(result.code());
                if let Some(mode) = mode {
                    w.push(mode as u8);
                }
            }
            Message::Watchdog | Message::GetStimulationMode | Message::StopChannelListMode => {}
            Message::InitChannelListMode(i) => {
                w.push(i.low_frequency_factor);
                w.push(i.active_channels);
                w.push(i.low_frequency_channels);
                w.push(i.inter_pulse_interval_code);
                w.push_u16(i.main_interval_code);
                w.push(i.channel_execution);
            }
            Message::StartChannelListMode(list) => {
                for e in list.entries() {
                    w.push(e.mode as u8);
                    w.push_u16(e.pulse_width_us);
                    w.push(e.current_ma);
                }
            }
            Message::SinglePulse(p) => {
                w.push(p.channel);
                w.push_u16(p.pulse_width_us);
                w.push(p.current_ma);
            }
            Message::StimulationError { error } => w.push_i8(error.code()),
            Message::PhaseResult(r) => {
                w.push(r.phase_counter);
                w.push_u16(r.passive_distance_10m);
                w.push_u16(r.active_distance_10m);
                w.push(r.average_power_w);
                w.push(r.maximum_power_w);
                w.push_u16(r.phase_duration_s);
                w.push_u16(r.active_phase_duration_s);
                w.push_u16(r.phase_work_j);
                w.push(r.success_percent);
                w.push(r.symmetry_left_percent);
                w.push(r.average_muscle_tone_dnm);
            }
            Message::ActualValues {
                angle_deg,
                speed_rpm,
                torque_dnm,
            } => {
                w.push_u16(angle_deg);
                w.push_i16(speed_rpm);
                w.push_i16(torque_dnm);
            }
            Message::MotomedCommandDone { result } => w.push_i8(result.code()),
            Message::MotomedError { code } => w.push_i8(code),
        }
    }

    /// Decodes `command`'s `data` (unstuffed).
    pub fn decode(command: u8, data: &[u8]) -> Result<Message, DecodeError> {
        let command =
            Command::from_id(command).ok_or(DecodeError::UnknownCommand { number: 0, command })?;
        let f = Fields { command, data };
        let (expect, byte, signed, word, result) = (
            |n| f.expect(n),
            |i| f.byte(i),
            |i| f.signed(i),
            |i| f.word(i),
            |i| f.result(i),
        );
        let message = match command {
            Command::Init => {
                expect(1)?;
                Message::Init { version: byte(0) }
            }
            Command::InitAck => {
                expect(1)?;
                Message::InitAck { result: result(0) }
            }
            Command::UnknownCommand => {
                expect(1)?;
                Message::UnknownCommand { command: byte(0) }
            }
            Command::Watchdog => {
                expect(0)?;
                Message::Watchdog
            }
            Command::GetStimulationMode => {
                expect(0)?;
                Message::GetStimulationMode
            }
            Command::GetStimulationModeAck => f.mode_ack()?,
            Command::InitChannelListMode => {
                expect(7)?;
                Message::InitChannelListMode(ChannelListInit {
                    low_frequency_factor: byte(0),
                    active_channels: byte(1),
                    low_frequency_channels: byte(2),
                    inter_pulse_interval_code: byte(3),
                    main_interval_code: word(4),
                    channel_execution: byte(6),
                })
            }
            Command::InitChannelListModeAck => {
                expect(1)?;
                Message::InitChannelListModeAck { result: result(0) }
            }
            Command::StartChannelListMode => f.channel_list_update()?,
            Command::StartChannelListModeAck => {
                expect(1)?;
                Message::StartChannelListModeAck { result: result(0) }
            }
            Command::StopChannelListMode => {
                expect(0)?;
                Message::StopChannelListMode
            }
            Command::StopChannelListModeAck => {
                expect(1)?;
                Message::StopChannelListModeAck { result: result(0) }
            }
            Command::SinglePulse => {
                expect(4)?;
                Message::SinglePulse(SinglePulse {
                    channel: byte(0),
                    pulse_width_us: word(1),
                    current_ma: byte(3),
                })
            }
            Command::SinglePulseAck => {
                expect(1)?;
                Message::SinglePulseAck { result: result(0) }
            }
            Command::StimulationError => {
                expect(1)?;
                Message::StimulationError {
                    error: StimulationError::from_code(signed(0)),
                }
            }
            Command::PhaseResult => f.phase_result()?,
            Command::ActualValues => {
                expect(6)?;
                Message::ActualValues {
                    angle_deg: word(0),
                    speed_rpm: i16::from_be_bytes([byte(2), byte(3)]),
                    torque_dnm: i16::from_be_bytes([byte(4), byte(5)]),
                }
            }
            Command::MotomedCommandDone => {
                expect(1)?;
                Message::MotomedCommandDone { result: result(0) }
            }
            Command::MotomedError => {
                expect(1)?;
                Message::MotomedError { code: signed(0) }
            }
        };
        Ok(message)
    }
}

/// The data bytes of one received command, read by [`Message::decode`]: a short field
/// reads as 0 after its length was checked, so no read can go out of bounds.
struct Fields<'a> {
    command: Command,
    data: &'a [u8],
}

impl Fields<'_> {
    /// The data is exactly `n` bytes long (the command's length in §4).
    fn expect(&self, n: u8) -> Result<(), DecodeError> {
        if self.data.len() == usize::from(n) {
            Ok(())
        } else {
            Err(DecodeError::WrongDataLength {
                command: self.command,
                expected: n,
                actual: u8::try_from(self.data.len()).unwrap_or(u8::MAX),
            })
        }
    }

    fn byte(&self, i: usize) -> u8 {
        self.data.get(i).copied().unwrap_or(0)
    }

    fn signed(&self, i: usize) -> i8 {
        i8::from_be_bytes([self.byte(i)])
    }

    /// A big-endian 16-bit field (§2.2: the most significant byte first).
    fn word(&self, i: usize) -> u16 {
        u16::from_be_bytes([self.byte(i), self.byte(i + 1)])
    }

    fn result(&self, i: usize) -> AckResult {
        AckResult::from_code(self.signed(i))
    }

    /// GetStimulationModeAck: §4.2, "if Result != 0, then byte 8 = stop byte": an error
    /// acknowledgement carries the result only.
    fn mode_ack(&self) -> Result<Message, DecodeError> {
        if self.data.len() == 1 && !self.result(0).is_ok() {
            return Ok(Message::GetStimulationModeAck {
                result: self.result(0),
                mode: None,
            });
        }
        self.expect(2)?;
        let mode = StimulationMode::from_byte(self.byte(1)).ok_or(DecodeError::BadField {
            command: self.command,
            field: "mode",
            value: self.byte(1),
        })?;
        Ok(Message::GetStimulationModeAck {
            result: self.result(0),
            mode: Some(mode),
        })
    }

    /// StartChannelListMode: one to eight 4-byte channel entries (§4.3).
    fn channel_list_update(&self) -> Result<Message, DecodeError> {
        let (command, data) = (self.command, self.data);
        if data.is_empty() || !data.len().is_multiple_of(4) || data.len() > MAX_COMMAND_DATA {
            return Err(DecodeError::WrongDataLength {
                command,
                expected: 4 * (data.len() / 4).clamp(1, 8) as u8,
                actual: u8::try_from(data.len()).unwrap_or(u8::MAX),
            });
        }
        let mut entries = [ChannelPulse::default(); 8];
        for (slot, chunk) in entries.iter_mut().zip(data.chunks_exact(4)) {
            let mode = PulseMode::from_byte(chunk[0]).ok_or(DecodeError::BadField {
                command,
                field: "mode",
                value: chunk[0],
            })?;
            *slot = ChannelPulse {
                mode,
                pulse_width_us: u16::from_be_bytes([chunk[1], chunk[2]]),
                current_ma: chunk[3],
            };
        }
        Ok(Message::StartChannelListMode(ChannelListUpdate {
            entries,
            len: (data.len() / 4) as u8,
        }))
    }

    /// PhaseResult (§4.4, 16 bytes).
    fn phase_result(&self) -> Result<Message, DecodeError> {
        self.expect(16)?;
        let (byte, word) = (|i| self.byte(i), |i| self.word(i));
        Ok(Message::PhaseResult(PhaseResult {
            phase_counter: byte(0),
            passive_distance_10m: word(1),
            active_distance_10m: word(3),
            average_power_w: byte(5),
            maximum_power_w: byte(6),
            phase_duration_s: word(7),
            active_phase_duration_s: word(9),
            phase_work_j: word(11),
            success_percent: byte(13),
            symmetry_left_percent: byte(14),
            average_muscle_tone_dnm: byte(15),
        }))
    }
}

/// A packet: its number and its message.
///
/// The host numbers its packets 0, 1, ... 255, 0, ...; the device answers each with the
/// number of the packet it acknowledges (§2.2). InitAck carries the number of the Init it
/// answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Packet {
    /// Packet number.
    pub number: u8,
    /// The command and its data.
    pub message: Message,
}

impl Packet {
    /// Packet `number` carrying `message`.
    pub const fn new(number: u8, message: Message) -> Packet {
        Packet { number, message }
    }

    /// The unstuffed packet data: packet number, command, command data. Returns the
    /// buffer and the length used.
    pub fn data(&self) -> ([u8; MAX_COMMAND_DATA + 2], usize) {
        let mut w = DataWriter::new();
        self.message.write_data(&mut w);
        let mut out = [0u8; MAX_COMMAND_DATA + 2];
        out[0] = self.number;
        out[1] = self.message.command().id();
        out[2..2 + w.len].copy_from_slice(&w.buf[..w.len]);
        (out, 2 + w.len)
    }

    /// Encodes the packet into `out` (§2.2) and returns the bytes written. Allocation-free.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let (data, len) = self.data();
        crate::frame::encode_data(&data[..len], out)
    }
}
