//! The tick sources the process can run, chosen by the configuration's `[source]` table.

use std::time::Duration;

use anyhow::{Context, bail};
use rt_core::rt::process_config::SourceConfig;
use rt_core::rt::source::{TestPattern, TickDecision, TickSource};

/// The configured source (static dispatch: one `match` per tick, no allocation).
pub enum Source {
    /// The deterministic bench pattern.
    TestPattern(TestPattern),
}

impl Source {
    /// Builds the source; a controller file is read and validated here, at start-up.
    pub fn load(config: &SourceConfig, _period: Duration) -> anyhow::Result<Self> {
        match config {
            SourceConfig::TestPattern { ipi_ticks } => Ok(Source::TestPattern(
                TestPattern::new(*ipi_ticks).context("source")?,
            )),
            SourceConfig::Controller { path } => bail!(
                "source.kind = \"controller\" ({}): this build has no pattern generator \
                 (the control library is not merged yet); use kind = \"test-pattern\"",
                path.display()
            ),
        }
    }

    /// One line for the start-up log.
    pub fn describe(&self) -> String {
        match self {
            Source::TestPattern(p) => {
                format!(
                    "test pattern (pulse every {} ticks)",
                    p.min_pulse_gap_ticks()
                )
            }
        }
    }
}

impl TickSource for Source {
    fn tick(&mut self, reference: f64, measured_force: Option<f64>) -> TickDecision {
        match self {
            Source::TestPattern(p) => p.tick(reference, measured_force),
        }
    }

    fn reset(&mut self) {
        match self {
            Source::TestPattern(p) => p.reset(),
        }
    }

    fn min_pulse_gap_ticks(&self) -> u32 {
        match self {
            Source::TestPattern(p) => p.min_pulse_gap_ticks(),
        }
    }
}
