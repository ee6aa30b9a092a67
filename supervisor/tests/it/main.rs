//! supervisor's integration tests, one binary: bad input from the bus, the control protocol's
//! parser, the control and stop sockets against a running daemon, and the health rules'
//! properties.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod bad_input_bus;
mod command_link_props;
mod control_protocol;
mod control_socket;
mod health_props;
