//! The driver's timing: bounded HdrHistograms (fes-rt's [`Quantity`]) filled from
//! the forward thread's events on the report thread, written as `.hlog` intervals and
//! summarised in a [`TimingReport`] with `source = StimDriver`.
//!
//! | hlog tag | quantity | per | TimingReport field |
//! |---|---|---|---|
//! | `tick_to_can` | StimTick `t_publish_ns` → PULSE write returned | pulse | `publish` |
//! | `can_write` | time inside the write call(s) | pulse | — |
//! | `tick_to_tx_stamp` | StimTick `t_publish_ns` → the kernel's transmit timestamp | pulse, where the kernel gives one | — |
//! | `ipc` | StimTick `t_publish_ns` → received by the driver | tick | `ipc` |
//! | `compute` | received → decided and sent (interlocks, encode, write) | tick | `compute` |
//! | `input` | wake-up → every input taken and handled | wake-up | `input` |
//! | `wake` | lateness of timed wake-ups (watchdog, heartbeat) behind their deadline | timed wake-up | `wake` |

use fes_rt::msg::{TimingReport, TimingSource};
use fes_rt::rt::telemetry::{
    IntervalQuantities, Quantity, TAG_COMPUTE, TAG_INPUT, TAG_IPC, TAG_WAKE,
};

use crate::event::{Counters, DriverEvent};

/// hlog tag: StimTick publish → PULSE write returned.
pub const TAG_TICK_TO_CAN: &str = "tick_to_can";
/// hlog tag: time in the PULSE write call.
pub const TAG_CAN_WRITE: &str = "can_write";
/// hlog tag: StimTick publish → kernel transmit timestamp of the PULSE.
pub const TAG_TICK_TO_TX_STAMP: &str = "tick_to_tx_stamp";

/// The driver's histograms.
#[derive(Debug, Clone, Default)]
pub struct DriverTelemetry {
    /// StimTick publish → PULSE write returned.
    pub tick_to_can: Quantity,
    /// Time in the PULSE write call.
    pub can_write: Quantity,
    /// StimTick publish → kernel transmit timestamp.
    pub tick_to_tx_stamp: Quantity,
    /// StimTick publish → receipt.
    pub ipc: Quantity,
    /// Receipt → decided and sent.
    pub compute: Quantity,
    /// Wake-up → inputs handled.
    pub input: Quantity,
    /// Lateness of timed wake-ups.
    pub wake: Quantity,
    /// `seq` gaps seen.
    pub gaps: u64,
}

impl DriverTelemetry {
    /// Empty histograms (allocated here, once).
    pub fn new() -> Self {
        Self::default()
    }

    /// Records what `event` measured (events without timing are ignored).
    pub fn record(&mut self, event: &DriverEvent) {
        match *event {
            DriverEvent::Wake {
                timer_lateness_ns,
                input_ns,
            } => {
                self.input.record(input_ns);
                if let Some(l) = timer_lateness_ns {
                    self.wake.record(l);
                }
            }
            DriverEvent::Tick {
                ipc_ns, decide_ns, ..
            } => {
                self.ipc.record(ipc_ns);
                self.compute.record(decide_ns);
            }
            DriverEvent::PulseSent {
                t_publish_ns,
                written_ns,
                write_ns,
                ..
            } => {
                self.tick_to_can
                    .record(written_ns.saturating_sub(t_publish_ns));
                self.can_write.record(write_ns);
            }
            DriverEvent::TicksLost { .. } => self.gaps += 1,
            _ => {}
        }
    }

    /// Records one transmit timestamp measurement (StimTick publish → kernel stamp), ns.
    pub fn record_tx_stamp(&mut self, ns: u64) {
        self.tick_to_tx_stamp.record(ns);
    }

    /// A cumulative [`TimingReport`] (`source = StimDriver`; field mapping in the module
    /// documentation): `ticks` = StimTicks received, `misses` = ticks lost, `overruns` =
    /// `seq` gaps, `rejected_inputs` = refused ticks and commands.
    pub fn report(
        &self,
        seq: u64,
        t_ns: u64,
        counters: &Counters,
        queue_overflows: u64,
        hot_path_allocations: u64,
        flags: u8,
    ) -> TimingReport {
        TimingReport {
            seq,
            t_ns,
            ticks: counters.ticks_received,
            misses: counters.ticks_lost,
            overruns: self.gaps.min(counters.ticks_lost),
            queue_overflows,
            hot_path_allocations,
            rejected_inputs: counters.ticks_refused + counters.commands_refused,
            wake: self.wake.summary(),
            input: self.input.summary(),
            compute: self.compute.summary(),
            publish: self.tick_to_can.summary(),
            ipc: self.ipc.summary(),
            source: TimingSource::StimDriver as u8,
            flags,
            prescription: [0; 6],
        }
    }
}

impl IntervalQuantities for DriverTelemetry {
    fn quantities(&mut self) -> impl IntoIterator<Item = (&'static str, &mut Quantity)> {
        [
            (TAG_TICK_TO_CAN, &mut self.tick_to_can),
            (TAG_CAN_WRITE, &mut self.can_write),
            (TAG_TICK_TO_TX_STAMP, &mut self.tick_to_tx_stamp),
            (TAG_IPC, &mut self.ipc),
            (TAG_COMPUTE, &mut self.compute),
            (TAG_INPUT, &mut self.input),
            (TAG_WAKE, &mut self.wake),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fes_rt::msg::Contract;

    #[test]
    fn events_fill_the_right_histograms_and_the_report_validates() {
        let mut t = DriverTelemetry::new();
        for k in 1..=100u64 {
            t.record(&DriverEvent::Tick {
                seq: k,
                ipc_ns: 1000 * k,
                decide_ns: 10 * k,
            });
            t.record(&DriverEvent::Wake {
                timer_lateness_ns: (k % 2 == 0).then_some(k),
                input_ns: 5,
            });
        }
        t.record(&DriverEvent::PulseSent {
            tick_seq: 1,
            pulse_seq: 1,
            t_publish_ns: 1_000,
            written_ns: 31_000,
            write_ns: 4_000,
            retries: 0,
        });
        t.record(&DriverEvent::TicksLost { seq: 9, count: 3 });
        assert_eq!(t.ipc.total().count(), 100);
        assert_eq!(t.wake.total().count(), 50);
        // HdrHistogram keeps 3 significant digits: 30 000 within 0.1 %.
        assert!(t.tick_to_can.total().max_ns().abs_diff(30_000) <= 30);
        let c = Counters {
            ticks_received: 100,
            ticks_lost: 3,
            ..Counters::default()
        };
        let r = t.report(1, 5, &c, 0, 0, 0);
        assert_eq!(r.validate(), Ok(()));
        assert_eq!((r.ticks, r.misses, r.overruns), (100, 3, 1));
        assert_eq!(r.publish.count, 1);
        // p50 of 1..=100 us within the histogram's 0.1 % resolution.
        let p50 = r.ipc.p50_ns as f64;
        assert!((p50 - 50_000.0).abs() <= 50.0, "{p50}");
        assert_eq!(r.source, TimingSource::StimDriver as u8);
    }
}
