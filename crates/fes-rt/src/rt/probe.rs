//! File formats of the `rt-probe` measurement process, shared with `rt-latency` and the
//! tests: the JSON summary ([`ProbeSummary`]) and the per-tick CSV record ([`TickRecord`]).

use std::io::{self, BufRead, Write};
use std::num::{ParseFloatError, ParseIntError};
use std::str::FromStr;

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

/// What `rt-probe` writes with `--summary` when it exits (the default: nothing received).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
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
    /// rt-core's last (ideally final) timing report, as received.
    pub rt_core: Option<TimingReport>,
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
    pub fn parse_csv(line: &str) -> Result<Self, RecordError> {
        let f: Vec<&str> = line.trim().split(',').collect();
        if f.len() != RECORD_FIELDS {
            return Err(RecordError::FieldCount {
                found: f.len(),
                line: line.to_owned(),
            });
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
                min_gap_ticks: 0,
            },
            t_recv_ns: int(f[4], "t_recv_ns")?,
        })
    }
}

/// Fields of a [`TickRecord`] line ([`RECORD_HEADER`]).
const RECORD_FIELDS: usize = 16;

/// Why one line of a `rt-probe --record` file is not a [`TickRecord`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RecordError {
    /// The line does not have [`RECORD_HEADER`]'s 16 fields.
    #[error("expected 16 fields, found {found}: {line:?}")]
    FieldCount {
        /// Fields found.
        found: usize,
        /// The line.
        line: String,
    },
    /// An integer field does not hold an integer of its type.
    #[error("{field}: not an integer: {text:?}")]
    NotInteger {
        /// The field's name in [`RECORD_HEADER`].
        field: &'static str,
        /// Its text.
        text: String,
        /// The parser's reason.
        source: ParseIntError,
    },
    /// A real field does not hold a number.
    #[error("{field}: not a number: {text:?}")]
    NotNumber {
        /// The field's name in [`RECORD_HEADER`].
        field: &'static str,
        /// Its text.
        text: String,
        /// The parser's reason.
        source: ParseFloatError,
    },
}

/// The integer field `field` from its text `s`.
fn int<T: FromStr<Err = ParseIntError>>(s: &str, field: &'static str) -> Result<T, RecordError> {
    s.parse().map_err(|source| RecordError::NotInteger {
        field,
        text: s.to_owned(),
        source,
    })
}

/// The real field `field` from its text `s`.
fn real(s: &str, field: &'static str) -> Result<f64, RecordError> {
    s.parse().map_err(|source| RecordError::NotNumber {
        field,
        text: s.to_owned(),
        source,
    })
}

/// Why a `rt-probe --record` file could not be read; each names the 1-based line.
#[derive(Debug, thiserror::Error)]
pub enum ReadRecordsError {
    /// The line could not be read.
    #[error("line {line}: {source}")]
    Io {
        /// 1-based line.
        line: usize,
        /// The reader's error.
        source: io::Error,
    },
    /// The first line is not [`RECORD_HEADER`].
    #[error("line 1: unexpected header {0:?}")]
    Header(String),
    /// A line is not a [`TickRecord`].
    #[error("line {line}: {source}")]
    Record {
        /// 1-based line.
        line: usize,
        /// What is wrong with it.
        source: RecordError,
    },
}

/// Reads a `rt-probe --record` CSV file.
pub fn read_records(reader: impl BufRead) -> Result<Vec<TickRecord>, ReadRecordsError> {
    let mut out = Vec::new();
    for (i, line) in reader.lines().enumerate() {
        let line = line.map_err(|source| ReadRecordsError::Io {
            line: i + 1,
            source,
        })?;
        if i == 0 {
            if line.trim() != RECORD_HEADER {
                return Err(ReadRecordsError::Header(line));
            }
            continue;
        }
        if line.trim().is_empty() {
            continue;
        }
        let record = TickRecord::parse_csv(&line).map_err(|source| ReadRecordsError::Record {
            line: i + 1,
            source,
        })?;
        out.push(record);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code: a failed assumption is a failed test

    use super::*;

    const LINE: &str = "7,1000,1010,1020,1050,1,0,0,0.5,0.25,0.125,0.75,20000,200,3,4";

    #[test]
    fn a_written_record_reads_back() {
        let record = TickRecord::parse_csv(LINE).unwrap();
        let mut text = Vec::new();
        record.write_csv(&mut text).unwrap();
        assert_eq!(String::from_utf8(text).unwrap().trim(), LINE);
        let file = format!("{RECORD_HEADER}\n{LINE}\n\n{LINE}\n");
        assert_eq!(read_records(file.as_bytes()).unwrap(), vec![record, record]);
    }

    #[test]
    fn errors_name_the_line_the_field_and_why() {
        let e = TickRecord::parse_csv("1,2").unwrap_err();
        assert_eq!(e.to_string(), r#"expected 16 fields, found 2: "1,2""#);
        let e = TickRecord::parse_csv(&LINE.replacen("7", "x", 1)).unwrap_err();
        assert_eq!(e.to_string(), r#"seq: not an integer: "x""#);
        assert!(std::error::Error::source(&e).is_some());
        let e = TickRecord::parse_csv(&LINE.replace("0.125", "y")).unwrap_err();
        assert_eq!(e.to_string(), r#"model_force: not a number: "y""#);

        let e = read_records("seq,t_ns\n".as_bytes()).unwrap_err();
        assert_eq!(e.to_string(), r#"line 1: unexpected header "seq,t_ns""#);
        let file = format!("{RECORD_HEADER}\n{LINE}\n{}\n", LINE.replace("20000", "-1"));
        let e = read_records(file.as_bytes()).unwrap_err();
        assert_eq!(
            e.to_string(),
            r#"line 3: amplitude_ua: not an integer: "-1""#
        );
        assert!(matches!(
            e,
            ReadRecordsError::Record {
                line: 3,
                source: RecordError::NotInteger {
                    field: "amplitude_ua",
                    ..
                }
            }
        ));
    }
}
