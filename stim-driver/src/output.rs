//! The stimulator output as a typestate: [`Disarmed`] → [`Armed`] → [`Disarmed`].
//!
//! Only [`Armed`] can send a PULSE, and only [`Disarmed::arm`] sends NMT start, so an unarmed
//! handle cannot make current flow: the compiler enforces it. Both states send the frames
//! that are always safe ([`ControlFrame`]: heartbeat, NMT stop or pre-operational, CONFIG).
//! [`Armed::disarm`] always yields the disarmed handle, even when its NMT stop could not be
//! written (the caller keeps retrying the stop; the handle can no longer pulse).

use fes_can::{
    AliveCounter, Config, EncodeError, Frame, Heartbeat, Message, Nmt, NmtCommand, NmtState, Nodes,
    Pulse,
};

use crate::interlock::PulseCommand;
use crate::tx::{CanTx, TxDone, TxError};

/// A frame either state may send (none of them can start stimulation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControlFrame {
    /// The host heartbeat with the host's NMT state.
    Heartbeat(NmtState),
    /// NMT stop to the stimulator.
    Stop,
    /// NMT enter pre-operational to the stimulator.
    EnterPreOperational,
    /// One CONFIG page.
    Config(Config),
}

/// A frame could not be sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SendError {
    /// The bus side refused it.
    #[error(transparent)]
    Tx(#[from] TxError),
    /// A field was outside its signal's range (a configuration error; never clamped).
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

/// A PULSE that was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SentPulse {
    /// The frame's contents.
    pub pulse: Pulse,
    /// The write.
    pub done: TxDone,
}

/// Sender state that survives arming cycles: the PULSE alive counter and sequence number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PulseCounters {
    alive: AliveCounter,
    seq: u16,
}

/// The bus end shared by both states.
#[derive(Debug)]
struct Port<T> {
    tx: T,
    nodes: Nodes,
    counters: PulseCounters,
}

impl<T: CanTx> Port<T> {
    fn send(&mut self, message: &Message) -> Result<TxDone, SendError> {
        let frame: Frame = message.encode_for(&self.nodes)?;
        Ok(self.tx.send(&frame)?)
    }

    fn nmt(&mut self, command: NmtCommand) -> Result<TxDone, SendError> {
        self.send(&Message::Nmt(Nmt {
            command,
            node: self.nodes.stim(),
        }))
    }

    fn control(&mut self, frame: &ControlFrame) -> Result<TxDone, SendError> {
        match *frame {
            ControlFrame::Heartbeat(state) => {
                self.send(&Message::HostHeartbeat(Heartbeat { state }))
            }
            ControlFrame::Stop => self.nmt(NmtCommand::Stop),
            ControlFrame::EnterPreOperational => self.nmt(NmtCommand::EnterPreOperational),
            ControlFrame::Config(c) => self.send(&Message::Config(c)),
        }
    }
}

/// The output while stimulation is not allowed: cannot send PULSE.
#[derive(Debug)]
pub struct Disarmed<T> {
    port: Port<T>,
}

/// The output while stimulation is allowed.
#[derive(Debug)]
pub struct Armed<T> {
    port: Port<T>,
}

impl<T: CanTx> Disarmed<T> {
    /// A disarmed output on `tx` for `nodes`; the first PULSE will carry sequence number 1
    /// and alive counter 0.
    pub fn new(tx: T, nodes: Nodes) -> Self {
        Self {
            port: Port {
                tx,
                nodes,
                counters: PulseCounters {
                    alive: AliveCounter::new(),
                    seq: 0,
                },
            },
        }
    }

    /// Sends a control frame.
    pub fn send_control(&mut self, frame: &ControlFrame) -> Result<TxDone, SendError> {
        self.port.control(frame)
    }

    /// Sends NMT start to the stimulator and becomes [`Armed`]; on failure stays disarmed.
    pub fn arm(mut self) -> Result<Armed<T>, (Self, SendError)> {
        match self.port.nmt(NmtCommand::Start) {
            Ok(_) => Ok(Armed { port: self.port }),
            Err(e) => Err((self, e)),
        }
    }

    /// The transmit side (for inspection in tests and benchmarks).
    pub fn tx(&self) -> &T {
        &self.port.tx
    }
}

impl<T: CanTx> Armed<T> {
    /// Sends a control frame.
    pub fn send_control(&mut self, frame: &ControlFrame) -> Result<TxDone, SendError> {
        self.port.control(frame)
    }

    /// Sends one PULSE for `command`. The alive counter and the sequence number advance only
    /// when the frame was written, so a dropped frame leaves no gap the stimulator would
    /// reject.
    pub fn send_pulse(&mut self, command: &PulseCommand) -> Result<SentPulse, SendError> {
        let mut alive = self.port.counters.alive;
        let seq = self.port.counters.seq.wrapping_add(1);
        let pulse = Pulse {
            seq,
            alive_counter: alive.next_value(),
            channel: command.channel,
            amplitude_100ua: command.amplitude_100ua,
            width_us: command.width_us,
        };
        let done = self.port.send(&Message::Pulse(pulse))?;
        self.port.counters = PulseCounters { alive, seq };
        Ok(SentPulse { pulse, done })
    }

    /// Sends NMT stop and becomes [`Disarmed`] whatever the write's outcome (returned).
    pub fn disarm(mut self) -> (Disarmed<T>, Result<TxDone, SendError>) {
        let result = self.port.nmt(NmtCommand::Stop);
        (Disarmed { port: self.port }, result)
    }

    /// The transmit side (for inspection in tests and benchmarks).
    pub fn tx(&self) -> &T {
        &self.port.tx
    }
}

/// Either state, for a holder that switches between them.
#[derive(Debug)]
pub enum Output<T> {
    /// Not armed.
    Disarmed(Disarmed<T>),
    /// Armed.
    Armed(Armed<T>),
}

impl<T: CanTx> Output<T> {
    /// True when armed.
    pub fn is_armed(&self) -> bool {
        matches!(self, Output::Armed(_))
    }

    /// Tells the transmit side whether pulses may come soon ([`CanTx::contraction_ahead`]).
    pub fn contraction_ahead(&mut self, ahead: bool) {
        match self {
            Output::Disarmed(d) => d.port.tx.contraction_ahead(ahead),
            Output::Armed(a) => a.port.tx.contraction_ahead(ahead),
        }
    }

    /// Sends a control frame in either state.
    pub fn send_control(&mut self, frame: &ControlFrame) -> Result<TxDone, SendError> {
        match self {
            Output::Disarmed(d) => d.send_control(frame),
            Output::Armed(a) => a.send_control(frame),
        }
    }

    /// The transmit side.
    pub fn tx(&self) -> &T {
        match self {
            Output::Disarmed(d) => d.tx(),
            Output::Armed(a) => a.tx(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tx::CountingSink;
    use fes_can::{MessageKind, decode};

    fn command(width_us: u16) -> PulseCommand {
        PulseCommand {
            tick_seq: 7,
            t_ns: 0,
            t_publish_ns: 0,
            channel: 0,
            amplitude_100ua: 200,
            width_us,
        }
    }

    #[test]
    fn arm_sends_nmt_start_and_pulses_carry_fresh_counters() {
        let nodes = Nodes::DEFAULT;
        let d = Disarmed::new(CountingSink::new(nodes.id_of(MessageKind::Pulse)), nodes);
        let mut a = d.arm().unwrap();
        let start = a.tx().last.unwrap();
        assert_eq!(
            decode(u32::from(start.id), start.payload()),
            Ok(Message::Nmt(Nmt {
                command: NmtCommand::Start,
                node: 0x10
            }))
        );
        for k in 0..20u16 {
            let s = a.send_pulse(&command(200)).unwrap();
            assert_eq!(s.pulse.seq, k + 1);
            assert_eq!(s.pulse.alive_counter, (k % 16) as u8);
            let f = a.tx().last.unwrap();
            assert_eq!(
                decode(u32::from(f.id), f.payload()),
                Ok(Message::Pulse(s.pulse))
            );
        }
        let (d, r) = a.disarm();
        assert!(r.is_ok());
        let stop = d.tx().last.unwrap();
        assert_eq!(stop.payload(), &[0x02, 0x10]);
        assert_eq!(d.tx().pulses, 20);
    }

    #[test]
    fn a_failed_write_does_not_advance_the_counters() {
        let nodes = Nodes::DEFAULT;
        let mut a = Disarmed::new(CountingSink::new(0x110), nodes)
            .arm()
            .unwrap();
        a.send_pulse(&command(200)).unwrap();
        a.port.tx.fail_with = Some(TxError::Dropped { attempts: 3 });
        assert_eq!(
            a.send_pulse(&command(200)),
            Err(SendError::Tx(TxError::Dropped { attempts: 3 }))
        );
        a.port.tx.fail_with = None;
        let s = a.send_pulse(&command(200)).unwrap();
        assert_eq!((s.pulse.seq, s.pulse.alive_counter), (2, 1));
        // An out-of-range width is an encode error, not a clamped frame.
        assert!(matches!(
            a.send_pulse(&command(1001)),
            Err(SendError::Encode(_))
        ));
    }

    #[test]
    fn disarm_yields_the_disarmed_handle_even_when_the_stop_fails() {
        let mut a = Disarmed::new(CountingSink::new(0x110), Nodes::DEFAULT)
            .arm()
            .unwrap();
        a.port.tx.fail_with = Some(TxError::LinkDown {
            errno: libc::ENETDOWN,
        });
        let (d, r) = a.disarm();
        assert!(r.is_err());
        let d = Output::Disarmed(d);
        assert!(!d.is_armed());
    }
}
