//! Linear least squares (thesis B.2): theta* = Psi^+ y (eq. B.14) with the pseudo-inverse
//! from a singular value decomposition, never from [Psi' Psi]^-1 (eq. B.15 squares the
//! condition number; the thesis recommends SVD).
//!
//! Columns are scaled to unit norm first (a diagonal change of variables that leaves the
//! solution unchanged when the problem is well posed), the tall matrix is reduced by a
//! Householder QR, and the SVD of the small triangular factor gives the pseudo-inverse;
//! singular values below `rcond` times the largest are treated as zero (the minimum-norm
//! solution of a rank-deficient problem, e.g. a unit the data never activate).

use nalgebra::{DMatrix, DVector};

/// Relative threshold on singular values used by [`solve`] when none is given.
pub const DEFAULT_RCOND: f64 = 1e-12;

/// Why a least-squares problem could not be solved.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LsqError {
    /// The right-hand side does not match the matrix.
    #[error("least squares: {rows} rows in the matrix but {rhs} in the right-hand side")]
    Shape {
        /// Matrix rows.
        rows: usize,
        /// Right-hand side length.
        rhs: usize,
    },
    /// A non-finite entry.
    #[error("least squares: the regression matrix or data contain non-finite values")]
    NonFinite,
    /// The SVD did not converge.
    #[error("least squares: the singular value decomposition did not converge")]
    Svd,
}

/// Solution of min ||a x - b|| (minimum norm if rank deficient) and the numerical rank.
#[derive(Debug, Clone, PartialEq)]
pub struct LsqSolution {
    /// x.
    pub x: DVector<f64>,
    /// Number of singular values kept.
    pub rank: usize,
}

/// Solves min ||a x - b|| by QR + SVD with relative singular-value threshold `rcond`.
pub fn solve(a: &DMatrix<f64>, b: &DVector<f64>, rcond: f64) -> Result<LsqSolution, LsqError> {
    let (m, n) = a.shape();
    if b.len() != m {
        return Err(LsqError::Shape {
            rows: m,
            rhs: b.len(),
        });
    }
    if !(a.iter().all(|v| v.is_finite()) && b.iter().all(|v| v.is_finite())) {
        return Err(LsqError::NonFinite);
    }
    if n == 0 {
        return Ok(LsqSolution {
            x: DVector::zeros(0),
            rank: 0,
        });
    }
    // Column scaling.
    let scale: Vec<f64> = (0..n)
        .map(|j| {
            let s = a.column(j).norm();
            if s > 0.0 { 1.0 / s } else { 1.0 }
        })
        .collect();
    let mut a_s = a.clone();
    for (j, s) in scale.iter().enumerate() {
        a_s.column_mut(j).scale_mut(*s);
    }
    // Reduce a tall problem to n x n with QR.
    let (r, rhs) = if m > n {
        let qr = a_s.qr();
        let mut qtb = b.clone();
        qr.q_tr_mul(&mut qtb);
        (qr.r(), qtb.rows(0, n).into_owned())
    } else {
        (a_s, b.clone())
    };
    let svd =
        nalgebra::linalg::SVD::try_new(r, true, true, f64::EPSILON, 0).ok_or(LsqError::Svd)?;
    let smax = svd.singular_values.iter().fold(0.0f64, |a, &s| a.max(s));
    let tol = rcond * smax;
    let rank = svd.singular_values.iter().filter(|&&s| s > tol).count();
    let (Some(u), Some(vt)) = (&svd.u, &svd.v_t) else {
        return Err(LsqError::Svd);
    };
    let mut y = u.tr_mul(&rhs);
    for (i, s) in svd.singular_values.iter().enumerate() {
        y[i] = if *s > tol { y[i] / s } else { 0.0 };
    }
    let mut x = vt.tr_mul(&y);
    for (j, s) in scale.iter().enumerate() {
        x[j] *= s;
    }
    Ok(LsqSolution { x, rank })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Overdetermined: the solution satisfies the normal equations (B.12).
    #[test]
    fn satisfies_normal_equations() {
        let a = DMatrix::from_fn(40, 3, |i, j| ((i * 7 + j * 3) % 11) as f64 - 5.0 + j as f64);
        let b = DVector::from_fn(40, |i, _| (i as f64 * 0.37).sin());
        let s = solve(&a, &b, DEFAULT_RCOND).unwrap();
        assert_eq!(s.rank, 3);
        let res = a.tr_mul(&(&a * &s.x - &b));
        assert!(res.norm() < 1e-10, "{res}");
    }

    /// Rank-deficient (duplicate column): the minimum-norm solution splits the weight.
    #[test]
    fn rank_deficient_gives_minimum_norm() {
        let a = DMatrix::from_fn(10, 2, |i, _| i as f64 + 1.0);
        let b = DVector::from_fn(10, |i, _| 2.0 * (i as f64 + 1.0));
        let s = solve(&a, &b, 1e-10).unwrap();
        assert_eq!(s.rank, 1);
        assert!((s.x[0] - 1.0).abs() < 1e-10 && (s.x[1] - 1.0).abs() < 1e-10);
    }
}
