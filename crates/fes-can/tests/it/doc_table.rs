//! `docs/can-protocol.md` carries the protocol table generated from `dbc/fes.dbc`; this
//! test regenerates it from the DBC (parsed by `can-dbc`) and fails if the document
//! differs, so the document cannot drift from the DBC.
//!
//! Regenerate after changing the DBC:
//! `FES_CAN_BLESS=1 cargo test -p fes-can --lib doc_table::`
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use can_dbc::{Dbc, MessageId, MultiplexIndicator, NumericValue, ValueType};
use std::fmt::Write as _;
use std::path::PathBuf;

const BEGIN: &str = "<!-- BEGIN GENERATED from crates/fes-can/dbc/fes.dbc; regenerate: FES_CAN_BLESS=1 cargo test -p fes-can --lib doc_table:: -->";
const END: &str = "<!-- END GENERATED -->";

fn doc_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/can-protocol.md")
}

fn num(v: &NumericValue) -> String {
    match *v {
        NumericValue::Uint(u) => u.to_string(),
        NumericValue::Int(i) => i.to_string(),
        NumericValue::Double(d) => d.to_string(),
    }
}

fn raw_id(id: MessageId) -> u32 {
    match id {
        MessageId::Standard(s) => u32::from(s),
        MessageId::Extended(e) => e,
    }
}

fn cell(text: &str) -> String {
    text.replace('|', "\\|")
}

/// The generated block: one table row per message followed by one per signal, then
/// the value tables.
fn render(dbc: &Dbc) -> String {
    let mut out = String::new();
    out.push_str("| COB-ID | Message | Direction | DLC | Cycle | Signal | Bits | Type | Factor | Range | Unit | Meaning |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let mut messages: Vec<_> = dbc.messages.iter().collect();
    messages.sort_by_key(|m| raw_id(m.id));
    for m in &messages {
        let cycle = match dbc.message_attribute(m.id, "GenMsgCycleTime") {
            Some(can_dbc::AttributeValue::Uint(v)) if *v > 0 => format!("{v} ms"),
            Some(can_dbc::AttributeValue::Int(v)) if *v > 0 => format!("{v} ms"),
            _ => "event".to_string(),
        };
        let sender = m.transmitter.clone().unwrap_or_else(|| "?".into());
        let receivers = m
            .signals
            .first()
            .map(|s| s.receivers.join(", "))
            .unwrap_or_default();
        let _ = writeln!(
            out,
            "| 0x{:03X} | **{}** | {} → {} | {} | {} | | | | | | | {} |",
            raw_id(m.id),
            m.name,
            sender,
            receivers,
            m.size,
            cycle,
            cell(dbc.message_comment(m.id).unwrap_or(""))
        );
        for s in &m.signals {
            let name = match s.multiplexer_indicator {
                MultiplexIndicator::Multiplexor => format!("{} (multiplexor)", s.name),
                MultiplexIndicator::MultiplexedSignal(p) => format!("{} (page {p})", s.name),
                _ => s.name.clone(),
            };
            let ty = format!(
                "{}{}",
                if s.value_type == ValueType::Signed {
                    "i"
                } else {
                    "u"
                },
                s.size
            );
            let _ = writeln!(
                out,
                "| | | | | | `{}` | {}-{} | {} | {} | {} … {} | {} | {} |",
                name,
                s.start_bit,
                s.start_bit + s.size - 1,
                ty,
                s.factor,
                num(&s.min),
                num(&s.max),
                cell(&s.unit),
                cell(dbc.signal_comment(m.id, &s.name).unwrap_or(""))
            );
        }
    }
    out.push_str("\nValue tables (`VAL_`):\n\n");
    for m in &messages {
        for s in &m.signals {
            if let Some(values) = dbc.value_descriptions_for_signal(m.id, &s.name) {
                let wide = values.iter().any(|v| v.id > 255);
                let list: Vec<String> = values
                    .iter()
                    .map(|v| {
                        if wide {
                            format!("0x{:04X} `{}`", v.id, v.description)
                        } else {
                            format!("{} `{}`", v.id, v.description)
                        }
                    })
                    .collect();
                let _ = writeln!(out, "- `{}.{}`: {}", m.name, s.name, list.join(", "));
            }
        }
    }
    out
}

#[test]
fn protocol_table_in_docs_matches_the_dbc() {
    let dbc = Dbc::try_from(fes_can::DBC).expect("fes.dbc parses");
    let generated = render(&dbc);
    let path = doc_path();
    let doc = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    let (Some(b), Some(e)) = (doc.find(BEGIN), doc.find(END)) else {
        panic!(
            "{} lacks the generated-table markers:\n{BEGIN}\n...\n{END}",
            path.display()
        );
    };
    let start = b + BEGIN.len() + 1;
    let current = &doc[start.min(e)..e];
    if current == generated {
        return;
    }
    if std::env::var_os("FES_CAN_BLESS").is_some() {
        let updated = format!("{}{}{}", &doc[..start], generated, &doc[e..]);
        std::fs::write(&path, updated)
            .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
        eprintln!("regenerated the protocol table in {}", path.display());
        return;
    }
    let first_diff = current
        .lines()
        .zip(generated.lines())
        .position(|(a, b)| a != b)
        .unwrap_or(current.lines().count().min(generated.lines().count()));
    panic!(
        "{} is out of date with fes.dbc (first differing line {}):\n  doc: {:?}\n  dbc: {:?}\n\
         regenerate with: FES_CAN_BLESS=1 cargo test -p fes-can --lib doc_table::",
        path.display(),
        first_diff + 1,
        current.lines().nth(first_diff),
        generated.lines().nth(first_diff)
    );
}
