//! HdrHistogram interval logs (`.hlog`): writing with hdrhistogram's interval-log writer and
//! reading them back with its iterator.
//!
//! Each interval is written as one tagged histogram line per measured quantity (tags such as
//! `wake`, `compute`, `publish`, `ipc`), values in nanoseconds. The header carries a
//! `BaseTime` (wall clock at start), so the per-interval timestamps are seconds since start;
//! any HdrHistogram tool (e.g. HistogramLogAnalyzer) can read the file.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use hdrhistogram::serialization::interval_log::{
    IntervalLogIterator, IntervalLogWriterBuilder, IntervalLogWriterError, LogEntry, Tag,
};
use hdrhistogram::serialization::{DeserializeError, Deserializer, V2SerializeError, V2Serializer};

use super::histogram::LatencyHistogram;

/// Failure writing or reading an interval log.
#[derive(Debug, thiserror::Error)]
pub enum HlogError {
    /// File I/O failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// A histogram could not be encoded.
    #[error("{path}: cannot encode histogram: {source}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: IntervalLogWriterError<V2SerializeError>,
    },
    /// A tag is not a valid interval-log tag (no `,`, space or newline allowed).
    #[error("invalid hlog tag {0:?}")]
    Tag(String),
    /// The file is not a valid interval log.
    #[error("{path}: line {line}: {detail}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based entry number.
        line: usize,
        /// What is wrong: the Debug text of hdrhistogram's `LogIteratorError`, which
        /// implements neither `Display` nor `std::error::Error` and so cannot be kept as a
        /// source.
        detail: String,
    },
    /// An interval's histogram is not valid base64.
    #[error("{path}: line {line}: histogram is not valid base64: {source}")]
    Base64 {
        /// The file.
        path: PathBuf,
        /// 1-based entry number.
        line: usize,
        /// The cause.
        #[source]
        source: base64::DecodeError,
    },
    /// An interval's histogram cannot be decoded.
    #[error("{path}: line {line}: cannot decode histogram: {source}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// 1-based entry number.
        line: usize,
        /// The cause.
        #[source]
        source: DeserializeError,
    },
}

/// Appends tagged interval histograms to an `.hlog` file.
pub struct HlogWriter {
    path: PathBuf,
    out: BufWriter<File>,
    serializer: V2Serializer,
}

impl HlogWriter {
    /// Creates (truncates) `path` and writes the header: a comment naming the source and
    /// units, StartTime and BaseTime = `start` (wall clock).
    pub fn create(path: &Path, comment: &str, start: SystemTime) -> Result<Self, HlogError> {
        let io_err = |source| HlogError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = File::create(path).map_err(io_err)?;
        let mut out = BufWriter::new(file);
        let mut serializer = V2Serializer::new();
        IntervalLogWriterBuilder::new()
            .add_comment(comment)
            .add_comment("values in nanoseconds")
            .with_start_time(start)
            .with_base_time(start)
            .begin_log_with(&mut out, &mut serializer)
            .map_err(io_err)?;
        Ok(Self {
            path: path.to_path_buf(),
            out,
            serializer,
        })
    }

    /// Writes one interval histogram: `start` is the interval's start relative to the
    /// BaseTime, `duration` its length.
    pub fn write(
        &mut self,
        hist: &LatencyHistogram,
        tag: &str,
        start: Duration,
        duration: Duration,
    ) -> Result<(), HlogError> {
        let tag_value = Tag::new(tag).ok_or_else(|| HlogError::Tag(tag.to_owned()))?;
        // A builder with no headers writes nothing when it begins: it only borrows our file
        // and serializer for this one interval.
        let mut writer = IntervalLogWriterBuilder::new()
            .begin_log_with(&mut self.out, &mut self.serializer)
            .map_err(|source| HlogError::Io {
                path: self.path.clone(),
                source,
            })?;
        writer
            .write_histogram(hist.raw(), start, duration, Some(tag_value))
            .map_err(|source| HlogError::Encode {
                path: self.path.clone(),
                source,
            })
    }

    /// Flushes buffered lines to the file.
    pub fn flush(&mut self) -> Result<(), HlogError> {
        self.out.flush().map_err(|source| HlogError::Io {
            path: self.path.clone(),
            source,
        })
    }
}

/// One interval read back from a log.
#[derive(Debug, Clone)]
pub struct HlogInterval {
    /// Its tag ("" when untagged).
    pub tag: String,
    /// Start relative to the log's BaseTime.
    pub start: Duration,
    /// Length.
    pub duration: Duration,
    /// The histogram.
    pub histogram: hdrhistogram::Histogram<u64>,
}

/// Reads every interval of an `.hlog` file with hdrhistogram's interval-log iterator.
pub fn read_intervals(path: &Path) -> Result<Vec<HlogInterval>, HlogError> {
    let bytes = std::fs::read(path).map_err(|source| HlogError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut deserializer = Deserializer::new();
    let mut out = Vec::new();
    for (i, entry) in IntervalLogIterator::new(&bytes).enumerate() {
        let (path, line) = (path.to_path_buf(), i + 1);
        let entry = entry.map_err(|e| HlogError::Parse {
            path: path.clone(),
            line,
            detail: format!("{e:?}"),
        })?;
        match entry {
            LogEntry::Interval(ilh) => {
                let encoded = ilh.encoded_histogram();
                let decoded =
                    BASE64
                        .decode(encoded.trim())
                        .map_err(|source| HlogError::Base64 {
                            path: path.clone(),
                            line,
                            source,
                        })?;
                let histogram: hdrhistogram::Histogram<u64> = deserializer
                    .deserialize(&mut &decoded[..])
                    .map_err(|source| HlogError::Decode { path, line, source })?;
                out.push(HlogInterval {
                    tag: ilh.tag().map(|t| t.as_str().to_owned()).unwrap_or_default(),
                    start: ilh.start_timestamp(),
                    duration: ilh.duration(),
                    histogram,
                });
            }
            LogEntry::StartTime(_) | LogEntry::BaseTime(_) => {}
        }
    }
    Ok(out)
}

/// Merges all intervals of a log per tag into bounded histograms.
pub fn merge_by_tag(path: &Path) -> Result<BTreeMap<String, LatencyHistogram>, HlogError> {
    let mut merged: BTreeMap<String, LatencyHistogram> = BTreeMap::new();
    for interval in read_intervals(path)? {
        merged
            .entry(interval.tag)
            .or_default()
            .add_raw(&interval.histogram);
    }
    Ok(merged)
}
