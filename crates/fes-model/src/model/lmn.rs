//! A complete Local Model Network described in its parameterisation: what the model file
//! stores and what identification, analysis and `modify` work on.
//!
//! [`Lmn::validate`] checks every invariant and names the offending field with the model
//! file's field names (`ts_s`, `units[2].eigenvalues[1]`, ...). [`Lmn::network`] builds the
//! run-time [`Network`].

use super::arx::{ArxUnit, MAX_ARX_ORDER, delta_to_shift, shift_poles};
use super::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel, eigenvalue_in_region};
use super::network::{MAX_DELAY, Network, NetworkError};
use super::scheduling::{Scheduler, SchedulingSpec};
use super::validity::ValidityFunctions;
#[cfg(not(feature = "std"))]
use crate::num::math::ComplexMath as _;
use alloc::collections::BTreeMap;
use alloc::{
    format,
    string::{String, ToString},
    vec::Vec,
};
use nalgebra::Complex;
use serde::{Deserialize, Serialize};

/// The local model structure and parameterisation (names used by the CLI and the file).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Structure {
    /// State space, A, b, c, dx, dy free (11 per unit).
    SsDirect,
    /// State space, real eigensystem with local eigenvectors (eq. 5.5).
    SsEigLocal,
    /// State space, real eigensystem with common eigenvectors (eq. 5.6), gauge-fixed.
    SsEigCommon,
    /// ARX in shift form (eq. 2.20-2.24).
    ArxShift,
    /// ARX with delta-domain parameters (D.2.2), simulated in shift form.
    ArxDelta,
}

impl Structure {
    /// Every structure, in a fixed order.
    pub const ALL: [Structure; 5] = [
        Self::SsDirect,
        Self::SsEigLocal,
        Self::SsEigCommon,
        Self::ArxShift,
        Self::ArxDelta,
    ];

    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::SsDirect => "ss-direct",
            Self::SsEigLocal => "ss-eig-local",
            Self::SsEigCommon => "ss-eig-common",
            Self::ArxShift => "arx-shift",
            Self::ArxDelta => "arx-delta",
        }
    }

    /// True for the state-space structures.
    pub fn is_state_space(self) -> bool {
        matches!(self, Self::SsDirect | Self::SsEigLocal | Self::SsEigCommon)
    }
}

impl core::fmt::Display for Structure {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl core::str::FromStr for Structure {
    type Err = UnknownStructure;
    fn from_str(s: &str) -> Result<Self, UnknownStructure> {
        Self::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| UnknownStructure {
                name: s.to_string(),
            })
    }
}

/// A structure name that is none of [`Structure::ALL`]'s (from [`Structure`]'s `FromStr`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown structure {name:?} (expected one of {expected})", expected = structure_names())]
pub struct UnknownStructure {
    /// The name given.
    pub name: String,
}

/// Every structure's name, comma-separated, in [`Structure::ALL`]'s order.
fn structure_names() -> String {
    let names: Vec<_> = Structure::ALL.iter().map(|x| x.name()).collect();
    names.join(", ")
}

/// The per-unit parameters, in the structure's own parameterisation.
#[derive(Debug, Clone, PartialEq)]
pub enum LocalModelSet {
    /// `ss-direct`.
    SsDirect(Vec<SsLocalModel<f64>>),
    /// `ss-eig-local`.
    SsEigLocal(Vec<EigLocalUnit<f64>>),
    /// `ss-eig-common` in the gauge-fixed modal coordinates (b of `reference_unit` = (1, 1)).
    SsEigCommon {
        /// Units.
        units: Vec<EigCommonUnit<f64>>,
        /// The unit r whose b is fixed at (1, 1).
        reference_unit: usize,
    },
    /// `arx-shift`: [`ArxUnit`] in shift form.
    ArxShift {
        /// n = 1..=3.
        order: usize,
        /// Units.
        units: Vec<ArxUnit<f64>>,
    },
    /// `arx-delta`: [`ArxUnit`] in delta form.
    ArxDelta {
        /// n = 1..=3.
        order: usize,
        /// Units.
        units: Vec<ArxUnit<f64>>,
    },
}

impl LocalModelSet {
    /// The structure.
    pub fn structure(&self) -> Structure {
        match self {
            Self::SsDirect(_) => Structure::SsDirect,
            Self::SsEigLocal(_) => Structure::SsEigLocal,
            Self::SsEigCommon { .. } => Structure::SsEigCommon,
            Self::ArxShift { .. } => Structure::ArxShift,
            Self::ArxDelta { .. } => Structure::ArxDelta,
        }
    }

    /// Number of units.
    pub fn len(&self) -> usize {
        match self {
            Self::SsDirect(u) => u.len(),
            Self::SsEigLocal(u) => u.len(),
            Self::SsEigCommon { units, .. } => units.len(),
            Self::ArxShift { units, .. } | Self::ArxDelta { units, .. } => units.len(),
        }
    }

    /// True when there are no units.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Where a model came from (free-form; the four error/timing keys have fixed names).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Training MSPE (eq. B.8, one-step prediction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_mspe: Option<f64>,
    /// Training MSSE (eq. B.8, free-run simulation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_msse: Option<f64>,
    /// Test MSSE.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_msse: Option<f64>,
    /// Wall-clock time of the fit in seconds.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_seconds: Option<f64>,
    /// Anything else: data set, seed, tool version, date, ...
    #[serde(flatten)]
    pub extra: BTreeMap<String, serde_json::Value>,
}

/// Why a model description is invalid. Every message names the field (file names).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LmnError {
    /// A field has an invalid value.
    #[error("{field}: {problem}")]
    Invalid {
        /// The field, e.g. `units[2].eigenvalues[1]`.
        field: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A local model is unstable (some pole has |1 + Ts p| >= 1, Fig. D.4).
    #[error(
        "units[{unit}]: local model is unstable: max |1 + Ts p| = {radius:.6} >= 1 (poles {poles}); open it with the stability check disabled to repair it"
    )]
    Unstable {
        /// The unit.
        unit: usize,
        /// max |1 + Ts p|.
        radius: f64,
        /// The poles, formatted.
        poles: String,
    },
    /// The scheduling specification makes no scheduler at this Ts.
    #[error("scheduling: {0}")]
    Scheduling(#[source] crate::model::scheduling::SchedulingError),
    /// The local models do not make a network, or it has no rest state.
    #[error("units: {0}")]
    Network(#[source] NetworkError),
    /// The structure name is not one of [`Structure::ALL`]'s.
    #[error("structure: {0}")]
    Structure(#[source] UnknownStructure),
    /// The knots make no validity functions.
    #[error("knots: {0}")]
    Knots(#[source] crate::model::validity::ValidityError),
}

/// Largest magnitude accepted for any local-model parameter: far above any identified value
/// (forces are normalised; delta-domain ARX coefficients scale as Ts^-n, 1e9 for n = 3 at
/// Ts = 1 ms) and far below overflow, so an edited or corrupted file cannot load as a model
/// whose simulated force overflows to infinity.
pub const MAX_PARAMETER_MAGNITUDE: f64 = 1e12;

/// Scheduling values at which the interpolated model's stability is checked on load.
pub const FROZEN_STABILITY_POINTS: usize = 201;

fn invalid(field: impl Into<String>, problem: impl Into<String>) -> LmnError {
    LmnError::Invalid {
        field: field.into(),
        problem: problem.into(),
    }
}

/// Every value of unit `i`'s parameter `name` is finite and at most
/// [`MAX_PARAMETER_MAGNITUDE`] in magnitude. The field is `units[i].name[j]`, or
/// `units[i].name` for a scalar.
fn check_finite(i: usize, name: &str, vals: &[f64]) -> Result<(), LmnError> {
    for (j, v) in vals.iter().enumerate() {
        let field = || {
            if vals.len() == 1 {
                format!("units[{i}].{name}")
            } else {
                format!("units[{i}].{name}[{j}]")
            }
        };
        if !v.is_finite() {
            return Err(invalid(field(), format!("{v} is not a finite number")));
        }
        if v.abs() > MAX_PARAMETER_MAGNITUDE {
            return Err(invalid(
                field(),
                format!(
                    "|{v:e}| exceeds {MAX_PARAMETER_MAGNITUDE:e}: no muscle model of \
                     normalised force has a parameter this large"
                ),
            ));
        }
    }
    Ok(())
}

/// Stability of one local model (delta domain, Fig. D.4).
#[derive(Debug, Clone, PartialEq)]
pub struct UnitStability {
    /// Unit index.
    pub unit: usize,
    /// Delta-domain poles p (for ARX: (z - 1)/Ts of the shift-domain poles z).
    pub poles: Vec<Complex<f64>>,
    /// max |1 + Ts p| (the shift-domain pole magnitude); < 1 is stable.
    pub radius: f64,
    /// radius < 1.
    pub stable: bool,
}

/// Whether [`Lmn::validate`] requires every local model to be stable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stability {
    /// Reject unstable local models and eigenvalues outside (-1/Ts, 0) (the default).
    Require,
    /// Accept them (analysis and repair must open an unstable model); see
    /// [`Lmn::stability`].
    Report,
}

/// A complete Local Model Network in its parameterisation.
#[derive(Debug, Clone, PartialEq)]
pub struct Lmn {
    /// Sampling period Ts in seconds.
    pub ts: f64,
    /// Input delay d in samples.
    pub delay: usize,
    /// The scheduling variable.
    pub scheduling: SchedulingSpec,
    /// The validity functions (knots and order).
    pub validity: ValidityFunctions<f64>,
    /// The local models.
    pub local: LocalModelSet,
    /// Offsets fixed at zero (thesis 6.5.3): every dx and dy must be 0.
    pub zero_offsets: bool,
    /// Newtons per normalised force unit.
    pub force_scale_n: f64,
    /// Where the model came from.
    pub provenance: Provenance,
}

impl Lmn {
    /// The structure.
    pub fn structure(&self) -> Structure {
        self.local.structure()
    }

    /// Number of units M.
    pub fn units(&self) -> usize {
        self.validity.units()
    }

    /// Checks every invariant (module docs); with [`Stability::Require`] also that every
    /// local model is stable and every eigenvalue is in (-1/Ts, 0). The parts are checked
    /// in a fixed order and the first failure is returned.
    pub fn validate(&self, stability: Stability) -> Result<(), LmnError> {
        self.check_structure()?;
        self.check_scheduling()?;
        self.check_force_scale()?;
        self.check_validity_functions()?;
        match &self.local {
            LocalModelSet::SsDirect(units) => self.check_ss_direct(units)?,
            LocalModelSet::SsEigLocal(units) => self.check_ss_eig_local(units, stability)?,
            LocalModelSet::SsEigCommon {
                units,
                reference_unit,
            } => self.check_ss_eig_common(units, *reference_unit, stability)?,
            LocalModelSet::ArxShift { order, units } | LocalModelSet::ArxDelta { order, units } => {
                self.check_arx(*order, units)?
            }
        }
        if stability == Stability::Require {
            self.check_unit_stability()?;
            self.check_frozen_stability()?;
            self.check_rest_state()?;
        }
        Ok(())
    }

    /// The sampling period is finite and > 0; the delay is at most [`MAX_DELAY`].
    fn check_structure(&self) -> Result<(), LmnError> {
        if !(self.ts.is_finite() && self.ts > 0.0) {
            return Err(invalid(
                "ts_s",
                format!("sampling period {} must be finite and > 0", self.ts),
            ));
        }
        if self.delay > MAX_DELAY {
            return Err(invalid(
                "delay_samples",
                format!("{} exceeds the maximum {MAX_DELAY}", self.delay),
            ));
        }
        Ok(())
    }

    /// The scheduling variable's specification makes a [`Scheduler`] at this Ts.
    fn check_scheduling(&self) -> Result<(), LmnError> {
        Scheduler::new(&self.scheduling, self.ts)
            .map(|_| ())
            .map_err(LmnError::Scheduling)
    }

    /// The force scale is finite and > 0.
    fn check_force_scale(&self) -> Result<(), LmnError> {
        if self.force_scale_n.is_finite() && self.force_scale_n > 0.0 {
            return Ok(());
        }
        Err(invalid(
            "force_scale_n",
            format!("{} must be finite and > 0", self.force_scale_n),
        ))
    }

    /// The validity functions (knots and order) define as many units as are given.
    fn check_validity_functions(&self) -> Result<(), LmnError> {
        let m = self.validity.units();
        if self.local.len() == m {
            return Ok(());
        }
        Err(invalid(
            "units",
            format!(
                "{} units given but the knots ({}) and order ({}) define {m}",
                self.local.len(),
                self.validity.knots().len(),
                self.validity.order()
            ),
        ))
    }

    /// `ss-direct`: every parameter finite and bounded, offsets as required.
    fn check_ss_direct(&self, units: &[SsLocalModel<f64>]) -> Result<(), LmnError> {
        for (i, u) in units.iter().enumerate() {
            check_finite(i, "a", &[u.a[0][0], u.a[0][1], u.a[1][0], u.a[1][1]])?;
            self.check_b_c_offsets(i, &u.b, &u.c, &u.dx, u.dy)?;
        }
        Ok(())
    }

    /// `ss-eig-local`: eigenvalues, eigenvector angles, b, c and offsets; the two
    /// eigenvectors must not be parallel.
    fn check_ss_eig_local(
        &self,
        units: &[EigLocalUnit<f64>],
        stability: Stability,
    ) -> Result<(), LmnError> {
        for (i, u) in units.iter().enumerate() {
            self.check_eigenvalues(i, &u.eigenvalues, stability)?;
            check_finite(i, "eigenvector_angles_rad", &u.eigenvector_angles)?;
            self.check_b_c_offsets(i, &u.b, &u.c, &u.dx, u.dy)?;
            if u.to_local_model().is_none() {
                return Err(invalid(
                    format!("units[{i}].eigenvector_angles_rad"),
                    "the two eigenvectors are parallel (V is singular)",
                ));
            }
        }
        Ok(())
    }

    /// `ss-eig-common`: eigenvalues, b, c and offsets of every unit; the reference unit
    /// exists and its b is (1, 1) (the gauge).
    fn check_ss_eig_common(
        &self,
        units: &[EigCommonUnit<f64>],
        reference_unit: usize,
        stability: Stability,
    ) -> Result<(), LmnError> {
        for (i, u) in units.iter().enumerate() {
            self.check_eigenvalues(i, &u.eigenvalues, stability)?;
            self.check_b_c_offsets(i, &u.b, &u.c, &u.dx, u.dy)?;
        }
        let r = reference_unit;
        let Some(ru) = units.get(r) else {
            return Err(invalid(
                "reference_unit",
                format!("unit {r} does not exist ({} units)", self.units()),
            ));
        };
        if ru.b != [1.0, 1.0] {
            return Err(invalid(
                format!("units[{r}].b"),
                format!(
                    "the reference unit's b must be (1, 1) in the gauge-fixed form, found ({}, {})",
                    ru.b[0], ru.b[1]
                ),
            ));
        }
        Ok(())
    }

    /// `arx-shift` and `arx-delta`: the order is in 1..=[`MAX_ARX_ORDER`]; a, b (the first
    /// `order` of each) and the offset d finite and bounded; d zero when offsets are.
    fn check_arx(&self, order: usize, units: &[ArxUnit<f64>]) -> Result<(), LmnError> {
        if !(1..=MAX_ARX_ORDER).contains(&order) {
            return Err(invalid(
                "units",
                format!("ARX order {order} is outside 1..={MAX_ARX_ORDER}"),
            ));
        }
        for (i, u) in units.iter().enumerate() {
            check_finite(i, "a", &u.a[..order])?;
            check_finite(i, "b", &u.b[..order])?;
            check_finite(i, "d", &[u.d])?;
            if self.zero_offsets && u.d != 0.0 {
                return Err(invalid(
                    format!("units[{i}].d"),
                    "must be zero when zero_offsets is true",
                ));
            }
        }
        Ok(())
    }

    /// A state-space unit's b, c, dx and dy finite and bounded, then its offsets.
    fn check_b_c_offsets(
        &self,
        i: usize,
        b: &[f64; 2],
        c: &[f64; 2],
        dx: &[f64; 2],
        dy: f64,
    ) -> Result<(), LmnError> {
        check_finite(i, "b", b)?;
        check_finite(i, "c", c)?;
        check_finite(i, "dx", dx)?;
        check_finite(i, "dy", &[dy])?;
        self.check_offsets(i, dx, dy)
    }

    /// Offsets: with `zero_offsets`, every dx and dy of unit `i` is 0.
    fn check_offsets(&self, i: usize, dx: &[f64], dy: f64) -> Result<(), LmnError> {
        if !self.zero_offsets {
            return Ok(());
        }
        if dx.iter().any(|v| *v != 0.0) {
            return Err(invalid(
                format!("units[{i}].dx"),
                "must be zero when zero_offsets is true",
            ));
        }
        if dy != 0.0 {
            return Err(invalid(
                format!("units[{i}].dy"),
                "must be zero when zero_offsets is true",
            ));
        }
        Ok(())
    }

    /// Unit `i`'s eigenvalues finite and bounded; with [`Stability::Require`] each in
    /// (-1/Ts, 0).
    fn check_eigenvalues(
        &self,
        i: usize,
        e: &[f64; 2],
        stability: Stability,
    ) -> Result<(), LmnError> {
        check_finite(i, "eigenvalues", e)?;
        if stability != Stability::Require {
            return Ok(());
        }
        let ts = self.ts;
        match e.iter().position(|v| !eigenvalue_in_region(*v, ts)) {
            None => Ok(()),
            Some(j) => Err(invalid(
                format!("units[{i}].eigenvalues[{j}]"),
                format!(
                    "eigenvalue {} is outside the region (-1/Ts, 0) = ({}, 0)",
                    e[j],
                    -1.0 / ts
                ),
            )),
        }
    }

    /// Every local model is stable ([`Lmn::stability`]).
    fn check_unit_stability(&self) -> Result<(), LmnError> {
        match self.stability().into_iter().find(|s| !s.stable) {
            None => Ok(()),
            Some(s) => {
                let poles: Vec<String> = s.poles.iter().map(|p| format!("{p:.4}")).collect();
                Err(LmnError::Unstable {
                    unit: s.unit,
                    radius: s.radius,
                    poles: poles.join(", "),
                })
            }
        }
    }

    /// The network builds and has a rest state (the initial state of every simulation,
    /// replay and RT run). A model that passes the per-parameter checks can still fail
    /// here, e.g. an output-scheduled network whose interpolated A(1) is singular on the
    /// whole valid range; such a model cannot be run, so it is not a valid model file.
    pub fn check_rest_state(&self) -> Result<(), LmnError> {
        self.network()?
            .rest_state()
            .map(|_| ())
            .map_err(LmnError::Network)
    }

    /// Every local model is stable *and* so is their interpolation at every frozen
    /// scheduling value ([`Network::frozen_stability_radius`] on
    /// [`FROZEN_STABILITY_POINTS`] points).
    fn check_frozen_stability(&self) -> Result<(), LmnError> {
        let (radius, phi) = self
            .network()?
            .frozen_stability_radius(FROZEN_STABILITY_POINTS);
        if radius < 1.0 {
            return Ok(());
        }
        Err(invalid(
            "units",
            format!(
                "the local models are stable but their interpolation at phi = {phi:.4} is not \
                 (max pole radius {radius:.6} >= 1)"
            ),
        ))
    }

    /// The state-space local models in direct form (`None` for ARX structures or parallel
    /// eigenvectors).
    pub fn ss_units(&self) -> Option<Vec<SsLocalModel<f64>>> {
        match &self.local {
            LocalModelSet::SsDirect(u) => Some(u.clone()),
            LocalModelSet::SsEigLocal(u) => u.iter().map(|x| x.to_local_model()).collect(),
            LocalModelSet::SsEigCommon { units, .. } => {
                Some(units.iter().map(|x| x.to_local_model()).collect())
            }
            _ => None,
        }
    }

    /// ARX order and shift-form units (delta form converted exactly); `None` for state space.
    pub fn arx_shift_units(&self) -> Option<(usize, Vec<ArxUnit<f64>>)> {
        match &self.local {
            LocalModelSet::ArxShift { order, units } => Some((*order, units.clone())),
            LocalModelSet::ArxDelta { order, units } => Some((
                *order,
                units
                    .iter()
                    .map(|u| delta_to_shift(u, *order, self.ts))
                    .collect(),
            )),
            _ => None,
        }
    }

    /// Per-unit stability (delta-domain poles and max |1 + Ts p|).
    pub fn stability(&self) -> Vec<UnitStability> {
        let ts = self.ts;
        let unit = |(unit, (poles, radius)): (usize, (Vec<Complex<f64>>, f64))| UnitStability {
            unit,
            poles,
            radius,
            stable: radius < 1.0,
        };
        if let Some(units) = self.ss_units() {
            units
                .iter()
                .map(|m| (m.poles().to_vec(), m.stability_radius(ts)))
                .enumerate()
                .map(unit)
                .collect()
        } else if let Some((n, units)) = self.arx_shift_units() {
            units
                .iter()
                .map(|m| {
                    let z = shift_poles(m, n);
                    let radius = z.iter().map(|z| z.norm()).fold(0.0, f64::max);
                    (z.iter().map(|z| (z - 1.0) / ts).collect(), radius)
                })
                .enumerate()
                .map(unit)
                .collect()
        } else {
            Vec::new()
        }
    }

    /// The run-time network (validates without the stability requirement first).
    pub fn network(&self) -> Result<Network<f64>, LmnError> {
        self.validate(Stability::Report)?;
        let scheduler = Scheduler::new(&self.scheduling, self.ts).map_err(LmnError::Scheduling)?;
        let net = if let Some(units) = self.ss_units() {
            Network::state_space(self.ts, self.delay, self.validity, scheduler, &units)
        } else if let Some((n, units)) = self.arx_shift_units() {
            Network::arx(self.ts, self.delay, self.validity, scheduler, n, &units)
        } else {
            return Err(invalid("units", "eigenvectors are parallel"));
        };
        net.map_err(LmnError::Network)
    }
}
