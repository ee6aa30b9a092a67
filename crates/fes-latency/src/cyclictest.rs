//! Running `cyclictest` (rt-tests) and reading its histogram output.
//!
//! With `-h <max_us> -q`, cyclictest prints one line `<latency_us> <count>` per microsecond
//! bucket (latencies truncated to whole microseconds), then summary comments such as
//! `# Max Latencies: 00045` and `# Histogram Overflows: 00000`.

use std::process::Command;

use anyhow::{Context, bail};
use fes_rt::rt::histogram::LatencyHistogram;

/// cyclictest's result.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CyclictestHistogram {
    /// `counts[b]` = samples with latency in [b, b+1) µs.
    pub counts: Vec<u64>,
    /// Samples above the histogram range.
    pub overflows: u64,
    /// Largest latency, µs, from `# Max Latencies`.
    pub max_us: u64,
}

impl CyclictestHistogram {
    /// Parses cyclictest's `-h ... -q` output for one thread.
    pub fn parse(text: &str) -> anyhow::Result<Self> {
        let mut counts = Vec::new();
        let mut overflows = None;
        let mut max_us = None;
        for line in text.lines() {
            let line = line.trim();
            if let Some(rest) = line.strip_prefix('#') {
                let rest = rest.trim();
                if let Some(v) = rest.strip_prefix("Max Latencies:") {
                    max_us = Some(first_number(v).context("# Max Latencies")?);
                } else if let Some(v) = rest.strip_prefix("Histogram Overflows:") {
                    overflows = Some(first_number(v).context("# Histogram Overflows")?);
                }
                continue;
            }
            let mut fields = line.split_whitespace();
            let (Some(bucket), Some(count)) = (fields.next(), fields.next()) else {
                continue;
            };
            let (Ok(bucket), Ok(count)) = (bucket.parse::<usize>(), count.parse::<u64>()) else {
                continue;
            };
            if bucket != counts.len() {
                bail!("cyclictest histogram: bucket {bucket} out of sequence");
            }
            counts.push(count);
        }
        let (Some(overflows), Some(max_us)) = (overflows, max_us) else {
            bail!(
                "cyclictest output lacks '# Max Latencies' / '# Histogram Overflows' (was -h given?)"
            );
        };
        if counts.is_empty() {
            bail!("cyclictest output has no histogram lines");
        }
        Ok(Self {
            counts,
            overflows,
            max_us,
        })
    }

    /// Adds another run's counts (same bucket width; the longer histogram wins).
    pub fn merge(&mut self, other: &CyclictestHistogram) {
        if self.counts.len() < other.counts.len() {
            self.counts.resize(other.counts.len(), 0);
        }
        for (mine, theirs) in self.counts.iter_mut().zip(&other.counts) {
            *mine += theirs;
        }
        self.overflows += other.overflows;
        self.max_us = self.max_us.max(other.max_us);
    }

    /// Total samples (including overflows).
    pub fn total(&self) -> u64 {
        self.counts.iter().sum::<u64>() + self.overflows
    }

    /// Samples with latency >= `us`.
    pub fn at_least(&self, us: usize) -> u64 {
        self.counts.iter().skip(us).sum::<u64>() + self.overflows
    }

    /// The same samples as a [`LatencyHistogram`] in ns, each at the middle of its
    /// whole-microsecond bucket (`b + 0.5` µs, as the ratios compare), overflows at the
    /// maximum; written to `cyclictest.hlog` so that every curve is read the same way.
    #[expect(
        clippy::expect_used,
        reason = "the bounds are LatencyHistogram's constants, valid for HdrHistogram"
    )]
    pub fn to_latency_histogram(&self) -> LatencyHistogram {
        let mut raw = hdrhistogram::Histogram::<u64>::new_with_bounds(
            LatencyHistogram::LOWEST_NS,
            LatencyHistogram::HIGHEST_NS,
            LatencyHistogram::SIGNIFICANT_DIGITS,
        )
        .expect("constant HdrHistogram bounds are valid");
        let mut record = |ns: u64, n: u64| {
            if n > 0 {
                let _ = raw.record_n(ns.min(LatencyHistogram::HIGHEST_NS), n);
            }
        };
        for (bucket, &count) in self.counts.iter().enumerate() {
            record(bucket as u64 * 1000 + 500, count);
        }
        record(self.max_us * 1000, self.overflows);
        let mut h = LatencyHistogram::new();
        h.add_raw(&raw);
        h
    }

    /// The bucket (µs, truncated) holding quantile `q`; a quantile among the overflows
    /// reports the maximum.
    pub fn quantile_us(&self, q: f64) -> u64 {
        let total = self.total();
        if total == 0 {
            return 0;
        }
        let rank = ((q * total as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (bucket, &count) in self.counts.iter().enumerate() {
            seen += count;
            if seen >= rank {
                return bucket as u64;
            }
        }
        self.max_us
    }
}

fn first_number(text: &str) -> anyhow::Result<u64> {
    text.split_whitespace()
        .next()
        .context("no value")?
        .parse()
        .context("not a number")
}

/// The exact command run for the comparison.
pub fn command_line(
    priority: u8,
    core: usize,
    period_us: u64,
    seconds: u64,
    max_us: u64,
) -> Vec<String> {
    [
        "cyclictest".to_owned(),
        "-m".to_owned(),
        "-t1".to_owned(),
        "-p".to_owned(),
        priority.to_string(),
        "-a".to_owned(),
        core.to_string(),
        "-i".to_owned(),
        period_us.to_string(),
        "-D".to_owned(),
        format!("{seconds}s"),
        "-h".to_owned(),
        max_us.to_string(),
        "-q".to_owned(),
    ]
    .into()
}

/// Runs cyclictest and returns its raw output.
pub fn run(args: &[String]) -> anyhow::Result<String> {
    let out = Command::new(&args[0])
        .args(&args[1..])
        .output()
        .with_context(|| format!("running {} (install rt-tests: scripts/setup)", args[0]))?;
    if !out.status.success() {
        bail!(
            "cyclictest failed ({}): {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}
