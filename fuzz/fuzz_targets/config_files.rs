//! The three configuration-file parsers (rt-core, stim-driver, supervisor) on any text:
//! a configuration that passes its own validation, or an error; never a panic.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use rt_core::rt::process_config::RtCoreConfig;
use stim_driver::config::DriverConfig;
use supervisor::config::SupervisorConfig;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(c) = RtCoreConfig::parse(text) {
        c.validate()
            .expect("a parsed rt-core configuration validates");
    }
    if let Ok(c) = DriverConfig::parse(text) {
        c.validate()
            .expect("a parsed driver configuration validates");
        let _ = c.forward_settings();
    }
    let _ = SupervisorConfig::from_toml(text, Path::new("supervisor.toml"));
});
