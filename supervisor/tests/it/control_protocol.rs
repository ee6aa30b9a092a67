//! The control protocol's parser never panics and refuses what it cannot read.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use proptest::prelude::*;
use supervisor::protocol::{
    Command, ProtocolError, Request, VERSION, parse_request, parse_response,
};

fn command() -> impl Strategy<Value = Command> {
    prop_oneof![
        Just(Command::Status),
        Just(Command::Stop),
        Just(Command::Arm),
        any::<bool>().prop_map(|enabled| Command::OuterLoop { enabled }),
        (-2.0f64..2.0, proptest::option::of(0.0f64..100.0))
            .prop_map(|(force, rate_per_s)| Command::Set { force, rate_per_s }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// Arbitrary bytes: an error or a request, never a panic.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let _ = parse_request(&bytes);
        let _ = parse_response(&bytes);
    }

    /// JSON-alphabet text (more likely to get deep into the parser) never panics either.
    #[test]
    fn json_like_text_never_panics(s in r#"[{}\[\]":,0-9a-z_. eE+-]{0,200}"#) {
        let _ = parse_request(s.as_bytes());
    }

    /// Every well-formed request reads back as itself; a mutated one is either refused or
    /// a valid request (never a panic).
    #[test]
    fn requests_round_trip_and_mutations_are_safe(
        c in command(),
        id in any::<u64>(),
        flip in any::<proptest::sample::Index>(),
        byte in any::<u8>(),
    ) {
        let r = Request { v: VERSION, id, command: c };
        let line = serde_json::to_vec(&r).unwrap();
        prop_assert_eq!(parse_request(&line).unwrap(), r);
        let mut m = line.clone();
        let i = flip.index(m.len());
        m[i] = byte;
        let _ = parse_request(&m);
    }
}

#[test]
fn oversized_and_wrong_version_requests_are_refused_by_name() {
    let long = vec![b' '; supervisor::protocol::MAX_LINE + 1];
    assert!(matches!(
        parse_request(&long).unwrap_err(),
        ProtocolError::TooLong
    ));
    let e = parse_request(br#"{"v":7,"command":{"kind":"status"}}"#).unwrap_err();
    assert_eq!(
        e.to_string(),
        "protocol version 7 is not supported (this supervisor speaks version 1)"
    );
    let e = parse_request(br#"{"command":{"kind":"status"}}"#).unwrap_err();
    assert!(matches!(e, ProtocolError::NoVersion), "{e}");
    assert!(
        e.to_string().contains("missing or non-integer field `v`"),
        "{e}"
    );
}
