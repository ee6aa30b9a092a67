//! The rt-core configuration file: documented defaults, round trip, path resolution.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::PathBuf;

use fes_rt::rt::config_file::FileError;
use fes_rt::rt::{MissingRightsPolicy, RtConfig};
use rt_core::rt::process_config::{ConfigError, RtCoreConfig, SCHEMA, SourceConfig};

#[test]
fn a_minimal_file_gets_the_documented_defaults() {
    let c = RtCoreConfig::parse(
        "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 5\n",
    )
    .unwrap();
    assert_eq!(c.schema, SCHEMA);
    assert_eq!(c.period_us, 1000);
    assert_eq!(c.source, SourceConfig::TestPattern { ipi_ticks: 5 });
    assert_eq!(
        c.rt,
        RtConfig {
            priority: 80,
            core: None,
            on_missing_rights: MissingRightsPolicy::BestEffort,
            lock_memory: true,
            prefault_stack_bytes: 256 * 1024,
            cpu_dma_latency_us: Some(0),
        }
    );
    assert_eq!(
        (c.reference.stale_after_ms, c.reference.stale_ramp_per_s),
        (100, 2.0)
    );
    assert!(!c.feedback.enabled);
    assert_eq!(
        (c.pulse.channel, c.pulse.amplitude_ua, c.pulse.width_us),
        (0, 20_000, 200)
    );
    assert_eq!(c.telemetry.hlog, None);
    assert_eq!(
        (c.telemetry.report_period_ms, c.telemetry.queue_capacity),
        (1000, 8192)
    );
    assert_eq!((c.ipc.prefix.as_str(), c.ipc.own.notify), ("fes", true));
    assert_eq!(c.reference_policy().stale_after_ns, 100_000_000);
    assert_eq!(c.feedback_max_age_ns(), None);
}

#[test]
fn serialised_configurations_parse_back_identically() {
    let mut c = RtCoreConfig::with_source(SourceConfig::Controller {
        path: PathBuf::from("/etc/fes/fast.json"),
    });
    c.rt.core = Some(1);
    c.rt.on_missing_rights = MissingRightsPolicy::Refuse;
    c.telemetry.hlog = Some(PathBuf::from("/var/log/fes/rt-core.hlog"));
    c.feedback.enabled = true;
    assert_eq!(RtCoreConfig::parse(&c.to_toml()).unwrap(), c);
    let plain = RtCoreConfig::with_source(SourceConfig::TestPattern { ipi_ticks: 9 });
    assert_eq!(RtCoreConfig::parse(&plain.to_toml()).unwrap(), plain);
}

#[test]
fn a_relative_controller_path_is_relative_to_the_file() {
    let dir = fes_testkit::Scratch::new("rt-config");
    let path = dir.join("rt-core.toml");
    std::fs::write(
        &path,
        "schema = \"fes-rt-core/1\"\n[source]\nkind = \"controller\"\npath = \"ctrl/fast.json\"\n",
    )
    .unwrap();
    let c = RtCoreConfig::load(&path).unwrap();
    assert_eq!(
        c.source,
        SourceConfig::Controller {
            path: dir.join("ctrl/fast.json")
        }
    );
}

#[test]
fn errors_name_the_problem() {
    let base = "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 5\n";
    let err = |extra: &str| RtCoreConfig::parse(&format!("{base}{extra}")).unwrap_err();
    assert!(matches!(
        err("[reference]\nstale_ramp_per_s = nan\n"),
        ConfigError::File(FileError::Range {
            field: "reference.stale_ramp_per_s",
            ..
        })
    ));
    assert!(matches!(
        err("[telemetry]\nqueue_capacity = 4\n"),
        ConfigError::File(FileError::Range {
            field: "telemetry.queue_capacity",
            ..
        })
    ));
    assert!(matches!(
        err("[pulse]\nchannel = 16\n"),
        ConfigError::File(FileError::Range {
            field: "pulse.channel",
            ..
        })
    ));
    assert!(matches!(
        err("[pulse]\nwidth_us = 0\n"),
        ConfigError::File(FileError::Range {
            field: "pulse.width_us",
            ..
        })
    ));
    assert!(matches!(
        err("[feedback]\nmax_age_ms = 0\n"),
        ConfigError::File(FileError::Range {
            field: "feedback.max_age_ms",
            ..
        })
    ));
    assert!(matches!(
        err("[rt]\nprefault_stack_bytes = 99999999\n"),
        ConfigError::Rt(_)
    ));
    assert!(matches!(
        err("[rt]\npriority = 80\nnice = 3\n"),
        ConfigError::File(FileError::Parse { .. })
    ));
    let wrong_kind =
        RtCoreConfig::parse("schema = \"fes-rt-core/1\"\n[source]\nkind = \"magic\"\n")
            .unwrap_err();
    assert!(wrong_kind.to_string().contains("magic"), "{wrong_kind}");
    let unreadable =
        RtCoreConfig::load(std::path::Path::new("/nonexistent/rt-core.toml")).unwrap_err();
    assert!(unreadable.to_string().contains("/nonexistent/rt-core.toml"));
}
