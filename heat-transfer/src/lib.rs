//! # heat-transfer: thesis App. E through the project's toolchain
//!
//! The simulated air heater ([`sim_heat`]) identified and analysed with the same code as
//! the muscle (`fes-ident`, `fes-model`), example by example:
//!
//! - Table E.1: the delays per valve angle, read off the plant's step responses.
//! - E.4.2, Table E.2: a linear 1st-order ARX model with the data vector
//!   psi = \[alpha(t-3), u(t-5), y(t-1)\] (eq. E.3) and an offset, in prediction and in
//!   simulation mode.
//! - E.4.3-E.4.4, Tables E.3-E.4: networks of 5 and 10 uniformly distributed B-splines
//!   over phi = alpha(t-3) (eq. E.2), local vs global learning, prediction vs simulation
//!   mode; E.4.6, Table E.6 and Fig. E.7: the global simulation-mode networks frozen over
//!   phi (G_u, G_alpha, pole).
//!
//! - E.4.7, Fig. E.8: a Local Controller Network designed by input-output pole placement
//!   with integral action (C.1) against one linear controller ([`control`]).
//!
//! [`study`] runs all of it for one seed and returns a [`Report`] that serialises to the
//! JSON the `heat-transfer` binary writes.

use std::collections::BTreeMap;

use fes_ident::ident::Learning;
use fes_ident::ident::lm::LmOptions;
use fes_ident::ident::miso::{self, MisoRecord};
use fes_ident::ident::problem::Horizon;
use fes_model::model::miso::{MisoArx, MisoStructure};
use fes_model::model::validity::{KnotLayout, ValidityFunctions};
use serde::Serialize;
use sim_heat::plant::{HeatParams, StepInput, TABLE_E1_DELAY_U, TEST_ANGLES_DEG, step_delay};

/// Why the study failed.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// The plant's parameters.
    #[error(transparent)]
    Plant(#[from] sim_heat::plant::HeatParamError),
    /// Identification.
    #[error(transparent)]
    Ident(#[from] fes_ident::ident::IdentError),
    /// A model structure.
    #[error(transparent)]
    Model(#[from] fes_model::model::miso::MisoError),
    /// Validity functions.
    #[error(transparent)]
    Validity(#[from] fes_model::model::validity::ValidityError),
    /// A controller design.
    #[error(transparent)]
    Control(#[from] fes_model::control::io_design::IoDesignError),
    /// The experiments' data set could not be written.
    #[error("writing the data set: {0}")]
    Dataset(#[from] fes_dataset::WriteError),
    /// A figure could not be drawn or written.
    #[error("{path}: drawing failed: {message}")]
    Figure {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
}

pub mod control;
pub mod figures;
pub mod rig;

/// The u -> y delay of eq. E.3 in samples (Table E.1 at mid angles).
pub const DELAY_U: usize = 5;
/// The alpha -> y delay of eq. E.3 in samples, also the scheduling delay (eq. E.2).
pub const DELAY_ALPHA: usize = 3;

/// The local ARX structure of E.4.2-E.4.4: order 1, inputs (alpha, u) with delays 3 and 5
/// (eq. E.3), an offset, phi = alpha(t - 3) (eq. E.2), over `units` uniformly distributed
/// B-splines (the thesis's uniform layout, [`KnotLayout::Uniform`]) on \[0, 1\]; 1 unit is
/// the linear model of E.4.2.
pub fn template(units: usize) -> Result<MisoArx, StudyError> {
    let st = MisoStructure {
        order: 1,
        delays: vec![DELAY_ALPHA, DELAY_U],
        unit_delays: vec![],
        scheduling_input: 0,
        scheduling_delay: DELAY_ALPHA,
        scheduling2: None,
        offset: true,
    };
    let v = if units == 1 {
        ValidityFunctions::uniform(1, 0.0, 1.0)?
    } else {
        ValidityFunctions::with_layout(KnotLayout::Uniform, units, 0.0, 1.0)?
    };
    let r = st.regressors();
    Ok(MisoArx::new(
        sim_heat::plant::TS_S,
        st,
        v,
        vec![0.0; units * r],
    )?)
}

/// Table E.2's two columns for one model.
#[derive(Debug, Clone, Serialize)]
pub struct ArxColumn {
    /// Training MSSE.
    pub train_mse: f64,
    /// Test MSSE.
    pub test_mse: f64,
    /// b of alpha(t-3).
    pub b_alpha: f64,
    /// b of u(t-5).
    pub b_u: f64,
    /// The pole (-a_1).
    pub pole: f64,
    /// Offset d.
    pub d: f64,
    /// Steady-state gain alpha -> y.
    pub g_alpha: f64,
    /// Steady-state gain u -> y.
    pub g_u: f64,
}

/// E.4.2 (Table E.2) and the JSON's `arx1`.
#[derive(Debug, Clone, Serialize)]
pub struct Arx1 {
    /// The prediction model's pole.
    pub pole_prediction: f64,
    /// The simulation model's pole.
    pub pole_simulation: f64,
    /// G_alpha of the simulation model.
    pub g_alpha: f64,
    /// G_u of the simulation model.
    pub g_u: f64,
    /// The prediction model's column.
    pub prediction: ArxColumn,
    /// The simulation model's column.
    pub simulation: ArxColumn,
}

/// One row of Tables E.3 and E.4 (one network size and learning).
#[derive(Debug, Clone, Serialize)]
pub struct LearningRow {
    /// Units M.
    pub units: usize,
    /// `global` or `local`.
    pub learning: String,
    /// Prediction-mode model: training MSPE (Table E.3).
    pub pred_train_mspe: f64,
    /// Prediction-mode model: training MSSE (Table E.3).
    pub pred_train_msse: f64,
    /// Prediction-mode model: test MSSE (Table E.3).
    pub pred_test_msse: f64,
    /// Simulation-mode model: training MSSE (Table E.4).
    pub sim_train_msse: f64,
    /// Simulation-mode model: test MSSE (Table E.4).
    pub sim_test_msse: f64,
}

/// The orderings the thesis draws from Tables E.2-E.6.
#[derive(Debug, Clone, Serialize)]
pub struct Orderings {
    /// Table E.2 (train and test) and Tables E.3 vs E.4 (training MSSE, every size and
    /// learning): the simulation-mode model beats the prediction-mode model.
    pub simulation_beats_prediction: bool,
    /// Table E.4: global learning has the smaller training MSSE for 5 and 10 units and the
    /// smaller test MSSE for 5 units.
    pub global_beats_local_in_simulation: bool,
    /// Table E.4's test column at 10 units (the thesis: global 1.50e-3 < local 1.54e-3).
    pub global_beats_local_in_simulation_test_10: bool,
    /// Table E.3: local learning has the larger training MSPE (its bias) for both sizes,
    /// and the smaller test MSSE at 10 units (its regularisation).
    pub prediction_local_bias_and_regularisation: bool,
    /// Table E.6: the 10-unit network (global, simulation mode) has the smaller training
    /// and the larger test error than the 5-unit one.
    pub ten_units_generalise_worse: bool,
    /// Table E.5: the common-eigenvector (restricted) state-space network's training and
    /// test MSSE within 25 % of the general one's.
    pub restricted_close_to_general: Option<bool>,
}

/// The network frozen at one phi (Fig. E.7).
#[derive(Debug, Clone, Serialize)]
pub struct FrozenRow {
    /// phi (normalised valve angle).
    pub phi: f64,
    /// G_alpha.
    pub g_alpha: f64,
    /// G_u.
    pub g_u: f64,
    /// The pole.
    pub pole: f64,
}

/// Everything [`study`] found.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The seed of the experiments' inputs and noise.
    pub seed: u64,
    /// Table E.1, u -> y: angle (deg) -> delay in samples from the step responses.
    pub delays_u_samples: BTreeMap<String, usize>,
    /// Table E.1, alpha -> y.
    pub delays_alpha_samples: BTreeMap<String, usize>,
    /// Table E.1's u -> y column, for comparison.
    pub delays_u_table_e1: BTreeMap<String, usize>,
    /// E.4.2.
    pub arx1: Arx1,
    /// Tables E.3 and E.4.
    pub learning: Vec<LearningRow>,
    /// The orderings.
    pub orderings: Orderings,
    /// Table E.5 and Fig. E.6: general and restricted state-space networks.
    pub state_space: Vec<SsRow>,
    /// E.4.1, eq. E.1: two-dimensional scheduling.
    pub scheduling_2d: Scheduling2d,
    /// Fig. E.7: the 5-unit network (global, simulation mode) over phi.
    pub static_5: Vec<FrozenRow>,
    /// Fig. E.7: the 10-unit network.
    pub static_10: Vec<FrozenRow>,
    /// E.4.7, Fig. E.8(a): the LCN and the linear controller on the design model.
    pub control: control::ControlResults,
    /// Fig. E.8(b): the same controllers on the 5-unit model of E.4.4 (alpha also an input).
    pub control_changed_plant: control::ControlResults,
    /// The same controllers on the simulated process itself (noise-free).
    pub control_process: control::ControlResults,
    /// Anti-reset-windup on the design model (Fig. E.8 at 37 s).
    pub windup: control::Windup,
    /// E.4.7's design model's gain from the heater power against the process's at
    /// alpha = 0.1, 0.5, 0.9.
    pub control_gains: Vec<control::GainCheck>,
}

fn angle_key(a: f64) -> String {
    format!("{a:.0}")
}

/// Delay in samples per angle (the angle in degrees as a string).
pub type DelayTable = BTreeMap<String, usize>;

/// Table E.1 read off the plant's step responses: (u -> y, alpha -> y).
pub fn delays(p: &HeatParams) -> Result<(DelayTable, DelayTable), StudyError> {
    let mut u = BTreeMap::new();
    let mut a = BTreeMap::new();
    for &deg in &TEST_ANGLES_DEG {
        u.insert(angle_key(deg), step_delay(p, deg, StepInput::Voltage)?);
        a.insert(angle_key(deg), step_delay(p, deg, StepInput::Angle)?);
    }
    Ok((u, a))
}

fn column(m: &MisoArx, train: &[MisoRecord], test: &[MisoRecord]) -> Result<ArxColumn, StudyError> {
    let l = m.local(0);
    Ok(ArxColumn {
        train_mse: miso::mse(m, train, Horizon::Simulation)?,
        test_mse: miso::mse(m, test, Horizon::Simulation)?,
        b_alpha: l.b[0][0],
        b_u: l.b[1][0],
        pole: -l.a[0],
        d: l.c,
        g_alpha: l.gain(0).unwrap_or(f64::NAN),
        g_u: l.gain(1).unwrap_or(f64::NAN),
    })
}

/// The fitted networks of one size and learning: (prediction-mode, simulation-mode).
pub fn fit_pair(
    units: usize,
    learning: Learning,
    train: &[MisoRecord],
) -> Result<(MisoArx, MisoArx), StudyError> {
    let pred = miso::fit_prediction(&template(units)?, train, learning)?;
    let sim = miso::fit_simulation(&pred, train, learning, &LmOptions::default())?;
    Ok((pred, sim))
}

/// Fig. E.7's curves of a network at 21 points.
pub fn frozen_rows(m: &MisoArx) -> Vec<FrozenRow> {
    miso::static_analysis(m, 21)
        .into_iter()
        .map(|p| FrozenRow {
            phi: p.phi,
            g_alpha: p.gains[0],
            g_u: p.gains[1],
            pole: p.poles[0].re,
        })
        .collect()
}

/// The training and test records of the E.2 experiments for `seed`.
pub fn records(
    p: &HeatParams,
    seed: u64,
) -> Result<(Vec<MisoRecord>, Vec<MisoRecord>), StudyError> {
    let set = sim_heat::experiment::dataset(p, seed)?;
    Ok(miso::records(&set, &["alpha", "u"], "y")?)
}

/// Writes the E.2 experiments for `seed` into `dir` as the `fes-dataset/2` data set the
/// study identifies from (`sim_heat::experiment::dataset`: inputs `alpha`, `u`, output
/// `y`, Ts = 50 ms); `dir` must be new or empty. Readers: `fes_dataset::signals`,
/// `python/fes_io.py`, `matlab/load_fes_dataset.m`; `fes dataset inspect` describes it.
pub fn write_dataset(p: &HeatParams, seed: u64, dir: &std::path::Path) -> Result<(), StudyError> {
    let set = sim_heat::experiment::dataset(p, seed)?;
    set.write(dir, fes_dataset::WriteMode::CreateNew)?;
    Ok(())
}

/// E.4.1, eq. E.1: the scheduling vector phi = \[alpha(t-3), u(t-5)\] over 3 x 3
/// tensor-product B-splines, local models as E.4.2, global learning in simulation mode.
#[derive(Debug, Clone, Serialize)]
pub struct Scheduling2d {
    /// Units M = 9.
    pub units: usize,
    /// Training MSSE.
    pub train_mse: f64,
    /// Test MSSE.
    pub test_mse: f64,
}

/// Fits [`Scheduling2d`]'s network.
pub fn scheduling_2d(
    train: &[MisoRecord],
    test: &[MisoRecord],
) -> Result<Scheduling2d, StudyError> {
    let mut st = template(1)?.structure;
    st.scheduling2 = Some((1, DELAY_U));
    let v = ValidityFunctions::with_layout(KnotLayout::Uniform, 3, 0.0, 1.0)?;
    let r = st.regressors();
    let t = MisoArx::tensor(sim_heat::plant::TS_S, st, v, v, vec![0.0; 9 * r])?;
    let pred = miso::fit_prediction(&t, train, Learning::Global)?;
    let sim = miso::fit_simulation(&pred, train, Learning::Global, &LmOptions::default())?;
    Ok(Scheduling2d {
        units: sim.units(),
        train_mse: miso::mse(&sim, train, Horizon::Simulation)?,
        test_mse: miso::mse(&sim, test, Horizon::Simulation)?,
    })
}

/// Table E.5 and Fig. E.6: one state-space network's errors and eigenvectors.
#[derive(Debug, Clone, Serialize)]
pub struct SsRow {
    /// `general` or `restricted`.
    pub model: String,
    /// Training MSSE.
    pub train_mse: f64,
    /// Test MSSE.
    pub test_mse: f64,
    /// Eigenvector angles (rad) per unit (the same for every unit when restricted).
    pub angles_rad: Vec<[f64; 2]>,
    /// Eigenvalues (delta domain, 1/s) per unit.
    pub eigenvalues: Vec<[f64; 2]>,
}

/// E.4.5: a 2nd-order delta-domain state-space network over the E.4.4 structure, started
/// from the E.4.4 ARX network (its pole as the slow eigenvalue, a fast one at -1/0.15 s),
/// inputs alpha(t-2), u(t-4) (the ARX's 3 and 5: the state-space output sees the input one
/// sample later), fitted globally in simulation mode with general and with common
/// eigenvectors.
pub fn state_space_study(
    arx: &MisoArx,
    train: &[MisoRecord],
    test: &[MisoRecord],
) -> Result<Vec<SsRow>, StudyError> {
    use fes_model::model::local_model::{eigenvalue_from_eta, eta_from_eigenvalue};
    use fes_model::model::miso_ss::{Eigenvectors, MisoSs};
    let ts = arx.ts;
    let fast = -1.0 / 0.15;
    let eta = |e: f64| eta_from_eigenvalue(e, ts).unwrap_or(0.0);
    let mut rows = Vec::new();
    for ev in [Eigenvectors::Local, Eigenvectors::Common] {
        let mut theta = Vec::new();
        if ev == Eigenvectors::Common {
            theta.extend([0.0, std::f64::consts::FRAC_PI_2]);
        }
        for i in 0..arx.units() {
            let l = arx.local(i);
            let pole = (-l.a[0]).clamp(0.5, 0.999);
            theta.extend([eta((pole - 1.0) / ts), eta(fast)]);
            if ev == Eigenvectors::Local {
                theta.extend([0.0, std::f64::consts::FRAC_PI_2]);
            }
            theta.extend([l.b[0][0] / ts, 0.0, l.b[1][0] / ts, 0.0]);
            theta.extend([1.0, 0.1, l.c / ts, 0.0, 0.0]);
        }
        let start = MisoSs {
            ts,
            delays: vec![DELAY_ALPHA - 1, DELAY_U - 1],
            scheduling_input: 0,
            scheduling_delay: DELAY_ALPHA,
            validity: arx.validity,
            eigenvectors: ev,
            theta,
        };
        start.validate()?;
        let fit = miso::fit_free_run(&start, train, &LmOptions::default())?;
        let units: Vec<_> = (0..arx.units()).collect();
        let off = |i: usize| {
            (if ev == Eigenvectors::Common { 2 } else { 0 })
                + i * fes_model::model::miso_ss::unit_params(2, ev)
        };
        rows.push(SsRow {
            model: if ev == Eigenvectors::Local {
                "general"
            } else {
                "restricted"
            }
            .into(),
            train_mse: miso::msse(&fit, train),
            test_mse: miso::msse(&fit, test),
            angles_rad: units
                .iter()
                .map(|&i| match ev {
                    Eigenvectors::Local => [fit.theta[off(i) + 2], fit.theta[off(i) + 3]],
                    Eigenvectors::Common => [fit.theta[0], fit.theta[1]],
                })
                .collect(),
            eigenvalues: units
                .iter()
                .map(|&i| {
                    [
                        eigenvalue_from_eta(fit.theta[off(i)], ts),
                        eigenvalue_from_eta(fit.theta[off(i) + 1], ts),
                    ]
                })
                .collect(),
        });
    }
    Ok(rows)
}

/// Runs App. E for one seed (module docs).
pub fn study(seed: u64) -> Result<Report, StudyError> {
    study_with_figures(seed, None)
}

/// [`study`], drawing the figures (PNG) into `figures_dir` when given ([`figures`]).
pub fn study_with_figures(
    seed: u64,
    figures_dir: Option<&std::path::Path>,
) -> Result<Report, StudyError> {
    study_with(&HeatParams::default(), seed, figures_dir)
}

/// [`study_with_figures`] on a plant with other parameters.
pub fn study_with(
    params: &HeatParams,
    seed: u64,
    figures_dir: Option<&std::path::Path>,
) -> Result<Report, StudyError> {
    let p = *params;
    let (delays_u, delays_a) = delays(&p)?;
    let (train, test) = records(&p, seed)?;

    let arx1 = arx1_study(&train, &test)?;
    let (learning, sims) = learning_study(&train, &test)?;
    let mut orderings = error_orderings(&arx1, &learning);
    let static_of = |u| {
        sims.get(&(u, "global"))
            .map(frozen_rows)
            .unwrap_or_default()
    };
    // E.4.7: the design model sees the channels (w, alpha), w = u^2 the heater power.
    let swapped = power_records(&train);
    let e44 = match sims.get(&(5, "global")) {
        Some(m) => m.clone(),
        None => fit_pair(5, Learning::Global, &train)?.1,
    };
    let state_space = state_space_study(&e44, &train, &test)?;
    let scheduling_2d = scheduling_2d(&train, &test)?;
    let close = |a: f64, b: f64| (a / b - 1.0).abs() <= 0.25;
    orderings.restricted_close_to_general = match state_space.as_slice() {
        [g, r] => Some(close(r.train_mse, g.train_mse) && close(r.test_mse, g.test_mse)),
        _ => None,
    };
    let cs = control::study(&p, &delays_u, &swapped, &e44)?;
    if let Some(dir) = figures_dir {
        figures::draw_all(dir, &p, seed, &sims, &e44, &cs, &state_space)?;
    }
    Ok(Report {
        seed,
        delays_u_samples: delays_u,
        delays_alpha_samples: delays_a,
        delays_u_table_e1: TEST_ANGLES_DEG
            .iter()
            .zip(TABLE_E1_DELAY_U)
            .map(|(&a, d)| (angle_key(a), d))
            .collect(),
        arx1,
        learning,
        orderings,
        state_space,
        scheduling_2d,
        static_5: static_of(5),
        static_10: static_of(10),
        control: cs.design,
        control_changed_plant: cs.changed,
        control_process: cs.process,
        windup: cs.windup,
        control_gains: cs.gains,
    })
}

/// E.4.2, Table E.2: the linear 1st-order ARX model fitted in prediction and in simulation mode.
fn arx1_study(train: &[MisoRecord], test: &[MisoRecord]) -> Result<Arx1, StudyError> {
    let (pred, sim) = fit_pair(1, Learning::Global, train)?;
    let (cp, cs) = (column(&pred, train, test)?, column(&sim, train, test)?);
    Ok(Arx1 {
        pole_prediction: cp.pole,
        pole_simulation: cs.pole,
        g_alpha: cs.g_alpha,
        g_u: cs.g_u,
        prediction: cp,
        simulation: cs,
    })
}

/// The fitted networks of E.4.3-E.4.4 by (units, `global` or `local`).
type Networks = BTreeMap<(usize, &'static str), MisoArx>;

/// E.4.3-E.4.4, Tables E.3-E.4: the 5- and 10-unit networks, global and local learning.
fn learning_study(
    train: &[MisoRecord],
    test: &[MisoRecord],
) -> Result<(Vec<LearningRow>, Networks), StudyError> {
    let mut learning = Vec::new();
    let mut sims = BTreeMap::new();
    for units in [5, 10] {
        for l in [Learning::Global, Learning::Local] {
            let (pm, sm) = fit_pair(units, l, train)?;
            let name = if l == Learning::Global {
                "global"
            } else {
                "local"
            };
            learning.push(LearningRow {
                units,
                learning: name.into(),
                pred_train_mspe: miso::mse(&pm, train, Horizon::Prediction)?,
                pred_train_msse: miso::mse(&pm, train, Horizon::Simulation)?,
                pred_test_msse: miso::mse(&pm, test, Horizon::Simulation)?,
                sim_train_msse: miso::mse(&sm, train, Horizon::Simulation)?,
                sim_test_msse: miso::mse(&sm, test, Horizon::Simulation)?,
            });
            sims.insert((units, name), sm);
        }
    }
    Ok((learning, sims))
}

/// The orderings of the errors the thesis reports, but the state-space one (set after E.4.5).
fn error_orderings(arx1: &Arx1, learning: &[LearningRow]) -> Orderings {
    let (cp, cs) = (&arx1.prediction, &arx1.simulation);
    // Rows in the order pushed: 5 global, 5 local, 10 global, 10 local.
    let [g5, l5, g10, l10] = [0, 1, 2, 3].map(|i| learning[i].clone());
    Orderings {
        simulation_beats_prediction: cs.train_mse < cp.train_mse
            && cs.test_mse < cp.test_mse
            && learning
                .iter()
                .all(|r| r.sim_train_msse < r.pred_train_msse),
        global_beats_local_in_simulation: g5.sim_train_msse < l5.sim_train_msse
            && g10.sim_train_msse < l10.sim_train_msse
            && g5.sim_test_msse < l5.sim_test_msse,
        global_beats_local_in_simulation_test_10: g10.sim_test_msse < l10.sim_test_msse,
        prediction_local_bias_and_regularisation: g5.pred_train_mspe < l5.pred_train_mspe
            && g10.pred_train_mspe < l10.pred_train_mspe
            && l10.pred_test_msse < g10.pred_test_msse,
        ten_units_generalise_worse: g10.sim_train_msse < g5.sim_train_msse
            && g10.sim_test_msse > g5.sim_test_msse,
        restricted_close_to_general: None,
    }
}

/// E.4.7: the training records on the channels (w, alpha), w = u^2 the heater power.
fn power_records(train: &[MisoRecord]) -> Vec<MisoRecord> {
    train
        .iter()
        .map(|r| MisoRecord {
            name: r.name.clone(),
            u: vec![
                r.u[1].iter().map(|&v| control::power(v)).collect(),
                r.u[0].clone(),
            ],
            y: r.y.clone(),
        })
        .collect()
}

// The integration tests (tests/it) compile into this crate's one test binary.
#[cfg(test)]
extern crate self as heat_transfer;
#[cfg(test)]
#[path = "../tests/it/main.rs"]
mod it;
