//! The system tests, one binary: the test harness itself, interop with python-can and
//! cantools, pyScienceMode as a peer of the ScienceMode 2 codec and as the host of the
//! virtual RehaStim 2 on a pty, the virtual stimulator on vcan and its allocation-free
//! tick, the driver's allocation-free ScienceMode sides, the systemd units (static checks,
//! and the boot test in a VM) and the Debian packages. The latency tools' tests are
//! fes-latency's.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod common;
mod systemd_support;

mod harness;
mod hostbus;
mod interop;
mod package;
mod rehastim2_pty;
mod safety_traceability;
mod sciencemode_no_alloc;
mod sciencemode_peer;
mod stimulator_no_alloc;
mod stimulator_vcan;
mod systemd_units;
