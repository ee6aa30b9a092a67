//! [`StimTick`]: the pattern generator's decision for one tick (rt-core -> stim-driver).

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_STIM_TICK};
use super::validate::{
    ValidationError, finite, in_range, int_in_range, known_flags, nonzero_seq, ordered,
};

/// One tick of the pattern generator (thesis Fig. 6.8), published every period whether or
/// not it fires, so that its absence is itself a fault the driver's watchdog sees.
///
/// `seq` increases by exactly one per published tick, also across overruns; skipped periods
/// are reported in `missed_periods`, not as `seq` gaps. A gap in `seq` at a receiver therefore
/// means that receiver lost samples.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("fes::StimTick::v2")]
pub struct StimTick {
    /// Sequence number, 1, 2, ... without gaps.
    pub seq: u64,
    /// The deadline this tick serves (a point of the period grid), CLOCK_MONOTONIC ns.
    pub t_ns: u64,
    /// When the real-time thread woke for it, ns (>= `t_ns`).
    pub t_wake_ns: u64,
    /// Stamped just before the sample was handed to iceoryx2, ns (>= `t_wake_ns`).
    pub t_publish_ns: u64,
    /// `seq` of the [`super::Reference`] in use; 0 = none received yet.
    pub ref_seq: u64,
    /// Target r given to the generator this tick, normalised force in [0, 1] (after ramps and
    /// the staleness rule).
    pub reference: f64,
    /// Continuous control signal u_cont of the LCN (thesis 6.5.2).
    pub u_cont: f64,
    /// Pulse-shaper energy since the last pulse, E (thesis eq. 6.8).
    pub energy: f64,
    /// Output of the simulated muscle model (the LMN in the loop), normalised force.
    pub model_force: f64,
    /// Model force predicted `d` samples ahead (the input delay), normalised force.
    pub predicted_force: f64,
    /// Scheduling variable phi of the LMN/LCN (thesis 5.4.1).
    pub phi: f64,
    /// Pulse amplitude in microamperes; 0 when `pulse` is 0.
    pub amplitude_ua: u32,
    /// Whole periods skipped just before this tick (overrun); 0 normally.
    pub missed_periods: u32,
    /// Pulse width in microseconds; 0 when `pulse` is 0.
    pub width_us: u16,
    /// `StimTick::FLAG_*` bits.
    pub flags: u16,
    /// 1 = fire one pulse now, 0 = no pulse.
    pub pulse: u8,
    /// Stimulator output channel, 0..=[`StimTick::MAX_CHANNEL`].
    pub channel: u8,
    /// The generator's minimum interval between two pulses, ticks (its pulse shaper's
    /// `min_gap` + 1); 0 = not stated. A transport that cannot deliver pulses that close
    /// refuses to arm (stim-driver, `[transport] min_interval_ms`).
    pub min_gap_ticks: u16,
}

impl StimTick {
    /// The reference is older than the staleness age: the target is ramping to zero.
    pub const FLAG_STALE_REFERENCE: u16 = 1 << 0;
    /// No valid reference has been received yet: the target is zero.
    pub const FLAG_NO_REFERENCE: u16 = 1 << 1;
    /// Periods were skipped before this tick (`missed_periods` > 0).
    pub const FLAG_OVERRUN: u16 = 1 << 2;
    /// Last tick before rt-core stops; `pulse` is 0.
    pub const FLAG_FINAL: u16 = 1 << 3;
    /// An invalid or out-of-order reference was received and ignored this tick.
    pub const FLAG_REFERENCE_REJECTED: u16 = 1 << 4;
    /// A measured force was passed to the generator (feedback mode).
    pub const FLAG_FEEDBACK: u16 = 1 << 5;
    /// The generator produced a non-finite value: outputs zeroed, no pulse, generator reset.
    pub const FLAG_SOURCE_FAULT: u16 = 1 << 6;
    /// rt-core runs without some real-time guarantee (best-effort mode).
    pub const FLAG_DEGRADED: u16 = 1 << 7;
    /// The operator stop of the reference is in effect.
    pub const FLAG_STOP: u16 = 1 << 8;
    /// The target is heading to rest (a zero reference still ramping down): the pattern
    /// generator rested (added 2026-12).
    pub const FLAG_RESTING: u16 = 1 << 9;
    /// A contraction is running (the target is not resting) or a scheduled one starts
    /// within [`Self::CONTRACTION_AHEAD_MS`] (the reference preview says so): pulses may
    /// come. A transport that carries one command at a time (ScienceMode 2) keeps its line
    /// free of liveness queries meanwhile, so that a pulse does not wait behind one.
    pub const FLAG_CONTRACTION_AHEAD: u16 = 1 << 10;
    /// How far ahead [`Self::FLAG_CONTRACTION_AHEAD`] looks, ms: longer than a RehaStim
    /// 2's longest answer (100 ms, protocol §2.3), so that a query started before it is
    /// answered before the contraction.
    pub const CONTRACTION_AHEAD_MS: u32 = 120;
    /// All flags defined.
    pub const KNOWN_FLAGS: u16 = (1 << 11) - 1;
    /// Highest stimulator channel index.
    pub const MAX_CHANNEL: u8 = 15;
    /// Contract ceiling of the amplitude, µA (a sanity bound; the driver and the stimulator
    /// enforce their own, lower, clinical limits).
    pub const MAX_AMPLITUDE_UA: u32 = 250_000;

    /// A tick of deadline `t_ns` (woken and stamped at `t_ns` too) that fires nothing and
    /// carries no generator state: every other field zero. The base of rt-core's final
    /// tick and of hand-made ticks in tests and benches.
    pub const fn quiet(seq: u64, t_ns: u64) -> Self {
        Self {
            seq,
            t_ns,
            t_wake_ns: t_ns,
            t_publish_ns: t_ns,
            ref_seq: 0,
            reference: 0.0,
            u_cont: 0.0,
            energy: 0.0,
            model_force: 0.0,
            predicted_force: 0.0,
            phi: 0.0,
            amplitude_ua: 0,
            missed_periods: 0,
            width_us: 0,
            flags: 0,
            pulse: 0,
            channel: 0,
            min_gap_ticks: 0,
        }
    }

    /// This tick, firing one pulse of `amplitude_ua` and `width_us` on `channel`.
    pub const fn firing(mut self, channel: u8, amplitude_ua: u32, width_us: u16) -> Self {
        self.pulse = 1;
        self.channel = channel;
        self.amplitude_ua = amplitude_ua;
        self.width_us = width_us;
        self
    }

    /// True when this tick fires a pulse.
    pub fn fires(&self) -> bool {
        self.pulse != 0
    }

    /// True when `flag` is set.
    pub fn has(&self, flag: u16) -> bool {
        self.flags & flag != 0
    }
}

impl Contract for StimTick {
    const TOPIC: &'static str = TOPIC_STIM_TICK;
    const QOS: PubSubQos = PubSubQos {
        max_publishers: 1,
        max_subscribers: 8,
        // About 1 s of ticks: the supervisor records every tick from a normal-priority
        // thread that may be descheduled for tens of ms (and much longer in a UML guest);
        // 64 lost ticks there. The shared memory this costs is 8 x 1024 samples.
        subscriber_buffer: 1024,
        history: 0,
        max_loaned_samples: 1,
    };

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        ordered("t_ns", self.t_ns, "t_wake_ns", self.t_wake_ns)?;
        ordered(
            "t_wake_ns",
            self.t_wake_ns,
            "t_publish_ns",
            self.t_publish_ns,
        )?;
        in_range("reference", self.reference, 0.0, 1.0)?;
        finite("u_cont", self.u_cont)?;
        finite("energy", self.energy)?;
        finite("model_force", self.model_force)?;
        finite("predicted_force", self.predicted_force)?;
        finite("phi", self.phi)?;
        int_in_range("pulse", self.pulse.into(), 0, 1)?;
        int_in_range("channel", self.channel.into(), 0, Self::MAX_CHANNEL.into())?;
        int_in_range(
            "amplitude_ua",
            self.amplitude_ua.into(),
            0,
            Self::MAX_AMPLITUDE_UA.into(),
        )?;
        known_flags("flags", self.flags.into(), Self::KNOWN_FLAGS.into())?;
        if self.fires() {
            if self.amplitude_ua == 0 || self.width_us == 0 {
                return Err(ValidationError::Inconsistent(
                    "a pulse needs a non-zero amplitude and width",
                ));
            }
            if self.has(Self::FLAG_FINAL) {
                return Err(ValidationError::Inconsistent(
                    "the final tick fires a pulse",
                ));
            }
            if self.has(Self::FLAG_SOURCE_FAULT) {
                return Err(ValidationError::Inconsistent(
                    "a faulted tick fires a pulse",
                ));
            }
        } else if self.amplitude_ua != 0 || self.width_us != 0 {
            return Err(ValidationError::Inconsistent(
                "amplitude and width must be 0 without a pulse",
            ));
        }
        if self.has(Self::FLAG_OVERRUN) != (self.missed_periods > 0) {
            return Err(ValidationError::Inconsistent(
                "FLAG_OVERRUN must be set exactly when missed_periods > 0",
            ));
        }
        Ok(())
    }
}
