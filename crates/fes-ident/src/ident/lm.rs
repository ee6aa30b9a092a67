//! Levenberg-Marquardt (thesis B.3.2, eq. B.29-B.30) on any [`LeastSquares`] problem (a
//! network's [`Problem`], or the multi-input ARX problems of [`super::miso`]).
//!
//! At p the (exact) Jacobian J gives g = J' r and the Gauss-Newton Hessian H = J' J
//! (eq. B.21-B.24; the factors 2 cancel). The step solves (H + lambda D) delta = -g with D
//! the diagonal of H (eq. B.29: the diagonal multiplied by 1 + lambda); a diagonal entry that
//! is zero (a parameter without effect on the data) is replaced by 1e-12 times the largest,
//! so the system stays positive definite. The trial point is evaluated with a plain f64
//! simulation:
//! - cost decreased: accept, lambda / 10 (towards Newton-Raphson, eq. B.26);
//! - otherwise (also when the trial model cannot be run or diverges): reject,
//!   lambda x 10 (towards steepest descent, eq. B.28), solve again with the same J.
//!
//! Parameters are kept inside the box their [`ParamMap::bounds`] give: the trial point is
//! projected onto it (a projected LM step). Bounds only cut off directions in which the
//! cost flattens out: an eigenvalue parameter eta running off to infinity makes the LM
//! crawl (each step gains almost nothing) while the eigenvalue is already at 0 or -1/Ts to
//! machine precision.
//!
//! Stopping rules ([`StopReason`]), checked after every accepted step:
//! 1. two consecutive accepted steps each reduced the cost by less than `rel_tol` (relative)
//!    -> `Converged`;
//! 2. the last `window` accepted steps together reduced the cost by less than `window_tol`
//!    (relative) -> `Converged`: the search is crawling along a flat valley, typically a
//!    parameter the data hardly determine drifting towards the edge of its range (an
//!    eigenvalue of a barely reached unit running to 0, pitfall (d)); the remaining gain
//!    is below what the error measures resolve;
//! 3. the cost is zero -> `Converged`;
//! 4. lambda exceeded `lambda_max` without an accepted step (no descent direction left at
//!    working precision) -> `Stalled`;
//! 5. `max_iter` accepted steps -> `MaxIterations`.
//!
//! An *iteration* is one accepted step, i.e. one Jacobian evaluation.

use super::problem::{Normal, ParamMap, Problem, ProblemError};
use nalgebra::{Cholesky, DMatrix, DVector};

/// A sum-of-squares problem the search can minimise: its cost, its normal equations over
/// chosen columns and the box its parameters stay in. The muscle network's [`Problem`]
/// is one; the multi-input ARX networks of App. E ([`super::miso`]) are another, so both
/// share this one implementation of B.3.2.
pub trait LeastSquares: Sync {
    /// Box bounds (lo, hi) per parameter.
    fn bounds(&self) -> Vec<(f64, f64)>;
    /// Sum of squared residuals at p (plus any prior).
    fn cost(&self, p: &[f64]) -> Result<f64, ProblemError>;
    /// cost, J' r and J' J at p over the columns `cols`.
    fn normal(&self, p: &[f64], cols: &[usize]) -> Result<Normal, ProblemError>;
}

impl<M: ParamMap> LeastSquares for Problem<'_, M> {
    fn bounds(&self) -> Vec<(f64, f64)> {
        self.map.bounds()
    }
    fn cost(&self, p: &[f64]) -> Result<f64, ProblemError> {
        Problem::cost(self, p)
    }
    fn normal(&self, p: &[f64], cols: &[usize]) -> Result<Normal, ProblemError> {
        Problem::normal(self, p, cols)
    }
}

/// Settings of [`levenberg_marquardt`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    /// Maximum number of accepted steps (Jacobian evaluations).
    pub max_iter: usize,
    /// Initial lambda.
    pub lambda0: f64,
    /// Relative cost decrease below which an accepted step counts as "no progress".
    pub rel_tol: f64,
    /// lambda above which the search gives up (rule 4).
    pub lambda_max: f64,
    /// Number of accepted steps of rule 2.
    pub window: usize,
    /// Relative decrease over `window` steps below which rule 2 stops.
    pub window_tol: f64,
}

impl Default for LmOptions {
    /// max_iter 200, lambda0 1e-3 (Press et al.), rel_tol 1e-6, lambda_max 1e10, window
    /// 10 steps, window_tol 1e-3.
    fn default() -> Self {
        Self {
            max_iter: 200,
            lambda0: 1e-3,
            rel_tol: 1e-6,
            lambda_max: 1e10,
            window: 10,
            window_tol: 1e-3,
        }
    }
}

/// Why the search ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The cost no longer decreases (rules 1-2).
    Converged,
    /// No descent step could be found (rule 3).
    Stalled,
    /// The iteration limit was reached (rule 4).
    MaxIterations,
}

impl core::fmt::Display for StopReason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Converged => "converged",
            Self::Stalled => "stalled (no descent step)",
            Self::MaxIterations => "iteration limit",
        })
    }
}

/// Result of [`levenberg_marquardt`].
#[derive(Debug, Clone, PartialEq)]
pub struct LmReport {
    /// The parameters found.
    pub p: Vec<f64>,
    /// Their cost (sum of squared residuals).
    pub cost: f64,
    /// The starting cost.
    pub initial_cost: f64,
    /// Accepted steps (= Jacobian evaluations after the first).
    pub iterations: usize,
    /// Trial evaluations (f64 simulations), accepted or not.
    pub evaluations: usize,
    /// Why it stopped.
    pub stop: StopReason,
    /// Final lambda.
    pub lambda: f64,
}

/// The inner loop of [`levenberg_marquardt`]: solves the damped normal equations
/// (H + lambda diag(H)) delta = -g, raising lambda tenfold until a step within the bounds
/// decreases the cost; the trial point and its cost, or `None` once lambda passes
/// `lambda_max`. Counts the cost evaluations.
#[allow(clippy::too_many_arguments)]
fn damped_step<P: LeastSquares>(
    problem: &P,
    p: &[f64],
    free: &[usize],
    bounds: &[(f64, f64)],
    normal: &Normal,
    lambda: &mut f64,
    lambda_max: f64,
    evaluations: &mut usize,
) -> Option<(Vec<f64>, f64)> {
    let n = free.len();
    let dmax = normal.h.diagonal().iter().fold(0.0f64, |a, &v| a.max(v));
    let floor = 1e-12 * dmax.max(f64::MIN_POSITIVE);
    loop {
        if *lambda > lambda_max {
            return None;
        }
        let mut a: DMatrix<f64> = normal.h.clone();
        for k in 0..n {
            a[(k, k)] += *lambda * normal.h[(k, k)].max(floor);
        }
        let Some(chol) = Cholesky::new(a) else {
            *lambda *= 10.0;
            continue;
        };
        let delta: DVector<f64> = chol.solve(&(-&normal.g));
        let mut trial = p.to_vec();
        for (k, &i) in free.iter().enumerate() {
            let (lo, hi) = bounds[i];
            trial[i] = (trial[i] + delta[k]).clamp(lo, hi);
        }
        *evaluations += 1;
        match problem.cost(&trial) {
            Ok(c) if c.is_finite() && c < normal.cost => return Some((trial, c)),
            _ => *lambda *= 10.0,
        }
    }
}

/// Minimises the problem's sum of squared residuals over the parameters `free` (the others
/// stay at their value in `p0`), starting from `p0` (projected into the bounds). `on_step(iteration, cost)` is called
/// after every accepted step. Fails only if the starting point cannot be evaluated.
pub fn levenberg_marquardt<P: LeastSquares>(
    problem: &P,
    p0: &[f64],
    free: &[usize],
    opts: &LmOptions,
    on_step: &mut dyn FnMut(usize, f64),
) -> Result<LmReport, ProblemError> {
    let bounds = problem.bounds();
    let mut p: Vec<f64> = p0
        .iter()
        .zip(&bounds)
        .map(|(v, (lo, hi))| v.clamp(*lo, *hi))
        .collect();
    let mut normal = problem.normal(&p, free)?;
    // Costs are compared in plain f64 (the dual value can differ in the last bits).
    normal.cost = problem.cost(&p)?;
    let initial_cost = normal.cost;
    let mut lambda = opts.lambda0;
    let mut iterations = 0;
    let mut evaluations = 0;
    let mut small_steps = 0;
    let mut history = vec![normal.cost];
    let n = free.len();
    let stop = loop {
        if normal.cost == 0.0 || n == 0 {
            break StopReason::Converged;
        }
        if iterations >= opts.max_iter {
            break StopReason::MaxIterations;
        }
        let accepted = damped_step(
            problem,
            &p,
            free,
            &bounds,
            &normal,
            &mut lambda,
            opts.lambda_max,
            &mut evaluations,
        );
        let Some((trial, c)) = accepted else {
            break StopReason::Stalled;
        };
        let decrease = (normal.cost - c) / normal.cost;
        p = trial;
        lambda = (lambda / 10.0).max(1e-12);
        iterations += 1;
        match problem.normal(&p, free) {
            Ok(nrm) => normal = Normal { cost: c, ..nrm },
            Err(_) => {
                // The Jacobian at the accepted point cannot be formed (should not happen
                // when its value could): keep the point, stop here.
                normal.cost = c;
                on_step(iterations, c);
                break StopReason::Stalled;
            }
        }
        on_step(iterations, normal.cost);
        small_steps = if decrease < opts.rel_tol {
            small_steps + 1
        } else {
            0
        };
        history.push(normal.cost);
        if small_steps >= 2 {
            break StopReason::Converged;
        }
        if opts.window > 0 && history.len() > opts.window {
            let old = history[history.len() - 1 - opts.window];
            if old - normal.cost < opts.window_tol * old {
                break StopReason::Converged;
            }
        }
    };
    Ok(LmReport {
        p,
        cost: normal.cost,
        initial_cost,
        iterations,
        evaluations,
        stop,
        lambda,
    })
}
