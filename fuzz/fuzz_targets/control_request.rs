//! The supervisor's control-socket request parser on any line: an error, or a request
//! that writes back to a line parsing to the same request.
#![no_main]

use libfuzzer_sys::fuzz_target;
use supervisor::protocol::parse_request;

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = parse_request(data) {
        let line = serde_json::to_string(&r).expect("a request serialises");
        let back = parse_request(line.as_bytes()).expect("a written request parses");
        assert_eq!(back, r);
    }
});
