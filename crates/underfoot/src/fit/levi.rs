//! Levi's linearised least squares (what Octave's `invfreqz` does), and its
//! Sanathanan-Koerner / Steiglitz-McBride re-weighting.
//!
//! The output error `h_k - B(w_k)/A(w_k)` is non-linear in the denominator. Levi (1959)
//! multiplies through by `A`, which makes the *equation error* linear:
//!
//! ```math
//! \min_{b, a} \sum_k W_k \left| A(\omega_k) h_k - B(\omega_k) \right|^2,
//!   \quad A(\omega) = 1 + \sum_{i=1}^{N} a_i e^{-j\omega i},
//!   \quad B(\omega) = \sum_{i=0}^{M} b_i e^{-j\omega i}.
//! ```
//!
//! Stacking real and imaginary parts gives an ordinary real least-squares problem in the
//! `M + N + 1` unknowns, solved here by SVD after scaling each column to unit norm.
//!
//! The price of linearity is a bias: the error is weighted by `|A(w_k)|^2`, which is small
//! near resonances, so peaks are fitted loosely. Sanathanan and Koerner (1963) divide the
//! weights by `|A_{prev}(w_k)|^2` from the previous solution and iterate; at a fixed point the
//! equation error equals the output error. In the frequency domain this is the same
//! iteration Steiglitz and McBride run in the time domain.
//!
//! Nothing here guarantees stable poles; callers reflect them before use.

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

use super::{FitError, Target};
use crate::numeric::solve_scaled;
use crate::units::{Hz, SampleRate};

/// Levi's fit of a numerator of degree `nb` and denominator of degree `na` with per-point
/// weights `weight` (multiplying the target's own weights).
///
/// Returns `(b, a)` with `a[0] = 1`.
///
/// # Errors
/// [`FitError::Numerical`] when the least-squares problem cannot be solved.
pub fn levi(
    target: &Target,
    nb: usize,
    na: usize,
    weight: Option<&[f64]>,
) -> Result<(Vec<f64>, Vec<f64>), FitError> {
    let k = target.len();
    let cols = nb + 1 + na;
    let mut m = DMatrix::<f64>::zeros(2 * k, cols);
    let mut rhs = DVector::<f64>::zeros(2 * k);
    for i in 0..k {
        let w = (target.weight[i] * weight.map_or(1.0, |w| w[i])).sqrt();
        let h = target.h[i];
        let z1 = Complex64::from_polar(1.0, -target.omega[i]);
        let mut zp = Complex64::new(1.0, 0.0);
        for j in 0..=nb.max(na) {
            if j <= nb {
                // +B(w) term, moved to the left: B - (A - 1) h = h
                m[(2 * i, j)] = w * zp.re;
                m[(2 * i + 1, j)] = w * zp.im;
            }
            if j >= 1 && j <= na {
                let v = -h * zp;
                m[(2 * i, nb + j)] = w * v.re;
                m[(2 * i + 1, nb + j)] = w * v.im;
            }
            zp *= z1;
        }
        rhs[2 * i] = w * h.re;
        rhs[2 * i + 1] = w * h.im;
    }
    let x = solve_scaled(m, &rhs)?;
    let b = x.iter().take(nb + 1).copied().collect();
    let mut a = vec![1.0];
    a.extend(x.iter().skip(nb + 1).copied());
    Ok((b, a))
}

/// Sanathanan-Koerner iterations: `iterations` re-weighted solves started from `start`,
/// usually Levi's fit of the same degrees.
///
/// # Errors
/// As [`levi`].
pub fn sanathanan_koerner(
    target: &Target,
    start: (Vec<f64>, Vec<f64>),
    iterations: usize,
) -> Result<(Vec<f64>, Vec<f64>), FitError> {
    let (mut b, mut a) = start;
    let (nb, na) = (b.len().saturating_sub(1), a.len().saturating_sub(1));
    let mut w = vec![1.0; target.len()];
    for _ in 0..iterations {
        for (wi, &om) in w.iter_mut().zip(&target.omega) {
            let den = eval_poly(&a, om).norm_sqr();
            *wi = 1.0 / den.max(1e-300);
        }
        let (nb2, na2) = levi(target, nb, na, Some(&w))?;
        if nb2.iter().chain(&na2).any(|c| !c.is_finite()) {
            break;
        }
        (b, a) = (nb2, na2);
    }
    Ok((b, a))
}

/// `p(e^{j w})` for coefficients of `z^0, z^-1, ...`.
#[must_use]
pub fn eval_poly(p: &[f64], omega: f64) -> Complex64 {
    let z1 = Complex64::from_polar(1.0, -omega);
    p.iter()
        .rev()
        .fold(Complex64::new(0.0, 0.0), |acc, &c| acc * z1 + c)
}

/// `|B/A|` of an expanded filter (as Levi's fit returns it, unstable poles and all) at
/// each of `freqs`, for a filter running at `rate`.
#[must_use]
pub fn magnitude_on(b: &[f64], a: &[f64], rate: SampleRate, freqs: &[Hz]) -> Vec<f64> {
    freqs
        .iter()
        .map(|&f| {
            let w = rate.omega(f);
            (eval_poly(b, w) / eval_poly(a, w)).norm()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{Band, SampleRate};

    /// On noisy data Levi's equation error under-weights the resonance; re-weighting by
    /// `1/|A|^2` brings the fit closer in output error, which is what it is for.
    #[test]
    fn sanathanan_koerner_lowers_the_output_error_of_levi() {
        use crate::signal::noise::SplitMix64;
        let rate = SampleRate(2000);
        let b = [0.05, 0.02, -0.01, 0.004, 0.001];
        let a = crate::signal::sos::poly_mul(&[1.0, -1.9, 0.97], &[1.0, -0.6, 0.5]);
        let freqs = Band::new(10.0, 950.0).log_grid(150);
        let mut rng = SplitMix64::new(5);
        let h = freqs
            .iter()
            .map(|&f| {
                let w = rate.omega(f);
                let noise = Complex64::new(rng.normal(), rng.normal()) * 0.02;
                eval_poly(&b, w) / eval_poly(&a, w) * (1.0 + noise)
            })
            .collect();
        let t = Target::from_response(rate, &freqs, h).unwrap();
        let output_error = |(fb, fa): &(Vec<f64>, Vec<f64>)| -> f64 {
            t.omega
                .iter()
                .zip(&t.h)
                .map(|(&w, hk)| (eval_poly(fb, w) / eval_poly(fa, w) - hk).norm_sqr())
                .sum()
        };
        let start = levi(&t, 4, 4, None).unwrap();
        let sk = sanathanan_koerner(&t, start.clone(), 5).unwrap();
        assert!(
            output_error(&sk) < 0.9 * output_error(&start),
            "SK {} vs Levi {}",
            output_error(&sk),
            output_error(&start)
        );
    }

    /// With exact data, the equation error is zero at the true filter: Levi recovers it.
    #[test]
    fn levi_recovers_exact_low_order_filter() {
        let rate = SampleRate(2000);
        let b = [0.3, -0.1, 0.05];
        let a = [1.0, -1.2, 0.7];
        let freqs = Band::new(10.0, 950.0).log_grid(100);
        let h = freqs
            .iter()
            .map(|&f| eval_poly(&b, rate.omega(f)) / eval_poly(&a, rate.omega(f)))
            .collect();
        let t = Target::from_response(rate, &freqs, h).unwrap();
        let (fb, fa) = levi(&t, 2, 2, None).unwrap();
        for (x, y) in fb.iter().zip(&b).chain(fa.iter().zip(&a)) {
            assert!((x - y).abs() < 1e-9, "{fb:?} {fa:?}");
        }
    }
}
