//! [`PatternLoop`]: one tick of the rt-core process without any I/O: references in, the
//! source's decision, a [`StimTick`] out. The iceoryx2 adapter ([`super::runner`]) feeds it
//! and publishes what it returns; tests drive it with mock wake-ups.

use super::feedback::{FeedbackRejection, FeedbackTracker};
use super::reference::{ReferencePolicy, ReferenceRejection, ReferenceTracker};
use super::source::{TickDecision, TickSource};
use fes_rt::msg::{ForceSample, Reference, ReferencePreview, StimTick};
use fes_rt::rt::clock::Wakeup;

/// Pulse parameters of every fired pulse (supramaximal pulses: amplitude and width are
/// fixed; the generator only decides *when*, thesis 6.5.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PulseSettings {
    /// Stimulator channel.
    pub channel: u8,
    /// Amplitude, µA.
    pub amplitude_ua: u32,
    /// Width, µs.
    pub width_us: u16,
}

/// The pattern generator's tick logic around a [`TickSource`].
#[derive(Debug, Clone)]
pub struct PatternLoop<S> {
    source: S,
    references: ReferenceTracker,
    feedback: Option<FeedbackTracker>,
    pulse: PulseSettings,
    degraded: bool,
    seq: u64,
    rejected_since_last_tick: bool,
    /// [`StimTick::CONTRACTION_AHEAD_MS`] in ticks of the loop's period.
    ahead_ticks: u32,
}

/// What happened in one [`PatternLoop::step`], besides the tick itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StepEvents {
    /// The source returned a non-finite value and was reset.
    pub source_fault: bool,
}

impl<S: TickSource> PatternLoop<S> {
    /// A loop around `source`. `feedback_max_age_ns` enables the feedback mode. `degraded`
    /// marks every tick with [`StimTick::FLAG_DEGRADED`].
    pub fn new(
        source: S,
        reference_policy: ReferencePolicy,
        feedback_max_age_ns: Option<u64>,
        pulse: PulseSettings,
        degraded: bool,
    ) -> Self {
        let ahead_ns = u64::from(StimTick::CONTRACTION_AHEAD_MS) * 1_000_000;
        Self {
            ahead_ticks: ahead_ns.div_ceil(reference_policy.tick_ns.max(1)) as u32,
            source,
            references: ReferenceTracker::new(reference_policy),
            feedback: feedback_max_age_ns.map(FeedbackTracker::new),
            pulse,
            degraded,
            seq: 0,
            rejected_since_last_tick: false,
        }
    }

    /// The wrapped source.
    pub fn source(&self) -> &S {
        &self.source
    }

    /// `seq` of the last tick produced (0 = none).
    pub fn last_seq(&self) -> u64 {
        self.seq
    }

    /// Offers a received reference (see [`ReferenceTracker::offer`]); a rejection marks the
    /// next tick with [`StimTick::FLAG_REFERENCE_REJECTED`].
    pub fn offer_reference(
        &mut self,
        reference: &Reference,
        now_ns: u64,
    ) -> Result<(), ReferenceRejection> {
        let result = self.references.offer(reference, now_ns);
        self.rejected_since_last_tick |= result.is_err();
        result
    }

    /// Offers a received preview of the scheduled setpoints (see
    /// [`ReferenceTracker::offer_preview`]); a rejection marks the next tick with
    /// [`StimTick::FLAG_REFERENCE_REJECTED`].
    pub fn offer_preview(
        &mut self,
        preview: &ReferencePreview,
        now_ns: u64,
    ) -> Result<(), ReferenceRejection> {
        let result = self.references.offer_preview(preview, now_ns);
        self.rejected_since_last_tick |= result.is_err();
        result
    }

    /// Offers a received force sample (ignored unless feedback mode is on).
    pub fn offer_force(&mut self, sample: &ForceSample) -> Result<(), FeedbackRejection> {
        match &mut self.feedback {
            Some(f) => f.offer(sample),
            None => Ok(()),
        }
    }

    /// Runs the source once for this wake-up and returns the tick to publish
    /// (`t_publish_ns` is set to the wake time; the publisher stamps it just before sending).
    ///
    /// The source decides once whatever the number of skipped periods, so a stall can
    /// never produce more than one pulse in a tick; it is told of the skipped periods first
    /// ([`TickSource::missed`]: no pulse in them) so that it keeps wall-clock time. While
    /// the reference's operator stop is in effect no pulse is fired.
    pub fn step(&mut self, wake: &Wakeup) -> (StimTick, StepEvents) {
        let target = self.references.advance_on_grid(wake.wake_ns, wake.grid_ns);
        let measured = self
            .feedback
            .as_ref()
            .and_then(|f| f.measured(wake.wake_ns));
        if wake.missed_periods > 0 {
            self.source.missed(wake.missed_periods, &target);
        }
        let mut decision = self.source.tick(&target, measured);
        let mut events = StepEvents::default();
        if !decision.is_finite() {
            self.source.reset();
            decision = TickDecision::default();
            events.source_fault = true;
        }
        let fire = decision.pulse && !target.stop;

        let mut flags = 0u16;
        let mut set = |cond: bool, flag: u16| {
            if cond {
                flags |= flag;
            }
        };
        set(target.stale, StimTick::FLAG_STALE_REFERENCE);
        set(target.none, StimTick::FLAG_NO_REFERENCE);
        set(target.stop, StimTick::FLAG_STOP);
        set(target.resting, StimTick::FLAG_RESTING);
        set(
            !target.resting || target.preview.contraction_within(self.ahead_ticks),
            StimTick::FLAG_CONTRACTION_AHEAD,
        );
        set(wake.missed_periods > 0, StimTick::FLAG_OVERRUN);
        set(
            self.rejected_since_last_tick,
            StimTick::FLAG_REFERENCE_REJECTED,
        );
        set(measured.is_some(), StimTick::FLAG_FEEDBACK);
        set(events.source_fault, StimTick::FLAG_SOURCE_FAULT);
        set(self.degraded, StimTick::FLAG_DEGRADED);
        self.rejected_since_last_tick = false;

        self.seq += 1;
        let tick = StimTick {
            seq: self.seq,
            t_ns: wake.grid_ns,
            t_wake_ns: wake.wake_ns,
            t_publish_ns: wake.wake_ns,
            ref_seq: target.ref_seq,
            reference: target.value,
            u_cont: decision.u_cont,
            energy: decision.energy,
            model_force: decision.model_force,
            predicted_force: decision.predicted_force,
            phi: decision.phi,
            amplitude_ua: if fire { self.pulse.amplitude_ua } else { 0 },
            missed_periods: wake.missed_periods,
            width_us: if fire { self.pulse.width_us } else { 0 },
            flags,
            pulse: u8::from(fire),
            channel: self.pulse.channel,
            min_gap_ticks: self.source.min_pulse_gap_ticks().min(u32::from(u16::MAX)) as u16,
        };
        (tick, events)
    }

    /// The last tick of a run: no pulse, [`StimTick::FLAG_FINAL`], stamped `now_ns`.
    pub fn final_tick(&mut self, now_ns: u64) -> StimTick {
        self.seq += 1;
        StimTick {
            flags: StimTick::FLAG_FINAL
                | if self.degraded {
                    StimTick::FLAG_DEGRADED
                } else {
                    0
                },
            channel: self.pulse.channel,
            ..StimTick::quiet(self.seq, now_ns)
        }
    }
}
