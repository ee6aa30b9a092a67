//! The two muscles of the thesis (5.2.1) as Ding-model parameter sets.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::ding::DingParams;

/// A documented parameter set standing in for one of the thesis's rabbit muscles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The control muscle: fast twitch with a strong catch-like effect (thesis Fig. 6.3(a):
    /// short high-frequency bursts raise FTIpP above 1).
    Fast,
    /// The chronically stimulated muscle (10 Hz for 4 weeks): slower, no catch-like gain
    /// (thesis Fig. 6.3(b), 6.4(b): the best FTIpP is a single pulse).
    Slow,
}

/// `--preset` named no known preset.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown preset `{0}`; known presets: fast, slow")]
pub struct UnknownPreset(pub String);

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 2] = [Preset::Fast, Preset::Slow];

    /// The preset's name as used on the command line and in data sets.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Fast => "fast",
            Preset::Slow => "slow",
        }
    }

    /// The rested force-model parameters; see `docs/sim-muscle.md` for each value's source.
    pub fn params(self) -> DingParams {
        match self {
            Preset::Fast => DingParams {
                tauc: 0.010,
                r0: 8.0,
                km: 0.3,
                a: 6000.0,
                tau1: 0.030,
                tau2: 0.060,
            },
            Preset::Slow => DingParams {
                tauc: 0.020,
                r0: 1.0,
                km: 0.103,
                a: 3009.0,
                tau1: 0.090,
                tau2: 0.0,
            },
        }
    }

    /// Record length of the thesis protocol, ms (5.2.1: 590 fast, 600 slow).
    pub fn record_ms(self) -> u32 {
        match self {
            Preset::Fast => 590,
            Preset::Slow => 600,
        }
    }

    /// Number of records of the thesis protocol (5.2.1: 60 fast, 84 slow).
    pub fn records(self) -> usize {
        match self {
            Preset::Fast => 60,
            Preset::Slow => 84,
        }
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Preset {
    type Err = UnknownPreset;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fast" => Ok(Preset::Fast),
            "slow" => Ok(Preset::Slow),
            other => Err(UnknownPreset(other.to_string())),
        }
    }
}
