//! Identification of the muscle model (thesis 2.3, 5.2.2, 5.3, 5.4, App. B).
//!
//! One implementation of the numerics, used by `fes identify / sweep / compare` and
//! by the tests:
//!
//! - [`records`]: a data set's training and test records (split from its metadata).
//! - [`resample`]: pulse-preserving down-sampling to a longer model period (5.2.2) and the
//!   interpolation back to the base period for the error measures (5.3).
//! - [`problem`]: the least-squares problem: a parameter vector -> network map
//!   ([`problem::ParamMap`]), residuals over records in simulation (B.6/B.7) or prediction
//!   (B.4) mode, exact Jacobians from `Dual` numbers through the network's own step, in
//!   parallel over records.
//! - [`lsq`]: linear least squares by SVD (B.2).
//! - [`regression`]: prediction-mode estimation, global (eq. 2.33) and local (eq. 2.35).
//! - [`lm`]: Levenberg-Marquardt (B.3.2).
//! - [`gauge`]: the state-coordinate gauge of state-space networks (held fixed).
//! - [`start`]: starting points (separated real poles; a linear fit copied into every unit).
//! - [`knots`]: interior knots as free parameters (5.4.2).
//! - [`metrics`]: training MSPE, training / test MSSE (eq. B.8) and each unit's validity
//!   weight.
//! - [`identify`](mod@identify): one run with options, stages and provenance.
//! - [`validation`]: the field's figures: NRMSE fit %, RRSE, residual tests (`resid`).
//! - [`miso`]: multi-input ARX networks scheduled on a measured input (App. E, the
//!   heat-transfer process): prediction- and simulation-mode fits, global and local
//!   learning, static analysis.
//! - [`sweep`]: network sizes swept (Figs. 5.13-5.21) and the comparison of Tables 5.1/5.2.
//!
//! Method, options and pitfalls: `docs/identification.md`.

pub mod gauge;
pub mod identify;
pub mod knots;
pub mod lm;
pub mod lsq;
pub mod metrics;
pub mod miso;
pub mod problem;
pub mod records;
pub mod regression;
pub mod resample;
pub mod start;
pub mod sweep;
pub mod validation;

pub use identify::{Hooks, IdentOptions, Identified, Mode, Progress, SchedulingKind, identify};
pub use metrics::Metrics;
pub use records::{IdentRecord, RecordSet, RecordsError, Undelivered};
pub use regression::Learning;

/// Why prediction mode refuses a state-space structure ([`IdentError::Conflict`]).
pub(crate) const PREDICTION_NEEDS_ARX: &str = "prediction mode needs an ARX structure \
     (arx-shift or arx-delta): a state-space network's state is not measured (B.5); use \
     simulation mode";

/// Why an identification failed. Every message names the problem.
#[derive(Debug, thiserror::Error)]
pub enum IdentError {
    /// The records are unusable.
    #[error(transparent)]
    Records(#[from] RecordsError),
    /// Down-sampling failed.
    #[error(transparent)]
    Resample(#[from] resample::ResampleError),
    /// An option's value is outside what it allows.
    #[error("{option} = {value}: must be {allowed}")]
    Option {
        /// The option.
        option: &'static str,
        /// Its value, as given.
        value: String,
        /// The values it allows.
        allowed: String,
    },
    /// An option's value does not fit with another option.
    #[error("{option} = {value} with {with}: {rule}")]
    Conflict {
        /// The option.
        option: &'static str,
        /// Its value, as given.
        value: String,
        /// The other option and its value.
        with: String,
        /// Why they do not fit together.
        rule: &'static str,
    },
    /// The data set has no channel of that name.
    #[error("the data set has no {kind} `{name}`")]
    NoChannel {
        /// `input` or `output`.
        kind: &'static str,
        /// The name asked for.
        name: String,
    },
    /// A multi-input model could not be built or run.
    #[error(transparent)]
    Miso(#[from] fes_model::model::miso::MisoError),
    /// A record does not fit the multi-input model's structure.
    #[error("{record}: {source}")]
    MisoRecord {
        /// The record's name.
        record: String,
        /// Why.
        #[source]
        source: fes_model::model::miso::MisoError,
    },
    /// A parameter vector does not define a model.
    #[error(transparent)]
    Param(#[from] fes_model::model::params::ParamError),
    /// The model could not be evaluated.
    #[error(transparent)]
    Problem(#[from] problem::ProblemError),
    /// A least-squares problem could not be solved.
    #[error(transparent)]
    Lsq(#[from] lsq::LsqError),
    /// No starting point gave a finite training error.
    #[error(
        "no starting point gives a finite training error (every candidate simulation diverges)"
    )]
    NoStart,
}
