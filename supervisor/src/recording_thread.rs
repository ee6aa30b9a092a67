//! The recorder on its own thread, so that the daemon's control loop never waits for the
//! disk.
//!
//! The loop hands every message to [`RecorderThread::send`] (a bounded, preallocated
//! queue; never blocks) and the writer thread applies them to the [`Recorder`] in order,
//! flushing when the loop asks ([`Item::Flush`], at least every flush period). Writes,
//! flushes and the data set's fsync at each record boundary can take seconds on a busy
//! disk (a build writing gigabytes next to the bench); in the loop they stalled the
//! supervisor past its self-stall limit (`[health] self_stall_ms`), found by the bench run
//! next to a CI build. A writer that fails, or falls behind by more than the queue holds
//! ([`QUEUE_CAPACITY`], several seconds of traffic), is reported by the next `send` or
//! [`RecorderThread::failure`], and the daemon stops stimulation: no recording means no
//! evidence. [`RecorderThread::close`] ends the run (everything written, fsynced) without
//! blocking the loop; [`RecorderThread::join`] waits for it.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use crossbeam::channel::{Sender, TrySendError, bounded};
use fes_rt::msg::{
    DriverStatus, ForceSample, PulseOutcome, Reference, ReferencePreview, StimTick, TimingReport,
};

use crate::core::BeatRecord;
use crate::recording::{Recorder, RecorderSettings, RecordingError, RecordingSummary};

/// Entries the queue holds: about 7 s of the stack's traffic (1000 StimTicks and 1000
/// ForceSamples per second, plus references, statuses and reports).
pub const QUEUE_CAPACITY: usize = 16_384;

/// Why a run's recording could not start ([`RecorderThread::start`]).
#[derive(Debug, thiserror::Error)]
pub enum StartError {
    /// The run directory or one of its files could not be created.
    #[error(transparent)]
    Create {
        /// The failure, naming the path.
        #[from]
        source: RecordingError,
    },
    /// The writer thread could not be started.
    #[error("recording: cannot start the writer thread: {source}")]
    Spawn {
        /// The operating system's reason.
        #[source]
        source: std::io::Error,
    },
}

/// Why a message could not be queued for the recording ([`RecorderThread::send`]): the
/// recording cannot go on.
#[derive(Debug, Clone, thiserror::Error)]
pub enum SendError {
    /// The writer failed (disk full, I/O error).
    #[error(transparent)]
    WriterFailed {
        /// Its failure, naming the file.
        #[from]
        source: Arc<RecordingError>,
    },
    /// The run was closed already.
    #[error("recording {}: already closed", .dir.display())]
    Closed {
        /// The run directory.
        dir: PathBuf,
    },
    /// The queue is full: the writer fell [`QUEUE_CAPACITY`] entries behind.
    #[error(
        "recording {}: the writer fell {} entries behind (the disk is too slow)",
        .dir.display(),
        QUEUE_CAPACITY
    )]
    FellBehind {
        /// The run directory.
        dir: PathBuf,
    },
    /// The writer stopped without a failure of its own.
    #[error("recording {}: the writer stopped", .dir.display())]
    WriterStopped {
        /// The run directory.
        dir: PathBuf,
    },
}

/// Why a run did not end cleanly ([`RecorderThread::join`]).
#[derive(Debug, Clone, thiserror::Error)]
pub enum JoinError {
    /// The writer failed (disk full, I/O error), before or while finishing the run.
    #[error(transparent)]
    WriterFailed {
        /// Its failure, naming the file.
        #[from]
        source: Arc<RecordingError>,
    },
    /// The writer thread panicked.
    #[error("recording {}: the writer panicked", .dir.display())]
    WriterPanicked {
        /// The run directory.
        dir: PathBuf,
    },
    /// The writer was joined already.
    #[error("recording {}: already joined", .dir.display())]
    AlreadyJoined {
        /// The run directory.
        dir: PathBuf,
    },
}

/// One thing to record, with the time the loop received it where that matters.
#[derive(Debug, Clone)]
pub enum Item {
    /// A StimTick received at the time given.
    Tick(StimTick, u64),
    /// A ForceSample received at the time given.
    Force(ForceSample, u64),
    /// A published Reference.
    Reference(Reference),
    /// A published ReferencePreview.
    Preview(ReferencePreview),
    /// A DriverStatus.
    Status(DriverStatus),
    /// A PulseOutcome and when it was taken, ns.
    Outcome(PulseOutcome, u64),
    /// A TimingReport.
    Timing(TimingReport),
    /// A completed beat.
    Beat(BeatRecord),
    /// A record boundary before the tick at the time given.
    Boundary(u64, String),
    /// An event line at the time given.
    Event(u64, String),
    /// Flush if the flush period has passed (the loop's time).
    Flush(u64),
}

// The queue's slots are preallocated at the size of the largest message; boxing the item
// would allocate for every message instead.
#[allow(clippy::large_enum_variant)]
enum Message {
    Item(Item),
    Close(u64),
}

struct Shared {
    failed: AtomicBool,
    error: Mutex<Option<Arc<RecordingError>>>,
}

/// The writer thread of one run.
pub struct RecorderThread {
    dir: PathBuf,
    tx: Option<Sender<Message>>,
    shared: Arc<Shared>,
    handle: Option<JoinHandle<Result<RecordingSummary, Arc<RecordingError>>>>,
}

impl RecorderThread {
    /// Creates the run directory `root/name` ([`Recorder::create`]) and moves its recorder
    /// to a new writer thread.
    pub fn start(
        root: &Path,
        name: &str,
        settings: RecorderSettings,
        now_ns: u64,
    ) -> Result<Self, StartError> {
        let recorder = Recorder::create(root, name, settings, now_ns)?;
        Self::spawn(recorder).map_err(|source| StartError::Spawn { source })
    }

    /// Moves `recorder` to a new writer thread.
    pub fn spawn(recorder: Recorder) -> std::io::Result<Self> {
        let dir = recorder.dir().to_path_buf();
        let (tx, rx) = bounded::<Message>(QUEUE_CAPACITY);
        let shared = Arc::new(Shared {
            failed: AtomicBool::new(false),
            error: Mutex::new(None),
        });
        let s = shared.clone();
        let handle = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || {
                let mut rec = recorder;
                let fail = |e: RecordingError| {
                    let e = Arc::new(e);
                    *s.error.lock().unwrap_or_else(|p| p.into_inner()) = Some(Arc::clone(&e));
                    s.failed.store(true, Ordering::Release);
                    e
                };
                let mut close_at = None;
                for m in rx.iter() {
                    match m {
                        Message::Close(now) => {
                            close_at = Some(now);
                            break;
                        }
                        Message::Item(item) => apply(&mut rec, item).map_err(fail)?,
                    }
                }
                let now = close_at.unwrap_or_else(fes_rt::rt::clock::monotonic_ns);
                rec.finish(now).map_err(fail)
            })?;
        Ok(Self {
            dir,
            tx: Some(tx),
            shared,
            handle: Some(handle),
        })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Queues `item`; never blocks. An error when the writer has failed or the queue is
    /// full (the disk is too slow for the run).
    pub fn send(&self, item: Item) -> Result<(), SendError> {
        if let Some(e) = self.failure() {
            return Err(e.into());
        }
        let Some(tx) = &self.tx else {
            return Err(SendError::Closed {
                dir: self.dir.clone(),
            });
        };
        match tx.try_send(Message::Item(item)) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => Err(SendError::FellBehind {
                dir: self.dir.clone(),
            }),
            Err(TrySendError::Disconnected(_)) => Err(self.failure().map_or_else(
                || SendError::WriterStopped {
                    dir: self.dir.clone(),
                },
                SendError::from,
            )),
        }
    }

    /// The writer's failure, if it failed.
    pub fn failure(&self) -> Option<Arc<RecordingError>> {
        self.shared
            .failed
            .load(Ordering::Acquire)
            .then(|| {
                self.shared
                    .error
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .clone()
            })
            .flatten()
    }

    /// Ends the run at `now_ns`: the writer writes what is queued, then finishes the
    /// recording (flush, fsync). Does not wait ([`Self::is_closed`], [`Self::join`]).
    pub fn close(&mut self, now_ns: u64) {
        if let Some(tx) = self.tx.take() {
            // Blocks only if the queue is full, and then only until the writer makes room.
            let _ = tx.send(Message::Close(now_ns));
        }
    }

    /// True when the writer has finished.
    pub fn is_closed(&self) -> bool {
        self.handle.as_ref().is_none_or(JoinHandle::is_finished)
    }

    /// Waits for the writer (closing the run first if needed) and returns its summary.
    pub fn join(mut self) -> Result<RecordingSummary, JoinError> {
        self.close(fes_rt::rt::clock::monotonic_ns());
        match self.handle.take().map(JoinHandle::join) {
            Some(Ok(Ok(s))) => Ok(s),
            Some(Ok(Err(e))) => Err(e.into()),
            Some(Err(_)) => Err(JoinError::WriterPanicked {
                dir: self.dir.clone(),
            }),
            None => Err(JoinError::AlreadyJoined {
                dir: self.dir.clone(),
            }),
        }
    }
}

impl Drop for RecorderThread {
    fn drop(&mut self) {
        self.close(fes_rt::rt::clock::monotonic_ns());
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn apply(rec: &mut Recorder, item: Item) -> Result<(), RecordingError> {
    match item {
        Item::Tick(t, now) => rec.on_stim_tick(&t, now),
        Item::Force(f, now) => rec.on_force(&f, now),
        Item::Reference(r) => rec.on_reference(&r),
        Item::Preview(p) => rec.on_preview(&p),
        Item::Status(s) => rec.on_status(&s),
        Item::Outcome(o, now) => rec.on_outcome(&o, now),
        Item::Timing(t) => rec.on_timing(&t),
        Item::Beat(b) => rec.on_beat(&b),
        Item::Boundary(t, kind) => {
            rec.boundary(t, kind);
            Ok(())
        }
        Item::Event(t, text) => rec.on_event(t, &text),
        Item::Flush(now) => rec.maybe_flush(now),
    }
}
