//! The two muscles of the thesis (5.2.1) as Ding-model parameter sets, and a fast muscle
//! whose identified local models have the dynamics the thesis reports for its fast muscle
//! (Table 5.3).

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
    /// A fast muscle like the thesis's: the local models identified from its thesis-protocol
    /// data have a fast pole of -87 to -256 1/s beside a slow one of -8 to -33 1/s (Table
    /// 5.3), where the `fast` preset's identified fast poles are -25 to -50 1/s. A calcium
    /// transient of tau_c = 3 ms (one pulse gives the double pole -1/tau_c, which a
    /// second-order local model lumps near -1/(2 tau_c) ~ -170 1/s) and Ding et al.'s
    /// (2003) human quadriceps force decay tau_1 = 50.957 ms, tau_2 = 124.4 ms (51-175 ms,
    /// the slow pole); K_m, R_0 and A as `fast` (a doublet still gives more force-time
    /// integral per pulse: x1.10 at 5 ms). docs/sim-muscle.md.
    ThesisFast,
}

/// `--preset` named no known preset.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown preset `{0}`; known presets: fast, slow, thesis-fast")]
pub struct UnknownPreset(pub String);

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 3] = [Preset::Fast, Preset::Slow, Preset::ThesisFast];

    /// The preset's name as used on the command line and in data sets.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Fast => "fast",
            Preset::Slow => "slow",
            Preset::ThesisFast => "thesis-fast",
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
            Preset::ThesisFast => DingParams {
                tauc: 0.003,
                tau1: 0.050_957,
                tau2: 0.1244,
                ..Preset::Fast.params()
            },
        }
    }

    /// Record length of the thesis protocol, ms (5.2.1: 590 fast, 600 slow).
    pub fn record_ms(self) -> u32 {
        match self {
            Preset::Fast | Preset::ThesisFast => 590,
            Preset::Slow => 600,
        }
    }

    /// Number of records of the thesis protocol (5.2.1: 60 fast, 84 slow).
    pub fn records(self) -> usize {
        match self {
            Preset::Fast | Preset::ThesisFast => 60,
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
            "thesis-fast" => Ok(Preset::ThesisFast),
            other => Err(UnknownPreset(other.to_string())),
        }
    }
}
