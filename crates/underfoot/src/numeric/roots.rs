//! Polynomial roots, from the eigenvalues of the companion matrix.
//!
//! For `$c_0 z^m + c_1 z^{m-1} + \dots + c_m$` the companion matrix has first row
//! `$-c_{1..m} / c_0$` and ones on its subdiagonal; its eigenvalues, from the real Schur
//! form, are the roots, so complex roots arrive as exact conjugate pairs. The Schur
//! iteration is capped, and a non-finite coefficient is refused before it starts.

use nalgebra::{DMatrix, Schur};
use num_complex::Complex64;

/// The roots in `z` of `c[0] z^m + c[1] z^(m-1) + ... + c[m]`, i.e. of the `z^-1` polynomial
/// `c[0] + c[1] z^-1 + ... + c[m] z^-m`. Leading zeros of `c` must have been stripped.
///
/// Returns `None` when the eigenvalue iteration does not converge or a coefficient is not finite.
#[must_use]
pub fn roots(c: &[f64]) -> Option<Vec<Complex64>> {
    let m = c.len().saturating_sub(1);
    if m == 0 {
        return Some(Vec::new());
    }
    if c.iter().any(|v| !v.is_finite()) || c[0] == 0.0 {
        return None;
    }
    let mut comp = DMatrix::<f64>::zeros(m, m);
    for j in 0..m {
        comp[(0, j)] = -c[j + 1] / c[0];
    }
    for i in 1..m {
        comp[(i, i - 1)] = 1.0;
    }
    let schur = Schur::try_new(comp, f64::EPSILON, 100_000)?;
    Some(schur.complex_eigenvalues().iter().copied().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_known_polynomial() {
        // (z - 0.5)(z^2 - 1.6z + 0.89) -> roots 0.5, 0.8 +- 0.5j
        let c = [1.0, -2.1, 1.69, -0.445];
        let mut r = roots(&c).unwrap();
        r.sort_by(|x, y| x.im.total_cmp(&y.im));
        assert!((r[0] - Complex64::new(0.8, -0.5)).norm() < 1e-12);
        assert!((r[1] - Complex64::new(0.5, 0.0)).norm() < 1e-12);
        assert!((r[2] - Complex64::new(0.8, 0.5)).norm() < 1e-12);
    }
}
