//! [`CommandLink`]: the supervisor's orders to the driver, acknowledged.
//!
//! Every [`DriverCommand`] carries a sequence number; the driver's [`DriverStatus`] echoes
//! the last one it handled with its result (accepted, or refused with a
//! [`CommandRefusal`]). The link keeps the order still waiting for its acknowledgement
//! and turns what the statuses say into [`LinkEvent`]s the daemon acts on
//! ([`crate::pass::on_link_event`]):
//!
//! - an **Arm** is confirmed by the driver's acceptance (only then does `status` say
//!   `armed`); a refusal, or no acknowledgement within `ack_timeout_ns`, is a fault. An
//!   Arm is never re-sent: the driver refuses a stale one, and arming is the operator's act.
//! - a **Disarm** or **SafeStop** is re-sent every `resend_ns` (each time with a new
//!   sequence number) until the driver acknowledges one of them; unacknowledged after
//!   `ack_timeout_ns` it raises an alarm once, and the re-sending goes on.
//! - once nothing is pending, a status that answers the last confirmed order but
//!   contradicts it is a **mismatch**: a confirmed Arm with the driver back in boot,
//!   pre-operational or stopped (its own faults are the health monitor's), or a confirmed
//!   stop with the driver armed or stimulating.
//!
//! Sequence numbers start at the supervisor's start time in microseconds, so a restarted
//! supervisor never takes an acknowledgement meant for its predecessor as its own.
//! Without a watched driver (`health.watch_stim_driver = false`) orders are sent once and
//! taken as confirmed.

use fes_rt::msg::{
    CommandAck, CommandRefusal, DeviceState, DriverCommand, DriverCommandKind, DriverStatus,
};

use crate::core::DriverOrder;

/// Timing of the acknowledgements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkSettings {
    /// A stop not yet acknowledged is re-sent this often, ns.
    pub resend_ns: u64,
    /// An order not acknowledged within this is a fault (Arm) or an alarm (stops), ns.
    pub ack_timeout_ns: u64,
    /// Acknowledgements are expected (the driver is watched).
    pub required: bool,
}

impl Default for LinkSettings {
    fn default() -> Self {
        Self {
            resend_ns: 50_000_000,
            ack_timeout_ns: 1_000_000_000,
            required: true,
        }
    }
}

/// What the driver's statuses said about the orders.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkEvent {
    /// The driver carried out the order.
    Confirmed(DriverOrder),
    /// The driver refused the order.
    Refused {
        /// The order.
        order: DriverOrder,
        /// Why.
        reason: CommandRefusal,
    },
    /// No acknowledgement within the timeout (reported once per order).
    Unacknowledged {
        /// The order.
        order: DriverOrder,
        /// How long it has waited, ns.
        waited_ns: u64,
    },
    /// The driver is not armed although it confirmed the Arm.
    NotArmed {
        /// The state it reports.
        state: DeviceState,
    },
    /// The driver is armed although it confirmed a stop.
    StillArmed {
        /// The state it reports.
        state: DeviceState,
    },
}

/// Where the newest order stands, as `status` shows it (the operator's `stop` and `arm`
/// wait on it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Sent, not acknowledged yet (a stop is re-sent meanwhile).
    Pending,
    /// The driver carried it out.
    Confirmed,
    /// The driver refused it (a stop is re-sent until carried out).
    Refused(CommandRefusal),
    /// Not acknowledged within the timeout (a stop is still re-sent).
    Unacknowledged,
    /// Acknowledgements are not watched (`health.watch_stim_driver = false`): unknown.
    Unwatched,
}

/// The newest order and where it stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OrderRecord {
    /// The order.
    pub order: DriverOrder,
    /// Its identity: the sequence number of its first send.
    pub id: u64,
    /// Where it stands.
    pub outcome: Outcome,
}

/// An order waiting for its acknowledgement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Pending {
    order: DriverOrder,
    /// Sequence numbers of its sends: every one from `first_seq` to `last_seq` is it.
    first_seq: u64,
    last_seq: u64,
    issued_ns: u64,
    last_sent_ns: u64,
    alarmed: bool,
}

/// The orders and their acknowledgements (see the module documentation).
#[derive(Debug, Clone)]
pub struct CommandLink {
    settings: LinkSettings,
    next_seq: u64,
    pending: Option<Pending>,
    /// The last order the driver carried out, and the sequence number it acknowledged.
    confirmed: Option<(DriverOrder, u64)>,
    /// The newest order and where it stands.
    last: Option<OrderRecord>,
}

fn kind(order: DriverOrder) -> DriverCommandKind {
    match order {
        DriverOrder::Arm => DriverCommandKind::Arm,
        DriverOrder::Disarm => DriverCommandKind::Disarm,
        DriverOrder::SafeStop => DriverCommandKind::SafeStop,
    }
}

impl CommandLink {
    /// A link whose first command has sequence number `seq_base` (at least 1), e.g. the
    /// start time in µs.
    pub fn new(seq_base: u64, settings: LinkSettings) -> Self {
        Self {
            settings,
            next_seq: seq_base.clamp(1, DriverCommand::MAX_SEQ / 2),
            pending: None,
            confirmed: None,
            last: None,
        }
    }

    /// The newest order issued and where it stands.
    pub fn last_order(&self) -> Option<OrderRecord> {
        self.last
    }

    fn set_outcome(&mut self, outcome: Outcome) {
        if let Some(r) = self.last.as_mut() {
            r.outcome = outcome;
        }
    }

    /// The settings.
    pub fn settings(&self) -> &LinkSettings {
        &self.settings
    }

    fn command(&mut self, order: DriverOrder, now_ns: u64) -> DriverCommand {
        let seq = self.next_seq;
        self.next_seq += 1;
        DriverCommand::new(seq, now_ns, kind(order))
    }

    /// Issues `order` at `now_ns`: the command to send. It replaces any order still
    /// pending (the newer order is what the supervisor wants).
    pub fn issue(&mut self, order: DriverOrder, now_ns: u64) -> DriverCommand {
        let command = self.command(order, now_ns);
        self.last = Some(OrderRecord {
            order,
            id: command.seq,
            outcome: if self.settings.required {
                Outcome::Pending
            } else {
                Outcome::Unwatched
            },
        });
        if self.settings.required {
            // What the driver last confirmed no longer says what it is doing.
            self.confirmed = None;
            self.pending = Some(Pending {
                order,
                first_seq: command.seq,
                last_seq: command.seq,
                issued_ns: now_ns,
                last_sent_ns: now_ns,
                alarmed: false,
            });
        } else {
            self.confirmed = Some((order, command.seq));
        }
        command
    }

    /// The order waiting for its acknowledgement, if any.
    pub fn pending(&self) -> Option<DriverOrder> {
        self.pending.map(|p| p.order)
    }

    /// True when the driver confirmed an Arm and no other order followed it.
    pub fn armed_confirmed(&self) -> bool {
        self.pending.is_none() && matches!(self.confirmed, Some((DriverOrder::Arm, _)))
    }

    /// A validated DriverStatus: its acknowledgement, then (with nothing pending) its
    /// state against the last confirmed order.
    pub fn on_status(&mut self, s: &DriverStatus) -> Option<LinkEvent> {
        let ack = s.command_ack().ok()?;
        if let Some(p) = self.pending {
            let (seq, refusal) = match ack {
                CommandAck::Accepted { seq } => (seq, None),
                CommandAck::Refused { seq, reason } => (seq, Some(reason)),
                CommandAck::None => return None,
            };
            if !(p.first_seq..=p.last_seq).contains(&seq) {
                return None;
            }
            return Some(match refusal {
                None => {
                    self.pending = None;
                    self.confirmed = Some((p.order, seq));
                    self.set_outcome(Outcome::Confirmed);
                    LinkEvent::Confirmed(p.order)
                }
                Some(reason) => {
                    self.set_outcome(Outcome::Refused(reason));
                    // A refused Arm is over; a stop is re-sent until carried out.
                    if p.order == DriverOrder::Arm {
                        self.pending = None;
                    }
                    LinkEvent::Refused {
                        order: p.order,
                        reason,
                    }
                }
            });
        }
        let (order, seq) = self.confirmed?;
        if !matches!(ack, CommandAck::Accepted { seq: s_seq } if s_seq == seq) {
            return None;
        }
        let state = s.state().ok()?;
        let armed = matches!(state, DeviceState::Armed | DeviceState::Stimulating);
        match order {
            DriverOrder::Arm => matches!(
                state,
                DeviceState::Boot | DeviceState::PreOperational | DeviceState::Stopped
            )
            .then_some(LinkEvent::NotArmed { state }),
            DriverOrder::Disarm | DriverOrder::SafeStop => {
                armed.then_some(LinkEvent::StillArmed { state })
            }
        }
    }

    /// At `now_ns`: a stop to re-send, and an order that has waited too long.
    pub fn poll(&mut self, now_ns: u64) -> (Option<DriverCommand>, Option<LinkEvent>) {
        let Some(mut p) = self.pending else {
            return (None, None);
        };
        let waited_ns = now_ns.saturating_sub(p.issued_ns);
        let late = waited_ns >= self.settings.ack_timeout_ns;
        if p.order == DriverOrder::Arm {
            if late {
                self.pending = None;
                self.set_outcome(Outcome::Unacknowledged);
                return (
                    None,
                    Some(LinkEvent::Unacknowledged {
                        order: p.order,
                        waited_ns,
                    }),
                );
            }
            return (None, None);
        }
        let mut resend = None;
        if now_ns.saturating_sub(p.last_sent_ns) >= self.settings.resend_ns {
            let c = self.command(p.order, now_ns);
            p.last_seq = c.seq;
            p.last_sent_ns = now_ns;
            resend = Some(c);
        }
        let mut event = None;
        if late && !p.alarmed {
            p.alarmed = true;
            self.set_outcome(Outcome::Unacknowledged);
            event = Some(LinkEvent::Unacknowledged {
                order: p.order,
                waited_ns,
            });
        }
        self.pending = Some(p);
        (resend, event)
    }
}
