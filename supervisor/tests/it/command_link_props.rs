//! The supervisor's orders and the driver's acknowledgements ([`CommandLink`]) over
//! arbitrary interleavings: orders at any time, commands and statuses lost,
//! arms refused, a driver that falls back to pre-operational by itself. After every step:
//! "armed" is shown only while the driver really is armed; a refused arm is never
//! confirmed. After a final quiet phase (nothing lost): every stop is acknowledged and the
//! driver is stopped; an unacknowledged arm has ended in an event.

use fes_rt::msg::{
    CommandRefusal, CommandResult, Contract, DeviceState, DriverCommand, DriverCommandKind,
    DriverStatus,
};
use proptest::prelude::*;
use supervisor::command_link::{CommandLink, LinkEvent, LinkSettings, OrderRecord, Outcome};
use supervisor::core::DriverOrder;

const MS: u64 = 1_000_000;

/// The driver as the link sees it: a state, the last command handled and its result.
#[derive(Debug, Clone, Default)]
struct Driver {
    armed: bool,
    refuse_arms: bool,
    ack: (u64, u8, u8),
    seq: u64,
}

impl Driver {
    fn handle(&mut self, c: &DriverCommand) {
        match c.kind().unwrap() {
            DriverCommandKind::Arm if self.refuse_arms && !self.armed => {
                self.ack = (
                    c.seq,
                    CommandResult::Refused as u8,
                    CommandRefusal::NoTicks as u8,
                );
            }
            DriverCommandKind::Arm => {
                self.armed = true;
                self.ack = (c.seq, CommandResult::Accepted as u8, 0);
            }
            DriverCommandKind::Disarm | DriverCommandKind::SafeStop => {
                self.armed = false;
                self.ack = (c.seq, CommandResult::Accepted as u8, 0);
            }
        }
    }

    fn status(&mut self, t_ns: u64) -> DriverStatus {
        self.seq += 1;
        let state = if self.armed {
            DeviceState::Armed
        } else {
            DeviceState::PreOperational
        };
        let s = DriverStatus {
            seq: self.seq,
            t_ns,
            ticks_received: 0,
            ticks_lost: 0,
            pulses_sent: 0,
            pulses_rejected: 0,
            can_tx_errors: 0,
            watchdog_trips: 0,
            fault_code: 0,
            state: state as u8,
            stimulator_state: DeviceState::Unknown as u8,
            command_seq: self.ack.0,
            command_result: self.ack.1,
            command_reason: self.ack.2,
            reserved: [0; 6],
        };
        assert_eq!(s.validate(), Ok(()));
        s
    }
}

#[derive(Debug, Clone)]
enum Step {
    /// The supervisor orders.
    Order(DriverOrder),
    /// Time passes (ms), the link polls.
    Wait(u64),
    /// The driver publishes a status; it is lost on the way when `lost`.
    Status { lost: bool },
    /// The next command on the way is lost.
    LoseNextCommand,
    /// The driver starts or stops refusing arms.
    RefuseArms(bool),
    /// The driver falls back to pre-operational by itself (a restart).
    DriverResets,
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        2 => prop_oneof![
            Just(DriverOrder::Arm),
            Just(DriverOrder::Disarm),
            Just(DriverOrder::SafeStop)
        ]
        .prop_map(Step::Order),
        3 => (1u64..400).prop_map(Step::Wait),
        4 => any::<bool>().prop_map(|lost| Step::Status { lost }),
        1 => Just(Step::LoseNextCommand),
        1 => any::<bool>().prop_map(Step::RefuseArms),
        1 => Just(Step::DriverResets),
    ]
}

struct World {
    link: CommandLink,
    driver: Driver,
    now: u64,
    lose_next: bool,
    events: Vec<LinkEvent>,
    /// Arms the driver refused (by the commands' seqs).
    refused_arms: usize,
}

impl World {
    fn send(&mut self, c: DriverCommand) {
        assert_eq!(c.validate(), Ok(()));
        if std::mem::take(&mut self.lose_next) {
            return;
        }
        let before = self.driver.ack;
        self.driver.handle(&c);
        if self.driver.ack != before && self.driver.ack.1 == CommandResult::Refused as u8 {
            self.refused_arms += 1;
        }
    }

    fn apply(&mut self, s: &Step) {
        match s {
            Step::Order(o) => {
                let c = self.link.issue(*o, self.now);
                self.send(c);
            }
            Step::Wait(ms) => {
                self.now += ms * MS;
                let (resend, event) = self.link.poll(self.now);
                if let Some(c) = resend {
                    self.send(c);
                }
                self.events.extend(event);
            }
            Step::Status { lost } => {
                let st = self.driver.status(self.now);
                if !lost {
                    let e = self.link.on_status(&st);
                    self.events.extend(e);
                }
            }
            Step::LoseNextCommand => self.lose_next = true,
            Step::RefuseArms(r) => self.driver.refuse_arms = *r,
            Step::DriverResets => self.driver.armed = false,
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn orders_are_acknowledged_and_armed_means_armed(steps in prop::collection::vec(step(), 1..120)) {
        let mut w = World {
            link: CommandLink::new(1_000, LinkSettings::default()),
            driver: Driver::default(),
            now: 1_000 * MS,
            lose_next: false,
            events: Vec::new(),
            refused_arms: 0,
        };
        let mut resets = false;
        for s in &steps {
            resets |= matches!(s, Step::DriverResets);
            w.apply(s);
            if w.link.armed_confirmed() && !resets {
                // Without a spontaneous reset, a confirmed arm is a driver that is armed.
                prop_assert!(w.driver.armed, "shown armed while the driver is not: {steps:?}");
            }
        }
        // A confirmation of an Arm is never produced by a refusal.
        let confirmed_arms = w.events.iter().filter(|e| **e == LinkEvent::Confirmed(DriverOrder::Arm)).count();
        let refusals = w.events.iter().filter(|e| matches!(e, LinkEvent::Refused { order: DriverOrder::Arm, .. })).count();
        prop_assert!(refusals <= w.refused_arms);
        let _ = confirmed_arms;
        // Quiet phase: a stop, then nothing is lost: it is acknowledged within a few resends
        // and the driver is stopped; nothing stays pending.
        w.lose_next = true; // even its first send is lost
        w.apply(&Step::Order(DriverOrder::SafeStop));
        for _ in 0..4 {
            w.apply(&Step::Wait(50));
            w.apply(&Step::Status { lost: false });
        }
        prop_assert_eq!(w.link.pending(), None, "stop never acknowledged: {:?}", steps);
        prop_assert!(!w.driver.armed);
        prop_assert!(!w.link.armed_confirmed());
    }
}

/// A refused Arm is reported with its reason and never shown as armed; an Arm nobody
/// answers ends in one Unacknowledged event after the timeout.
#[test]
fn a_refused_or_unanswered_arm_is_never_armed() {
    let s = LinkSettings::default();
    let mut link = CommandLink::new(10, s);
    let mut d = Driver {
        refuse_arms: true,
        ..Driver::default()
    };
    let c = link.issue(DriverOrder::Arm, 0);
    let shown = |link: &CommandLink| link.last_order().map(|r| (r.order, r.id, r.outcome));
    assert_eq!(
        shown(&link),
        Some((DriverOrder::Arm, c.seq, Outcome::Pending))
    );
    d.handle(&c);
    assert!(!link.armed_confirmed());
    assert_eq!(
        link.on_status(&d.status(MS)),
        Some(LinkEvent::Refused {
            order: DriverOrder::Arm,
            reason: CommandRefusal::NoTicks
        })
    );
    assert!(!link.armed_confirmed());
    assert_eq!(link.pending(), None);
    assert_eq!(
        shown(&link),
        Some((
            DriverOrder::Arm,
            c.seq,
            Outcome::Refused(CommandRefusal::NoTicks)
        ))
    );
    // Lost: no answer at all.
    let lost = link.issue(DriverOrder::Arm, 10 * MS);
    assert!(lost.seq > c.seq, "a newer order, a larger id");
    assert_eq!(link.poll(10 * MS + s.ack_timeout_ns - 1), (None, None));
    assert_eq!(
        link.poll(10 * MS + s.ack_timeout_ns),
        (
            None,
            Some(LinkEvent::Unacknowledged {
                order: DriverOrder::Arm,
                waited_ns: s.ack_timeout_ns
            })
        )
    );
    assert_eq!(link.pending(), None);
    assert!(!link.armed_confirmed());
    assert_eq!(
        shown(&link),
        Some((DriverOrder::Arm, lost.seq, Outcome::Unacknowledged))
    );
}

/// A stop is re-sent with a new seq every resend period until acknowledged, with one alarm
/// after the timeout; an acknowledgement of any of its sends ends it.
#[test]
fn a_stop_is_resent_until_acknowledged_and_alarms_once() {
    let s = LinkSettings::default();
    let mut link = CommandLink::new(10, s);
    let first = link.issue(DriverOrder::SafeStop, 0);
    let mut seqs = vec![first.seq];
    let mut alarms = 0;
    let mut t = 0;
    while t < 2 * s.ack_timeout_ns {
        t += 10 * MS;
        let (resend, event) = link.poll(t);
        if let Some(c) = resend {
            assert_eq!(c.kind(), Ok(DriverCommandKind::SafeStop));
            assert!(c.seq > *seqs.last().unwrap());
            seqs.push(c.seq);
        }
        alarms += usize::from(matches!(event, Some(LinkEvent::Unacknowledged { .. })));
    }
    assert_eq!(alarms, 1);
    assert_eq!(seqs.len() as u64, 1 + 2 * s.ack_timeout_ns / s.resend_ns);
    // Shown as one order (its first send's id), unacknowledged, while it is re-sent.
    assert_eq!(
        link.last_order(),
        Some(OrderRecord {
            order: DriverOrder::SafeStop,
            id: first.seq,
            outcome: Outcome::Unacknowledged
        })
    );
    // The driver handled an early send only: that acknowledges it.
    let mut d = Driver::default();
    d.handle(&DriverCommand::new(seqs[3], t, DriverCommandKind::SafeStop));
    assert_eq!(
        link.on_status(&d.status(t)),
        Some(LinkEvent::Confirmed(DriverOrder::SafeStop))
    );
    assert_eq!(link.pending(), None);
    assert_eq!(link.poll(t + s.resend_ns), (None, None));
    assert_eq!(
        link.last_order().map(|r| (r.id, r.outcome)),
        Some((first.seq, Outcome::Confirmed))
    );
}

/// With nothing pending, a status contradicting the confirmed order is a mismatch: a
/// driver back in pre-operational after a confirmed arm, a driver armed after a confirmed
/// stop. An acknowledgement from another supervisor's command is not taken as ours.
#[test]
fn a_driver_contradicting_its_confirmation_is_a_mismatch() {
    let mut link = CommandLink::new(10, LinkSettings::default());
    let mut d = Driver::default();
    let arm = link.issue(DriverOrder::Arm, 0);
    // A status answering an older command (seq 3, another supervisor's) is not ours.
    d.ack = (3, CommandResult::Accepted as u8, 0);
    d.armed = true;
    assert_eq!(link.on_status(&d.status(MS)), None);
    assert!(!link.armed_confirmed());
    d.handle(&arm);
    assert_eq!(
        link.on_status(&d.status(2 * MS)),
        Some(LinkEvent::Confirmed(DriverOrder::Arm))
    );
    assert!(link.armed_confirmed());
    assert_eq!(link.on_status(&d.status(3 * MS)), None);
    d.armed = false;
    assert_eq!(
        link.on_status(&d.status(4 * MS)),
        Some(LinkEvent::NotArmed {
            state: DeviceState::PreOperational
        })
    );
    let stop = link.issue(DriverOrder::Disarm, 5 * MS);
    d.handle(&stop);
    assert_eq!(
        link.on_status(&d.status(6 * MS)),
        Some(LinkEvent::Confirmed(DriverOrder::Disarm))
    );
    d.armed = true;
    assert_eq!(
        link.on_status(&d.status(7 * MS)),
        Some(LinkEvent::StillArmed {
            state: DeviceState::Armed
        })
    );
}

/// Without a watched driver, orders are sent once and taken as confirmed by the link; the
/// operator is shown `unwatched`, not `confirmed`.
#[test]
fn without_acknowledgements_orders_are_fire_and_forget() {
    let mut link = CommandLink::new(
        10,
        LinkSettings {
            required: false,
            ..LinkSettings::default()
        },
    );
    let _ = link.issue(DriverOrder::Arm, 0);
    assert!(link.armed_confirmed());
    assert_eq!(link.pending(), None);
    assert_eq!(link.poll(10_000 * MS), (None, None));
    assert_eq!(
        link.last_order().map(|r| r.outcome),
        Some(Outcome::Unwatched)
    );
}
