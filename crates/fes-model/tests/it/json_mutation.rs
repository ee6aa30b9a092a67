//! Mutations of a valid JSON document for the file-loader fuzz targets:
//! structural edits on the parsed tree (a number replaced by NaN / 1e308 / -1 / a huge
//! array..., a key dropped or duplicated) written back as text, then optionally a byte-level
//! edit (truncation, a flipped byte, an invalid UTF-8 sequence). The loaders must answer
//! every result with an error value or a model that passes validation, never a panic.

use proptest::prelude::*;
use serde_json::Value;
use std::fmt::Write as _;

/// Replacement texts for a number: not JSON (NaN, Infinity), out of range for f64 or for the
/// integer fields, negative, zero, subnormal, another type, and a 10 000-element array.
pub const NUMBER_REPLACEMENTS: &[&str] = &[
    "NaN",
    "Infinity",
    "-Infinity",
    "1e309",
    "1e308",
    "-1e308",
    "-1",
    "0",
    "-0.0",
    "5e-324",
    "4294967296",
    "18446744073709551616",
    "null",
    "\"1\"",
    "true",
    "[]",
    "{}",
    "HUGE_ARRAY",
];

/// One edit of a tree node, addressed by its pre-order index (numbers by their own index).
#[derive(Debug, Clone)]
pub enum Structural {
    /// Replace the `nth` number (modulo their count) with one of [`NUMBER_REPLACEMENTS`].
    ReplaceNumber { nth: usize, with: &'static str },
    /// Omit the `nth` node (modulo the node count) from its object or array.
    Drop { nth: usize },
    /// Write the `nth` node twice (a duplicated key in an object).
    Duplicate { nth: usize },
}

/// A byte-level edit applied to the written text; positions are per-mille of its length.
#[derive(Debug, Clone)]
pub enum Bytes {
    /// Keep only the first `at` per-mille of the bytes.
    Truncate { at: u16 },
    /// XOR one byte with a non-zero mask.
    Flip { at: u16, mask: u8 },
    /// Insert bytes that are not UTF-8 (a lone continuation byte, 0xFF, a cut sequence).
    InsertNonUtf8 { at: u16, which: u8 },
}

/// A complete mutation: up to three structural edits, then at most one byte-level edit.
#[derive(Debug, Clone)]
pub struct Mutation {
    pub structural: Vec<Structural>,
    pub bytes: Option<Bytes>,
}

fn structural() -> impl Strategy<Value = Structural> {
    prop_oneof![
        3 => (any::<usize>(), proptest::sample::select(NUMBER_REPLACEMENTS))
            .prop_map(|(nth, with)| Structural::ReplaceNumber { nth, with }),
        1 => any::<usize>().prop_map(|nth| Structural::Drop { nth }),
        1 => any::<usize>().prop_map(|nth| Structural::Duplicate { nth }),
    ]
}

fn bytes() -> impl Strategy<Value = Bytes> {
    prop_oneof![
        (0u16..1000).prop_map(|at| Bytes::Truncate { at }),
        (0u16..1000, 1u8..=255).prop_map(|(at, mask)| Bytes::Flip { at, mask }),
        (0u16..=1000, 0u8..3).prop_map(|(at, which)| Bytes::InsertNonUtf8 { at, which }),
    ]
}

/// Any mutation with at least one edit.
pub fn mutation() -> impl Strategy<Value = Mutation> {
    (
        proptest::collection::vec(structural(), 0..=3),
        proptest::option::of(bytes()),
    )
        .prop_filter("at least one edit", |(s, b)| !s.is_empty() || b.is_some())
        .prop_map(|(structural, bytes)| Mutation { structural, bytes })
}

/// Counts of the tree's nodes (pre-order, the root excluded) and of its numbers.
fn count(v: &Value, nodes: &mut usize, numbers: &mut usize) {
    let children: Vec<&Value> = match v {
        Value::Object(m) => m.values().collect(),
        Value::Array(a) => a.iter().collect(),
        Value::Number(_) => {
            *numbers += 1;
            return;
        }
        _ => return,
    };
    for c in children {
        *nodes += 1;
        count(c, nodes, numbers);
    }
}

struct Writer<'a> {
    /// (node index, edit) with indices already reduced modulo the counts.
    node_edits: Vec<(usize, &'a Structural)>,
    number_edits: Vec<(usize, &'static str)>,
    node: usize,
    number: usize,
    out: String,
}

impl Writer<'_> {
    fn value(&mut self, v: &Value) {
        match v {
            Value::Number(_) => {
                let k = self.number;
                self.number += 1;
                match self.number_edits.iter().find(|(i, _)| *i == k) {
                    Some((_, "HUGE_ARRAY")) => {
                        self.out.push('[');
                        self.out.push_str(&vec!["0.5"; 10_000].join(","));
                        self.out.push(']');
                    }
                    Some((_, with)) => self.out.push_str(with),
                    None => self.out.push_str(&v.to_string()),
                }
            }
            Value::Object(m) => {
                self.out.push('{');
                let mut first = true;
                for (k, c) in m {
                    self.child(c, Some(k), &mut first);
                }
                self.out.push('}');
            }
            Value::Array(a) => {
                self.out.push('[');
                let mut first = true;
                for c in a {
                    self.child(c, None, &mut first);
                }
                self.out.push(']');
            }
            other => self.out.push_str(&other.to_string()),
        }
    }

    /// Writes one member of an object or array: dropped, once, or twice (a duplicate
    /// repeats the very same subtree with its edits); then moves the counters past it.
    fn child(&mut self, c: &Value, key: Option<&str>, first: &mut bool) {
        let (idx, number) = (self.node, self.number);
        let copies = match self.node_edits.iter().find(|(i, _)| *i == idx) {
            Some((_, Structural::Drop { .. })) => 0,
            Some((_, Structural::Duplicate { .. })) => 2,
            _ => 1,
        };
        for _ in 0..copies {
            if !*first {
                self.out.push(',');
            }
            *first = false;
            if let Some(k) = key {
                let _ = write!(self.out, "{}:", Value::from(k));
            }
            (self.node, self.number) = (idx + 1, number);
            self.value(c);
        }
        let (mut nodes, mut numbers) = (1, 0);
        count(c, &mut nodes, &mut numbers);
        (self.node, self.number) = (idx + nodes, number + numbers);
    }
}

/// Applies `m` to the document `doc`, returning the bytes a loader would read.
pub fn apply(doc: &Value, m: &Mutation) -> Vec<u8> {
    let (mut nodes, mut numbers) = (0, 0);
    count(doc, &mut nodes, &mut numbers);
    let mut w = Writer {
        node_edits: Vec::new(),
        number_edits: Vec::new(),
        node: 0,
        number: 0,
        out: String::new(),
    };
    for s in &m.structural {
        match s {
            Structural::ReplaceNumber { nth, with } if numbers > 0 => {
                w.number_edits.push((nth % numbers, with));
            }
            Structural::Drop { nth } | Structural::Duplicate { nth } if nodes > 0 => {
                w.node_edits.push((nth % nodes, s));
            }
            _ => {}
        }
    }
    w.value(doc);
    let mut out = w.out.into_bytes();
    let at = |per_mille: u16, len: usize| len * usize::from(per_mille) / 1000;
    match m.bytes {
        Some(Bytes::Truncate { at: p }) => out.truncate(at(p, out.len())),
        Some(Bytes::Flip { at: p, mask }) if !out.is_empty() => {
            let i = at(p, out.len() - 1);
            out[i] ^= mask;
        }
        Some(Bytes::InsertNonUtf8 { at: p, which }) => {
            let bad: &[u8] = match which {
                0 => &[0x80],
                1 => &[0xFF],
                _ => &[0xE2, 0x82],
            };
            let i = at(p, out.len());
            out.splice(i..i, bad.iter().copied());
        }
        _ => {}
    }
    out
}

/// Tallies of a fuzz run, printed by each target so the executions are on record.
#[derive(Debug, Default)]
#[allow(dead_code)] // not every test that builds a mutation reads each field
pub struct Tally {
    /// Inputs tried.
    pub cases: usize,
    /// Inputs accepted (each then checked by the target).
    pub accepted: usize,
    /// Inputs rejected with an error value.
    pub rejected: usize,
    /// Inputs that were not UTF-8 (read through the file path).
    pub non_utf8: usize,
    /// Accepted inputs whose model or controller produced a non-finite output.
    pub non_finite: usize,
    /// The first such input, for the report.
    pub example: String,
}

/// Writes `bytes` to the target's scratch file in `dir` (a `fes_testkit::Scratch`).
pub fn scratch_file(dir: &std::path::Path, target: &str, bytes: &[u8]) -> std::path::PathBuf {
    let path = dir.join(format!("fuzz-{target}.json"));
    std::fs::write(&path, bytes).expect("scratch file");
    path
}
