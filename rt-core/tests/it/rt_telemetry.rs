//! Telemetry: the lock-free queue counts overflows instead of blocking, the histograms are
//! bounded and exact to their stated precision, and an interval log written by the
//! telemetry code is read back by hdrhistogram's own interval-log reader with equal counts.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::time::{Duration, SystemTime};

use base64::Engine;
use fes_rt::msg::{Contract, TimingSource};
use fes_rt::rt::histogram::LatencyHistogram;
use fes_rt::rt::hlog::{HlogWriter, merge_by_tag, read_intervals};
use fes_rt::rt::telemetry::{
    IntervalQuantities, TAG_COMPUTE, TAG_INPUT, TAG_PUBLISH, TAG_WAKE, TelemetryChannel,
    TickTiming, TimingAggregator,
};
use hdrhistogram::serialization::Deserializer;
use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};

/// HdrHistogram with 3 significant digits: any reported value is within 0.1 % of the truth.
fn close(got: u64, exact: u64) -> bool {
    (got as f64 - exact as f64).abs() <= exact as f64 * 1e-3
}

#[test]
fn quantiles_match_the_exact_order_statistics() {
    let mut h = LatencyHistogram::new();
    for v in 1..=100_000u64 {
        h.record(v);
    }
    assert_eq!(h.count(), 100_000);
    assert!(close(h.quantile_ns(0.5), 50_000), "{}", h.quantile_ns(0.5));
    assert!(close(h.quantile_ns(0.99), 99_000));
    assert!(close(h.quantile_ns(0.999), 99_900));
    assert!(close(h.max_ns(), 100_000));
    let s = h.summary();
    assert_eq!(s.count, 100_000);
    assert!(s.p50_ns <= s.p99_ns && s.p99_ns <= s.p999_ns && s.p999_ns <= s.max_ns);
}

#[test]
fn the_histogram_is_bounded_and_never_resizes() {
    let mut h = LatencyHistogram::new();
    let high = h.raw().high();
    let buckets = h.raw().distinct_values();
    h.record(0);
    h.record(3);
    h.record(20_000_000_000); // 20 s: above the range
    assert_eq!(h.count(), 3);
    assert_eq!(h.saturated(), 1);
    assert!(close(h.max_ns(), LatencyHistogram::HIGHEST_NS));
    assert_eq!(h.raw().high(), high);
    assert_eq!(h.raw().distinct_values(), buckets);
    let empty = LatencyHistogram::new().summary();
    assert_eq!((empty.count, empty.p99_ns, empty.max_ns), (0, 0, 0));
}

#[test]
fn a_full_queue_drops_and_counts_instead_of_blocking() {
    let channel = TelemetryChannel::new(16);
    for k in 0..20u64 {
        channel.push(TickTiming {
            grid_ns: k,
            ..TickTiming::default()
        });
    }
    assert_eq!(channel.overflows(), 4);
    let popped: Vec<u64> = std::iter::from_fn(|| channel.pop())
        .map(|t| t.grid_ns)
        .collect();
    assert_eq!(popped, (0..16).collect::<Vec<_>>());
}

#[test]
fn an_interval_log_reads_back_with_hdrhistograms_reader_and_the_counts_match() {
    let dir = fes_testkit::Scratch::new("rt-telemetry");
    let path = dir.join("telemetry.hlog");
    let mut log = HlogWriter::create(&path, "test", SystemTime::now()).unwrap();
    let mut agg = TimingAggregator::new();
    let channel = TelemetryChannel::new(4096);
    let per_interval = [1000u64, 250, 3];
    for (i, &n) in per_interval.iter().enumerate() {
        for k in 0..n {
            channel.push(TickTiming {
                grid_ns: k,
                lateness_ns: 10_000 + k,
                input_ns: 700,
                compute_ns: 2_000 + i as u64,
                publish_ns: 500,
            });
        }
        assert_eq!(agg.drain(&channel), n as usize);
        agg.write_interval(
            &mut log,
            Duration::from_secs(i as u64),
            Duration::from_secs(1),
        )
        .unwrap();
    }
    log.flush().unwrap();
    drop(log);

    // hdrhistogram's own reader, line by line.
    let bytes = std::fs::read(&path).unwrap();
    let mut deserializer = Deserializer::new();
    let mut counts: Vec<(String, u64, u64)> = Vec::new();
    for entry in IntervalLogIterator::new(&bytes) {
        if let LogEntry::Interval(ilh) = entry.unwrap() {
            let raw = base64::engine::general_purpose::STANDARD
                .decode(ilh.encoded_histogram())
                .unwrap();
            let h: hdrhistogram::Histogram<u64> = deserializer.deserialize(&mut &raw[..]).unwrap();
            counts.push((
                ilh.tag().unwrap().as_str().to_owned(),
                ilh.start_timestamp().as_secs(),
                h.len(),
            ));
        }
    }
    let mut expected = Vec::new();
    for (i, &n) in per_interval.iter().enumerate() {
        for tag in [TAG_WAKE, TAG_INPUT, TAG_COMPUTE, TAG_PUBLISH] {
            expected.push((tag.to_owned(), i as u64, n));
        }
    }
    assert_eq!(counts, expected);

    // Our reader agrees, and the merged distributions are the recorded ones.
    assert_eq!(read_intervals(&path).unwrap().len(), 12);
    let merged = merge_by_tag(&path).unwrap();
    let total: u64 = per_interval.iter().sum();
    assert_eq!(merged[TAG_WAKE].count(), total);
    assert!(close(merged[TAG_WAKE].max_ns(), 10_999));
    assert!(close(merged[TAG_PUBLISH].quantile_ns(0.5), 500));
    assert_eq!(agg.wake().count(), total);

    // The cumulative report carries the same counts and is itself valid.
    let report = agg.report(
        1,
        1,
        TimingSource::RtCore,
        &channel.counters.snapshot(),
        channel.overflows(),
        0,
    );
    assert_eq!(report.wake.count, total);
    report.validate().unwrap();
}
