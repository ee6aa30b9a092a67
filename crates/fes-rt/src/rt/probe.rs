//! File formats of the `rt-probe` measurement process, shared with `rt-latency` and the
//! tests: the JSON summary ([`ProbeSummary`]) and the per-tick CSV record ([`TickRecord`]).

use std::io::{self, BufRead, Write};

use serde::{Deserialize, Serialize};

use crate::msg::{LatencySummary, StimTick, TimingReport};

/// Percentiles in nanoseconds (JSON form of [`LatencySummary`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct PercentilesNs {
    /// Number of values.
    pub count: u64,
    /// Median.
    pub p50: u64,
    /// 99th percentile.
    pub p99: u64,
    /// 99.9th percentile.
    pub p999: u64,
    /// Maximum.
    pub max: u64,
}

impl From<LatencySummary> for PercentilesNs {
    fn from(s: LatencySummary) -> Self {
        Self {
            count: s.count,
            p50: s.p50_ns,
            p99: s.p99_ns,
            p999: s.p999_ns,
            max: s.max_ns,
        }
    }
}

/// The last [`TimingReport`] the probe received from rt-core (JSON form).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RtCoreTiming {
    /// Ticks executed.
    pub ticks: u64,
    /// Skipped periods.
    pub misses: u64,
    /// Ticks preceded by skipped periods.
    pub overruns: u64,
    /// Telemetry records dropped.
    pub queue_overflows: u64,
    /// Heap allocations of the real-time thread after start-up.
    pub hot_path_allocations: u64,
    /// Rejected inputs.
    pub rejected_inputs: u64,
    /// Wake-up lateness.
    pub wake_ns: PercentilesNs,
    /// Input time.
    pub input_ns: PercentilesNs,
    /// Compute time.
    pub compute_ns: PercentilesNs,
    /// Publish time.
    pub publish_ns: PercentilesNs,
    /// `TimingReport` flags.
    pub flags: u8,
}

impl From<&TimingReport> for RtCoreTiming {
    fn from(r: &TimingReport) -> Self {
        Self {
            ticks: r.ticks,
            misses: r.misses,
            overruns: r.overruns,
            queue_overflows: r.queue_overflows,
            hot_path_allocations: r.hot_path_allocations,
            rejected_inputs: r.rejected_inputs,
            wake_ns: r.wake.into(),
            input_ns: r.input.into(),
            compute_ns: r.compute.into(),
            publish_ns: r.publish.into(),
            flags: r.flags,
        }
    }
}

/// What `rt-probe` writes with `--summary` when it exits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ProbeSummary {
    /// StimTicks received.
    pub received: u64,
    /// StimTicks that failed validation.
    pub invalid: u64,
    /// StimTicks lost by this receiver (gaps in `seq`).
    pub lost: u64,
    /// First `seq` received (0 = none).
    pub first_seq: u64,
    /// Last `seq` received.
    pub last_seq: u64,
    /// Pulses among the received ticks.
    pub pulses: u64,
    /// Whether the final tick was received.
    pub final_seen: bool,
    /// Publish-to-receive latency.
    pub ipc_ns: PercentilesNs,
    /// rt-core's last (ideally final) timing report.
    pub rt_core: Option<RtCoreTiming>,
    /// Whether that report is rt-core's final one.
    pub rt_core_final: bool,
}

/// One received tick, as a CSV line of `rt-probe --record`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickRecord {
    /// The tick as received.
    pub tick: StimTick,
    /// When the probe received it, CLOCK_MONOTONIC ns.
    pub t_recv_ns: u64,
}

/// CSV header of [`TickRecord`] files.
pub const RECORD_HEADER: &str = "seq,t_ns,t_wake_ns,t_publish_ns,t_recv_ns,pulse,flags,\
missed_periods,reference,u_cont,model_force,phi,amplitude_ua,width_us,channel,ref_seq";

impl TickRecord {
    /// Writes one CSV line.
    pub fn write_csv(&self, out: &mut impl Write) -> io::Result<()> {
        let t = &self.tick;
        writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            t.seq,
            t.t_ns,
            t.t_wake_ns,
            t.t_publish_ns,
            self.t_recv_ns,
            t.pulse,
            t.flags,
            t.missed_periods,
            t.reference,
            t.u_cont,
            t.model_force,
            t.phi,
            t.amplitude_ua,
            t.width_us,
            t.channel,
            t.ref_seq
        )
    }

    /// Parses one CSV line (fields not in the file are zero).
    pub fn parse_csv(line: &str) -> Result<Self, String> {
        let f: Vec<&str> = line.trim().split(',').collect();
        if f.len() != 16 {
            return Err(format!("expected 16 fields, found {}: {line:?}", f.len()));
        }
        fn int<T: std::str::FromStr>(s: &str, name: &str) -> Result<T, String> {
            s.parse()
                .map_err(|_| format!("{name}: not an integer: {s:?}"))
        }
        fn real(s: &str, name: &str) -> Result<f64, String> {
            s.parse()
                .map_err(|_| format!("{name}: not a number: {s:?}"))
        }
        Ok(Self {
            tick: StimTick {
                seq: int(f[0], "seq")?,
                t_ns: int(f[1], "t_ns")?,
                t_wake_ns: int(f[2], "t_wake_ns")?,
                t_publish_ns: int(f[3], "t_publish_ns")?,
                ref_seq: int(f[15], "ref_seq")?,
                reference: real(f[8], "reference")?,
                u_cont: real(f[9], "u_cont")?,
                energy: 0.0,
                model_force: real(f[10], "model_force")?,
                predicted_force: 0.0,
                phi: real(f[11], "phi")?,
                amplitude_ua: int(f[12], "amplitude_ua")?,
                missed_periods: int(f[7], "missed_periods")?,
                width_us: int(f[13], "width_us")?,
                flags: int(f[6], "flags")?,
                pulse: int(f[5], "pulse")?,
                channel: int(f[14], "channel")?,
                reserved: [0; 2],
            },
            t_recv_ns: int(f[4], "t_recv_ns")?,
        })
    }
}

/// Reads a `rt-probe --record` CSV file.
pub fn read_records(reader: impl BufRead) -> Result<Vec<TickRecord>, String> {
    let mut out = Vec::new();
    for (i, line) in reader.lines().enumerate() {
        let line = line.map_err(|e| format!("line {}: {e}", i + 1))?;
        if i == 0 {
            if line.trim() != RECORD_HEADER {
                return Err(format!("line 1: unexpected header {line:?}"));
            }
            continue;
        }
        if line.trim().is_empty() {
            continue;
        }
        out.push(TickRecord::parse_csv(&line).map_err(|e| format!("line {}: {e}", i + 1))?);
    }
    Ok(out)
}
