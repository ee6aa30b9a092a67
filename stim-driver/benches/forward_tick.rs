//! Criterion benchmark of the forward path's per-tick cost on the host (no CAN): one
//! StimTick through [`ForwardPath::on_tick`] and the timers ([`ForwardPath::poll`]), armed,
//! with the CAN write replaced by a counting sink ([`CountingSink`]) and the events by a
//! [`NullSink`]. Cases: a tick without a pulse, and a tick with a pulse (interlocks,
//! PULSE encode with CRC and alive counter, write). Simulated time: 1 ms per tick; a
//! STATUS every 10 ticks keeps the stimulator watchdog fed, as on the bus.
//!
//! Run: `cargo bench -p stim-driver --bench forward_tick`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use fes_can::{MessageKind, StimState};
use fes_rt::msg::{DriverCommand, DriverCommandKind, StimTick};
use fes_rt::rt::liveness::Liveness;
use stim_driver::config::DriverConfig;
use stim_driver::event::{DriverState, NullSink};
use stim_driver::forward::ForwardPath;
use stim_driver::tx::CountingSink;

const MS: u64 = 1_000_000;

#[path = "../tests/it/support/recording_bus.rs"]
mod recording_bus;
use recording_bus::status;

fn tick(seq: u64, t_ns: u64, pulse: bool) -> StimTick {
    let quiet = StimTick {
        t_publish_ns: t_ns + 10_000,
        reference: 0.5,
        ..StimTick::quiet(seq, t_ns)
    };
    if pulse {
        quiet.firing(0, 20_000, 200)
    } else {
        quiet
    }
}

/// A forward path brought up, armed and confirmed at simulated time `now`.
struct Armed {
    fp: ForwardPath<CountingSink>,
    now: u64,
    seq: u64,
    config_id: u8,
}

impl Armed {
    fn new() -> Self {
        let mut config = DriverConfig::with_defaults("vcan0", 40.0);
        // 500 pulses/s (every other tick) must stay within the rate interlock.
        config.interlocks.max_pulses = 1000;
        let settings = config.forward_settings().expect("defaults are valid");
        let pulse_id = settings.nodes.id_of(MessageKind::Pulse);
        let mut fp = ForwardPath::new(settings, CountingSink::new(pulse_id));
        let ev = &mut NullSink;
        let mut now = 1_000 * MS;
        fp.start(now, ev);
        fp.on_bus(status(StimState::PreOperational, 0), now, ev);
        let config_id = 1;
        fp.on_bus(status(StimState::PreOperational, config_id), now, ev);
        fp.on_liveness(Liveness::Alive, now, ev);
        // An armed driver must see its supervisor alive (arm_confirm_ms).
        fp.on_supervisor_liveness(Liveness::Alive, now, ev);
        let mut seq = 0;
        for _ in 0..3 {
            now += MS;
            seq += 1;
            fp.on_tick(&tick(seq, now - 20_000, false), now, ev);
        }
        fp.on_command(
            &DriverCommand::new(1, now - 1000, DriverCommandKind::Arm),
            now,
            ev,
        );
        fp.on_bus(status(StimState::Armed, config_id), now, ev);
        assert_eq!(fp.state(), DriverState::Armed);
        Self {
            fp,
            now,
            seq,
            config_id,
        }
    }

    /// One period: a StimTick (with a pulse when `pulse`), a STATUS every 10th, the timers.
    fn step(&mut self, pulse: bool) {
        let ev = &mut NullSink;
        self.now += MS;
        self.seq += 1;
        if self.seq.is_multiple_of(10) {
            self.fp
                .on_bus(status(StimState::Stimulating, self.config_id), self.now, ev);
        }
        let t = tick(self.seq, self.now - 20_000, pulse);
        self.fp.on_tick(black_box(&t), self.now, ev);
        self.fp.poll(self.now, ev);
    }
}

fn bench_forward(c: &mut Criterion) {
    let mut group = c.benchmark_group("forward_tick");
    let mut a = Armed::new();
    group.bench_function("no_pulse", |b| b.iter(|| a.step(false)));
    assert_eq!(a.fp.state(), DriverState::Armed);
    // A pulse every tick would break the 2 ms minimum IPI: every other tick fires, and the
    // figure is the pair's cost.
    let mut a = Armed::new();
    group.bench_function("pulse_then_no_pulse", |b| {
        b.iter(|| {
            a.step(true);
            a.step(false);
        })
    });
    assert_eq!(a.fp.state(), DriverState::Armed);
    assert_eq!(a.fp.counters().pulses_rejected, 0, "every pulse legal");
    assert!(a.fp.tx().pulses > 0);
    group.finish();
}

criterion_group!(benches, bench_forward);
criterion_main!(benches);
