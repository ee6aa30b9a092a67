//! Importing a recording made elsewhere into the data-set format: a table of force and
//! stimulation (CSV, semicolon- or tab-separated, or whitespace-separated columns) at any
//! sample rate, with its own column names, force units and record layout, becomes a
//! validated [`DataSet`] on the format's grid.
//!
//! What [`import`] does, in order:
//!
//! 1. **Columns** are found by header name or 1-based number ([`ColumnRef`]); a first line
//!    with a number in it is data, not a header ([`ImportOptions::header`]). Fields may be quoted (`"Force (N)"`); lines
//!    starting with `#` are comments; [`ImportOptions::skip_lines`] skips a preamble.
//! 2. **Time** comes from a column (in s, ms or us, [`TimeUnit`]) or from a fixed input rate
//!    ([`TimeSource::Rate`]). Within a record it must strictly increase.
//! 3. **Records** are split where the time jumps by more than
//!    [`ImportOptions::split_gap_s`] and/or where the value of
//!    [`ImportOptions::record_column`] changes (that value becomes the record's `kind`).
//! 4. **Force** in newtons is `gain * x` for the column's value `x`; it is resampled onto
//!    the grid `t_first + k ts` of each record by linear interpolation between the input
//!    samples, then normalised: `(F_N - offset_n) / scale_n` ([`Level`]: given, or estimated
//!    as `sim-muscle` does: the offset is the mean force up to each record's first pulse,
//!    the scale the largest offset-free sample).
//! 5. **Pulses** come from a column (a pulse in every sample whose value is > 0, or with
//!    [`Pulses::Column::edges`] one pulse per run of non-zero samples, at its first) or
//!    from a list of times ([`parse_pulse_times`]); each is placed on the nearest grid tick
//!    of its record. Two pulses on one tick are refused, naming both lines: the grid
//!    cannot hold them (choose a shorter `ts`, or `edges` for a pulse that spans samples).
//! 6. **Split**: the first records train, the rest test ([`SplitSpec`]).
//!
//! Every problem is an [`ImportError`] naming the file, the line and the column.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::{DataSet, FORCE_SLACK, FormatError, Header, Record, Split, line_of};

/// The most samples one record may have on the grid (about 2.8 hours at 1 ms): beyond it a
/// time column is in the wrong unit or records are not split.
pub const MAX_GRID_SAMPLES: usize = 10_000_000;

/// Refused input or options, naming the file, line (1-based, as an editor counts) and
/// column.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImportError {
    /// An option's value cannot be used.
    #[error("{option}: {problem}")]
    Option {
        /// The option (as the command line spells it).
        option: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A file is not UTF-8 text.
    #[error("{}:{line}: not UTF-8 text", path.display())]
    NotUtf8 {
        /// The file.
        path: PathBuf,
        /// Line of the first invalid byte.
        line: usize,
    },
    /// The input holds no data line.
    #[error("{}: no data lines{}", path.display(), if *skipped > 0 { format!(" after the {skipped} skipped line(s)") } else { String::new() })]
    Empty {
        /// The file.
        path: PathBuf,
        /// Lines skipped before the header.
        skipped: usize,
    },
    /// A column named by an option is not in the input.
    #[error("{}: {option} `{wanted}`: {problem}; the columns are {available}", path.display())]
    NoColumn {
        /// The file.
        path: PathBuf,
        /// The option naming the column.
        option: &'static str,
        /// The name or number given.
        wanted: String,
        /// Why it does not resolve.
        problem: String,
        /// The columns there are, numbered.
        available: String,
    },
    /// A line is not split into as many fields as the header.
    #[error("{}:{line}: {found} field(s), expected {expected} (as line {header_line}){hint}", path.display())]
    Fields {
        /// The file.
        path: PathBuf,
        /// The line.
        line: usize,
        /// Fields found.
        found: usize,
        /// Fields of the first line.
        expected: usize,
        /// The first (header) line.
        header_line: usize,
        /// A hint on the delimiter, or empty.
        hint: String,
    },
    /// A field is not a usable value.
    #[error("{}:{line}: column {column} `{name}`: {problem}", path.display())]
    Value {
        /// The file.
        path: PathBuf,
        /// The line.
        line: usize,
        /// 1-based column number.
        column: usize,
        /// Column name (the header's, or `#n`).
        name: String,
        /// What is wrong.
        problem: String,
    },
    /// Two pulses fall on one tick of the grid.
    #[error("{0}")]
    PulseCollision(Box<PulseCollision>),
    /// A pulse time lies in no record.
    #[error("{}:{line}: pulse at t = {t} is in no record: {problem}", path.display())]
    PulseOutside {
        /// The file.
        path: PathBuf,
        /// The line.
        line: usize,
        /// Time on the input's clock, as written, with its unit.
        t: String,
        /// Where it lies.
        problem: String,
    },
    /// A record spans less than two grid samples.
    #[error("{span}, less than two samples of {ts_ms} ms; {hint}", ts_ms = span.ts_ms)]
    RecordTooShort {
        /// The record.
        span: RecordSpan,
        /// What splits records.
        hint: String,
    },
    /// A record would be longer than [`MAX_GRID_SAMPLES`] on the grid (a time in the wrong
    /// unit, or a missing split).
    #[error("{0}: more than {max} samples of {ts_ms} ms; check the time unit and the record split", ts_ms = .0.ts_ms, max = MAX_GRID_SAMPLES)]
    RecordTooLong(RecordSpan),
    /// Fewer than two records: a data set needs a train and a test record.
    #[error("{}: {count} record(s); a data set needs at least 2 (train and test): {hint}", path.display())]
    TooFewRecords {
        /// The file.
        path: PathBuf,
        /// Records found.
        count: usize,
        /// How to split.
        hint: String,
    },
    /// The force scale or offset cannot be estimated.
    #[error("{}: {problem}", path.display())]
    Normalise {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A normalised force sample is outside the format's range.
    #[error(
        "{}:{line}: column {column} `{name}`: force {newtons} N normalises to {normalised}, outside [{lo}, {hi}] (offset_n {offset_n} N, scale_n {scale_n} N); check the force gain, offset and scale",
        path.display(),
        lo = -FORCE_SLACK,
        hi = 1.0 + FORCE_SLACK
    )]
    ForceRange {
        /// The file.
        path: PathBuf,
        /// The line.
        line: usize,
        /// 1-based column number.
        column: usize,
        /// Column name.
        name: String,
        /// Force in newtons (after the gain).
        newtons: f64,
        /// Normalised value.
        normalised: f64,
        /// Offset used, N.
        offset_n: f64,
        /// Scale used, N.
        scale_n: f64,
    },
    /// The train/test split does not fit the records.
    #[error("{option}: {problem} ({count} records, numbered from 0)")]
    Split {
        /// The option.
        option: &'static str,
        /// What is wrong.
        problem: String,
        /// Records found.
        count: usize,
    },
    /// The imported data set violates the format (a bug of the importer if it happens:
    /// every rule is checked before).
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// A record whose span does not fit the grid ([`ImportError::RecordTooShort`],
/// [`ImportError::RecordTooLong`]); shown as where it is and how long it is.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSpan {
    /// The file.
    pub path: PathBuf,
    /// Record index.
    pub record: usize,
    /// Its first line.
    pub first_line: usize,
    /// Its last line.
    pub last_line: usize,
    /// Its span, ms.
    pub span_ms: f64,
    /// The grid's sample period, ms.
    pub ts_ms: f64,
}

impl std::fmt::Display for RecordSpan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}:{}-{}: record {} spans {} ms",
            self.path.display(),
            self.first_line,
            self.last_line,
            self.record,
            self.span_ms
        )
    }
}

/// Two pulses on one tick of the grid ([`ImportError::PulseCollision`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{}:{line}: column {column} `{name}`: the pulse at t = {t} falls on the same {ts_ms} ms tick (record {record}, sample {tick}) as the pulse of line {first_line}; the grid holds one pulse per sample: import at a shorter sample period, or {hint}",
    path.display()
)]
pub struct PulseCollision {
    /// The file holding the pulse (input, or the pulse-time list).
    pub path: PathBuf,
    /// Line of the second pulse.
    pub line: usize,
    /// Line of the first pulse.
    pub first_line: usize,
    /// 1-based column number (1 in a list of times).
    pub column: usize,
    /// Column name.
    pub name: String,
    /// Time of the second pulse on the input's clock, as written, with its unit.
    pub t: String,
    /// Record index.
    pub record: usize,
    /// Sample index in the record.
    pub tick: usize,
    /// The grid's sample period, ms.
    pub ts_ms: f64,
    /// What else could be meant.
    pub hint: &'static str,
}

/// How the fields of a line are separated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Delimiter {
    /// From the first line: `,` if it has one, else `;`, else a tab, else whitespace.
    Auto,
    /// `,` (RFC 4180 quoting).
    Comma,
    /// `;` (RFC 4180 quoting).
    Semicolon,
    /// A tab (RFC 4180 quoting).
    Tab,
    /// Runs of spaces and tabs (no quoting).
    Whitespace,
}

/// A column, by header name or by 1-based number.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ColumnRef {
    /// The header's name (exact; else the only case-insensitive match).
    Name(String),
    /// 1-based column number.
    Number(usize),
}

impl ColumnRef {
    /// A column as given on a command line: resolved as a header name first, then, when
    /// no column has that name and `text` is a positive integer, as a column number.
    pub fn parse(text: &str) -> ColumnRef {
        ColumnRef::Name(text.trim().to_string())
    }
}

impl std::fmt::Display for ColumnRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ColumnRef::Name(n) => write!(f, "{n}"),
            ColumnRef::Number(k) => write!(f, "{k}"),
        }
    }
}

/// Unit of times in the input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeUnit {
    /// Seconds.
    S,
    /// Milliseconds.
    Ms,
    /// Microseconds.
    Us,
}

impl TimeUnit {
    /// Milliseconds per unit.
    pub fn ms(self) -> f64 {
        match self {
            TimeUnit::S => 1e3,
            TimeUnit::Ms => 1.0,
            TimeUnit::Us => 1e-3,
        }
    }

    fn name(self) -> &'static str {
        match self {
            TimeUnit::S => "s",
            TimeUnit::Ms => "ms",
            TimeUnit::Us => "us",
        }
    }
}

/// Where sample times come from.
#[derive(Debug, Clone, PartialEq)]
pub enum TimeSource {
    /// A column of times.
    Column(ColumnRef),
    /// No time column: line k of the data (from 0) is at `k / hz`.
    Rate {
        /// Input sample rate, Hz.
        hz: f64,
    },
}

/// Where pulses come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Pulses {
    /// A column: 0 = no pulse, > 0 (1, or an amplitude) = a pulse in this sample.
    Column {
        /// The column.
        column: ColumnRef,
        /// One pulse per run of consecutive non-zero samples (at its first sample), for a
        /// stimulator output sampled so fast that one pulse spans several samples.
        edges: bool,
    },
    /// Pulse times ([`parse_pulse_times`]), on the input's clock and in its time unit.
    Times {
        /// The file they were read from (named in errors).
        path: PathBuf,
        /// (line, time) of each pulse.
        times: Vec<(usize, f64)>,
    },
}

/// The force offset or scale: given, or estimated from the data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Level {
    /// Given, N.
    Given(f64),
    /// Offset: mean force over each record's samples up to its first pulse. Scale: the
    /// largest offset-free sample (normalised maximum 1). As `sim-muscle record`.
    Auto,
}

/// Which records train and which test.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SplitSpec {
    /// The first half (rounded up) trains, the rest test.
    Half,
    /// The first n train, the rest test.
    TrainFirst(usize),
    /// These records (0-based) test, the rest train.
    Test(Vec<usize>),
}

/// Everything [`import`] needs to know besides the input.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Field separator.
    pub delimiter: Delimiter,
    /// Lines to skip before the header (an instrument's preamble).
    pub skip_lines: usize,
    /// Whether the first line names the columns; `None`: it does unless one of its
    /// fields is a number.
    pub header: Option<bool>,
    /// Sample times.
    pub time: TimeSource,
    /// Unit of the time column and of pulse times.
    pub time_unit: TimeUnit,
    /// The force column.
    pub force: ColumnRef,
    /// Newtons per unit of the force column.
    pub force_gain: f64,
    /// Offset removed, N.
    pub force_offset: Level,
    /// Newtons per normalised unit.
    pub force_scale: Level,
    /// Pulses.
    pub pulses: Pulses,
    /// The grid's sample period, s (the format's `ts_s`; 1 ms for muscle data).
    pub ts_s: f64,
    /// A new record where consecutive samples are more than this apart, s.
    pub split_gap_s: Option<f64>,
    /// A new record where this column's value changes; the value is the record's kind.
    pub record_column: Option<ColumnRef>,
    /// Train/test split.
    pub split: SplitSpec,
    /// `kind` of the records without a record column.
    pub kind: String,
    /// `source` of the data set.
    pub source: String,
}

impl ImportOptions {
    /// Options with the format's defaults: auto delimiter, time column in seconds, pulse
    /// column as levels, gain 1, offset and scale estimated, 1 ms grid, half split.
    pub fn new(time: TimeSource, force: ColumnRef, pulses: Pulses) -> ImportOptions {
        ImportOptions {
            delimiter: Delimiter::Auto,
            skip_lines: 0,
            header: None,
            time,
            time_unit: TimeUnit::S,
            force,
            force_gain: 1.0,
            force_offset: Level::Auto,
            force_scale: Level::Auto,
            pulses,
            ts_s: 1e-3,
            split_gap_s: None,
            record_column: None,
            split: SplitSpec::Half,
            kind: "imported".into(),
            source: "imported".into(),
        }
    }
}

/// What an import found, besides the data set.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportReport {
    /// Data lines read.
    pub lines: usize,
    /// Median step between input samples, ms.
    pub input_step_ms: f64,
    /// Pulses placed.
    pub pulses: usize,
    /// Largest distance of a pulse from its tick, ms.
    pub max_pulse_shift_ms: f64,
    /// Offset used, N.
    pub offset_n: f64,
    /// Scale used, N.
    pub scale_n: f64,
    /// Per record: (first line, last line) of the input.
    pub record_lines: Vec<(usize, usize)>,
}

/// A data set and what the import found.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    /// The data set (validated).
    pub dataset: DataSet,
    /// The report.
    pub report: ImportReport,
}

/// One input line's fields.
struct Row {
    line: usize,
    fields: Vec<String>,
}

/// The table: header names (or `#n`), whether there was a header, data rows.
struct Table {
    names: Vec<String>,
    header: bool,
    rows: Vec<Row>,
}

fn utf8<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a str, ImportError> {
    let text = std::str::from_utf8(bytes).map_err(|e| ImportError::NotUtf8 {
        path: path.to_path_buf(),
        line: line_of(bytes, e.valid_up_to()),
    })?;
    Ok(text.strip_prefix('\u{feff}').unwrap_or(text))
}

/// Splits `text` into rows (comments and blank lines dropped), after `skip` lines.
fn read_table(
    path: &Path,
    text: &str,
    delimiter: Delimiter,
    skip: usize,
    header: Option<bool>,
) -> Result<Table, ImportError> {
    let body = &text[skipped_offset(text, skip)..];
    let first_line = body
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .ok_or_else(|| ImportError::Empty {
            path: path.to_path_buf(),
            skipped: skip,
        })?;
    let rows = match resolve_delimiter(delimiter, first_line) {
        Delimiter::Whitespace | Delimiter::Auto => whitespace_rows(body, skip),
        Delimiter::Comma => csv_rows(path, body, skip, b',')?,
        Delimiter::Semicolon => csv_rows(path, body, skip, b';')?,
        Delimiter::Tab => csv_rows(path, body, skip, b'\t')?,
    };
    table_from_rows(path, skip, rows, header)
}

/// Byte offset in `text` after its first `skip` lines (its length if it has fewer).
fn skipped_offset(text: &str, skip: usize) -> usize {
    let mut start = 0;
    for _ in 0..skip {
        match text[start..].find('\n') {
            Some(i) => start += i + 1,
            None => start = text.len(),
        }
    }
    start
}

/// The delimiter to split by: `delimiter`, or for `Auto` the first of `,`, `;` and tab
/// that `first_line` holds, else whitespace.
fn resolve_delimiter(delimiter: Delimiter, first_line: &str) -> Delimiter {
    match delimiter {
        Delimiter::Auto if first_line.contains(',') => Delimiter::Comma,
        Delimiter::Auto if first_line.contains(';') => Delimiter::Semicolon,
        Delimiter::Auto if first_line.contains('\t') => Delimiter::Tab,
        Delimiter::Auto => Delimiter::Whitespace,
        d => d,
    }
}

/// Rows of whitespace-separated fields of `body` (no quoting), numbered after `skip` lines.
fn whitespace_rows(body: &str, skip: usize) -> Vec<Row> {
    let mut rows = Vec::new();
    for (i, l) in body.lines().enumerate() {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        rows.push(Row {
            line: skip + i + 1,
            fields: l.split_whitespace().map(str::to_string).collect(),
        });
    }
    rows
}

/// Rows of `body` read as CSV with delimiter `byte` (quoting, `#` comments), numbered
/// after `skip` lines.
fn csv_rows(path: &Path, body: &str, skip: usize, byte: u8) -> Result<Vec<Row>, ImportError> {
    let mut rows = Vec::new();
    let mut reader = csv::ReaderBuilder::new()
        .delimiter(byte)
        .has_headers(false)
        .flexible(true)
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .from_reader(body.as_bytes());
    let mut record = csv::StringRecord::new();
    loop {
        let line_hint = reader.position().line() as usize;
        match reader.read_record(&mut record) {
            Ok(false) => break,
            Ok(true) => {
                let line = record.position().map_or(line_hint, |p| p.line() as usize);
                if record.len() == 1 && record.get(0).is_some_and(str::is_empty) {
                    continue;
                }
                rows.push(Row {
                    line: skip + line,
                    fields: record.iter().map(str::to_string).collect(),
                });
            }
            Err(e) => {
                let line = e.position().map_or(line_hint, |p| p.line() as usize);
                return Err(ImportError::Value {
                    path: path.to_path_buf(),
                    line: skip + line,
                    column: 0,
                    name: String::new(),
                    problem: e.to_string(),
                });
            }
        }
    }
    Ok(rows)
}

/// The table of `rows`: the first is the header when `header` says so (when `None`,
/// unless it holds a number), and every data row must be as wide as the first.
fn table_from_rows(
    path: &Path,
    skip: usize,
    mut rows: Vec<Row>,
    header: Option<bool>,
) -> Result<Table, ImportError> {
    let Some(first) = rows.first() else {
        return Err(ImportError::Empty {
            path: path.to_path_buf(),
            skipped: skip,
        });
    };
    let header_line = first.line;
    let header = header.unwrap_or_else(|| !first.fields.iter().any(|f| f.parse::<f64>().is_ok()));
    let width = first.fields.len();
    let names = if header {
        first.fields.clone()
    } else {
        (1..=width).map(|k| format!("#{k}")).collect()
    };
    if header {
        rows.remove(0);
    }
    let hint = |found: usize| -> String {
        if found == 1 && width > 1 {
            " (is the delimiter right? see the delimiter option)".into()
        } else {
            String::new()
        }
    };
    for r in &rows {
        if r.fields.len() != width {
            return Err(ImportError::Fields {
                path: path.to_path_buf(),
                line: r.line,
                found: r.fields.len(),
                expected: width,
                header_line,
                hint: hint(r.fields.len()),
            });
        }
    }
    if rows.is_empty() {
        return Err(ImportError::Empty {
            path: path.to_path_buf(),
            skipped: skip,
        });
    }
    Ok(Table {
        names,
        header,
        rows,
    })
}

impl Table {
    /// 0-based index of a column.
    fn resolve(
        &self,
        path: &Path,
        option: &'static str,
        col: &ColumnRef,
    ) -> Result<usize, ImportError> {
        let available = self
            .names
            .iter()
            .enumerate()
            .map(|(i, n)| format!("{} `{n}`", i + 1))
            .collect::<Vec<_>>()
            .join(", ");
        let err = |wanted: String, problem: String| ImportError::NoColumn {
            path: path.to_path_buf(),
            option,
            wanted,
            problem,
            available: available.clone(),
        };
        match col {
            ColumnRef::Number(k) => {
                if (1..=self.names.len()).contains(k) {
                    Ok(k - 1)
                } else {
                    Err(err(
                        k.to_string(),
                        format!("there are {} column(s)", self.names.len()),
                    ))
                }
            }
            ColumnRef::Name(name) => {
                if let Some(i) = self.names.iter().position(|n| n == name) {
                    return Ok(i);
                }
                let folded: Vec<usize> = self
                    .names
                    .iter()
                    .enumerate()
                    .filter(|(_, n)| n.eq_ignore_ascii_case(name))
                    .map(|(i, _)| i)
                    .collect();
                if let [i] = folded[..] {
                    return Ok(i);
                }
                if let Ok(k) = name.parse::<usize>() {
                    return self.resolve(path, option, &ColumnRef::Number(k));
                }
                let problem = if !self.header {
                    "the input has no header line (its first line holds a number): name columns by number".to_string()
                } else if folded.len() > 1 {
                    "several columns match when case is ignored".to_string()
                } else {
                    "no such column".to_string()
                };
                Err(err(name.clone(), problem))
            }
        }
    }
}

/// Parses a list of pulse times: one number per line (the first field of a CSV or
/// whitespace-separated line); blank lines and `#` comments skipped; a first line that is
/// not a number is a header.
pub fn parse_pulse_times(path: &Path, bytes: &[u8]) -> Result<Vec<(usize, f64)>, ImportError> {
    let text = utf8(path, bytes)?;
    let mut out = Vec::new();
    let mut first = true;
    for (i, l) in text.lines().enumerate() {
        let l = l.trim();
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        let field = l
            .split([',', ';', '\t', ' '])
            .next()
            .unwrap_or("")
            .trim()
            .trim_matches('"');
        match field.parse::<f64>() {
            Ok(t) if t.is_finite() => out.push((i + 1, t)),
            _ if first => {}
            _ => {
                return Err(ImportError::Value {
                    path: path.to_path_buf(),
                    line: i + 1,
                    column: 1,
                    name: "pulse time".into(),
                    problem: format!("`{field}` is not a finite number"),
                });
            }
        }
        first = false;
    }
    Ok(out)
}

/// One record's input rows: times (ms), force (N), and the input line of each.
struct Segment {
    kind: String,
    t: Vec<f64>,
    f: Vec<f64>,
    lines: Vec<usize>,
    /// Index in `Table::rows` of the first row.
    first_row: usize,
    /// Samples on the record's grid (set by [`Importer::set_grid_lengths`]).
    ticks: usize,
}

impl Segment {
    /// Time of the last tick of the record's grid, ms.
    fn grid_end(&self, ts_ms: f64) -> f64 {
        self.t[0] + (self.ticks - 1) as f64 * ts_ms
    }

    /// Time of the record's last input sample, ms.
    fn last_t(&self) -> f64 {
        self.t[self.t.len() - 1]
    }
}

/// A pulse on a record's grid: the line and column it came from.
struct Placed {
    record: usize,
    tick: usize,
    line: usize,
    t: String,
    shift_ms: f64,
}

/// Where the pulses come from, as errors name it: the file, the column (1-based, 0 for
/// none) and its name, and the hint for two pulses on one tick.
struct PulseSource {
    path: PathBuf,
    column: usize,
    name: String,
    hint: &'static str,
}

/// One import's shared context: the input, the options, the table and its columns.
struct Importer<'a> {
    path: &'a Path,
    opts: &'a ImportOptions,
    table: Table,
    /// The grid's sample period, ms.
    ts_ms: f64,
    /// Milliseconds per unit of the input's times.
    unit_ms: f64,
    time_col: Option<usize>,
    force_col: usize,
    pulse_col: Option<usize>,
    record_col: Option<usize>,
}

/// Imports the table in `bytes` (`path` names it in errors).
pub fn import(path: &Path, bytes: &[u8], opts: &ImportOptions) -> Result<Imported, ImportError> {
    check_options(opts)?;
    let text = utf8(path, bytes)?;
    let table = read_table(path, text, opts.delimiter, opts.skip_lines, opts.header)?;
    let im = Importer::new(path, opts, table)?;
    let mut segments = im.segments()?;
    im.set_grid_lengths(&mut segments)?;
    let source = im.pulse_source();
    let placed = im.place_pulses(&source, &segments)?;
    let grid = im.pulse_grid(source, &segments, &placed)?;
    // Normalisation (on the input samples, so every grid value, a convex combination of
    // them, is in range when they are).
    let offset_n = im.offset(&segments, &grid)?;
    let scale_n = im.scale(&segments, offset_n)?;
    im.check_force_range(&segments, offset_n, scale_n)?;
    let records = im.resample(&segments, &grid, offset_n, scale_n);
    im.assemble(&segments, records, &placed, offset_n, scale_n)
}

impl<'a> Importer<'a> {
    /// The context of importing `table`: the columns the options name, resolved.
    fn new(
        path: &'a Path,
        opts: &'a ImportOptions,
        table: Table,
    ) -> Result<Importer<'a>, ImportError> {
        let time_col = match &opts.time {
            TimeSource::Column(c) => Some(table.resolve(path, "time column", c)?),
            TimeSource::Rate { .. } => None,
        };
        let force_col = table.resolve(path, "force column", &opts.force)?;
        let pulse_col = match &opts.pulses {
            Pulses::Column { column, .. } => Some(table.resolve(path, "pulse column", column)?),
            Pulses::Times { .. } => None,
        };
        let record_col = opts
            .record_column
            .as_ref()
            .map(|c| table.resolve(path, "record column", c))
            .transpose()?;
        Ok(Importer {
            path,
            opts,
            table,
            ts_ms: opts.ts_s * 1e3,
            unit_ms: opts.time_unit.ms(),
            time_col,
            force_col,
            pulse_col,
            record_col,
        })
    }

    /// The error for the field of `row` in column `col` (0-based).
    fn value_err(&self, row: &Row, col: usize, problem: String) -> ImportError {
        ImportError::Value {
            path: self.path.to_path_buf(),
            line: row.line,
            column: col + 1,
            name: self.table.names[col].clone(),
            problem,
        }
    }

    /// The finite number in column `col` (0-based) of `row`.
    fn number(&self, row: &Row, col: usize) -> Result<f64, ImportError> {
        let s = row.fields[col].as_str();
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(v) => Err(self.value_err(row, col, format!("{v} is not finite"))),
            Err(_) if s.is_empty() => Err(self.value_err(row, col, "empty field".into())),
            Err(_) => Err(self.value_err(row, col, format!("`{s}` is not a number"))),
        }
    }

    /// Time of data row `k` (`row`), ms: from the time column, or `k / rate`.
    fn row_time(&self, k: usize, row: &Row) -> Result<f64, ImportError> {
        match self.time_col {
            Some(c) => {
                let t = self.number(row, c)? * self.unit_ms;
                if !t.is_finite() {
                    return Err(self.value_err(
                        row,
                        c,
                        format!("{} is out of range", row.fields[c]),
                    ));
                }
                Ok(t)
            }
            None => {
                let rate_hz = match self.opts.time {
                    TimeSource::Rate { hz } => hz,
                    TimeSource::Column(_) => f64::NAN,
                };
                Ok(k as f64 * 1e3 / rate_hz)
            }
        }
    }

    /// Reads each row's time and force and cuts the rows into records where the time
    /// jumps by more than the split gap or the record column changes: at least two.
    fn segments(&self) -> Result<Vec<Segment>, ImportError> {
        let gap_ms = self.opts.split_gap_s.map(|g| g * 1e3);
        let mut segments: Vec<Segment> = Vec::new();
        let mut prev: Option<(f64, &Row, &str)> = None;
        for (k, row) in self.table.rows.iter().enumerate() {
            let t = self.row_time(k, row)?;
            let f = self.number(row, self.force_col)? * self.opts.force_gain;
            let key = self.record_col.map_or("", |c| row.fields[c].as_str());
            let new_record = match prev {
                None => true,
                Some((pt, _, pkey)) => {
                    self.record_col.is_some() && key != pkey || gap_ms.is_some_and(|g| t - pt > g)
                }
            };
            if let (false, Some((pt, prow, _)), Some(c)) = (new_record, prev, self.time_col)
                && t <= pt
            {
                let unit = self.opts.time_unit.name();
                return Err(self.value_err(
                    row,
                    c,
                    format!(
                        "time {} {unit} does not increase (line {}: {} {unit})",
                        row.fields[c], prow.line, prow.fields[c]
                    ),
                ));
            }
            if new_record {
                segments.push(Segment {
                    kind: if self.record_col.is_some() {
                        key.to_string()
                    } else {
                        self.opts.kind.clone()
                    },
                    t: Vec::new(),
                    f: Vec::new(),
                    lines: Vec::new(),
                    first_row: k,
                    ticks: 0,
                });
            }
            if let Some(s) = segments.last_mut() {
                s.t.push(t);
                s.f.push(f);
                s.lines.push(row.line);
            }
            prev = Some((t, row, key));
        }
        if segments.len() < 2 {
            return Err(ImportError::TooFewRecords {
                path: self.path.to_path_buf(),
                count: segments.len(),
                hint: self.split_hint(),
            });
        }
        Ok(segments)
    }

    /// The hint for records that are too few or too short: how records are split.
    fn split_hint(&self) -> String {
        match (self.opts.split_gap_s.is_some(), self.record_col.is_some()) {
            (false, false) => {
                "records are split by a time gap (split gap) or a record column; neither was given"
                    .into()
            }
            _ => "check the split gap or the record column".into(),
        }
    }

    /// Sets each record's grid length, refusing records too long or shorter than 2 ticks.
    fn set_grid_lengths(&self, segments: &mut [Segment]) -> Result<(), ImportError> {
        let ts_ms = self.ts_ms;
        for (i, s) in segments.iter_mut().enumerate() {
            let (t0, t1) = (s.t[0], s.last_t());
            let span = t1 - t0;
            let steps = (span / ts_ms + 1e-6).floor();
            let record_span = || RecordSpan {
                path: self.path.to_path_buf(),
                record: i,
                first_line: s.lines[0],
                last_line: s.lines[s.lines.len() - 1],
                span_ms: span,
                ts_ms,
            };
            if steps.is_nan() || steps >= MAX_GRID_SAMPLES as f64 {
                return Err(ImportError::RecordTooLong(record_span()));
            }
            let n = steps as usize + 1;
            if n < 2 {
                return Err(ImportError::RecordTooShort {
                    span: record_span(),
                    hint: self.split_hint(),
                });
            }
            s.ticks = n;
        }
        Ok(())
    }

    /// Where the pulses come from, as errors name it.
    fn pulse_source(&self) -> PulseSource {
        match &self.opts.pulses {
            Pulses::Column { edges, .. } => PulseSource {
                path: self.path.to_path_buf(),
                column: self.pulse_col.map_or(0, |c| c + 1),
                name: self
                    .pulse_col
                    .map_or_else(String::new, |c| self.table.names[c].clone()),
                hint: if *edges {
                    "check the pulse column"
                } else {
                    "count a run of non-zero samples as one pulse (pulse edges) if one pulse spans several samples"
                },
            },
            Pulses::Times { path: p, .. } => PulseSource {
                path: p.clone(),
                column: 1,
                name: "pulse time".into(),
                hint: "check the pulse times for duplicates",
            },
        }
    }

    /// Places every pulse, from the pulse column or the list of pulse times, on its
    /// record's grid.
    fn place_pulses(
        &self,
        source: &PulseSource,
        segments: &[Segment],
    ) -> Result<Vec<Placed>, ImportError> {
        match (&self.opts.pulses, self.pulse_col) {
            (Pulses::Column { edges, .. }, Some(c)) => {
                self.column_pulses(source, segments, c, *edges)
            }
            (Pulses::Times { times, .. }, _) => self.time_pulses(source, segments, times),
            (Pulses::Column { .. }, None) => Ok(Vec::new()),
        }
    }

    /// Places a pulse at time `t` (ms) of record `record` on its nearest tick, refusing
    /// one outside the record's grid.
    fn place(
        &self,
        source: &PulseSource,
        segments: &[Segment],
        record: usize,
        t: f64,
        line: usize,
        text: String,
    ) -> Result<Placed, ImportError> {
        let ts_ms = self.ts_ms;
        let s = &segments[record];
        let x = (t - s.t[0]) / ts_ms;
        let tick = x.round();
        if tick < 0.0 || tick as usize >= s.ticks {
            return Err(ImportError::PulseOutside {
                path: source.path.clone(),
                line,
                t: text,
                problem: format!(
                    "record {record} runs from {} to {} ms on the input's clock, its grid to {} ms",
                    s.t[0],
                    s.last_t(),
                    s.grid_end(ts_ms)
                ),
            });
        }
        Ok(Placed {
            record,
            tick: tick as usize,
            line,
            t: text,
            shift_ms: (x - tick).abs() * ts_ms,
        })
    }

    /// The pulses of pulse column `c`: one in each sample > 0 or, with `edges`, at the
    /// first sample of each run of them.
    fn column_pulses(
        &self,
        source: &PulseSource,
        segments: &[Segment],
        c: usize,
        edges: bool,
    ) -> Result<Vec<Placed>, ImportError> {
        let mut placed = Vec::new();
        for (r, s) in segments.iter().enumerate() {
            let mut was_on = false;
            for (j, &t) in s.t.iter().enumerate() {
                let row = &self.table.rows[s.first_row + j];
                let v = self.number(row, c)?;
                if v < 0.0 {
                    return Err(self.value_err(
                        row,
                        c,
                        format!("{v} is negative; a pulse is > 0, no pulse 0"),
                    ));
                }
                let on = v > 0.0;
                if on && !(edges && was_on) {
                    let text = match self.time_col {
                        Some(tc) => format!("{} {}", row.fields[tc], self.opts.time_unit.name()),
                        None => format!("{t} ms"),
                    };
                    placed.push(self.place(source, segments, r, t, row.line, text)?);
                }
                was_on = on;
            }
        }
        Ok(placed)
    }

    /// The pulses of a list of (line, time): each in the one record whose grid holds it.
    fn time_pulses(
        &self,
        source: &PulseSource,
        segments: &[Segment],
        times: &[(usize, f64)],
    ) -> Result<Vec<Placed>, ImportError> {
        let ts_ms = self.ts_ms;
        let mut placed = Vec::new();
        for &(line, t) in times {
            let text = format!("{t} {}", self.opts.time_unit.name());
            let t = t * self.unit_ms;
            let within: Vec<usize> = segments
                .iter()
                .enumerate()
                .filter(|(_, s)| {
                    let end = s.grid_end(ts_ms);
                    t >= s.t[0] - ts_ms / 2.0 && t < end + ts_ms / 2.0
                })
                .map(|(r, _)| r)
                .collect();
            let problem = match within[..] {
                [r] => {
                    placed.push(self.place(source, segments, r, t, line, text)?);
                    continue;
                }
                [] => outside_records(segments, t),
                _ => format!(
                    "records {within:?} overlap in time there; pulse times need records on one clock (times that restart per record cannot be told apart)"
                ),
            };
            return Err(ImportError::PulseOutside {
                path: source.path.clone(),
                line,
                t: text,
                problem,
            });
        }
        Ok(placed)
    }

    /// Each record's grid with the input line of the pulse on each tick, refusing two
    /// pulses on one tick.
    fn pulse_grid(
        &self,
        source: PulseSource,
        segments: &[Segment],
        placed: &[Placed],
    ) -> Result<Vec<Vec<Option<usize>>>, ImportError> {
        let mut grid: Vec<Vec<Option<usize>>> =
            segments.iter().map(|s| vec![None; s.ticks]).collect();
        for p in placed {
            let slot = &mut grid[p.record][p.tick];
            if let Some(first) = *slot {
                return Err(ImportError::PulseCollision(Box::new(PulseCollision {
                    path: source.path,
                    line: p.line,
                    first_line: first,
                    column: source.column,
                    name: source.name,
                    t: p.t.clone(),
                    record: p.record,
                    tick: p.tick,
                    ts_ms: self.ts_ms,
                    hint: source.hint,
                })));
            }
            *slot = Some(p.line);
        }
        Ok(grid)
    }

    /// The force offset, N: given, or the mean force up to each record's first pulse.
    fn offset(
        &self,
        segments: &[Segment],
        grid: &[Vec<Option<usize>>],
    ) -> Result<f64, ImportError> {
        let ts_ms = self.ts_ms;
        match self.opts.force_offset {
            Level::Given(o) => Ok(o),
            Level::Auto => {
                let (mut sum, mut n) = (0.0, 0usize);
                for (r, s) in segments.iter().enumerate() {
                    let first_pulse = grid[r].iter().position(Option::is_some);
                    let until = first_pulse.map_or(f64::INFINITY, |k| s.t[0] + k as f64 * ts_ms);
                    for (&t, &f) in s.t.iter().zip(&s.f) {
                        if t <= until + 1e-9 * ts_ms {
                            sum += f;
                            n += 1;
                        }
                    }
                }
                if n == 0 {
                    return Err(ImportError::Normalise {
                        path: self.path.to_path_buf(),
                        problem: "no sample at rest (before a record's first pulse) to estimate the force offset from; give the offset".into(),
                    });
                }
                Ok(sum / n as f64)
            }
        }
    }

    /// The force scale, N: given, or the largest offset-free sample.
    fn scale(&self, segments: &[Segment], offset_n: f64) -> Result<f64, ImportError> {
        match self.opts.force_scale {
            Level::Given(s) => Ok(s),
            Level::Auto => {
                let peak = segments
                    .iter()
                    .flat_map(|s| s.f.iter())
                    .map(|f| f - offset_n)
                    .fold(f64::NEG_INFINITY, f64::max);
                if peak.is_nan() || peak <= 0.0 {
                    return Err(ImportError::Normalise {
                        path: self.path.to_path_buf(),
                        problem: format!(
                            "no force above the offset {offset_n} N to scale by; give the scale"
                        ),
                    });
                }
                Ok(peak)
            }
        }
    }

    /// Refuses an input sample whose normalised force is out of the format's range.
    fn check_force_range(
        &self,
        segments: &[Segment],
        offset_n: f64,
        scale_n: f64,
    ) -> Result<(), ImportError> {
        for s in segments {
            for (j, &f) in s.f.iter().enumerate() {
                let v = (f - offset_n) / scale_n;
                if !(-FORCE_SLACK..=1.0 + FORCE_SLACK).contains(&v) {
                    return Err(ImportError::ForceRange {
                        path: self.path.to_path_buf(),
                        line: s.lines[j],
                        column: self.force_col + 1,
                        name: self.table.names[self.force_col].clone(),
                        newtons: f,
                        normalised: v,
                        offset_n,
                        scale_n,
                    });
                }
            }
        }
        Ok(())
    }

    /// The records on the grid: normalised force resampled, pulses from `grid`.
    fn resample(
        &self,
        segments: &[Segment],
        grid: &[Vec<Option<usize>>],
        offset_n: f64,
        scale_n: f64,
    ) -> Vec<Record> {
        let mut records = Vec::with_capacity(segments.len());
        let width = segments.len().saturating_sub(1).to_string().len().max(3);
        for (r, s) in segments.iter().enumerate() {
            let force = resample_force(s, self.ts_ms, offset_n, scale_n);
            let pulse = grid[r].iter().map(Option::is_some).collect();
            records.push(Record::uniform(
                format!("record_{r:0width$}.csv"),
                s.kind.clone(),
                self.opts.ts_s,
                pulse,
                force,
            ));
        }
        records
    }

    /// The validated data set of `records` (split as the options say) and its report.
    fn assemble(
        &self,
        segments: &[Segment],
        records: Vec<Record>,
        placed: &[Placed],
        offset_n: f64,
        scale_n: f64,
    ) -> Result<Imported, ImportError> {
        let split = make_split(&self.opts.split, records.len())?;
        let mut steps: Vec<f64> = segments
            .iter()
            .flat_map(|s| s.t.windows(2).map(|w| w[1] - w[0]))
            .collect();
        steps.sort_by(f64::total_cmp);
        let input_step_ms = steps.get(steps.len() / 2).copied().unwrap_or(f64::NAN);
        let max_pulse_shift_ms = placed.iter().map(|p| p.shift_ms).fold(0.0, f64::max);
        let report = ImportReport {
            lines: self.table.rows.len(),
            input_step_ms,
            pulses: placed.len(),
            max_pulse_shift_ms,
            offset_n,
            scale_n,
            record_lines: segments
                .iter()
                .map(|s| (s.lines[0], s.lines[s.lines.len() - 1]))
                .collect(),
        };
        let protocol = protocol_json(self.path, self.opts, &self.table, &report);
        let dataset = DataSet {
            header: Header {
                source: self.opts.source.clone(),
                preset: None,
                parameters: BTreeMap::new(),
                seed: None,
                noise: serde_json::Value::Null,
                protocol,
                scale_n,
                offset_n,
                ts_s: self.opts.ts_s,
                split,
            },
            records,
        };
        dataset.validate(Path::new("."))?;
        Ok(Imported { dataset, report })
    }
}

/// Why a pulse at `t` ms is in no record: before the first, in a gap, or after the last.
fn outside_records(segments: &[Segment], t: f64) -> String {
    let before = segments.iter().rposition(|s| s.t[0] <= t);
    match before {
        None => format!(
            "it is before the first record (from {} ms)",
            segments[0].t[0]
        ),
        Some(r) if r + 1 < segments.len() => format!(
            "it is in the gap after record {r} (to {} ms), before record {} (from {} ms)",
            segments[r].last_t(),
            r + 1,
            segments[r + 1].t[0]
        ),
        Some(r) => format!(
            "it is after the last record (to {} ms)",
            segments[r].last_t()
        ),
    }
}

/// Record `s`'s normalised force on its grid, interpolated linearly between its samples.
fn resample_force(s: &Segment, ts_ms: f64, offset_n: f64, scale_n: f64) -> Vec<f64> {
    let n = s.ticks;
    let mut force = Vec::with_capacity(n);
    let mut j = 0;
    let last = s.t.len() - 1;
    for k in 0..n {
        let t = (s.t[0] + k as f64 * ts_ms).min(s.t[last]);
        while j + 1 < last && s.t[j + 1] <= t {
            j += 1;
        }
        let (ta, tb) = (s.t[j], s.t[j + 1]);
        let w = ((t - ta) / (tb - ta)).clamp(0.0, 1.0);
        let f = if w == 0.0 {
            s.f[j]
        } else if w == 1.0 {
            s.f[j + 1]
        } else {
            s.f[j] + (s.f[j + 1] - s.f[j]) * w
        };
        force.push((f - offset_n) / scale_n);
    }
    force
}

fn check_options(o: &ImportOptions) -> Result<(), ImportError> {
    let bad = |option: &'static str, problem: String| Err(ImportError::Option { option, problem });
    if !(o.ts_s.is_finite() && o.ts_s > 0.0) {
        return bad("sample period", format!("{} s is not > 0", o.ts_s));
    }
    if let TimeSource::Rate { hz } = o.time
        && !(hz.is_finite() && hz > 0.0)
    {
        return bad("input rate", format!("{hz} Hz is not > 0"));
    }
    if !(o.force_gain.is_finite() && o.force_gain != 0.0) {
        return bad(
            "force gain",
            format!("{} is not a finite, non-zero factor", o.force_gain),
        );
    }
    if let Level::Given(v) = o.force_offset
        && !v.is_finite()
    {
        return bad("force offset", format!("{v} is not finite"));
    }
    if let Level::Given(v) = o.force_scale
        && !(v.is_finite() && v > 0.0)
    {
        return bad("force scale", format!("{v} is not a scale > 0 N"));
    }
    if let Some(g) = o.split_gap_s
        && !(g.is_finite() && g > 0.0)
    {
        return bad("split gap", format!("{g} s is not > 0"));
    }
    Ok(())
}

fn make_split(spec: &SplitSpec, n: usize) -> Result<Split, ImportError> {
    let err = |option: &'static str, problem: String| ImportError::Split {
        option,
        problem,
        count: n,
    };
    match spec {
        SplitSpec::Half => Ok(Split::first(n.div_ceil(2).min(n - 1), n)),
        SplitSpec::TrainFirst(k) => {
            if *k == 0 || *k >= n {
                Err(err(
                    "train records",
                    format!("{k} training records leave the train or the test split empty"),
                ))
            } else {
                Ok(Split::first(*k, n))
            }
        }
        SplitSpec::Test(list) => {
            let mut test = list.clone();
            test.sort_unstable();
            test.dedup();
            if test.len() != list.len() {
                return Err(err("test records", "a record is listed twice".into()));
            }
            if let Some(i) = test.iter().find(|&&i| i >= n) {
                return Err(err("test records", format!("record {i} does not exist")));
            }
            let train: Vec<usize> = (0..n).filter(|i| !test.contains(i)).collect();
            if train.is_empty() || test.is_empty() {
                return Err(err(
                    "test records",
                    "the train or the test split would be empty".into(),
                ));
            }
            Ok(Split { train, test })
        }
    }
}

/// The import's provenance, stored as the data set's `protocol`.
fn protocol_json(
    path: &Path,
    o: &ImportOptions,
    table: &Table,
    report: &ImportReport,
) -> serde_json::Value {
    let col = |c: &ColumnRef| serde_json::Value::String(c.to_string());
    let level = |l: Level| match l {
        Level::Given(v) => serde_json::json!(v),
        Level::Auto => serde_json::json!("auto"),
    };
    serde_json::json!({
        "kind": "import",
        "input": path.file_name().map(|n| n.to_string_lossy().into_owned()),
        "input_lines": report.lines,
        "input_step_ms": report.input_step_ms,
        "columns": table.names,
        "time": match &o.time {
            TimeSource::Column(c) => serde_json::json!({"column": col(c), "unit": o.time_unit.name()}),
            TimeSource::Rate { hz } => serde_json::json!({"rate_hz": hz}),
        },
        "force": {"column": col(&o.force), "gain_n": o.force_gain,
                  "offset_n": level(o.force_offset), "scale_n": level(o.force_scale)},
        "pulses": match &o.pulses {
            Pulses::Column { column, edges } => serde_json::json!({"column": col(column), "edges": edges}),
            Pulses::Times { path, times } => serde_json::json!({
                "times": path.file_name().map(|n| n.to_string_lossy().into_owned()),
                "count": times.len()}),
        },
        "max_pulse_shift_ms": report.max_pulse_shift_ms,
        "split_gap_s": o.split_gap_s,
        "record_column": o.record_column.as_ref().map(col),
    })
}
