//! The codec's descriptor table must say exactly what `dbc/fes.dbc` says: every message
//! (COB-ID, name, DLC, cycle time, sender, receivers) and every signal (start bit, length,
//! byte order, signedness, factor, offset, min, max, unit, multiplexing, value table).
//! The DBC is parsed by an independent parser (`can-dbc`).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use can_dbc::{ByteOrder as DbcOrder, Dbc, MessageId, MultiplexIndicator, NumericValue, ValueType};
use fes_can::desc::{ByteOrder, Mux, SignalDesc};
use fes_can::{MessageKind, Nodes};

fn dbc() -> Dbc {
    Dbc::try_from(fes_can::DBC).expect("fes.dbc parses")
}

fn num(v: &NumericValue) -> f64 {
    match *v {
        NumericValue::Uint(u) => u as f64,
        NumericValue::Int(i) => i as f64,
        NumericValue::Double(d) => d,
    }
}

fn cycle_time(dbc: &Dbc, id: MessageId) -> Option<u16> {
    match dbc.message_attribute(id, "GenMsgCycleTime")? {
        can_dbc::AttributeValue::Uint(0) | can_dbc::AttributeValue::Int(0) => None,
        can_dbc::AttributeValue::Uint(v) => Some(u16::try_from(*v).expect("cycle fits u16")),
        can_dbc::AttributeValue::Int(v) => Some(u16::try_from(*v).expect("cycle fits u16")),
        other => panic!("GenMsgCycleTime of {id:?} is {other:?}"),
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs()).max(1.0)
}

fn check_signal(msg: &str, ours: &SignalDesc, theirs: &can_dbc::Signal, receiver: &str) {
    let at = format!("{msg}.{}", ours.name);
    assert_eq!(theirs.name, ours.name, "{at}: name/order");
    assert_eq!(
        theirs.start_bit,
        u64::from(ours.start_bit),
        "{at}: start bit"
    );
    assert_eq!(theirs.size, u64::from(ours.length), "{at}: length");
    let order = match theirs.byte_order {
        DbcOrder::LittleEndian => ByteOrder::LittleEndian,
        DbcOrder::BigEndian => ByteOrder::BigEndian,
    };
    assert_eq!(order, ours.byte_order, "{at}: byte order");
    assert_eq!(
        theirs.value_type == ValueType::Signed,
        ours.signed,
        "{at}: signedness"
    );
    assert!(
        close(theirs.factor, ours.factor),
        "{at}: factor {} vs {}",
        theirs.factor,
        ours.factor
    );
    assert!(close(theirs.offset, ours.offset), "{at}: offset");
    assert!(
        close(num(&theirs.min), ours.min),
        "{at}: min {:?} vs {}",
        theirs.min,
        ours.min
    );
    assert!(
        close(num(&theirs.max), ours.max),
        "{at}: max {:?} vs {}",
        theirs.max,
        ours.max
    );
    assert_eq!(theirs.unit, ours.unit, "{at}: unit");
    let mux = match theirs.multiplexer_indicator {
        MultiplexIndicator::Plain => Mux::Plain,
        MultiplexIndicator::Multiplexor => Mux::Multiplexor,
        MultiplexIndicator::MultiplexedSignal(p) => {
            Mux::Page(u8::try_from(p).expect("page fits u8"))
        }
        MultiplexIndicator::MultiplexorAndMultiplexedSignal(_) => {
            panic!("{at}: nested multiplexing unsupported")
        }
    };
    assert_eq!(mux, ours.mux, "{at}: multiplexing");
    assert_eq!(
        theirs.receivers,
        vec![receiver.to_string()],
        "{at}: receivers"
    );
}

#[test]
fn every_message_and_signal_matches_the_dbc() {
    let dbc = dbc();
    let nodes = Nodes::DEFAULT;
    assert_eq!(
        dbc.messages.len(),
        MessageKind::ALL.len(),
        "DBC and codec list the same number of messages"
    );
    for kind in MessageKind::ALL {
        let ours = kind.desc();
        let id = MessageId::Standard(nodes.id_of(kind));
        let theirs = dbc
            .messages
            .iter()
            .find(|m| m.id == id)
            .unwrap_or_else(|| panic!("{} ({id:?}) missing from fes.dbc", ours.name));
        assert_eq!(theirs.name, ours.name, "{id:?}: name");
        assert_eq!(theirs.size, u64::from(ours.dlc), "{}: DLC", ours.name);
        assert_eq!(
            theirs.transmitter.as_deref(),
            Some(ours.sender.dbc_name()),
            "{}: sender",
            ours.name
        );
        assert_eq!(
            cycle_time(&dbc, id),
            ours.cycle_time_ms,
            "{}: GenMsgCycleTime",
            ours.name
        );
        assert_eq!(
            theirs.signals.len(),
            ours.signals.len(),
            "{}: signal count",
            ours.name
        );
        for (o, t) in ours.signals.iter().zip(&theirs.signals) {
            check_signal(ours.name, o, t, ours.receiver.dbc_name());
        }
    }
}

#[test]
fn value_tables_match_the_dbc() {
    let dbc = dbc();
    let nodes = Nodes::DEFAULT;
    let mut codec_tables = 0;
    for kind in MessageKind::ALL {
        let id = MessageId::Standard(nodes.id_of(kind));
        for s in kind.desc().signals {
            let theirs: Vec<(i64, String)> = dbc
                .value_descriptions_for_signal(id, s.name)
                .unwrap_or(&[])
                .iter()
                .map(|v| (v.id, v.description.clone()))
                .collect();
            let ours: Vec<(i64, String)> = s
                .values
                .iter()
                .map(|&(v, n)| (i64::try_from(v).expect("value fits i64"), n.to_string()))
                .collect();
            assert_eq!(theirs, ours, "{}.{}: value table", kind.name(), s.name);
            codec_tables += usize::from(!ours.is_empty());
        }
    }
    let dbc_tables = dbc.value_descriptions.len();
    assert_eq!(
        codec_tables, dbc_tables,
        "every VAL_ in the DBC belongs to a codec signal"
    );
}

#[test]
fn nodes_and_comments_are_complete() {
    let dbc = dbc();
    let names: Vec<&str> = dbc.nodes.iter().map(|n| n.0.as_str()).collect();
    assert_eq!(names, ["HOST", "STIM"]);
    for m in &dbc.messages {
        assert!(
            dbc.message_comment(m.id).is_some_and(|c| !c.is_empty()),
            "{}: CM_ BO_ missing",
            m.name
        );
        for s in &m.signals {
            assert!(
                dbc.signal_comment(m.id, &s.name).is_some(),
                "{}.{}: CM_ SG_ missing",
                m.name,
                s.name
            );
        }
    }
}
