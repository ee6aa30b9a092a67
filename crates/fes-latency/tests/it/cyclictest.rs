//! cyclictest's histogram output read by `fes_latency::cyclictest`.

use fes_latency::cyclictest::*;

const SAMPLE: &str = "\
# /dev/cpu_dma_latency set to 0us
# Histogram
000000 000000
000001 000010
000002 000070
000003 000015
000004 000004
# Total: 000000100
# Min Latencies: 00001
# Avg Latencies: 00002
# Max Latencies: 00009
# Histogram Overflows: 00001
# Histogram Overflow at cycle number:
# Thread 0: 00042
";

#[test]
fn parses_the_histogram_and_its_summary() {
    let h = CyclictestHistogram::parse(SAMPLE).unwrap();
    assert_eq!(h.counts, vec![0, 10, 70, 15, 4]);
    assert_eq!((h.overflows, h.max_us, h.total()), (1, 9, 100));
    // Ranks by hand: 50th sample is in bucket 2 (10 < 50 <= 80), 99th in bucket 4
    // (95 < 99 <= 99), 100th (p99.9 -> rank 100) is the overflow: the maximum.
    assert_eq!(h.quantile_us(0.5), 2);
    assert_eq!(h.quantile_us(0.99), 4);
    assert_eq!(h.quantile_us(0.999), 9);
    assert_eq!(h.at_least(3), 20);
}

#[test]
fn merged_runs_add_their_counts() {
    let mut a = CyclictestHistogram::parse(SAMPLE).unwrap();
    let b = CyclictestHistogram {
        counts: vec![1, 0, 0, 0, 0, 0, 3],
        overflows: 2,
        max_us: 40,
    };
    a.merge(&b);
    assert_eq!(a.counts, vec![1, 10, 70, 15, 4, 0, 3]);
    assert_eq!((a.overflows, a.max_us, a.total()), (3, 40, 106));
}

#[test]
fn output_without_a_histogram_is_an_error() {
    assert!(CyclictestHistogram::parse("# Max Latencies: 00010\n").is_err());
    assert!(CyclictestHistogram::parse("000000 1\n000001 2\n").is_err());
}
