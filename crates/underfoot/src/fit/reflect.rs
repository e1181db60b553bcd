//! Unstable poles of a linear start, reflected into the unit circle.
//!
//! A pole `$p$` with `$|p| \ge 1$` becomes `$1/\bar p$`: since
//! `$|1 - p e^{-j\omega}| = |p|\,|1 - \bar p^{-1} e^{-j\omega}|$`, the magnitude response
//! keeps its shape up to the constant `$|p|$`, which the returned gain compensates.

use num_complex::Complex64;

/// Reflects poles outside the unit circle to `1/conj(p)`, which keeps the magnitude
/// response's shape (up to a constant gain per reflected pole, compensated here).
///
/// Used only to make a linear initial guess usable; the refinements never leave the
/// stable region in the first place.
#[must_use]
pub fn reflect_unstable(poles: &[Complex64], max_radius: f64) -> (Vec<Complex64>, f64) {
    let mut gain = 1.0;
    let out = poles
        .iter()
        .map(|&p| {
            let r = p.norm();
            if r >= 1.0 {
                // |1 - p e^{-jw}| = |p| |1 - (1/p*) e^{-jw}|: compensate |p|.
                gain /= r;
                let q = 1.0 / p.conj();
                if q.norm() > max_radius {
                    q * (max_radius / q.norm())
                } else {
                    q
                }
            } else if r > max_radius {
                p * (max_radius / r)
            } else {
                p
            }
        })
        .collect();
    (out, gain)
}
