//! The controller file: pretty JSON, schema `fes-lcn/1` (format in docs/control.md).
//!
//! It embeds the complete model (the model library's `fes-lmn/1` document, validated by the
//! model library on load, stability required) and, per unit, the design inputs (rise time,
//! damping, `p3`) with the design results (`p1`, `p2`, `K_x`, `K_I`, and the estimator gain
//! `l` when estimator poles are given), plus the shaper settings and the feedback mode.
//!
//! Loading recomputes the whole design from the embedded model and the stored inputs and
//! requires the stored results to match within [`MATCH_TOLERANCE`] (relative): a corrupted
//! file, or gains designed for another model, is rejected with an error naming the unit
//! and the field.
//!
//! Reading and writing files ([`Controller`]'s `load` and `save`) needs the `std` feature;
//! [`Controller::from_json_str`] and [`Controller::to_json_string`] work on text in every
//! build.

#[cfg(feature = "std")]
use std::path::{Path, PathBuf};

use alloc::{
    format,
    string::{String, ToString},
    vec::Vec,
};
use serde::{Deserialize, Serialize};

use crate::model::Network;
use crate::model::file::{self as model_file, FileError as ModelFileError};
use crate::model::lmn::{Lmn, LmnError, Stability};

use super::design::{DesignOptions, EstimatorPoles, LocalGains};
use super::lcn::AntiWindup;
use super::lcn_design::{LcnDesignError, UnitDesign, UnitSpec, design_lcn};
use super::pattern_generator::{
    FeedbackMode, FeedbackState, PatternGenerator, PatternGeneratorError, loop_runs_on,
};
use super::planner::{PlanningConfig, PlanningConfigError, PlanningMode};
use super::poles::Pole;
use super::shaper::{ShaperConfig, ShaperConfigError};

/// The schema string this code reads and writes.
pub const SCHEMA: &str = "fes-lcn/1";

/// Relative tolerance between stored and recomputed design results.
pub const MATCH_TOLERANCE: f64 = 1e-9;

/// One unit's record in the file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UnitRecord {
    /// Rise time `t_r` in seconds (design input).
    pub rise_time_s: f64,
    /// Damping factor `xi` (design input).
    pub damping: f64,
    /// Dominant pole `p1`, delta domain, 1/s (result; checked).
    pub p1: Pole,
    /// Dominant pole `p2`, delta domain, 1/s (result; checked).
    pub p2: Pole,
    /// Integrator pole `p3`, delta domain, 1/s (design input).
    pub p3: Pole,
    /// State gain `K_x` (result; checked).
    pub k_x: [f64; 2],
    /// Integral gain `K_I` (result; checked).
    pub k_i: f64,
    /// Estimator gain `L` (result; present exactly when `estimator_poles` is).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub l: Option<[f64; 2]>,
}

/// The file's document (serde form; [`Controller`] is the validated form).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerFile {
    /// Must be [`SCHEMA`].
    pub schema: String,
    /// The model, a complete `fes-lmn/1` document.
    pub model: serde_json::Value,
    /// Design options (negative-gain override, conditioning threshold).
    #[serde(default)]
    pub design: DesignOptions,
    /// One record per local model, in unit order.
    pub units: Vec<UnitRecord>,
    /// Pulse-shaper settings.
    #[serde(default)]
    pub shaper: ShaperConfig,
    /// Anti-windup rule of the integrator (a file without it was written with
    /// [`AntiWindup::legacy`]).
    #[serde(default = "AntiWindup::legacy")]
    pub anti_windup: AntiWindup,
    /// Feedback mode.
    pub mode: FeedbackMode,
    /// Which model state the LCN feeds back in the model mode (a file without it was
    /// written with [`FeedbackState::legacy`]).
    #[serde(default = "FeedbackState::legacy")]
    pub feedback_state: FeedbackState,
    /// Estimator poles (needed for `measured_force`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimator_poles: Option<EstimatorPoles>,
    /// Receding-horizon pulse decisions over the reference preview (a file without it
    /// decides causally: [`PlanningMode::Off`]).
    #[serde(default, skip_serializing_if = "planning_off")]
    pub planning: Option<PlanningConfig>,
}

fn planning_off(p: &Option<PlanningConfig>) -> bool {
    p.is_none_or(|p| p.mode == PlanningMode::Off)
}

/// Everything of a controller besides the model and the per-unit specifications.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ControllerSettings {
    /// Design options (negative-gain override, conditioning threshold).
    pub design: DesignOptions,
    /// Pulse-shaper settings.
    pub shaper: ShaperConfig,
    /// Anti-windup rule.
    pub anti_windup: AntiWindup,
    /// Feedback mode.
    pub mode: FeedbackMode,
    /// Which model state the LCN feeds back (model mode).
    pub feedback_state: FeedbackState,
    /// Estimator poles (needed for [`FeedbackMode::MeasuredForce`]; optional otherwise).
    pub estimator_poles: Option<EstimatorPoles>,
    /// The planner ([`PlanningMode::Off`]: the causal loop decides every pulse).
    pub planning: PlanningConfig,
}

/// Why a controller file could not be read, written or accepted.
#[derive(Debug, thiserror::Error)]
pub enum ControllerFileError {
    /// The file could not be read or written (`std` only).
    #[cfg(feature = "std")]
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Not valid JSON, or a field is missing, unknown or of the wrong type (the message
    /// names it, with line and column).
    #[error("controller file: {0} (note: NaN and Infinity are not valid JSON numbers)")]
    Syntax(#[from] serde_json::Error),
    /// Wrong schema string.
    #[error("schema: unsupported schema {found:?} (this build reads {SCHEMA:?})")]
    Schema {
        /// What the file says.
        found: String,
    },
    /// The embedded model is invalid.
    #[error("model.{0}")]
    Model(#[source] ModelFileError),
    /// The embedded model cannot run.
    #[error("model: {0}")]
    Network(#[source] LmnError),
    /// The pattern generator of the file's mode cannot be built.
    #[error("mode: {0}")]
    Mode(#[source] PatternGeneratorError),
    /// A field has an invalid value.
    #[error("{field}: {problem}")]
    Invalid {
        /// The field, e.g. `units[2].rise_time_s`.
        field: String,
        /// What is wrong.
        problem: String,
    },
    /// A stored design result differs from the one recomputed from the embedded model.
    #[error(
        "units[{unit}].{field}: stored {stored} but the design from the embedded model gives \
         {recomputed} (file corrupted, or gains designed for another model)"
    )]
    Mismatch {
        /// Unit index.
        unit: usize,
        /// The field, e.g. `k_x[1]`.
        field: String,
        /// The stored value.
        stored: f64,
        /// The recomputed value.
        recomputed: f64,
    },
    /// The design fails on the embedded model.
    #[error("units: {0}")]
    Design(#[from] LcnDesignError),
    /// Invalid shaper settings.
    #[error("shaper: {0}")]
    Shaper(#[from] ShaperConfigError),
    /// Invalid planner settings.
    #[error("planning: {0}")]
    Planning(#[from] PlanningConfigError),
}

fn invalid(field: impl Into<String>, problem: impl Into<String>) -> ControllerFileError {
    ControllerFileError::Invalid {
        field: field.into(),
        problem: problem.into(),
    }
}

/// A validated controller: the model, the designed LCN, the shaper and the mode.
#[derive(Debug, Clone)]
pub struct Controller {
    /// The model.
    pub lmn: Lmn,
    /// The model's run-time network.
    pub network: Network<f64>,
    /// One design per unit.
    pub units: Vec<UnitDesign>,
    /// Design options, shaper, anti-windup, mode and estimator poles.
    pub settings: ControllerSettings,
}

impl Controller {
    /// Design a controller for a model: one [`UnitSpec`] per unit. The model must pass the
    /// model library's validation with stability required.
    pub fn design(
        lmn: Lmn,
        specs: &[UnitSpec],
        settings: ControllerSettings,
    ) -> Result<Self, ControllerFileError> {
        lmn.validate(Stability::Require)
            .map_err(|e| ControllerFileError::Model(ModelFileError::Invalid(e)))?;
        let network = lmn.network().map_err(ControllerFileError::Network)?;
        settings.shaper.validate()?;
        settings.planning.validate()?;
        if settings.planning.mode != PlanningMode::Off
            && settings.feedback_state != FeedbackState::Advanced
        {
            return Err(invalid(
                "planning.mode",
                "planning needs feedback_state advanced (the warm start runs the advanced loop)",
            ));
        }
        if !loop_runs_on(&network, settings.mode, settings.feedback_state) {
            return Err(invalid(
                "feedback_state",
                "the model's scheduling_input is undelayed (eq. 5.2): the state d samples ahead depends on pulses not yet decided, so only mode model with feedback_state delayed (the thesis's loop) runs on it",
            ));
        }
        let min_rcond = settings.design.min_rcond;
        if !(min_rcond.is_finite() && min_rcond >= 0.0) {
            return Err(invalid(
                "design.min_rcond",
                format!("{min_rcond} is not a finite non-negative number"),
            ));
        }
        if settings.mode == FeedbackMode::MeasuredForce && settings.estimator_poles.is_none() {
            return Err(invalid(
                "estimator_poles",
                "mode measured_force needs estimator poles",
            ));
        }
        let units = design_lcn(
            &network,
            specs,
            settings.estimator_poles.as_ref(),
            &settings.design,
        )?;
        Ok(Self {
            lmn,
            network,
            units,
            settings,
        })
    }

    /// The controller gains, in unit order.
    pub fn gains(&self) -> Vec<LocalGains> {
        self.units.iter().map(|u| u.gains).collect()
    }

    /// A pattern generator running this controller (allocates; its `tick` does not).
    pub fn pattern_generator(&self) -> Result<PatternGenerator, PatternGeneratorError> {
        let l: Option<Vec<[f64; 2]>> = self.units.iter().map(|u| u.estimator_gain).collect();
        let s = &self.settings;
        PatternGenerator::new(
            self.network,
            &self.gains(),
            s.shaper,
            s.anti_windup,
            s.mode,
            s.feedback_state,
            l.as_deref(),
        )?
        .with_planning(s.planning)
    }

    /// The file document.
    pub fn to_file(&self) -> Result<ControllerFile, ControllerFileError> {
        let text = model_file::to_json_string(&self.lmn).map_err(ControllerFileError::Model)?;
        let model: serde_json::Value = serde_json::from_str(&text)?;
        Ok(ControllerFile {
            schema: SCHEMA.to_string(),
            model,
            design: self.settings.design,
            units: self
                .units
                .iter()
                .map(|u| UnitRecord {
                    rise_time_s: u.spec.rise_time_s,
                    damping: u.spec.damping,
                    p1: u.poles.p1,
                    p2: u.poles.p2,
                    p3: u.poles.p3,
                    k_x: u.gains.k_x,
                    k_i: u.gains.k_i,
                    l: u.estimator_gain,
                })
                .collect(),
            shaper: self.settings.shaper,
            anti_windup: self.settings.anti_windup,
            mode: self.settings.mode,
            feedback_state: self.settings.feedback_state,
            estimator_poles: self.settings.estimator_poles,
            planning: (self.settings.planning.mode != PlanningMode::Off)
                .then_some(self.settings.planning),
        })
    }

    /// The file text (pretty JSON).
    pub fn to_json_string(&self) -> Result<String, ControllerFileError> {
        Ok(serde_json::to_string_pretty(&self.to_file()?)?)
    }

    /// Write the file (`std` only).
    #[cfg(feature = "std")]
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), ControllerFileError> {
        let text = self.to_json_string()?;
        std::fs::write(path.as_ref(), text).map_err(|source| ControllerFileError::Io {
            path: path.as_ref().to_path_buf(),
            source,
        })
    }

    /// Read and validate a file (`std` only).
    #[cfg(feature = "std")]
    pub fn load(path: impl AsRef<Path>) -> Result<Self, ControllerFileError> {
        let text =
            std::fs::read_to_string(path.as_ref()).map_err(|source| ControllerFileError::Io {
                path: path.as_ref().to_path_buf(),
                source,
            })?;
        Self::from_json_str(&text)
    }

    /// Parse and validate a file's text.
    pub fn from_json_str(text: &str) -> Result<Self, ControllerFileError> {
        let file: ControllerFile = serde_json::from_str(text)?;
        Self::from_file(&file)
    }

    /// Validate a document: schema, the embedded model (model library), every number, and
    /// that recomputing the design reproduces the stored results (module docs).
    pub fn from_file(file: &ControllerFile) -> Result<Self, ControllerFileError> {
        if file.schema != SCHEMA {
            return Err(ControllerFileError::Schema {
                found: file.schema.clone(),
            });
        }
        let lmn = model_file::from_json_str(&file.model.to_string(), Stability::Require)
            .map_err(ControllerFileError::Model)?;
        if file.units.len() != lmn.units() {
            return Err(invalid(
                "units",
                format!(
                    "{} unit records for a model with {} units",
                    file.units.len(),
                    lmn.units()
                ),
            ));
        }
        for (i, u) in file.units.iter().enumerate() {
            check_record(i, u, file.estimator_poles.is_some())?;
        }
        if let Some(ep) = &file.estimator_poles {
            for (name, p) in [("p1", ep.p1), ("p2", ep.p2)] {
                if !(p.re.is_finite() && p.im.is_finite()) {
                    return Err(invalid(format!("estimator_poles.{name}"), "not finite"));
                }
            }
        }
        let specs: Vec<UnitSpec> = file
            .units
            .iter()
            .map(|u| UnitSpec {
                rise_time_s: u.rise_time_s,
                damping: u.damping,
                p3: u.p3,
            })
            .collect();
        let settings = ControllerSettings {
            design: file.design,
            shaper: file.shaper,
            anti_windup: file.anti_windup,
            mode: file.mode,
            feedback_state: file.feedback_state,
            estimator_poles: file.estimator_poles,
            planning: file.planning.unwrap_or_default(),
        };
        let c = Self::design(lmn, &specs, settings)?;
        for (i, (stored, design)) in file.units.iter().zip(&c.units).enumerate() {
            compare_unit(i, stored, design)?;
        }
        // Valid means runnable: the pattern generator of the file's mode must build (e.g.
        // the measured-force mode needs an input delay of at least one sample).
        c.pattern_generator().map_err(ControllerFileError::Mode)?;
        Ok(c)
    }
}

fn check_record(i: usize, u: &UnitRecord, want_l: bool) -> Result<(), ControllerFileError> {
    let field = |name: &str| format!("units[{i}].{name}");
    let finite = [
        ("rise_time_s", u.rise_time_s),
        ("damping", u.damping),
        ("p1.re", u.p1.re),
        ("p1.im", u.p1.im),
        ("p2.re", u.p2.re),
        ("p2.im", u.p2.im),
        ("p3.re", u.p3.re),
        ("p3.im", u.p3.im),
        ("k_x[0]", u.k_x[0]),
        ("k_x[1]", u.k_x[1]),
        ("k_i", u.k_i),
    ];
    for (name, v) in finite {
        if !v.is_finite() {
            return Err(invalid(field(name), format!("{v} is not finite")));
        }
    }
    if u.rise_time_s <= 0.0 {
        return Err(invalid(
            field("rise_time_s"),
            format!("{} s must be positive", u.rise_time_s),
        ));
    }
    if u.damping <= 0.0 {
        return Err(invalid(
            field("damping"),
            format!("{} must be positive", u.damping),
        ));
    }
    match (u.l, want_l) {
        (Some(l), true) if l.iter().all(|v| v.is_finite()) => Ok(()),
        (Some(_), true) => Err(invalid(field("l"), "not finite")),
        (None, true) => Err(invalid(
            field("l"),
            "missing (estimator_poles are given, so every unit needs its estimator gain)",
        )),
        (Some(_), false) => Err(invalid(
            field("l"),
            "present but no estimator_poles are given",
        )),
        (None, false) => Ok(()),
    }
}

fn compare_unit(i: usize, s: &UnitRecord, d: &UnitDesign) -> Result<(), ControllerFileError> {
    let check = |field: &str, stored: f64, recomputed: f64, scale: f64| {
        if (stored - recomputed).abs() <= MATCH_TOLERANCE * recomputed.abs().max(scale) {
            Ok(())
        } else {
            Err(ControllerFileError::Mismatch {
                unit: i,
                field: field.to_string(),
                stored,
                recomputed,
            })
        }
    };
    // Components near zero are compared against the size of the vector they belong to.
    let pole_scale = 1e-3 * d.poles.p1.re.abs().max(d.poles.p1.im.abs());
    check("p1.re", s.p1.re, d.poles.p1.re, pole_scale)?;
    check("p1.im", s.p1.im, d.poles.p1.im, pole_scale)?;
    check("p2.re", s.p2.re, d.poles.p2.re, pole_scale)?;
    check("p2.im", s.p2.im, d.poles.p2.im, pole_scale)?;
    let g = &d.gains;
    let k_scale = 1e-3 * g.k_x[0].abs().max(g.k_x[1].abs());
    check("k_x[0]", s.k_x[0], g.k_x[0], k_scale)?;
    check("k_x[1]", s.k_x[1], g.k_x[1], k_scale)?;
    check("k_i", s.k_i, g.k_i, 0.0)?;
    if let (Some(ls), Some(ld)) = (s.l, d.estimator_gain) {
        let l_scale = 1e-3 * ld[0].abs().max(ld[1].abs());
        check("l[0]", ls[0], ld[0], l_scale)?;
        check("l[1]", ls[1], ld[1], l_scale)?;
    }
    Ok(())
}
