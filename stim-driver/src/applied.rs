//! Which pulses the stimulator applied: the per-pulse account behind a recording's
//! decided / sent / applied.
//!
//! "Sent" is the driver's own knowledge (the frame was written); only the stimulator knows
//! whether it applied the pulse. It says so three ways, and the [`AppliedLedger`] turns
//! them into one [`PulseFate::Applied`] or [`PulseFate::NotApplied`] per pulse sent, in the
//! order the pulses were written:
//!
//! - STATUS `pulses_delivered` (every 10 ms; on a RehaStim 2 the SinglePulse
//!   acknowledgements with result 0, [`crate::serial_rx`]): the stimulator applies pulses
//!   in the order they arrive, so an increase by `n` applies the `n` oldest pulses still
//!   open that it did not reject;
//! - an EMCY naming a pulse's sequence number (`seq`, [`fes_can::Emcy`]): that pulse was
//!   rejected;
//! - a busy answer to a SinglePulse (ScienceMode 2, stop-and-wait: it answers the newest
//!   pulse): not executed.
//!
//! A pulse still open after the confirmation window (a STATUS should have counted it
//! long before: the driver's STATUS reconciliation trips when the count lags beyond the
//! in-flight window, [`crate::reconcile`]) is not applied as far as anyone knows: the
//! recording never claims what nobody confirmed. A count that goes backwards (the
//! stimulator reset) closes every open pulse as not applied and starts counting again.
//!
//! Fixed capacity, no allocation: it runs on the forward thread.

use fes_rt::msg::PulseFate;

/// STATUS `pulses_delivered` is modulo 2^24.
const MASK: u32 = (1 << 24) - 1;

/// Pulses that can wait for their account at once: at the 500 Hz interlock ceiling, 256
/// ms of pulses; a full ledger closes its oldest as not applied.
pub const LEDGER_LEN: usize = 128;

/// One pulse sent and not yet accounted for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct OpenPulse {
    /// The StimTick that asked for it.
    pub tick_seq: u64,
    /// Its grid time, ns.
    pub tick_t_ns: u64,
    /// The PULSE frame's sequence number.
    pub pulse_seq: u16,
    /// When it was written, ns.
    pub written_ns: u64,
    /// The stimulator rejected it (EMCY, busy).
    rejected: bool,
}

impl OpenPulse {
    /// A pulse written at `written_ns`.
    pub const fn new(tick_seq: u64, tick_t_ns: u64, pulse_seq: u16, written_ns: u64) -> Self {
        Self {
            tick_seq,
            tick_t_ns,
            pulse_seq,
            written_ns,
            rejected: false,
        }
    }
}

/// The pulses sent and not yet accounted for, oldest first (see the module documentation).
#[derive(Debug, Clone)]
pub struct AppliedLedger {
    open: [OpenPulse; LEDGER_LEN],
    head: usize,
    len: usize,
    /// The stimulator's count that stands for every pulse closed so far; `None` before the
    /// first STATUS.
    counted: Option<u32>,
    /// A pulse open longer than this is closed as not applied, ns.
    window_ns: u64,
}

impl AppliedLedger {
    /// An empty ledger whose pulses are closed as not applied after `window_ns` without a
    /// count.
    pub const fn new(window_ns: u64) -> Self {
        Self {
            open: [OpenPulse::new(0, 0, 0, 0); LEDGER_LEN],
            head: 0,
            len: 0,
            counted: None,
            window_ns,
        }
    }

    /// Pulses open.
    pub const fn len(&self) -> usize {
        self.len
    }

    /// Whether no pulse is open.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn at(&self, k: usize) -> usize {
        (self.head + k) % LEDGER_LEN
    }

    fn pop(&mut self) -> Option<OpenPulse> {
        if self.len == 0 {
            return None;
        }
        let p = self.open[self.head];
        self.head = (self.head + 1) % LEDGER_LEN;
        self.len -= 1;
        Some(p)
    }

    /// A pulse was written. A full ledger first closes its oldest as not applied.
    pub fn on_sent(&mut self, pulse: OpenPulse, mut close: impl FnMut(&OpenPulse, PulseFate)) {
        if self.len == LEDGER_LEN
            && let Some(old) = self.pop()
        {
            close(&old, PulseFate::NotApplied);
        }
        let k = self.at(self.len);
        self.open[k] = pulse;
        self.len += 1;
    }

    /// The stimulator's count of pulses applied (STATUS `pulses_delivered`, modulo 2^24):
    /// closes the oldest open pulses it covers as applied, and those rejected before them
    /// as not applied.
    pub fn on_status(&mut self, delivered: u32, mut close: impl FnMut(&OpenPulse, PulseFate)) {
        let delivered = delivered & MASK;
        let Some(mut counted) = self.counted else {
            // The first count: what it covers was applied before anything was written.
            self.counted = Some(delivered);
            return;
        };
        let mut new = delivered.wrapping_sub(counted) & MASK;
        if new > MASK / 2 {
            // The count went backwards: the stimulator restarted. What it applied of the
            // open pulses before that is not known.
            self.close_all(&mut close);
            self.counted = Some(delivered);
            return;
        }
        while let Some(p) = self.front() {
            if p.rejected {
                self.pop();
                close(&p, PulseFate::NotApplied);
            } else if new > 0 {
                self.pop();
                close(&p, PulseFate::Applied);
                new -= 1;
                counted = counted.wrapping_add(1) & MASK;
            } else {
                break;
            }
        }
        // Applied beyond what was written is not ours to account (a pulse written before
        // the count started, or a forged one, which STATUS reconciliation trips on).
        self.counted = Some(if self.len == 0 { delivered } else { counted });
    }

    fn front(&self) -> Option<OpenPulse> {
        (self.len > 0).then(|| self.open[self.head])
    }

    /// The stimulator rejected the pulse with sequence number `pulse_seq` (an EMCY naming
    /// it); `false` when no open pulse has it.
    pub fn on_rejected(&mut self, pulse_seq: u16) -> bool {
        for k in 0..self.len {
            let i = self.at(k);
            if self.open[i].pulse_seq == pulse_seq && !self.open[i].rejected {
                self.open[i].rejected = true;
                return true;
            }
        }
        false
    }

    /// The stimulator answered busy to a pulse: on a stop-and-wait transport that is the
    /// newest one written.
    pub fn on_busy(&mut self) {
        if self.len > 0 {
            let i = self.at(self.len - 1);
            self.open[i].rejected = true;
        }
    }

    /// Closes as not applied the pulses open longer than the window at `now_ns`.
    pub fn expire(&mut self, now_ns: u64, mut close: impl FnMut(&OpenPulse, PulseFate)) {
        while let Some(p) = self.front() {
            if now_ns.saturating_sub(p.written_ns) <= self.window_ns {
                break;
            }
            self.pop();
            close(&p, PulseFate::NotApplied);
        }
    }

    /// The stimulator was lost (it restarted, or lost our configuration): every open pulse
    /// is closed as not applied and the count starts again at the next STATUS.
    pub fn on_stimulator_lost(&mut self, mut close: impl FnMut(&OpenPulse, PulseFate)) {
        self.close_all(&mut close);
        self.counted = None;
    }

    fn close_all(&mut self, close: &mut impl FnMut(&OpenPulse, PulseFate)) {
        while let Some(p) = self.pop() {
            close(&p, PulseFate::NotApplied);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sent(
        l: &mut AppliedLedger,
        seqs: std::ops::RangeInclusive<u16>,
        out: &mut Vec<(u64, PulseFate)>,
    ) {
        for s in seqs {
            l.on_sent(
                OpenPulse::new(u64::from(s) * 10, 0, s, u64::from(s) * 1_000_000),
                |p, f| out.push((p.tick_seq, f)),
            );
        }
    }

    #[test]
    fn a_status_count_applies_the_oldest_pulses_in_order() {
        let mut l = AppliedLedger::new(200_000_000);
        let mut out = Vec::new();
        l.on_status(500, |p, f| out.push((p.tick_seq, f)));
        sent(&mut l, 1..=5, &mut out);
        l.on_status(503, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(
            out,
            [
                (10, PulseFate::Applied),
                (20, PulseFate::Applied),
                (30, PulseFate::Applied)
            ]
        );
        assert_eq!(l.len(), 2);
        // The same count again closes nothing; two more close the rest.
        l.on_status(503, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(out.len(), 3);
        l.on_status(505, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(
            out[3..],
            [(40, PulseFate::Applied), (50, PulseFate::Applied)]
        );
        assert!(l.is_empty());
    }

    /// A rejected pulse is skipped by the count: the pulses after it are the ones applied.
    #[test]
    fn a_rejected_pulse_is_not_applied_and_does_not_take_a_count() {
        let mut l = AppliedLedger::new(200_000_000);
        let mut out = Vec::new();
        l.on_status(0, |_, _| {});
        sent(&mut l, 1..=3, &mut out);
        assert!(l.on_rejected(2));
        assert!(!l.on_rejected(9), "no open pulse has that number");
        l.on_status(2, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(
            out,
            [
                (10, PulseFate::Applied),
                (20, PulseFate::NotApplied),
                (30, PulseFate::Applied)
            ]
        );
    }

    #[test]
    fn a_busy_answer_rejects_the_newest_pulse() {
        let mut l = AppliedLedger::new(200_000_000);
        let mut out = Vec::new();
        l.on_status(7, |_, _| {});
        sent(&mut l, 1..=2, &mut out);
        l.on_busy();
        l.on_status(8, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(out, [(10, PulseFate::Applied), (20, PulseFate::NotApplied)]);
    }

    /// What no count confirms within the window is not applied; the count wraps at 2^24.
    #[test]
    fn an_unconfirmed_pulse_expires_and_the_count_wraps() {
        let mut l = AppliedLedger::new(50_000_000);
        let mut out = Vec::new();
        l.on_status(MASK - 1, |_, _| {});
        sent(&mut l, 1..=4, &mut out);
        l.on_status(1, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(
            out,
            [
                (10, PulseFate::Applied),
                (20, PulseFate::Applied),
                (30, PulseFate::Applied)
            ],
            "MASK - 1 -> 1 is three pulses"
        );
        l.expire(54_000_000, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(out.len(), 3, "written at 4 ms: still within 50 ms");
        l.expire(54_000_001, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(out[3], (40, PulseFate::NotApplied));
    }

    /// A count that goes backwards (a restarted stimulator) applies nothing open; more
    /// applied than written is not attributed to later pulses.
    #[test]
    fn a_reset_count_closes_open_pulses_and_extra_counts_are_not_carried() {
        let mut l = AppliedLedger::new(200_000_000);
        let mut out = Vec::new();
        l.on_status(1000, |_, _| {});
        sent(&mut l, 1..=2, &mut out);
        l.on_status(3, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(
            out,
            [(10, PulseFate::NotApplied), (20, PulseFate::NotApplied)]
        );
        out.clear();
        l.on_status(10, |_, _| {});
        sent(&mut l, 3..=3, &mut out);
        l.on_status(10, |p, f| out.push((p.tick_seq, f)));
        assert!(
            out.is_empty(),
            "7 applied while nothing was open do not count for it"
        );
        l.on_status(11, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(out, [(30, PulseFate::Applied)]);
    }

    #[test]
    fn a_full_ledger_closes_its_oldest_and_a_lost_stimulator_closes_all() {
        let mut l = AppliedLedger::new(u64::MAX);
        let mut out = Vec::new();
        l.on_status(0, |_, _| {});
        sent(&mut l, 1..=(LEDGER_LEN as u16 + 1), &mut out);
        assert_eq!(out, [(10, PulseFate::NotApplied)]);
        assert_eq!(l.len(), LEDGER_LEN);
        out.clear();
        l.on_stimulator_lost(|p, f| out.push((p.tick_seq, f)));
        assert_eq!(out.len(), LEDGER_LEN);
        assert!(out.iter().all(|&(_, f)| f == PulseFate::NotApplied));
        // The next STATUS is a new baseline, not a count.
        sent(&mut l, 1..=1, &mut out);
        out.clear();
        l.on_status(40, |p, f| out.push((p.tick_seq, f)));
        assert!(out.is_empty());
        l.on_status(41, |p, f| out.push((p.tick_seq, f)));
        assert_eq!(out, [(10, PulseFate::Applied)]);
    }
}
