//! Linear least squares through a guarded SVD.
//!
//! [`svd`] is the one way the crate takes a singular value decomposition: nalgebra's
//! implicit QR iteration never ends on a matrix with a non-finite entry, so such a
//! matrix is refused before it starts, and the sweeps are capped
//! ([`SVD_SWEEPS_PER_COLUMN`] per column) so that a matrix that will not converge is an
//! error rather than a hang.
//!
//! [`solve_scaled`] solves `$\min_x \lVert M x - y \rVert_2$` with the columns of `$M$`
//! first scaled to unit norm, `$M = \tilde M S^{-1}$`, `$x = S \tilde x$`: the scaling makes
//! the cut-off on small singular values (`$\sigma < 10^{-13} \sigma_{\max}$`) relative to
//! each column's own size, so columns of very different magnitudes (powers of a
//! frequency, say) do not look rank deficient.

use nalgebra::{DMatrix, DVector, Dyn, SVD};

/// Most sweeps of the SVD's implicit QR iteration per column: a well-posed matrix needs a
/// few; a few hundred mean it will not converge.
pub const SVD_SWEEPS_PER_COLUMN: usize = 300;

/// Why a least-squares solve failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct NumericalError(pub &'static str);

/// The thin SVD of `m`, with its singular vectors.
///
/// # Errors
/// An entry of `m` is not finite, or the iteration did not converge within
/// [`SVD_SWEEPS_PER_COLUMN`] sweeps per column.
pub fn svd(m: DMatrix<f64>) -> Result<SVD<f64, Dyn, Dyn>, NumericalError> {
    if m.iter().any(|v| !v.is_finite()) {
        return Err(NumericalError(
            "a least-squares matrix has a non-finite entry",
        ));
    }
    let max_iterations = SVD_SWEEPS_PER_COLUMN * (m.nrows().min(m.ncols()) + 1);
    SVD::try_new(m, true, true, f64::EPSILON, max_iterations)
        .ok_or(NumericalError("the SVD did not converge"))
}

/// The least-squares solution of `m x = rhs` with unit-norm columns (see the module docs).
///
/// # Errors
/// `rhs` or the solution is not finite, or the SVD fails.
pub fn solve_scaled(
    mut m: DMatrix<f64>,
    rhs: &DVector<f64>,
) -> Result<DVector<f64>, NumericalError> {
    let mut scale = vec![1.0; m.ncols()];
    for (j, s) in scale.iter_mut().enumerate() {
        let n = m.column(j).norm();
        if n > 0.0 {
            *s = 1.0 / n;
            m.column_mut(j).scale_mut(*s);
        }
    }
    if rhs.iter().any(|v| !v.is_finite()) {
        return Err(NumericalError("a least-squares target is not finite"));
    }
    let svd = svd(m)?;
    let tol = svd.singular_values.max() * 1e-13;
    let mut x = svd.solve(rhs, tol).map_err(NumericalError)?;
    for (xi, s) in x.iter_mut().zip(&scale) {
        *xi *= s;
    }
    if x.iter().any(|v| !v.is_finite()) {
        return Err(NumericalError("least-squares solution is not finite"));
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svd_refuses_non_finite_entries_instead_of_spinning() {
        let start = std::time::Instant::now();
        let m = || DMatrix::from_fn(40, 8, |i, k| ((i * 7 + k * 3) % 11) as f64);
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut with = m();
            with[(17, 3)] = bad;
            assert!(svd(with).is_err(), "{bad}");
        }
        assert_eq!(svd(m()).unwrap().singular_values.len(), 8);
        assert!(start.elapsed() < std::time::Duration::from_secs(5));
    }
}
