//! Recording of a stimulation run: every Reference, StimTick, ForceSample, DriverStatus,
//! TimingReport, event and beat, to disk, as a `fes-dataset/1` data set
//! (`fes_dataset`, docs/sim-muscle.md) plus one CSV per message stream, so a bench
//! run can be fed straight back into identification.
//!
//! A run directory (mode 0750, files 0640) holds:
//!
//! | file | content |
//! |---|---|
//! | `dataset.json`, `record_NNN.csv` | the data set: per 1 ms tick, `pulse` (what the muscle got: the StimTick fired, the driver's [`PulseOutcome`] says sent and the stimulator's account of it says applied), `force` (the measured, normalised force nearest in time) and `decided` (the StimTick fired); one record per beat (cardiac) or per `max_record_ms`, and a new record after any gap |
//! | `pulses.csv` | every pulse decided: `tick_seq,t_ns,decided,sent,applied,fate` (1/0 each; `fate` the driver's decision: sent, refused, late, not_armed, not_written, or `unreported`) |
//! | `ticks.csv` | every StimTick, all fields |
//! | `force.csv` | every ForceSample |
//! | `references.csv` | every published Reference |
//! | `previews.csv` | every published ReferencePreview: `seq,t_ns,ref_seq,len`, then `t_ns_i,force_i,max_rate_per_s_i` for each of its 6 edge slots (empty where unused) |
//! | `status.csv` | every DriverStatus |
//! | `outcomes.csv` | every PulseOutcome: what the driver did with each pulse decision, then what the stimulator did with each pulse sent (`applied`, `not_applied`) |
//! | `timing.csv` | every TimingReport |
//! | `beats.csv` | per beat: target, reference amplitude, measured plateau/peak/FTI, pulses, outer-loop correction, pulses the driver refused |
//! | `events.jsonl` | commands, faults, warnings, with CLOCK_MONOTONIC and wall-clock times |
//!
//! Decided, sent and applied are three facts from three places: rt-core decided the pulse
//! (the StimTick), the driver wrote it (PulseOutcome `sent`), the stimulator applied it
//! (PulseOutcome `applied`, from its STATUS count, an EMCY naming it, or a RehaStim 2's
//! acknowledgement: stim-driver's `applied` module). A pulse the driver never reported on
//! within [`OUTCOME_WAIT_NS`] (or before a report on a later tick) is recorded as not sent,
//! one sent that the stimulator did not account for within [`APPLIED_WAIT_NS`] (or before
//! an account of a later pulse) as not applied: the data set never claims a pulse that
//! nobody saw applied. So a pulse cancelled in flight or dropped by the stimulator is
//! `decided` and `sent` but not `pulse`.
//!
//! Durability: the stream files are flushed at least every `flush_period_ms` (default
//! 1 s); each data-set record is at most `max_record_ms` (default 1 s) long, and when it
//! completes its file is flushed and `dataset.json` is rewritten atomically (temporary
//! file + rename), listing only complete records. A crash therefore leaves a readable
//! data set missing at most the record being written, and streams missing at most the
//! last flush period. [`Recorder::finish`] flushes and fsyncs everything.
//!
//! Any I/O failure (disk full, read-only file system) is returned as a
//! [`RecordingError`] naming the file; the daemon treats it as a fault and stops
//! stimulation (no recording means no evidence). The recorder then writes nothing more.

use std::collections::VecDeque;
use std::fs::{self, File, OpenOptions};
use std::io::{BufWriter, Write};
use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use fes_rt::msg::{
    DriverStatus, ForceSample, PulseFate, PulseOutcome, Reference, ReferencePreview, StimTick,
    TimingReport,
};

use crate::core::BeatRecord;

/// Mode of run directories.
pub const DIR_MODE: u32 = 0o750;
/// Mode of recorded files.
pub const FILE_MODE: u32 = 0o640;
/// Force range the data-set format accepts (normalised, with slack for noise).
pub const DATASET_FORCE_RANGE: (f64, f64) = (-0.1, 1.1);

/// What the recorder needs to know.
#[derive(Debug, Clone, PartialEq)]
pub struct RecorderSettings {
    /// Flush period, ns.
    pub flush_period_ns: u64,
    /// Longest record, ticks.
    pub max_record_ticks: usize,
    /// Fallback scale (N per normalised unit) while the stream cannot tell.
    pub scale_n: f64,
    /// Fallback offset, N.
    pub offset_n: f64,
    /// `source` of the data set.
    pub source: String,
    /// Free-form description of the run (goes into `protocol`).
    pub protocol: serde_json::Value,
    /// SHA-256 of the prescription file the run was made under (`dataset.json`
    /// `prescription_sha256`); None: none was read.
    pub prescription_sha256: Option<String>,
}

/// A recording failure.
#[derive(Debug, thiserror::Error)]
#[error("recording: cannot {op} {path}: {source}")]
pub struct RecordingError {
    /// What was being done.
    pub op: &'static str,
    /// The file or directory.
    pub path: PathBuf,
    /// The operating system's reason.
    pub source: std::io::Error,
}

fn err<'a>(op: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> RecordingError + 'a {
    move |source| RecordingError {
        op,
        path: path.to_path_buf(),
        source,
    }
}

/// A CSV (or JSONL) stream file.
struct Stream {
    path: PathBuf,
    out: BufWriter<File>,
}

impl Stream {
    fn create(dir: &Path, name: &str, header: Option<&str>) -> Result<Self, RecordingError> {
        let path = dir.join(name);
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(FILE_MODE)
            .open(&path)
            .map_err(err("create", &path))?;
        let mut s = Self {
            out: BufWriter::with_capacity(64 * 1024, file),
            path,
        };
        if let Some(h) = header {
            s.line(format_args!("{h}"))?;
        }
        Ok(s)
    }

    fn line(&mut self, args: std::fmt::Arguments<'_>) -> Result<(), RecordingError> {
        self.out
            .write_fmt(args)
            .and_then(|()| self.out.write_all(b"\n"))
            .map_err(err("write", &self.path))
    }

    fn flush(&mut self) -> Result<(), RecordingError> {
        self.out.flush().map_err(err("flush", &self.path))
    }

    fn sync(&mut self) -> Result<(), RecordingError> {
        self.flush()?;
        self.out
            .get_ref()
            .sync_all()
            .map_err(err("fsync", &self.path))
    }
}

/// One data-set record being written.
struct OpenRecord {
    file: String,
    kind: String,
    stream: Stream,
    samples: usize,
    pulses: usize,
    last_grid_ns: u64,
}

/// A completed record as listed in `dataset.json`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
struct Entry {
    file: String,
    kind: String,
    samples: usize,
    pulses: usize,
}

/// Least-squares fit of `force_n = scale force + offset` over the stream.
#[derive(Debug, Clone, Copy, Default)]
struct ScaleFit {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
}

impl ScaleFit {
    fn add(&mut self, x: f64, y: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.sxy += x * y;
    }

    fn get(&self) -> Option<(f64, f64)> {
        let var = self.sxx - self.sx * self.sx / self.n.max(1.0);
        if self.n < 2.0 || var <= 1e-9 * self.n {
            return None;
        }
        let scale = (self.sxy - self.sx * self.sy / self.n) / var;
        let offset = (self.sy - scale * self.sx) / self.n;
        (scale.is_finite() && scale > 0.0 && offset.is_finite()).then_some((scale, offset))
    }
}

/// Summary of a finished recording.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingSummary {
    /// The run directory.
    pub dir: PathBuf,
    /// Complete data-set records.
    pub records: usize,
    /// StimTicks recorded.
    pub ticks: u64,
    /// ForceSamples recorded.
    pub force_samples: u64,
    /// Pulses the pattern generator decided, over the ticks recorded.
    pub pulses_decided: u64,
    /// Of those, pulses the driver reported sent.
    pub pulses_sent: u64,
    /// Of those, pulses the stimulator accounted for as applied.
    pub pulses_applied: u64,
}

/// Records one stimulation run.
pub struct Recorder {
    dir: PathBuf,
    settings: RecorderSettings,
    ticks: Stream,
    force: Stream,
    references: Stream,
    previews: Stream,
    status: Stream,
    outcomes: Stream,
    pulses: Stream,
    timing: Stream,
    beats: Stream,
    events: Stream,
    record: Option<OpenRecord>,
    /// The driver's decisions (sent, refused, ...), in tick order.
    pending_outcomes: VecDeque<(u64, PulseFate)>,
    /// The stimulator's accounts of pulses sent (applied or not), in tick order.
    pending_applied: VecDeque<(u64, bool)>,
    pulses_decided: u64,
    pulses_sent: u64,
    pulses_applied: u64,
    entries: Vec<Entry>,
    next_record: usize,
    pending_ticks: VecDeque<StimTick>,
    recent_force: VecDeque<(u64, f64)>,
    scale: ScaleFit,
    boundary_pending: Option<String>,
    boundaries: VecDeque<(u64, String)>,
    last_flush_ns: u64,
    tick_count: u64,
    force_count: u64,
    last_tick_seq: u64,
    failed: bool,
}

/// Ticks wait at most this long for the force sample of their time, ns.
pub const FORCE_WAIT_NS: u64 = 100_000_000;
/// A force sample further than this from a tick's time does not belong to it, ns.
pub const FORCE_MATCH_NS: u64 = 1_500_000;
/// A tick that fired waits at most this long (after its grid time, by the recorder's
/// clock) for the driver's [`PulseOutcome`]; without one its pulse is recorded as not
/// delivered, ns. Outcomes cross two processes and the recorder thread may be descheduled.
pub const OUTCOME_WAIT_NS: u64 = 500_000_000;
/// A pulse sent waits at most this long (after its grid time) for the stimulator's account
/// of it ([`PulseFate::Applied`] or [`PulseFate::NotApplied`]); without one it is recorded as
/// not applied, ns. The account normally arrives with the next STATUS (10 ms) or a RehaStim
/// 2's acknowledgement; the driver closes a pulse no STATUS counted after twice its
/// stimulator timeout (200 ms by default, 800 ms on a RehaStim 2). A driver configured with
/// a stimulator timeout above 1 s may account later than this: such pulses are recorded as
/// not applied (the data set under-claims, never over-claims).
pub const APPLIED_WAIT_NS: u64 = 2_000_000_000;

impl Recorder {
    /// Creates the run directory `root/name` (0750, parents too) and its files.
    pub fn create(
        root: &Path,
        name: &str,
        settings: RecorderSettings,
        now_ns: u64,
    ) -> Result<Self, RecordingError> {
        fs::DirBuilder::new()
            .recursive(true)
            .mode(DIR_MODE)
            .create(root)
            .map_err(err("create directory", root))?;
        let dir = root.join(name);
        fs::DirBuilder::new()
            .mode(DIR_MODE)
            .create(&dir)
            .map_err(err("create directory", &dir))?;
        let d = dir.as_path();
        Ok(Self {
            ticks: Stream::create(
                d,
                "ticks.csv",
                Some(
                    "seq,t_ns,t_wake_ns,t_publish_ns,ref_seq,reference,u_cont,energy,model_force,predicted_force,phi,amplitude_ua,width_us,missed_periods,flags,pulse,channel",
                ),
            )?,
            force: Stream::create(d, "force.csv", Some("seq,t_ns,stim_seq,force_n,force"))?,
            references: Stream::create(
                d,
                "references.csv",
                Some("seq,t_ns,force,max_rate_per_s,flags"),
            )?,
            previews: Stream::create(d, "previews.csv", Some(&preview_header()))?,
            status: Stream::create(
                d,
                "status.csv",
                Some(
                    "seq,t_ns,ticks_received,ticks_lost,pulses_sent,pulses_rejected,can_tx_errors,watchdog_trips,fault_code,state,stimulator_state",
                ),
            )?,
            outcomes: Stream::create(d, "outcomes.csv", Some("seq,t_ns,tick_seq,tick_t_ns,fate"))?,
            pulses: Stream::create(
                d,
                "pulses.csv",
                Some("tick_seq,t_ns,decided,sent,applied,fate"),
            )?,
            timing: Stream::create(
                d,
                "timing.csv",
                Some(
                    "seq,t_ns,source,flags,ticks,misses,overruns,queue_overflows,hot_path_allocations,rejected_inputs,wake_p50_ns,wake_p99_ns,wake_p999_ns,wake_max_ns,compute_p99_ns,publish_p99_ns,ipc_p50_ns,ipc_p99_ns,ipc_p999_ns,ipc_max_ns,publish_p50_ns,publish_p999_ns,publish_max_ns",
                ),
            )?,
            beats: Stream::create(
                d,
                "beats.csv",
                Some(
                    "index,start_ns,period_ns,on_ns,bpm,target,amplitude,plateau_mean,peak,fti,pulses,samples,coverage,outer_loop_error,correction,next_amplitude,pulses_refused",
                ),
            )?,
            events: Stream::create(d, "events.jsonl", None)?,
            dir,
            settings,
            record: None,
            pending_outcomes: VecDeque::new(),
            pending_applied: VecDeque::new(),
            pulses_decided: 0,
            pulses_sent: 0,
            pulses_applied: 0,
            entries: Vec::new(),
            next_record: 0,
            pending_ticks: VecDeque::new(),
            recent_force: VecDeque::new(),
            scale: ScaleFit::default(),
            boundary_pending: Some("start".into()),
            boundaries: VecDeque::new(),
            last_flush_ns: now_ns,
            tick_count: 0,
            force_count: 0,
            last_tick_seq: 0,
            failed: false,
        })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn guard<T>(&mut self, r: Result<T, RecordingError>) -> Result<T, RecordingError> {
        if r.is_err() {
            self.failed = true;
        }
        r
    }

    fn ok(&self) -> Result<(), RecordingError> {
        if self.failed {
            return Err(RecordingError {
                op: "continue",
                path: self.dir.clone(),
                source: std::io::Error::other("an earlier write failed"),
            });
        }
        Ok(())
    }

    /// Records a StimTick (and, once its force sample is in, a data-set row).
    pub fn on_stim_tick(&mut self, t: &StimTick, now_ns: u64) -> Result<(), RecordingError> {
        self.ok()?;
        let r = self.ticks.line(format_args!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            t.seq,
            t.t_ns,
            t.t_wake_ns,
            t.t_publish_ns,
            t.ref_seq,
            t.reference,
            t.u_cont,
            t.energy,
            t.model_force,
            t.predicted_force,
            t.phi,
            t.amplitude_ua,
            t.width_us,
            t.missed_periods,
            t.flags,
            t.pulse,
            t.channel
        ));
        self.guard(r)?;
        self.tick_count += 1;
        self.pending_ticks.push_back(*t);
        let r = self.drain(now_ns);
        self.guard(r)
    }

    /// Records a ForceSample.
    pub fn on_force(&mut self, s: &ForceSample, now_ns: u64) -> Result<(), RecordingError> {
        self.ok()?;
        let r = self.force.line(format_args!(
            "{},{},{},{},{}",
            s.seq, s.t_ns, s.stim_seq, s.force_n, s.force
        ));
        self.guard(r)?;
        self.force_count += 1;
        self.scale.add(s.force, s.force_n);
        self.recent_force.push_back((s.t_ns, s.force));
        while self.recent_force.len() > 4096 {
            self.recent_force.pop_front();
        }
        let r = self.drain(now_ns);
        self.guard(r)
    }

    /// Records a published Reference.
    pub fn on_reference(&mut self, r: &Reference) -> Result<(), RecordingError> {
        self.ok()?;
        let res = self.references.line(format_args!(
            "{},{},{},{},{}",
            r.seq, r.t_ns, r.force, r.max_rate_per_s, r.flags
        ));
        self.guard(res)
    }

    /// Records a published ReferencePreview: its edges in `len` column triples, unused
    /// ones empty.
    pub fn on_preview(&mut self, p: &ReferencePreview) -> Result<(), RecordingError> {
        self.ok()?;
        let mut cols = String::new();
        for (i, e) in p.edges.iter().enumerate() {
            if i < p.len as usize {
                cols += &format!(",{},{},{}", e.t_ns, e.force, e.max_rate_per_s);
            } else {
                cols += ",,,";
            }
        }
        let res = self.previews.line(format_args!(
            "{},{},{},{}{}",
            p.seq, p.t_ns, p.ref_seq, p.len, cols
        ));
        self.guard(res)
    }

    /// Records a DriverStatus.
    pub fn on_status(&mut self, s: &DriverStatus) -> Result<(), RecordingError> {
        self.ok()?;
        let r = self.status.line(format_args!(
            "{},{},{},{},{},{},{},{},{},{},{}",
            s.seq,
            s.t_ns,
            s.ticks_received,
            s.ticks_lost,
            s.pulses_sent,
            s.pulses_rejected,
            s.can_tx_errors,
            s.watchdog_trips,
            s.fault_code,
            s.state,
            s.stimulator_state
        ));
        self.guard(r)
    }

    /// Records the driver's outcome of one pulse decision, or the stimulator's account of a
    /// pulse sent (what the data set's `pulse` column says was applied). An outcome that
    /// does not decode is kept in `outcomes.csv` and counts as not sent.
    pub fn on_outcome(&mut self, o: &PulseOutcome, now_ns: u64) -> Result<(), RecordingError> {
        self.ok()?;
        let fate = o.fate();
        let r = self.outcomes.line(format_args!(
            "{},{},{},{},{}",
            o.seq,
            o.t_ns,
            o.tick_seq,
            o.tick_t_ns,
            fate.map_or("invalid", PulseFate::name)
        ));
        self.guard(r)?;
        let fate = fate.unwrap_or(PulseFate::Refused);
        // Outcomes come in tick order (decisions and accounts each), and may overtake their
        // tick on the way here; one of a tick already written is too late and dropped.
        if o.tick_seq > self.last_tick_seq {
            if fate.is_confirmation() {
                self.pending_applied
                    .push_back((o.tick_seq, fate == PulseFate::Applied));
                while self.pending_applied.len() > 4096 {
                    self.pending_applied.pop_front();
                }
            } else {
                self.pending_outcomes.push_back((o.tick_seq, fate));
                while self.pending_outcomes.len() > 4096 {
                    self.pending_outcomes.pop_front();
                }
            }
        }
        let r = self.drain(now_ns);
        self.guard(r)
    }

    /// The driver's outcome for tick `seq` has arrived, or cannot arrive any more (an
    /// outcome of a later tick is in). Outcomes arrive in tick order: the newest decides.
    fn outcome_known(&self, seq: u64) -> bool {
        self.pending_outcomes.back().is_some_and(|&(s, _)| s >= seq)
    }

    /// The driver's decision on the pulse of tick `seq`, if it reported one.
    fn decision(&self, seq: u64) -> Option<PulseFate> {
        self.pending_outcomes
            .iter()
            .find(|&&(s, _)| s == seq)
            .map(|&(_, fate)| fate)
    }

    /// The driver's decision on the pulse of tick `seq`; forgets the decisions up to it.
    fn take_decision(&mut self, seq: u64) -> Option<PulseFate> {
        take_through(&mut self.pending_outcomes, seq)
    }

    /// The stimulator's account of the pulse of tick `seq` has arrived, or cannot arrive
    /// any more (one of a later pulse is in: accounts arrive in tick order).
    fn account_known(&self, seq: u64) -> bool {
        self.pending_applied.back().is_some_and(|&(s, _)| s >= seq)
    }

    /// Whether the stimulator applied the pulse of tick `seq`; forgets the accounts up to it.
    fn take_applied(&mut self, seq: u64) -> bool {
        take_through(&mut self.pending_applied, seq).unwrap_or(false)
    }

    /// Records a TimingReport.
    pub fn on_timing(&mut self, r: &TimingReport) -> Result<(), RecordingError> {
        self.ok()?;
        let res = self.timing.line(format_args!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.seq,
            r.t_ns,
            r.source,
            r.flags,
            r.ticks,
            r.misses,
            r.overruns,
            r.queue_overflows,
            r.hot_path_allocations,
            r.rejected_inputs,
            r.wake.p50_ns,
            r.wake.p99_ns,
            r.wake.p999_ns,
            r.wake.max_ns,
            r.compute.p99_ns,
            r.publish.p99_ns,
            r.ipc.p50_ns,
            r.ipc.p99_ns,
            r.ipc.p999_ns,
            r.ipc.max_ns,
            r.publish.p50_ns,
            r.publish.p999_ns,
            r.publish.max_ns
        ));
        self.guard(res)
    }

    /// Records an event (a line of `events.jsonl`).
    pub fn on_event(&mut self, now_ns: u64, text: &str) -> Result<(), RecordingError> {
        self.ok()?;
        let wall_s = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        let line = serde_json::json!({ "t_ns": now_ns, "unix_s": wall_s, "event": text });
        let r = self.events.line(format_args!("{line}"));
        self.guard(r)
    }

    /// Records a beat and starts a new data-set record at the next tick.
    pub fn on_beat(&mut self, b: &BeatRecord) -> Result<(), RecordingError> {
        self.ok()?;
        let m = &b.measurement;
        let opt = |v: Option<f64>| v.map_or(String::new(), |x| x.to_string());
        let r = self.beats.line(format_args!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            m.beat.index,
            m.beat.start_ns,
            m.beat.period_ns,
            m.beat.on_ns,
            m.beat.bpm,
            m.beat.target,
            m.beat.amplitude,
            opt(m.plateau_mean),
            m.peak,
            m.fti,
            m.pulses,
            m.samples,
            m.plateau_coverage,
            b.update.error,
            b.update.correction,
            b.update.amplitude,
            m.pulses_refused
        ));
        self.guard(r)
    }

    /// Ends the current data-set record before the tick at `t_ns` (a beat start); the
    /// next record has `kind`.
    pub fn boundary(&mut self, t_ns: u64, kind: String) {
        self.boundaries.push_back((t_ns, kind));
    }

    /// The force sample nearest to `t_ns`, if one is within [`FORCE_MATCH_NS`].
    fn force_at(&self, t_ns: u64) -> Option<f64> {
        self.recent_force
            .iter()
            .map(|&(t, f)| (t.abs_diff(t_ns), f))
            .filter(|&(d, _)| d <= FORCE_MATCH_NS)
            .min_by_key(|&(d, _)| d)
            .map(|(_, f)| f)
    }

    /// Writes the data-set rows of the ticks whose force sample has arrived (or waited
    /// long enough).
    fn drain(&mut self, now_ns: u64) -> Result<(), RecordingError> {
        let latest_force = self.recent_force.back().map_or(0, |&(t, _)| t);
        while let Some(t) = self.pending_ticks.front().copied() {
            let force_due =
                latest_force >= t.t_ns + FORCE_MATCH_NS / 2 || now_ns >= t.t_ns + FORCE_WAIT_NS;
            let outcome_due =
                !t.fires() || self.outcome_known(t.seq) || now_ns >= t.t_ns + OUTCOME_WAIT_NS;
            if !(force_due && outcome_due) {
                break;
            }
            let sent = t.fires() && self.decision(t.seq) == Some(PulseFate::Sent);
            let account_due =
                !sent || self.account_known(t.seq) || now_ns >= t.t_ns + APPLIED_WAIT_NS;
            if !account_due {
                break;
            }
            self.pending_ticks.pop_front();
            let force = self.force_at(t.t_ns);
            let applied = if t.fires() {
                let fate = self.take_decision(t.seq);
                let applied = sent && self.take_applied(t.seq);
                self.pulse_line(&t, fate, applied)?;
                applied
            } else {
                false
            };
            self.row(&t, force, applied)?;
        }
        // Forget force samples no pending tick can use.
        let oldest = self
            .pending_ticks
            .front()
            .map_or(latest_force, |t| t.t_ns)
            .saturating_sub(2 * FORCE_MATCH_NS);
        while self.recent_force.front().is_some_and(|&(t, _)| t < oldest) {
            self.recent_force.pop_front();
        }
        Ok(())
    }

    /// One line of `pulses.csv` for the pulse decided at tick `t`: decided, sent (the
    /// driver's `fate`), applied; counted in the summary.
    fn pulse_line(
        &mut self,
        t: &StimTick,
        fate: Option<PulseFate>,
        applied: bool,
    ) -> Result<(), RecordingError> {
        let sent = fate == Some(PulseFate::Sent);
        self.pulses_decided += 1;
        self.pulses_sent += u64::from(sent);
        self.pulses_applied += u64::from(applied);
        self.pulses.line(format_args!(
            "{},{},1,{},{},{}",
            t.seq,
            t.t_ns,
            u8::from(sent),
            u8::from(applied),
            fate.map_or("unreported", PulseFate::name)
        ))
    }

    fn row(
        &mut self,
        t: &StimTick,
        force: Option<f64>,
        applied: bool,
    ) -> Result<(), RecordingError> {
        while self.boundaries.front().is_some_and(|(b, _)| *b <= t.t_ns) {
            if let Some((_, kind)) = self.boundaries.pop_front() {
                self.boundary_pending = Some(kind);
            }
        }
        let (lo, hi) = DATASET_FORCE_RANGE;
        let usable = force.filter(|f| (lo..=hi).contains(f));
        let gap = self.last_tick_seq != 0 && t.seq != self.last_tick_seq + 1;
        self.last_tick_seq = t.seq;
        let Some(force) = usable else {
            // No force for this tick, or one the format cannot hold: the record ends.
            self.end_record()?;
            self.boundary_pending
                .get_or_insert_with(|| "after a gap".into());
            return Ok(());
        };
        let split = match &self.record {
            None => true,
            Some(r) => {
                gap || self.boundary_pending.is_some()
                    || r.samples >= self.settings.max_record_ticks
                    || t.t_ns != r.last_grid_ns + 1_000_000
            }
        };
        if split {
            self.end_record()?;
            let kind = self
                .boundary_pending
                .take()
                .unwrap_or_else(|| "continued".into());
            let file = format!("record_{:05}.csv", self.next_record);
            self.next_record += 1;
            let stream = Stream::create(&self.dir, &file, Some(fes_dataset::CSV_HEADER_DECIDED))?;
            self.record = Some(OpenRecord {
                file,
                kind: format!("{kind} (tick {})", t.seq),
                stream,
                samples: 0,
                pulses: 0,
                last_grid_ns: t.t_ns,
            });
        }
        // A record is open here: `split` is true whenever none is.
        let Some(r) = self.record.as_mut() else {
            return Ok(());
        };
        r.stream.line(format_args!(
            "{},{},{},{}",
            r.samples,
            u8::from(applied),
            force,
            u8::from(t.fires())
        ))?;
        r.samples += 1;
        r.pulses += usize::from(applied);
        r.last_grid_ns = t.t_ns;
        Ok(())
    }

    /// Completes the open record: flushed, listed, `dataset.json` rewritten.
    fn end_record(&mut self) -> Result<(), RecordingError> {
        let Some(mut r) = self.record.take() else {
            return Ok(());
        };
        r.stream.flush()?;
        if r.samples >= 2 {
            self.entries.push(Entry {
                file: r.file,
                kind: r.kind,
                samples: r.samples,
                pulses: r.pulses,
            });
            self.write_meta()?;
        } else {
            let _ = fs::remove_file(&r.stream.path);
        }
        Ok(())
    }

    /// Rewrites `dataset.json` (atomically) when there are at least two records.
    fn write_meta(&mut self) -> Result<(), RecordingError> {
        let n = self.entries.len();
        if n < 2 {
            return Ok(());
        }
        let (scale_n, offset_n, measured) = match self.scale.get() {
            Some((s, o)) => (s, o, true),
            None => (self.settings.scale_n, self.settings.offset_n, false),
        };
        let train: Vec<usize> = (0..n).step_by(2).collect();
        let test: Vec<usize> = (1..n).step_by(2).collect();
        let meta = serde_json::json!({
            "schema": fes_dataset::SCHEMA,
            "source": self.settings.source,
            "prescription_sha256": self.settings.prescription_sha256,
            "preset": null,
            "parameters": {},
            "noise": null,
            "protocol": {
                "kind": "supervisor recording",
                "run": self.settings.protocol,
                "scale": if measured { "fitted to the force stream (force_n = scale_n force + offset_n)" } else { "configured" },
                "split": "alternate records: even train, odd test",
            },
            "scale_n": scale_n,
            "offset_n": offset_n,
            "ts_s": 1e-3,
            "split": { "train": train, "test": test },
            "records": self.entries,
        });
        let text = serde_json::to_string_pretty(&meta).map_err(|e| RecordingError {
            op: "encode",
            path: self.dir.join("dataset.json"),
            source: std::io::Error::other(e),
        })?;
        let tmp = self.dir.join("dataset.json.tmp");
        let path = self.dir.join("dataset.json");
        let mut f = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .mode(FILE_MODE)
            .open(&tmp)
            .map_err(err("create", &tmp))?;
        f.write_all(text.as_bytes()).map_err(err("write", &tmp))?;
        f.sync_data().map_err(err("fsync", &tmp))?;
        fs::rename(&tmp, &path).map_err(err("rename into", &path))?;
        Ok(())
    }

    /// Flushes the streams when the flush period has passed (call often).
    pub fn maybe_flush(&mut self, now_ns: u64) -> Result<(), RecordingError> {
        self.ok()?;
        if now_ns < self.last_flush_ns + self.settings.flush_period_ns {
            return Ok(());
        }
        self.last_flush_ns = now_ns;
        let r = self.drain(now_ns).and_then(|()| self.flush_all());
        self.guard(r)
    }

    /// Every stream of the recording (not the record in progress).
    fn streams(&mut self) -> [&mut Stream; 10] {
        [
            &mut self.ticks,
            &mut self.force,
            &mut self.references,
            &mut self.previews,
            &mut self.status,
            &mut self.outcomes,
            &mut self.pulses,
            &mut self.timing,
            &mut self.beats,
            &mut self.events,
        ]
    }

    fn flush_all(&mut self) -> Result<(), RecordingError> {
        for s in self.streams() {
            s.flush()?;
        }
        if let Some(r) = &mut self.record {
            r.stream.flush()?;
        }
        Ok(())
    }

    /// Ends the recording: pending rows written, the last record completed, every file
    /// flushed and fsynced, the directory fsynced.
    pub fn finish(mut self, now_ns: u64) -> Result<RecordingSummary, RecordingError> {
        self.ok()?;
        let far = now_ns.saturating_add(FORCE_WAIT_NS.max(OUTCOME_WAIT_NS).max(APPLIED_WAIT_NS));
        self.drain(far)?;
        self.end_record()?;
        for s in self.streams() {
            s.sync()?;
        }
        File::open(&self.dir)
            .and_then(|d| d.sync_all())
            .map_err(err("fsync", &self.dir))?;
        Ok(RecordingSummary {
            dir: self.dir.clone(),
            records: self.entries.len(),
            ticks: self.tick_count,
            force_samples: self.force_count,
            pulses_decided: self.pulses_decided,
            pulses_sent: self.pulses_sent,
            pulses_applied: self.pulses_applied,
        })
    }
}

/// The value queued for tick `seq` in a queue kept in tick order, forgetting every entry up
/// to it (the driver's decisions, the stimulator's accounts).
fn take_through<T: Copy>(queue: &mut VecDeque<(u64, T)>, seq: u64) -> Option<T> {
    let mut found = None;
    while let Some(&(s, v)) = queue.front() {
        if s > seq {
            break;
        }
        queue.pop_front();
        if s == seq {
            found = Some(v);
        }
    }
    found
}

/// `YYYYMMDDTHHMMSSZ` of the current UTC time (run directory names).
pub fn utc_stamp() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// The header of `previews.csv`.
fn preview_header() -> String {
    let mut h = String::from("seq,t_ns,ref_seq,len");
    for i in 0..ReferencePreview::MAX_EDGES {
        h += &format!(",t_ns_{i},force_{i},max_rate_per_s_{i}");
    }
    h
}
