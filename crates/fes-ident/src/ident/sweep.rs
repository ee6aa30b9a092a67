//! Network sizes swept (thesis Figs. 5.13-5.21) and the comparison of every scheduling /
//! domain / estimation-mode combination (Tables 5.1 and 5.2).
//!
//! The thesis's rule for the network size: fit each size and keep the one with the lowest
//! **test** MSSE ([`best_by_test`]); a fit whose simulation diverges never wins.

use super::IdentError;
use super::identify::{Hooks, IdentOptions, Identified, Mode, SchedulingKind, identify};
use super::metrics::Metrics;
use super::records::RecordSet;
use super::regression::Learning;
use fes_model::model::lmn::{Lmn, Structure};
use serde::Serialize;
use std::ops::RangeInclusive;

/// One fitted size.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepRow {
    /// Number of units.
    pub units: usize,
    /// Training MSPE (ARX only; `None` if undefined or diverging).
    pub train_mspe: Option<f64>,
    /// Training MSSE (`None` if the simulation diverges).
    pub train_msse: Option<f64>,
    /// Test MSSE (`None` if the simulation diverges).
    pub test_msse: Option<f64>,
    /// Test NRMSE fit, % ([`super::validation`]).
    pub test_fit_percent: Option<f64>,
    /// Test RRSE.
    pub test_rrse: Option<f64>,
    /// LM iterations over all stages.
    pub iterations: usize,
    /// Fit time, s.
    pub seconds: f64,
    /// Every local model stable (|1 + Ts p| < 1).
    pub stable: bool,
    /// Number of warnings of the fit.
    pub warnings: usize,
}

impl SweepRow {
    /// The row of a fit.
    pub fn of(units: usize, r: &Identified) -> Self {
        let f = |v: f64| v.is_finite().then_some(v);
        let Metrics {
            train_mspe,
            train_msse,
            test_msse,
        } = r.metrics;
        Self {
            units,
            train_mspe: train_mspe.and_then(f),
            train_msse: f(train_msse),
            test_msse: f(test_msse),
            test_fit_percent: r.validation.test_fit_percent.and_then(f),
            test_rrse: r.validation.test_rrse.and_then(f),
            iterations: r.iterations,
            seconds: r.seconds,
            stable: r.lmn.stability().iter().all(|s| s.stable),
            warnings: r.warnings.len(),
        }
    }
}

/// Index of the row with the lowest finite test MSSE (the thesis's choice of size).
pub fn best_by_test(rows: &[SweepRow]) -> Option<usize> {
    rows.iter()
        .enumerate()
        .filter_map(|(i, r)| r.test_msse.map(|t| (i, t)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// A sweep: one row and one model per size.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// Rows in size order.
    pub rows: Vec<SweepRow>,
    /// The models, same order.
    pub models: Vec<Lmn>,
    /// [`best_by_test`] of the rows.
    pub best: Option<usize>,
}

/// Fits `base` with every number of units in `units`. `on_fit(units, result)` sees each fit
/// as it finishes.
pub fn sweep(
    records: &RecordSet,
    base: &IdentOptions,
    units: RangeInclusive<usize>,
    hooks: &Hooks<'_>,
    on_fit: &mut dyn FnMut(usize, &Identified),
) -> Result<Sweep, IdentError> {
    if units.is_empty() {
        return Err(IdentError::Option {
            option: "unit range",
            value: format!("{}..={}", units.start(), units.end()),
            allowed: "non-empty".into(),
        });
    }
    let mut rows = Vec::new();
    let mut models = Vec::new();
    for m in units {
        let opts = IdentOptions {
            units: m,
            ..base.clone()
        };
        let r = identify(records, &opts, hooks)?;
        on_fit(m, &r);
        rows.push(SweepRow::of(m, &r));
        models.push(r.lmn);
    }
    let best = best_by_test(&rows);
    Ok(Sweep { rows, models, best })
}

/// One row of the comparison: a setup of Table 5.1 / 5.2 and the network sizes (and model
/// periods) it tries.
#[derive(Debug, Clone, PartialEq)]
pub struct Setup {
    /// Scheduling column: `(linear)`, `output` or `input`.
    pub scheduling: &'static str,
    /// Parameter-domain / structure column: `shift`, `delta`, `ss, local eigenvectors`, ...
    pub domain: &'static str,
    /// Estimation mode.
    pub mode: Mode,
    /// The options (units set per fit).
    pub options: IdentOptions,
    /// Sizes tried.
    pub units: RangeInclusive<usize>,
    /// Model periods tried, in data samples (best test MSSE wins); empty: use the period
    /// the best linear shift model of the same mode chose (as the thesis, 5.4.1).
    pub ts_factors: Vec<usize>,
}

/// Unit ranges of [`setups`]: prediction-mode rows (least squares is cheap), then
/// simulation-mode rows.
pub const COMPARE_UNITS: (usize, usize) = (12, 8);
/// Unit range of every network row with `quick`.
pub const QUICK_UNITS: usize = 3;

/// The rows of Table 5.1 (linear, output and input scheduling; shift and delta; prediction
/// and simulation) and Table 5.2 (state space, local and common eigenvectors) plus the
/// zero-offset common-eigenvector row (6.5.3). Shift models try Ts = 1, 5, 10 data samples
/// (linear rows) or the linear rows' best period (network rows); `quick` sweeps only 1..=3
/// units with at most 30 LM iterations (for tests).
pub fn setups(quick: bool, seed: u64) -> Vec<Setup> {
    let (pred_max, sim_max) = if quick {
        (QUICK_UNITS, QUICK_UNITS)
    } else {
        COMPARE_UNITS
    };
    let base = IdentOptions {
        seed,
        max_iter: if quick { 30 } else { 200 },
        learning: Learning::Local,
        ..IdentOptions::default()
    };
    ROWS.iter()
        .map(
            |&Row(scheduling, domain, structure, mode, kind, zero_offsets)| Setup {
                scheduling,
                domain,
                mode,
                options: IdentOptions {
                    structure,
                    mode,
                    scheduling: kind,
                    zero_offsets,
                    ..base.clone()
                },
                units: match (scheduling, mode) {
                    ("(linear)", _) => 1..=1,
                    (_, Mode::Prediction) => 1..=pred_max,
                    (_, Mode::Simulation) => 1..=sim_max,
                },
                ts_factors: match (scheduling, structure) {
                    ("(linear)", Structure::ArxShift) => vec![1, 5, 10],
                    (_, Structure::ArxShift) => Vec::new(),
                    _ => vec![1],
                },
            },
        )
        .collect()
}

/// One row of Tables 5.1 / 5.2 as [`setups`] builds it: scheduling, domain, structure,
/// mode, scheduling kind, zero offsets. Linear rows fit one unit and try the periods 1, 5
/// and 10 (shift) or 1 (delta); network shift rows take the linear rows' best period;
/// delta and state-space rows run at the data's period.
struct Row(
    &'static str,
    &'static str,
    Structure,
    Mode,
    SchedulingKind,
    bool,
);

/// The rows, in the order of the tables.
const ROWS: [Row; 11] = {
    use Mode::{Prediction as P, Simulation as S};
    use SchedulingKind::{Input as I, Output as O};
    use Structure::*;
    [
        Row("(linear)", "shift", ArxShift, P, I, false),
        Row("(linear)", "shift", ArxShift, S, I, false),
        Row("(linear)", "delta", ArxDelta, S, I, false),
        Row("output", "shift", ArxShift, P, O, false),
        Row("output", "delta", ArxDelta, S, O, false),
        Row("input", "shift", ArxShift, P, I, false),
        Row("input", "shift", ArxShift, S, I, false),
        Row("input", "delta", ArxDelta, S, I, false),
        Row("input", "ss, local eigenvectors", SsEigLocal, S, I, false),
        Row("input", "ss, common eigenvectors", SsEigCommon, S, I, false),
        Row(
            "input",
            "ss, common eigenvectors, zero offsets",
            SsEigCommon,
            S,
            I,
            true,
        ),
    ]
};

/// One row of the comparison table: the best size (and period) of a setup.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CompareRow {
    /// Scheduling column.
    pub scheduling: String,
    /// Domain / structure column.
    pub domain: String,
    /// `pred.` or `sim.`.
    pub mode: String,
    /// Structure name.
    pub structure: String,
    /// Model period, ms.
    pub ts_ms: f64,
    /// Sizes tried.
    pub units_tried: (usize, usize),
    /// The best size's row (`None` if every fit diverged).
    pub best: Option<SweepRow>,
    /// Total fit time of the setup, s.
    pub seconds: f64,
}

/// Runs every setup ([`setups`]) and returns one row each. `on_fit(setup, ts_factor,
/// units, result)` sees every fit.
pub fn compare(
    records: &RecordSet,
    setups: &[Setup],
    hooks: &Hooks<'_>,
    on_fit: &mut dyn FnMut(&Setup, usize, usize, &Identified),
) -> Result<Vec<CompareRow>, IdentError> {
    let mut rows: Vec<CompareRow> = Vec::new();
    // The best linear shift period per mode (rows 1 and 2), reused by the network rows.
    let mut linear_ts: [Option<usize>; 2] = [None, None];
    let data_ms = records.ts * 1e3;
    for s in setups {
        let mode_ix = usize::from(s.mode == Mode::Simulation);
        let factors = if s.ts_factors.is_empty() {
            vec![linear_ts[mode_ix].unwrap_or(1)]
        } else {
            s.ts_factors.clone()
        };
        let mut best: Option<(SweepRow, usize)> = None;
        let mut seconds = 0.0;
        for &f in &factors {
            let base = IdentOptions {
                ts_factor: f,
                ..s.options.clone()
            };
            let sw = sweep(records, &base, s.units.clone(), hooks, &mut |m, r| {
                on_fit(s, f, m, r)
            })?;
            seconds += sw.rows.iter().map(|r| r.seconds).sum::<f64>();
            if let Some(b) = sw.best {
                let row = sw.rows[b].clone();
                let better = best
                    .as_ref()
                    .is_none_or(|(cur, _)| row.test_msse < cur.test_msse);
                if better {
                    best = Some((row, f));
                }
            }
        }
        let f = best.as_ref().map_or(factors[0], |b| b.1);
        if s.scheduling == "(linear)" && s.options.structure == Structure::ArxShift {
            linear_ts[mode_ix] = Some(f);
        }
        rows.push(CompareRow {
            scheduling: s.scheduling.into(),
            domain: s.domain.into(),
            mode: match s.mode {
                Mode::Prediction => "pred.".into(),
                Mode::Simulation => "sim.".into(),
            },
            structure: s.options.structure.name().into(),
            ts_ms: f as f64 * data_ms,
            units_tried: (*s.units.start(), *s.units.end()),
            best: best.map(|b| b.0),
            seconds,
        });
    }
    Ok(rows)
}
