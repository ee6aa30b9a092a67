//! fes-can's integration tests, one binary: the DBC against the codec, the protocol table
//! of the docs, encode/decode round trips and the allocation-free hot path.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod dbc_consistency;
mod doc_table;
mod no_alloc;
mod reserved_bits;
mod roundtrip;
