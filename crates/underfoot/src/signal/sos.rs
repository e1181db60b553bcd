//! Second-order sections: the form every IIR filter in underfoot is stored and run in.
//!
//! A filter of order `N` is the cascade of `ceil(N/2)` biquads
//!
//! ```math
//! H(z) = \prod_{i} \frac{b_{i0} + b_{i1} z^{-1} + b_{i2} z^{-2}}{1 + a_{i1} z^{-1} + a_{i2} z^{-2}}
//! ```
//!
//! rather than one long ratio of polynomials. A low resonance at a high sample rate puts
//! poles a hair's breadth from `z = 1`; expanded into one polynomial, their coefficients
//! need far more precision than a double has, and the direct form goes unstable. Each
//! biquad keeps its own pair of poles, so precision is local.
//!
//! A first-order section is a biquad with `b2 = a2 = 0`.
//!
//! Sections run in transposed direct form II, which has the best round-off behaviour of
//! the two-state forms for floating point.

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// One second-order section, normalised so that `a0 = 1`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Biquad {
    /// Numerator `[b0, b1, b2]`.
    pub b: [f64; 3],
    /// Denominator `[1, a1, a2]`.
    pub a: [f64; 3],
}

impl Biquad {
    /// The section that passes its input unchanged.
    pub const IDENTITY: Self = Self {
        b: [1.0, 0.0, 0.0],
        a: [1.0, 0.0, 0.0],
    };

    /// A section from a row `[b0, b1, b2, a0, a1, a2]`, normalised by `a0`.
    ///
    /// Returns `None` when `a0` is zero or a coefficient is not finite.
    #[must_use]
    pub fn from_row(row: [f64; 6]) -> Option<Self> {
        let a0 = row[3];
        if a0 == 0.0 || row.iter().any(|c| !c.is_finite()) {
            return None;
        }
        Some(Self {
            b: [row[0] / a0, row[1] / a0, row[2] / a0],
            a: [1.0, row[4] / a0, row[5] / a0],
        })
    }

    /// The row `[b0, b1, b2, 1, a1, a2]`.
    #[must_use]
    pub fn to_row(&self) -> [f64; 6] {
        [
            self.b[0], self.b[1], self.b[2], self.a[0], self.a[1], self.a[2],
        ]
    }

    /// The section with the given pair of poles and pair of zeros (each either a complex
    /// conjugate pair given by one member, or two real values), and numerator gain `k`.
    #[must_use]
    pub fn from_roots(zeros: RootPair, poles: RootPair, k: f64) -> Self {
        let [_, z1, z2] = zeros.monic();
        let a = poles.monic();
        Self {
            b: [k, k * z1, k * z2],
            a,
        }
    }

    /// Complex response at `omega` radians per sample.
    #[must_use]
    pub fn response(&self, omega: f64) -> Complex64 {
        self.response_at(Complex64::from_polar(1.0, -omega))
    }

    /// The response at `z^-1 = z1` (`e^{-jω}` on the unit circle): [`Self::response`]
    /// with the sine and cosine computed once by the caller.
    #[must_use]
    pub fn response_at(&self, z1: Complex64) -> Complex64 {
        let z2 = z1 * z1;
        (self.b[0] + self.b[1] * z1 + self.b[2] * z2)
            / (self.a[0] + self.a[1] * z1 + self.a[2] * z2)
    }

    /// Whether both poles lie strictly inside the unit circle.
    ///
    /// For `1 + a1 z^-1 + a2 z^-2` this is the stability triangle `|a2| < 1`,
    /// `|a1| < 1 + a2`.
    #[must_use]
    pub fn is_stable(&self) -> bool {
        let [_, a1, a2] = self.a;
        a1.is_finite() && a2.is_finite() && a2.abs() < 1.0 && a1.abs() < 1.0 + a2
    }

    /// The two poles (for a first-order section, the second is zero).
    #[must_use]
    pub fn poles(&self) -> [Complex64; 2] {
        quadratic_roots(self.a[1], self.a[2])
    }
}

/// A pair of roots of a real quadratic `1 + c1 x + c2 x^2` in `z^-1`, i.e. `z^2 + c1 z + c2`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RootPair {
    /// A complex-conjugate pair, given by its member with positive imaginary part.
    Conjugate(Complex64),
    /// Two real roots.
    Real(f64, f64),
    /// A single real root (first-order factor).
    Single(f64),
    /// No root (constant factor).
    None,
}

impl RootPair {
    /// `[1, c1, c2]` such that `z^2 + c1 z + c2` has these roots.
    #[must_use]
    pub fn monic(self) -> [f64; 3] {
        match self {
            RootPair::Conjugate(p) => [1.0, -2.0 * p.re, p.norm_sqr()],
            RootPair::Real(p, q) => [1.0, -(p + q), p * q],
            RootPair::Single(p) => [1.0, -p, 0.0],
            RootPair::None => [1.0, 0.0, 0.0],
        }
    }
}

/// The roots of `z^2 + c1 z + c2`.
#[must_use]
pub fn quadratic_roots(c1: f64, c2: f64) -> [Complex64; 2] {
    let disc = c1 * c1 - 4.0 * c2;
    if disc >= 0.0 {
        // Avoid cancellation: compute the larger root first, the other from the product.
        let s = disc.sqrt();
        let sign = if c1 >= 0.0 { 1.0 } else { -1.0 };
        let q = -0.5 * (c1 + sign * s);
        let r1 = if q != 0.0 { q } else { 0.0 };
        let r2 = if q != 0.0 { c2 / q } else { -c1 - r1 };
        [Complex64::new(r1, 0.0), Complex64::new(r2, 0.0)]
    } else {
        let im = (-disc).sqrt() / 2.0;
        [
            Complex64::new(-c1 / 2.0, im),
            Complex64::new(-c1 / 2.0, -im),
        ]
    }
}

/// The degree in `z^-1` of a section's numerator or denominator `[c0, c1, c2]`.
pub(crate) fn degree(c: &[f64; 3]) -> usize {
    if c[2] != 0.0 {
        2
    } else if c[1] != 0.0 {
        1
    } else {
        0
    }
}

/// A cascade of second-order sections with an overall gain folded into the first section.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Sos {
    /// The sections, applied in order.
    pub sections: Vec<Biquad>,
}

impl Sos {
    /// A cascade of the given sections.
    #[must_use]
    pub fn new(sections: Vec<Biquad>) -> Self {
        Self { sections }
    }

    /// The order: the larger of the expanded numerator's and denominator's degrees.
    #[must_use]
    pub fn order(&self) -> usize {
        let nb: usize = self.sections.iter().map(|s| degree(&s.b)).sum();
        let na: usize = self.sections.iter().map(|s| degree(&s.a)).sum();
        nb.max(na)
    }

    /// Complex response at `omega` radians per sample.
    #[must_use]
    pub fn response(&self, omega: f64) -> Complex64 {
        self.response_at(Complex64::from_polar(1.0, -omega))
    }

    /// The response at `z^-1 = z1` (`e^{-jω}` on the unit circle): [`Self::response`]
    /// with the sine and cosine computed once by the caller, for every section.
    #[must_use]
    pub fn response_at(&self, z1: Complex64) -> Complex64 {
        self.sections
            .iter()
            .fold(Complex64::new(1.0, 0.0), |h, s| h * s.response_at(z1))
    }

    /// Whether every pole lies strictly inside the unit circle.
    #[must_use]
    pub fn is_stable(&self) -> bool {
        self.sections.iter().all(Biquad::is_stable)
    }

    /// All poles.
    #[must_use]
    pub fn poles(&self) -> Vec<Complex64> {
        self.sections.iter().flat_map(|s| s.poles()).collect()
    }

    /// The expanded transfer function `(b, a)` as coefficients of `z^0, z^-1, ...`.
    ///
    /// For inspection and interchange only: running a high-order filter in this form is
    /// numerically unsafe (see the module docs). Trailing zero coefficients of first-order
    /// sections are trimmed.
    #[must_use]
    pub fn to_ba(&self) -> (Vec<f64>, Vec<f64>) {
        let mut b = vec![1.0];
        let mut a = vec![1.0];
        for s in &self.sections {
            b = poly_mul(&b, &s.b);
            a = poly_mul(&a, &s.a);
        }
        let n = self.order() + 1;
        b.truncate(n.max(1));
        a.truncate(n.max(1));
        (b, a)
    }

    /// Filters `x` in place from zero initial state.
    pub fn filter_in_place(&self, x: &mut [f64]) {
        let mut state = vec![[0.0; 2]; self.sections.len()];
        self.filter_with_state(x, &mut state);
    }

    /// Filters `x` in place, continuing from (and updating) `state`, one `[s1, s2]` per section.
    ///
    /// # Panics
    /// If `state` does not hold one entry per section.
    pub fn filter_with_state(&self, x: &mut [f64], state: &mut [[f64; 2]]) {
        assert_eq!(state.len(), self.sections.len(), "one state per section");
        // Up to four sections at a time, sample by sample: each section's recursion is a
        // chain of dependent multiply-adds, and the chains of the sections of one group
        // overlap in the processor where, one section after the other over the whole
        // signal, each would wait for itself. Every section does the same arithmetic in
        // the same order either way, so the output is the same to the bit.
        let mut sections = self.sections.as_slice();
        let mut state = state;
        while !sections.is_empty() {
            let k = sections.len().min(4);
            let (group, rest) = sections.split_at(k);
            let (st, st_rest) = state.split_at_mut(k);
            match k {
                1 => cascade::<1>(group, st, x),
                2 => cascade::<2>(group, st, x),
                3 => cascade::<3>(group, st, x),
                _ => cascade::<4>(group, st, x),
            }
            (sections, state) = (rest, st_rest);
        }
    }

    /// The first `n` samples of the impulse response.
    #[must_use]
    pub fn impulse_response(&self, n: usize) -> Vec<f64> {
        let mut x = vec![0.0; n];
        if let Some(first) = x.first_mut() {
            *first = 1.0;
        }
        self.filter_in_place(&mut x);
        x
    }
}

/// Product of two polynomials given by their coefficient vectors.
#[must_use]
pub fn poly_mul(p: &[f64], q: &[f64]) -> Vec<f64> {
    if p.is_empty() || q.is_empty() {
        return Vec::new();
    }
    let mut r = vec![0.0; p.len() + q.len() - 1];
    for (i, &pi) in p.iter().enumerate() {
        for (j, &qj) in q.iter().enumerate() {
            r[i + j] += pi * qj;
        }
    }
    r
}

/// `K` sections (transposed direct form II) run over `x` in place, one sample through all
/// of them before the next, from and into `state`.
fn cascade<const K: usize>(sections: &[Biquad], state: &mut [[f64; 2]], x: &mut [f64]) {
    let coefficients: [Biquad; K] = std::array::from_fn(|k| sections[k]);
    let mut st: [[f64; 2]; K] = std::array::from_fn(|k| state[k]);
    for v in x.iter_mut() {
        let mut u = *v;
        for (c, [s1, s2]) in coefficients.iter().zip(st.iter_mut()) {
            let [b0, b1, b2] = c.b;
            let [_, a1, a2] = c.a;
            let y = b0 * u + *s1;
            *s1 = b1 * u - a1 * y + *s2;
            *s2 = b2 * u - a2 * y;
            u = y;
        }
        *v = u;
    }
    state.copy_from_slice(&st);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quadratic_roots_are_roots() {
        for (c1, c2) in [
            (-1.9, 0.95),
            (0.5, -0.3),
            (-2.0, 1.0),
            (0.0, 0.0),
            (3.0, 2.0),
        ] {
            for r in quadratic_roots(c1, c2) {
                let v = r * r + c1 * r + c2;
                assert!(v.norm() < 1e-12, "c1={c1} c2={c2} r={r}");
            }
        }
    }

    #[test]
    fn stability_triangle_matches_pole_radius() {
        for a1 in [-1.99, -1.5, 0.0, 0.7, 1.2, 1.99] {
            for a2 in [-0.99, -0.5, 0.0, 0.5, 0.98, 1.01] {
                let s = Biquad {
                    b: [1.0, 0.0, 0.0],
                    a: [1.0, a1, a2],
                };
                let by_roots = s.poles().iter().all(|p| p.norm() < 1.0);
                assert_eq!(s.is_stable(), by_roots, "a1={a1} a2={a2}");
            }
        }
    }

    #[test]
    fn impulse_response_matches_recursion() {
        let s = Sos::new(vec![Biquad {
            b: [0.5, 0.2, -0.1],
            a: [1.0, -1.2, 0.5],
        }]);
        let h = s.impulse_response(20);
        let mut y = [0.0f64; 20];
        for n in 0..20 {
            let x = |k: isize| if k == 0 { 1.0 } else { 0.0 };
            let n_i = n as isize;
            let yp = |k: isize| if k >= 0 { y[k as usize] } else { 0.0 };
            y[n] = 0.5 * x(n_i) + 0.2 * x(n_i - 1) - 0.1 * x(n_i - 2) + 1.2 * yp(n_i - 1)
                - 0.5 * yp(n_i - 2);
        }
        for n in 0..20 {
            assert!((h[n] - y[n]).abs() < 1e-12);
        }
    }

    #[test]
    fn response_of_cascade_is_product() {
        let a = Biquad {
            b: [1.0, 0.3, 0.1],
            a: [1.0, -0.9, 0.4],
        };
        let b = Biquad {
            b: [0.2, -0.1, 0.0],
            a: [1.0, 0.5, 0.0],
        };
        let s = Sos::new(vec![a, b]);
        let w = 0.7;
        assert!((s.response(w) - a.response(w) * b.response(w)).norm() < 1e-14);
        let (bb, aa) = s.to_ba();
        assert_eq!(s.order(), 3);
        assert_eq!(bb.len(), 4);
        let z = Complex64::from_polar(1.0, -w);
        let eval = |p: &[f64]| {
            p.iter()
                .rev()
                .fold(Complex64::new(0.0, 0.0), |acc, &c| acc * z + c)
        };
        assert!((eval(&bb) / eval(&aa) - s.response(w)).norm() < 1e-12);
    }
}
