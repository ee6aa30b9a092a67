//! `stim-driver probe` against the virtual RehaStim 2 on a pty: it answers the device's
//! Init, times one command at a time, and suggests the transport's minimum interval from
//! the answers; it provokes no -8 and delivers no charge.

use fes_testkit::Scratch;
use stim_driver::probe::{ProbeSettings, probe};

use crate::on_serial::{Device, DeviceOptions};

fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("stim-driver-probe-{name}"))
}

/// A device processing each command for 5-15 ms (3 % for 100 ms, `--processing-ms 10`):
/// every command answered, none busy, the median answer within the processing time plus
/// the device's 1 ms tick, the suggestion the 90th percentile rounded up; the zero-current
/// pulses are answered like the queries and carry no current.
#[test]
fn probe_times_the_answers_one_at_a_time_and_suggests_the_interval() {
    let dir = scratch("busy");
    let mut device = Device::start(
        &dir,
        DeviceOptions {
            processing_ms: 10,
            ..DeviceOptions::default()
        },
    );
    let settings = ProbeSettings {
        commands: 120,
        zero_pulses: true,
        ..ProbeSettings::default()
    };
    let mut done = 0;
    let r = probe(&device.link, &settings, |k| done = k).unwrap();
    assert_eq!(done, 120);
    assert_eq!((r.busy, r.lost, r.errors.len()), (0, 0, 0), "{r:?}");
    assert_eq!(r.answer_ms.len(), 120);
    let p50 = r.quantile_ms(0.5).unwrap();
    assert!((4.0..=18.0).contains(&p50), "median {p50} ms");
    let max = *r.answer_ms.last().unwrap();
    assert!(max <= 110.0, "longest {max} ms");
    let (p90, p99) = (r.quantile_ms(0.9).unwrap(), r.quantile_ms(0.99).unwrap());
    assert_eq!(r.min_interval_ms(), Some(p90.ceil() as u32));
    // Nine in ten answers within the processing time's range, not the slow ones'.
    assert!(p90 <= 18.0, "p90 {p90} ms");
    let summary = device.stop().unwrap();
    assert_eq!((summary.busy_sent, summary.wrong_mode_sent), (0, 0));
    assert!(
        device.pulses().iter().all(|p| p.current_ma == 0),
        "no charge"
    );
    println!(
        "probe, --processing-ms 10: median {p50:.1} ms, p99 {p99:.1} ms, longest {max:.1} ms: min_interval_ms {:?}",
        r.min_interval_ms()
    );
}

/// A device answering at once: the answers take the line and the device's tick, a few ms.
#[test]
fn probe_of_a_prompt_device_suggests_a_few_ms() {
    let dir = scratch("prompt");
    let mut device = Device::start(&dir, DeviceOptions::default());
    let settings = ProbeSettings {
        commands: 50,
        ..ProbeSettings::default()
    };
    let r = probe(&device.link, &settings, |_| {}).unwrap();
    assert_eq!((r.busy, r.lost), (0, 0));
    let suggested = r.min_interval_ms().unwrap();
    assert!((1..=10).contains(&suggested), "{r:?}");
    device.stop();
}

/// No device answering: a clear error naming the wait, not a hang.
#[test]
fn probe_without_an_init_says_so() {
    let pty = nix::pty::openpty(None, None).unwrap();
    let path = nix::unistd::ttyname(&pty.slave).unwrap();
    let settings = ProbeSettings {
        init_timeout: std::time::Duration::from_millis(300),
        ..ProbeSettings::default()
    };
    let e = probe(&path, &settings, |_| {}).unwrap_err().to_string();
    assert!(e.contains("no Init") && e.contains("stim-driver"), "{e}");
}
