//! Property tests of the interlocks: for arbitrary tick sequences (duplicates, reordering,
//! gaps, bursts, late and future ticks, invalid messages, any amplitude, width and channel)
//! and arbitrary limits, the pulse train the interlocks let through never violates a
//! configured limit, checked here from the emitted train alone; and a legal stream is let
//! through whole (so the first property cannot hold by refusing everything).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_rt::msg::{Contract, StimTick};
use proptest::prelude::*;
use stim_driver::interlock::{InterlockLimits, Interlocks, PulseCommand, Verdict, charge_nc};

const MS: u64 = 1_000_000;

fn limits_strategy() -> impl Strategy<Value = InterlockLimits> {
    (
        1u64..20,
        1u16..8,
        1u64..120,
        1u32..400,
        1u16..1000,
        1u64..100_000,
        1u16..=u16::MAX,
        1u64..3000,
    )
        .prop_map(
            |(ipi_ms, max_pulses, window_ms, amp_100ua, width, charge, channels, delay_us)| {
                InterlockLimits {
                    min_ipi_ns: ipi_ms * MS,
                    max_pulses,
                    rate_window_ns: window_ms * MS,
                    max_amplitude_ua: amp_100ua * 100,
                    max_width_us: width,
                    max_charge_nc: charge,
                    allowed_channels: channels,
                    max_pulse_delay_ns: delay_us * 1000,
                }
            },
        )
}

/// One generated input: how seq and time move, and the tick's contents.
#[derive(Debug, Clone)]
struct Step {
    seq_step: i8,
    dt_us: u32,
    delay_us: i32,
    pulse: bool,
    amplitude_ua: u32,
    width_us: u16,
    channel: u8,
    corrupt: u8,
}

fn step_strategy() -> impl Strategy<Value = Step> {
    (
        prop_oneof![8 => Just(1i8), 1 => Just(0i8), 1 => -3i8..0, 1 => 2i8..6],
        prop_oneof![6 => 500u32..3000, 1 => 0u32..500, 1 => 3000u32..40_000],
        prop_oneof![8 => 0i32..800, 1 => 800i32..5000, 1 => -300i32..0],
        prop::bool::weighted(0.6),
        prop_oneof![4 => (1u32..400).prop_map(|a| a * 100), 1 => 0u32..50_000],
        0u16..1100,
        0u8..18,
        prop_oneof![12 => Just(0u8), 1 => 1u8..6],
    )
        .prop_map(
            |(seq_step, dt_us, delay_us, pulse, amplitude_ua, width_us, channel, corrupt)| Step {
                seq_step,
                dt_us,
                delay_us,
                pulse,
                amplitude_ua,
                width_us,
                channel,
                corrupt,
            },
        )
}

/// The input ticks and the driver's clock for each.
fn build(steps: &[Step]) -> Vec<(StimTick, u64)> {
    let mut seq: i64 = 10;
    let mut t: u64 = 1_000 * MS;
    let mut now: u64 = t;
    let mut out = Vec::new();
    for s in steps {
        seq = (seq + i64::from(s.seq_step)).max(1);
        t += u64::from(s.dt_us) * 1000;
        let at = if s.delay_us >= 0 {
            t + u64::try_from(s.delay_us).unwrap_or(0) * 1000
        } else {
            t.saturating_sub(u64::from(s.delay_us.unsigned_abs()) * 1000)
        };
        // The driver's clock never runs backwards.
        now = now.max(at);
        let mut tick = StimTick {
            seq: seq as u64,
            t_ns: t,
            t_wake_ns: t,
            t_publish_ns: t,
            ref_seq: 0,
            reference: 0.5,
            u_cont: 0.1,
            energy: 0.0,
            model_force: 0.2,
            predicted_force: 0.2,
            phi: 0.3,
            amplitude_ua: if s.pulse { s.amplitude_ua } else { 0 },
            missed_periods: 0,
            width_us: if s.pulse { s.width_us } else { 0 },
            flags: 0,
            pulse: u8::from(s.pulse),
            channel: s.channel,
            min_gap_ticks: 0,
        };
        match s.corrupt {
            1 => tick.phi = f64::NAN,
            2 => tick.flags = 1 << 12,
            3 => tick.pulse = 2,
            4 => tick.t_wake_ns = tick.t_ns.saturating_sub(1),
            5 => tick.channel = StimTick::MAX_CHANNEL + 1,
            _ => {}
        }
        out.push((tick, now));
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn the_emitted_train_never_violates_a_limit(
        limits in limits_strategy(),
        steps in prop::collection::vec(step_strategy(), 1..300),
    ) {
        let input = build(&steps);
        let mut interlocks = Interlocks::new(limits);
        let mut emitted: Vec<(usize, PulseCommand)> = Vec::new();
        for (k, (tick, now)) in input.iter().enumerate() {
            if let Verdict::Pulse(c) = interlocks.assess(tick, *now).verdict {
                emitted.push((k, c));
            }
        }
        for (n, &(k, c)) in emitted.iter().enumerate() {
            let (tick, now) = &input[k];
            // Only a valid tick that asked for exactly this pulse, unaltered.
            prop_assert!(tick.validate().is_ok());
            prop_assert!(tick.fires());
            prop_assert_eq!(c.tick_seq, tick.seq);
            prop_assert_eq!(c.t_ns, tick.t_ns);
            prop_assert_eq!(u32::from(c.amplitude_100ua) * 100, tick.amplitude_ua);
            prop_assert_eq!((c.width_us, c.channel), (tick.width_us, tick.channel));
            // Ceilings and channel.
            prop_assert!(tick.amplitude_ua <= limits.max_amplitude_ua);
            prop_assert!(c.width_us <= limits.max_width_us);
            prop_assert!(charge_nc(tick.amplitude_ua, c.width_us) <= limits.max_charge_nc);
            prop_assert!(c.channel < 16 && limits.allowed_channels & (1 << c.channel) != 0);
            // Sent no earlier than its grid time and no later than the delay limit.
            prop_assert!(tick.t_ns <= *now);
            prop_assert!(*now - tick.t_ns <= limits.max_pulse_delay_ns);
            // Never right after a gap: the tick before it in sequence was received valid.
            if n > 0 || k > 0 {
                let prev_ok = input[..k].iter().any(|(p, pn)| {
                    p.seq + 1 == tick.seq && p.validate().is_ok() && p.t_ns <= *pn
                });
                let first_valid = !input[..k]
                    .iter()
                    .any(|(p, pn)| p.validate().is_ok() && p.t_ns <= *pn);
                prop_assert!(prev_ok || first_valid, "pulse at seq {} after a gap", tick.seq);
            }
            if n > 0 {
                let prev = emitted[n - 1].1;
                // Order, and the minimum IPI.
                prop_assert!(c.tick_seq > prev.tick_seq);
                prop_assert!(c.t_ns >= prev.t_ns + limits.min_ipi_ns);
                // Send times are then at least min_ipi - max_delay apart.
                let prev_now = input[emitted[n - 1].0].1;
                prop_assert!(
                    *now + limits.max_pulse_delay_ns >= prev_now + limits.min_ipi_ns
                );
            }
            // Sliding window: at most max_pulses with grid times in (t - W, t].
            let in_window = emitted[..=n]
                .iter()
                .filter(|(_, p)| c.t_ns - p.t_ns < limits.rate_window_ns)
                .count();
            prop_assert!(in_window <= usize::from(limits.max_pulses));
        }
    }

    #[test]
    fn a_legal_stream_passes_whole(
        ipi_ms in 2u64..30,
        n in 1usize..200,
        delay_us in 0u64..400,
    ) {
        let limits = InterlockLimits {
            min_ipi_ns: 2 * MS,
            max_pulses: 1000,
            rate_window_ns: 1000 * MS,
            max_amplitude_ua: 100_000,
            max_width_us: 500,
            max_charge_nc: 50_000,
            allowed_channels: 1,
            max_pulse_delay_ns: 500_000,
        };
        let mut i = Interlocks::new(limits);
        let mut sent = 0;
        for k in 0..n as u64 {
            let t = 1_000 * MS + k * ipi_ms * MS;
            let tick = StimTick {
                reference: 0.5,
                ..StimTick::quiet(1 + k * ipi_ms, t)
            }
            .firing(0, 20_000, 200);
            // Only every ipi-th tick is shown: the ones between are pulse-free ticks,
            // given here so the stream has no gap.
            for j in (1..ipi_ms).filter(|_| k > 0) {
                let q = StimTick {
                    seq: tick.seq - ipi_ms + j,
                    t_ns: t - (ipi_ms - j) * MS,
                    amplitude_ua: 0,
                    width_us: 0,
                    pulse: 0,
                    ..tick
                };
                let qt = q.t_ns;
                prop_assert_eq!(i.assess(&q, qt + delay_us * 1000).verdict, Verdict::NoPulse);
            }
            if let Verdict::Pulse(_) = i.assess(&tick, t + delay_us * 1000).verdict {
                sent += 1;
            }
        }
        prop_assert_eq!(sent, n);
    }
}
