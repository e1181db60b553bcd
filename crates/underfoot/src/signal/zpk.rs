//! A transfer function as zeros, poles and gain, factored into second-order sections.
//!
//! Roots come from [`numeric::roots`](crate::numeric::roots()), so complex roots arrive as
//! exact conjugate pairs. Factoring `b(z^-1)` and `a(z^-1)` into sections:
//!
//! ```math
//! b(z^{-1}) = b_{d}\, z^{-d} \prod_i (1 - q_i z^{-1})
//! ```
//!
//! where `d` counts leading zero coefficients (pure delays) and `q_i` are the zeros in the
//! `z` plane. Poles are paired into sections by conjugacy; each pole section takes the
//! nearest remaining zeros (the pairing that keeps each section's gain moderate, as in the
//! usual zpk-to-sos rule), sections closest to the unit circle first.

use num_complex::Complex64;

use crate::numeric::roots;
use crate::signal::{Biquad, Sos};

/// Below this imaginary part (relative to the modulus) a root is taken as real.
const REAL_TOL: f64 = 1e-9;

/// Splits roots into conjugate pairs (by the member with positive imaginary part) and reals.
fn split(roots: &[Complex64]) -> (Vec<Complex64>, Vec<f64>) {
    let mut pairs = Vec::new();
    let mut reals = Vec::new();
    for r in roots {
        if r.im.abs() <= REAL_TOL * r.norm().max(1e-300) {
            reals.push(r.re);
        } else if r.im > 0.0 {
            pairs.push(*r);
        }
    }
    (pairs, reals)
}

/// A numerator factor: a finite zero `1 - q z^-1`, or a pure delay `z^-1`.
#[derive(Clone, Copy, Debug)]
enum Factor {
    Zero(Complex64),
    Delay,
}

/// Factors the transfer function `b/a` (coefficients of `z^0, z^-1, ...`, `a[0] != 0`)
/// into second-order sections.
///
/// Returns `None` when the roots cannot be found.
#[must_use]
pub fn ba_to_sos(b: &[f64], a: &[f64]) -> Option<Sos> {
    let a0 = *a.first()?;
    if a0 == 0.0 {
        return None;
    }
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tiny = 1e-14 * scale;
    let delays = b.iter().take_while(|v| v.abs() <= tiny).count();
    if delays == b.len() {
        // The zero filter: keep the poles so that the model stays well formed.
        let poles = roots(&trim_trailing(a, 0.0))?;
        let sections = sections_from_roots(&[], &poles, 0.0);
        return Some(Sos::new(sections));
    }
    let b_core = trim_trailing(&b[delays..], tiny);
    let gain = b_core[0] / a0;
    let mut zeros: Vec<Factor> = roots(&b_core)?.into_iter().map(Factor::Zero).collect();
    zeros.extend(std::iter::repeat_n(Factor::Delay, delays));
    let poles = roots(&trim_trailing(a, 1e-14 * a0.abs()))?;
    Some(Sos::new(sections_from_factors(zeros, &poles, gain)))
}

fn trim_trailing(c: &[f64], tiny: f64) -> Vec<f64> {
    let n = c.len() - c.iter().rev().take_while(|v| v.abs() <= tiny).count();
    c[..n.max(1)].to_vec()
}

/// Second-order sections from finite zeros and poles, with overall gain `k`.
#[must_use]
pub fn sections_from_roots(zeros: &[Complex64], poles: &[Complex64], k: f64) -> Vec<Biquad> {
    sections_from_factors(zeros.iter().copied().map(Factor::Zero).collect(), poles, k)
}

fn sections_from_factors(zeros: Vec<Factor>, poles: &[Complex64], k: f64) -> Vec<Biquad> {
    let (pole_pairs, pole_reals) = split(poles);
    // Denominator factors, each of degree <= 2, the most resonant first.
    let mut dens: Vec<[f64; 3]> = pole_pairs
        .iter()
        .map(|p| [1.0, -2.0 * p.re, p.norm_sqr()])
        .collect();
    let mut reals = pole_reals;
    reals.sort_by(|x, y| y.abs().total_cmp(&x.abs()));
    for ch in reals.chunks(2) {
        dens.push(match ch {
            [p, q] => [1.0, -(p + q), p * q],
            [p] => [1.0, -p, 0.0],
            _ => unreachable!("chunks(2) yields one or two"),
        });
    }
    let radius = |d: &[f64; 3]| quad_max_root(d);
    dens.sort_by(|x, y| radius(y).total_cmp(&radius(x)));

    // Numerator factors: conjugate zero pairs and single real zeros / delays.
    let mut z_pairs: Vec<Complex64> = Vec::new();
    let mut z_singles: Vec<Factor> = Vec::new();
    for f in zeros {
        match f {
            Factor::Zero(z) if z.im.abs() > REAL_TOL * z.norm().max(1e-300) => {
                if z.im > 0.0 {
                    z_pairs.push(z);
                }
            }
            Factor::Zero(z) => z_singles.push(Factor::Zero(Complex64::new(z.re, 0.0))),
            Factor::Delay => z_singles.push(Factor::Delay),
        }
    }

    let n_sections = dens
        .len()
        .max((z_pairs.len() * 2 + z_singles.len()).div_ceil(2))
        .max(1);
    dens.resize(n_sections, [1.0, 0.0, 0.0]);
    let mut sections = Vec::with_capacity(n_sections);
    for den in dens {
        let pole = quad_root_upper(&den);
        // The nearest conjugate pair, else the two nearest singles, to this section's pole.
        let dist = |f: &Factor| match f {
            Factor::Zero(z) => (z - pole).norm(),
            Factor::Delay => f64::INFINITY,
        };
        let best_pair = z_pairs
            .iter()
            .enumerate()
            .min_by(|(_, x), (_, y)| (*x - pole).norm().total_cmp(&(*y - pole).norm()));
        let best_single = z_singles.iter().map(dist).fold(f64::INFINITY, f64::min);
        let num = match best_pair {
            Some((i, z)) if (z - pole).norm() <= best_single || z_singles.len() < 2 => {
                let z = *z;
                z_pairs.swap_remove(i);
                [1.0, -2.0 * z.re, z.norm_sqr()]
            }
            _ => {
                let mut num = [1.0, 0.0, 0.0];
                for deg in 0..2 {
                    let Some((i, _)) = z_singles
                        .iter()
                        .enumerate()
                        .min_by(|(_, x), (_, y)| dist(x).total_cmp(&dist(y)))
                    else {
                        break;
                    };
                    let f = z_singles.swap_remove(i);
                    let factor = match f {
                        Factor::Zero(z) => [1.0, -z.re],
                        Factor::Delay => [0.0, 1.0],
                    };
                    let prod = crate::signal::sos::poly_mul(&num[..=deg], &factor);
                    num = [0.0; 3];
                    num[..prod.len()].copy_from_slice(&prod);
                }
                num
            }
        };
        sections.push(Biquad { b: num, a: den });
    }
    if let Some(first) = sections.first_mut() {
        for c in &mut first.b {
            *c *= k;
        }
    }
    sections
}

/// The largest root modulus of `d[0] + d[1] x + d[2] x^2` read as `z^2 + d1 z + d2`.
fn quad_max_root(d: &[f64; 3]) -> f64 {
    crate::signal::sos::quadratic_roots(d[1], d[2])
        .iter()
        .map(|r| r.norm())
        .fold(0.0, f64::max)
}

fn quad_root_upper(d: &[f64; 3]) -> Complex64 {
    let [r1, r2] = crate::signal::sos::quadratic_roots(d[1], d[2]);
    if r1.im >= r2.im { r1 } else { r2 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ba_to_sos_reproduces_response_with_delays() {
        let b = [0.0, 0.3, -0.2, 0.05, 0.01];
        let a = crate::signal::sos::poly_mul(&[1.0, -1.5, 0.8], &[1.0, 0.2, 0.3]);
        let sos = ba_to_sos(&b, &a).unwrap();
        for w in [0.01, 0.3, 1.0, 2.5, 3.1] {
            let z = Complex64::from_polar(1.0, -w);
            let ev = |p: &[f64]| {
                p.iter()
                    .rev()
                    .fold(Complex64::new(0.0, 0.0), |acc, &c| acc * z + c)
            };
            let h = ev(&b) / ev(&a);
            assert!(
                (sos.response(w) - h).norm() < 1e-10 * h.norm().max(1.0),
                "w={w}"
            );
        }
        assert!(sos.is_stable());
    }
}
