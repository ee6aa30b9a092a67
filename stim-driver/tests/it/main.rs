//! stim-driver's integration tests, one binary: the forward path against a recording bus
//! and on the host bus (interlocks, watchdog, arming, trips), and the property tests of the
//! forward path and the interlocks; the ScienceMode transmit side and the driver binary on the ScienceMode
//! transport against the virtual RehaStim 2.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

#[path = "support/on_bus.rs"]
mod on_bus;
#[path = "support/on_serial.rs"]
mod on_serial;
#[path = "support/recording_bus.rs"]
mod recording_bus;

mod forward_path;
mod forward_props;
mod interlock_props;
mod serial_device;
mod serial_driver;
mod serial_probe;
