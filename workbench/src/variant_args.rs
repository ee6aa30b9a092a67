//! The pattern generator's loop variants as command-line options, shared by `fes design`
//! and `fes lcn-variants`: every candidate of docs/control.md's variant table, each a named
//! option beside the thesis's reading, defaults as measured there.

use clap::ValueEnum;
use fes_model::control::file::ControllerSettings;
use fes_model::control::lcn::AntiWindup;
use fes_model::control::pattern_generator::FeedbackState;
use fes_model::control::poles::{RiseTimeRule, ThirdPoleRule};
use fes_model::control::shaper::ShaperSum;

/// `--rise-rule`: how a rise time becomes the dominant poles (docs/control.md, section 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RiseRuleArg {
    /// w_n t_r = 3.2: every pole of Tables 6.1 / 6.2 to the printed digit.
    Thesis,
    /// w_n = (2.16 xi + 0.6) / t_r: the rise-time approximation (within 0.83 %).
    Approximation,
}

impl From<RiseRuleArg> for RiseTimeRule {
    fn from(a: RiseRuleArg) -> Self {
        match a {
            RiseRuleArg::Thesis => Self::Thesis,
            RiseRuleArg::Approximation => Self::Approximation,
        }
    }
}

/// `--third-pole-rule`: how "p3 = -1.9/Ts" (6.5.3) is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ThirdPoleArg {
    /// Literally in the delta domain: -1.9/Ts (shift-domain pole -0.9, sign-alternating).
    Delta,
    /// A continuous pole -1.9/Ts mapped like the dominant pair: (exp(-1.9) - 1)/Ts.
    Mapped,
}

impl From<ThirdPoleArg> for ThirdPoleRule {
    fn from(a: ThirdPoleArg) -> Self {
        match a {
            ThirdPoleArg::Delta => Self::Delta,
            ThirdPoleArg::Mapped => Self::Mapped,
        }
    }
}

/// `--anti-windup`: when the integrator is frozen (docs/control.md, section 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AntiWindupArg {
    /// Never: plain integral action (thesis), reset at a zero reference. Holds every level.
    None,
    /// While clamped, when the error and the integral term both push the output down.
    IntegralSign,
    /// While clamped, when the error pushes the output down (textbook; biased high).
    OutputClamp,
}

impl From<AntiWindupArg> for AntiWindup {
    fn from(a: AntiWindupArg) -> Self {
        match a {
            AntiWindupArg::None => Self::None,
            AntiWindupArg::IntegralSign => Self::IntegralSign,
            AntiWindupArg::OutputClamp => Self::OutputClamp,
        }
    }
}

/// `--shaper-sum`: what the pulse shaper sums (docs/control.md, section 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ShaperSumArg {
    /// The control signal clamped at zero.
    Clamped,
    /// The control signal as it is (eq. 6.8): a negative one postpones the next pulse.
    Signed,
}

impl From<ShaperSumArg> for ShaperSum {
    fn from(a: ShaperSumArg) -> Self {
        match a {
            ShaperSumArg::Clamped => Self::Clamped,
            ShaperSumArg::Signed => Self::Signed,
        }
    }
}

/// `--feedback-state`: which model state the LCN feeds back (docs/control.md, section 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FeedbackStateArg {
    /// The advanced core state x[k+d]: no delay in the loop, the designed poles exactly.
    Advanced,
    /// The model state now, x\[k\]: the thesis's loop, with the 7 ms delay the design ignores.
    Delayed,
}

impl From<FeedbackStateArg> for FeedbackState {
    fn from(a: FeedbackStateArg) -> Self {
        match a {
            FeedbackStateArg::Advanced => Self::Advanced,
            FeedbackStateArg::Delayed => Self::Delayed,
        }
    }
}

/// The loop variant options shared by `design` and `lcn-variants`: every candidate of
/// docs/control.md's variant table, defaults as measured there.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct VariantArgs {
    /// Rise-time rule of the dominant poles.
    #[arg(long, value_enum, default_value_t = RiseRuleArg::Thesis)]
    pub rise_rule: RiseRuleArg,
    /// How p3 = -1.9/Ts is read (ignored when --third-pole gives a value).
    #[arg(long, value_enum, default_value_t = ThirdPoleArg::Delta)]
    pub third_pole_rule: ThirdPoleArg,
    /// Anti-windup rule of the integrator.
    #[arg(long, value_enum, default_value_t = AntiWindupArg::None)]
    pub anti_windup: AntiWindupArg,
    /// What the pulse shaper sums.
    #[arg(long, value_enum, default_value_t = ShaperSumArg::Clamped)]
    pub shaper_sum: ShaperSumArg,
    /// Floor of the shaper's energy E under --shaper-sum signed (<= 0; default: none).
    #[arg(long, allow_negative_numbers = true)]
    pub e_min: Option<f64>,
    /// Which model state the LCN feeds back.
    #[arg(long, value_enum, default_value_t = FeedbackStateArg::Advanced)]
    pub feedback_state: FeedbackStateArg,
}

impl Default for VariantArgs {
    /// The flags' defaults: the default loop (test `variant_defaults_are_the_flags`).
    fn default() -> Self {
        Self {
            rise_rule: RiseRuleArg::Thesis,
            third_pole_rule: ThirdPoleArg::Delta,
            anti_windup: AntiWindupArg::None,
            shaper_sum: ShaperSumArg::Clamped,
            e_min: None,
            feedback_state: FeedbackStateArg::Advanced,
        }
    }
}

impl VariantArgs {
    /// The settings these options give (everything else default).
    pub fn settings(&self) -> ControllerSettings {
        let mut s = ControllerSettings::default();
        s.design.rise_time_rule = self.rise_rule.into();
        s.anti_windup = self.anti_windup.into();
        s.shaper.sum = self.shaper_sum.into();
        s.shaper.e_min = self.e_min;
        s.feedback_state = self.feedback_state.into();
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        variant: VariantArgs,
    }

    /// `VariantArgs::default()` (what `lcn-variants` starts its variants from) is what the
    /// flags give when none is passed, and both are the library's default settings.
    #[test]
    fn variant_defaults_are_the_flags() {
        let parsed = Cli::parse_from(["design"]).variant;
        assert_eq!(parsed, VariantArgs::default());
        assert_eq!(parsed.settings(), ControllerSettings::default());
    }
}
