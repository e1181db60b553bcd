//! Vector fitting in the `z` domain: poles relocated by linear solves in a partial-fraction
//! basis, which stays well conditioned where polynomial coefficients do not.
//!
//! The model is a sum of partial fractions
//!
//! ```math
//! H(z) = d + \sum_i \frac{r_i}{z - p_i},
//! ```
//!
//! written with real unknowns: a real pole contributes `r/(z-p)`; a conjugate pair `p, p*`
//! contributes `c_1 \psi_1 + c_2 \psi_2` with `\psi_1 = 1/(z-p) + 1/(z-p^*)` and
//! `\psi_2 = j/(z-p) - j/(z-p^*)`. In state-space form `H(z) = d + c^T (zI - A)^{-1} b`, a pair
//! is the block `A = [[Re p, Im p], [-Im p, Re p]]`, `b = [2, 0]^T`, `c = [c_1, c_2]`.
//!
//! **Pole relocation** (Gustavsen and Semlyen, 1999). With the current poles fixed, solve
//! the linear least-squares problem
//!
//! ```math
//! \sum_i c_i \psi_i(z_k) + d - h_k \sum_i \tilde c_i \psi_i(z_k) = h_k
//! ```
//!
//! for `c, d, c~`. It says `sigma(z) H(z) ~ (fitted rational)`, with
//! `sigma(z) = 1 + c~^T (zI - A)^{-1} b` sharing the poles, so the zeros of `sigma` are the
//! improved poles of `H`: the eigenvalues of `A - b c~^T`. Unstable results are reflected
//! into the unit circle (`p -> 1/p*`, same magnitude shape). A few iterations converge.
//! The final residues come from the same least squares without `sigma`.
//!
//! The zeros of the fitted `H` are the eigenvalues of `A - b c^T / d`, which factors the model
//! into second-order sections without ever expanding a long polynomial.

use nalgebra::{DMatrix, DVector, Schur};
use num_complex::Complex64;

use super::{FitError, Target};
use crate::numeric::solve_scaled;
use crate::signal::Sos;
use crate::signal::sos::poly_mul;
use crate::signal::zpk::{ba_to_sos, sections_from_roots};

/// Poles are kept at most this far out during relocation.
const MAX_RADIUS: f64 = 1.0 - 1e-9;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Pole {
    /// A conjugate pair, by its member with positive imaginary part.
    Pair(Complex64),
    Real(f64),
}

impl Pole {
    fn width(self) -> usize {
        match self {
            Pole::Pair(_) => 2,
            Pole::Real(_) => 1,
        }
    }
}

/// Writes the basis functions of `poles` at `z` into `out` (one per real unknown).
fn basis(poles: &[Pole], z: Complex64, out: &mut Vec<Complex64>) {
    out.clear();
    let j = Complex64::new(0.0, 1.0);
    for &p in poles {
        match p {
            Pole::Pair(p) => {
                let (u, v) = (1.0 / (z - p), 1.0 / (z - p.conj()));
                out.push(u + v);
                out.push(j * (u - v));
            }
            Pole::Real(p) => out.push(Complex64::new(1.0, 0.0) / (z - p)),
        }
    }
}

/// The real state-space realisation `(A, b)` of the basis.
fn realisation(poles: &[Pole]) -> (DMatrix<f64>, DVector<f64>) {
    let n: usize = poles.iter().map(|p| p.width()).sum();
    let mut a = DMatrix::zeros(n, n);
    let mut b = DVector::zeros(n);
    let mut i = 0;
    for &p in poles {
        match p {
            Pole::Pair(p) => {
                a[(i, i)] = p.re;
                a[(i, i + 1)] = p.im;
                a[(i + 1, i)] = -p.im;
                a[(i + 1, i + 1)] = p.re;
                b[i] = 2.0;
                i += 2;
            }
            Pole::Real(p) => {
                a[(i, i)] = p;
                b[i] = 1.0;
                i += 1;
            }
        }
    }
    (a, b)
}

/// Eigenvalues of `A - b c^T / d` as poles (pairs and reals).
fn eig_poles(
    a: &DMatrix<f64>,
    b: &DVector<f64>,
    c: &[f64],
    d: f64,
) -> Result<Vec<Complex64>, FitError> {
    let mut m = a.clone();
    for i in 0..m.nrows() {
        for j in 0..m.ncols() {
            m[(i, j)] -= b[i] * c[j] / d;
        }
    }
    if m.iter().any(|v| !v.is_finite()) {
        return Err(FitError::Numerical("non-finite relocation matrix"));
    }
    let schur = Schur::try_new(m, f64::EPSILON, 100_000)
        .ok_or(FitError::Numerical("eigenvalues did not converge"))?;
    Ok(schur.complex_eigenvalues().iter().copied().collect())
}

fn classify(eigs: &[Complex64]) -> Vec<Pole> {
    let mut poles = Vec::new();
    for &e in eigs {
        let e = if e.norm() >= 1.0 { 1.0 / e.conj() } else { e };
        let e = if e.norm() > MAX_RADIUS {
            e * (MAX_RADIUS / e.norm())
        } else {
            e
        };
        if e.im.abs() <= 1e-12 * e.norm().max(1e-300) {
            poles.push(Pole::Real(e.re));
        } else if e.im > 0.0 {
            poles.push(Pole::Pair(e));
        }
    }
    poles
}

/// Starting poles: lightly damped pairs spread log-evenly over the target's frequencies,
/// plus one real pole for an odd order.
fn initial_poles(target: &Target, order: usize) -> Vec<Pole> {
    let pairs = order / 2;
    let (w_lo, w_hi) = (target.omega[0], target.omega[target.len() - 1]);
    let mut poles: Vec<Pole> = (0..pairs)
        .map(|i| {
            let t = (i as f64 + 0.5) / pairs as f64;
            let w = w_lo * (w_hi / w_lo).powf(t);
            // Damping of 1% of the frequency, as in continuous-time vector fitting.
            Pole::Pair(Complex64::new(-0.01 * w, w).exp())
        })
        .collect();
    if order % 2 == 1 {
        poles.push(Pole::Real((-w_lo).exp()));
    }
    poles
}

/// Least squares in the partial-fraction basis. With `relocate`, also solves for `sigma`'s
/// residues and returns them after `c` and `d`.
fn solve(target: &Target, poles: &[Pole], relocate: bool) -> Result<DVector<f64>, FitError> {
    let n: usize = poles.iter().map(|p| p.width()).sum();
    let cols = n + 1 + if relocate { n } else { 0 };
    let k = target.len();
    let mut m = DMatrix::<f64>::zeros(2 * k, cols);
    let mut rhs = DVector::<f64>::zeros(2 * k);
    let mut phi = Vec::with_capacity(n);
    for i in 0..k {
        let w = target.weight[i].sqrt();
        let z = Complex64::from_polar(1.0, target.omega[i]);
        let h = target.h[i];
        basis(poles, z, &mut phi);
        for (j, &f) in phi.iter().enumerate() {
            m[(2 * i, j)] = w * f.re;
            m[(2 * i + 1, j)] = w * f.im;
            if relocate {
                let g = -h * f;
                m[(2 * i, n + 1 + j)] = w * g.re;
                m[(2 * i + 1, n + 1 + j)] = w * g.im;
            }
        }
        m[(2 * i, n)] = w;
        rhs[2 * i] = w * h.re;
        rhs[2 * i + 1] = w * h.im;
    }
    Ok(solve_scaled(m, &rhs)?)
}

/// Fits an order-`order` filter by `iterations` pole relocations.
///
/// # Errors
/// [`FitError::Numerical`] when a least-squares or eigenvalue step fails.
pub fn vector_fit(target: &Target, order: usize, iterations: usize) -> Result<Sos, FitError> {
    let mut poles = initial_poles(target, order);
    let n = order;
    for _ in 0..iterations {
        let x = solve(target, &poles, true)?;
        let (a, b) = realisation(&poles);
        let ct: Vec<f64> = x.iter().skip(n + 1).copied().collect();
        let eigs = eig_poles(&a, &b, &ct, 1.0)?;
        let next = classify(&eigs);
        if next.iter().map(|p| p.width()).sum::<usize>() != n {
            break;
        }
        poles = next;
    }
    let x = solve(target, &poles, false)?;
    let c: Vec<f64> = x.iter().take(n).copied().collect();
    let d = x[n];
    to_sos(&poles, &c, d)
}

/// Factors the partial-fraction model into second-order sections.
fn to_sos(poles: &[Pole], c: &[f64], d: f64) -> Result<Sos, FitError> {
    let pole_list: Vec<Complex64> = poles
        .iter()
        .flat_map(|&p| match p {
            Pole::Pair(p) => vec![p, p.conj()],
            Pole::Real(p) => vec![Complex64::new(p, 0.0)],
        })
        .collect();
    let c_scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if d.abs() > 1e-6 * c_scale {
        let (a, b) = realisation(poles);
        let zeros = eig_poles(&a, &b, c, d)?;
        return Ok(Sos::new(sections_from_roots(&zeros, &pole_list, d)));
    }
    // A (nearly) strictly proper model: the zeros-at-infinity make the eigenvalue route
    // ill-posed, so expand into polynomials instead.
    let mut den = vec![1.0];
    let mut dens = Vec::new();
    for &p in poles {
        let f = match p {
            Pole::Pair(p) => vec![1.0, -2.0 * p.re, p.norm_sqr()],
            Pole::Real(p) => vec![1.0, -p],
        };
        den = poly_mul(&den, &f);
        dens.push(f);
    }
    let mut num: Vec<f64> = den.iter().map(|v| v * d).collect();
    let mut idx = 0;
    for (i, &p) in poles.iter().enumerate() {
        // Numerator of this term over its own denominator, in powers of z^-1.
        let term = match p {
            Pole::Pair(p) => vec![
                0.0,
                2.0 * c[idx],
                -2.0 * c[idx] * p.re - 2.0 * c[idx + 1] * p.im,
            ],
            Pole::Real(_) => vec![0.0, c[idx]],
        };
        idx += p.width();
        let others = dens
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .fold(vec![1.0], |acc, (_, f)| poly_mul(&acc, f));
        for (k, v) in poly_mul(&term, &others).into_iter().enumerate() {
            num[k] += v;
        }
    }
    ba_to_sos(&num, &den).ok_or(FitError::Numerical("could not factor the fitted model"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::Biquad;
    use crate::units::{Band, SampleRate};

    #[test]
    fn recovers_a_fourth_order_filter() {
        let rate = SampleRate(2000);
        let truth = Sos::new(vec![
            Biquad {
                b: [0.2, 0.1, -0.05],
                a: [1.0, -1.8, 0.95],
            },
            Biquad {
                b: [1.0, -0.4, 0.3],
                a: [1.0, 0.3, 0.6],
            },
        ]);
        let freqs = Band::new(5.0, 990.0).log_grid(200);
        let h = freqs
            .iter()
            .map(|&f| truth.response(rate.omega(f)))
            .collect();
        let t = Target::from_response(rate, &freqs, h).unwrap();
        let fit = vector_fit(&t, 4, 10).unwrap();
        for &f in &freqs {
            let (x, y) = (fit.response(rate.omega(f)), truth.response(rate.omega(f)));
            assert!((x - y).norm() < 1e-8 * y.norm(), "{f}: {x} vs {y}");
        }
    }
}
