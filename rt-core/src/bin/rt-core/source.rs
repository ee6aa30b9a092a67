//! The tick sources the process can run, chosen by the configuration's `[source]` table.

use std::time::Duration;

use anyhow::{Context, bail};
use fes_model::control::pattern_generator::FeedbackMode;
use rt_core::rt::process_config::SourceConfig;
use rt_core::rt::reference::Target;
use rt_core::rt::source::{ControllerSource, TestPattern, TickDecision, TickSource};

/// The configured source (static dispatch: one `match` per tick, no allocation).
#[allow(clippy::large_enum_variant)] // built once at start-up; never moved in the loop
pub enum Source {
    /// The deterministic bench pattern.
    TestPattern(TestPattern),
    /// The thesis's pattern generator.
    Controller(ControllerSource),
}

impl Source {
    /// Builds the source; a controller file is read and validated here, at start-up, and its
    /// feedback mode must agree with the configuration's `[feedback] enabled`.
    pub fn load(config: &SourceConfig, period: Duration, feedback: bool) -> anyhow::Result<Self> {
        match config {
            SourceConfig::TestPattern { ipi_ticks } => Ok(Source::TestPattern(
                TestPattern::new(*ipi_ticks).context("source")?,
            )),
            SourceConfig::Controller { path } => {
                let source = ControllerSource::load(path, period)
                    .with_context(|| format!("source.path {}", path.display()))?;
                let measured = source.mode() == FeedbackMode::MeasuredForce;
                if measured != feedback {
                    bail!(
                        "the controller's mode is {:?} but [feedback] enabled = {feedback}: \
                         measured_force needs enabled = true, model needs enabled = false",
                        source.mode()
                    );
                }
                Ok(Source::Controller(source))
            }
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
            Source::Controller(c) => format!(
                "pattern generator, {} unit(s), {:?} mode, min pulse gap {} ticks",
                c.units(),
                c.mode(),
                c.min_pulse_gap_ticks()
            ),
        }
    }
}

impl TickSource for Source {
    #[inline]
    fn tick(&mut self, target: &Target, measured_force: Option<f64>) -> TickDecision {
        match self {
            Source::TestPattern(p) => p.tick(target, measured_force),
            Source::Controller(c) => c.tick(target, measured_force),
        }
    }

    fn missed(&mut self, periods: u32, target: &Target) {
        match self {
            Source::TestPattern(p) => p.missed(periods, target),
            Source::Controller(c) => c.missed(periods, target),
        }
    }

    fn reset(&mut self) {
        match self {
            Source::TestPattern(p) => p.reset(),
            Source::Controller(c) => c.reset(),
        }
    }

    fn min_pulse_gap_ticks(&self) -> u32 {
        match self {
            Source::TestPattern(p) => p.min_pulse_gap_ticks(),
            Source::Controller(c) => c.min_pulse_gap_ticks(),
        }
    }

    fn summary(&self) -> Option<String> {
        match self {
            Source::TestPattern(p) => p.summary(),
            Source::Controller(c) => c.summary(),
        }
    }
}
