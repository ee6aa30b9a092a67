//! Optional per-tick record (CSV), written by a separate thread so the 1 ms loop only
//! does a non-blocking hand-over into a bounded channel.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use anyhow::Context as _;
use fes_can::StimState;

/// One tick as recorded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickRecord {
    /// Tick number.
    pub tick: u64,
    /// Scheduled time of the tick, CLOCK_MONOTONIC ns.
    pub nominal_ns: u64,
    /// Wake-up lateness behind the deadline the loop slept for, ns (a lateness over
    /// 1 ms means periods were skipped).
    pub late_ns: u64,
    /// State after the tick.
    pub state: StimState,
    /// Force published at this tick (N); for a tick caught up after a stall (a row only
    /// when a pulse was applied there), the plant force at that tick, not sent as FORCE.
    pub force_n: f64,
    /// The pulse applied at this tick: (seq, amplitude mA, width us).
    pub pulse: Option<(u16, f64, u16)>,
}

/// The writer side: a bounded queue and the thread emptying it.
pub struct Recorder {
    tx: Option<SyncSender<TickRecord>>,
    thread: Option<JoinHandle<std::io::Result<()>>>,
    dropped: u64,
}

const QUEUE: usize = 8192;

impl Recorder {
    /// Creates `path` and starts the writer thread.
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let file = File::create(path)
            .with_context(|| format!("creating the record file {}", path.display()))?;
        let (tx, rx) = sync_channel(QUEUE);
        let thread = std::thread::Builder::new()
            .name("stim-record".into())
            .spawn(move || write_all(BufWriter::new(file), &rx))
            .context("starting the record writer thread")?;
        Ok(Self {
            tx: Some(tx),
            thread: Some(thread),
            dropped: 0,
        })
    }

    /// Hands a record over without blocking; counts it as dropped if the queue is full.
    pub fn push(&mut self, r: TickRecord) {
        if let Some(tx) = &self.tx {
            match tx.try_send(r) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                    self.dropped += 1
                }
            }
        }
    }

    /// Flushes and closes the file; returns the number of records dropped because the
    /// writer fell behind.
    pub fn finish(mut self) -> anyhow::Result<u64> {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            t.join()
                .map_err(|_| anyhow::anyhow!("the record writer thread panicked"))?
                .context("writing the record")?;
        }
        Ok(self.dropped)
    }
}

fn write_all(mut w: BufWriter<File>, rx: &Receiver<TickRecord>) -> std::io::Result<()> {
    writeln!(
        w,
        "tick,nominal_ns,late_ns,state,force_n,pulse_seq,amplitude_ma,width_us"
    )?;
    for r in rx {
        match r.pulse {
            Some((seq, amp, width)) => writeln!(
                w,
                "{},{},{},{},{:.6},{},{:.1},{}",
                r.tick, r.nominal_ns, r.late_ns, r.state, r.force_n, seq, amp, width
            )?,
            None => writeln!(
                w,
                "{},{},{},{},{:.6},,,",
                r.tick, r.nominal_ns, r.late_ns, r.state, r.force_n
            )?,
        }
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_a_header_and_one_line_per_tick() {
        let dir = fes_testkit::Scratch::new("stim-record");
        let path = dir.join("r.csv");
        let mut r = Recorder::create(&path).unwrap();
        r.push(TickRecord {
            tick: 0,
            nominal_ns: 10,
            late_ns: 1,
            state: StimState::Armed,
            force_n: 0.5,
            pulse: None,
        });
        r.push(TickRecord {
            tick: 1,
            nominal_ns: 20,
            late_ns: 2,
            state: StimState::Stimulating,
            force_n: 1.25,
            pulse: Some((7, 20.0, 200)),
        });
        assert_eq!(r.finish().unwrap(), 0);
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(
            text,
            "tick,nominal_ns,late_ns,state,force_n,pulse_seq,amplitude_ma,width_us\n\
             0,10,1,armed,0.500000,,,\n1,20,2,stimulating,1.250000,7,20.0,200\n"
        );
    }
}
