//! Damped Gauss-Newton refinement over stable second-order sections.
//!
//! The IIR paper refines Levi's fit by minimising the output error of its equation (2),
//!
//! ```math
//! \min_{b,a} \sum_k W_k \left| h_k - \frac{B(\omega_k)}{A(\omega_k)} \right|^2,
//! ```
//!
//! with the damped Gauss-Newton method of Dennis and Schnabel, as MATLAB's iterative
//! `invfreqz` does. MATLAB searches over polynomial coefficients and only reflects unstable
//! poles at the end, which changes the fitted response after the fact. We search instead
//! over a parametrisation in which **every point is a stable filter**, so stability holds
//! at every step of the search, not just at its end:
//!
//! * the filter is a cascade of sections `B_i(z)/A_i(z)`;
//! * a second-order denominator `1 + a_1 z^-1 + a_2 z^-2` is written through its reflection
//!   coefficients, `a_2 = k_2`, `a_1 = k_1 (1 + k_2)`, with `k_i = tanh(u_i)`. The map from
//!   `(u_1, u_2)` in the whole plane onto the open stability triangle is smooth and onto
//!   (scaled by `1 - 1e-7` so that rounding can never reach the circle), so
//!   an unconstrained step in `u` can never cross the unit circle. A first-order
//!   denominator is `1 + tanh(u) z^-1`;
//! * the search can be held inside a smaller circle `|z| <= rho` (the **decay limit**: a
//!   pole of radius `rho` decays by `e` in `1 / (f_s ln(1/rho))` seconds, so no filter the
//!   search visits rings longer than a ground can). `A(z)` has its poles inside `|z| < rho`
//!   exactly when `A(rho z)`, i.e. `1 + (a_1/rho) z^-1 + (a_2/rho^2) z^-2`, has them inside
//!   the unit circle, so the same reflection map is applied to the scaled polynomial:
//!   `a_1 = rho k_1 (1 + k_2)`, `a_2 = rho^2 k_2` (and `a_1 = rho k` for one pole). The
//!   bound is part of the parametrisation, not a penalty or a clamp after the fact: the
//!   filter the search returns is the filter that plays;
//! * numerator coefficients `b_{i0} .. b_{i d_i}` are free (zeros may lie anywhere), up to
//!   the degree `d_i` each section starts with, so that the order never grows.
//!
//! In the log domain `ln H = sum_i ln B_i - ln A_i`, so every derivative is one division:
//! `d ln H / d b_{ij} = z^{-j} / B_i` and `d ln H / d a_{ij} = -z^{-j} / A_i`, chained
//! through `d a / d u`.
//!
//! Two objectives share this machinery:
//!
//! * [`Objective::OutputError`]: equation (2) with `W_k = w_k / |h_k|^2`, i.e. the relative
//!   complex error, so quiet frequencies count as much as loud ones;
//! * [`Objective::LogMagnitude`]: `sum_k w_k (ln|H(w_k)| - ln|h_k|)^2`, the log-spectral
//!   distance itself. It ignores phase, which for a magnitude-only measurement was only an
//!   assumption (minimum phase), and so leaves the zeros free to sit where the magnitude
//!   fits best;
//! * [`Objective::Balanced`]: both metrics of [`super::metrics`] at once, each residual
//!   divided by the error its target allows, `(|H| - |h|) / s_lin` and
//!   `ln(|H| / |h|) / s_log`: the log error keeps quiet bands honest, the linear error
//!   (what NRMSE measures) keeps the peaks, and neither is traded away for the other.
//!
//! The damping is Levenberg-Marquardt's: `(J^T J + lambda diag(J^T J)) delta = -J^T r`,
//! `lambda` shrinking after a step that lowers the cost and growing after one that does not,
//! so that the method moves between Gauss-Newton and scaled gradient descent. A step is
//! only ever accepted if it lowers the cost.

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

use super::{FitError, Target};
use crate::signal::{Biquad, Sos};

/// Reflection coefficients are `K_MAX tanh(u)`. `tanh` alone rounds to exactly 1 for
/// `u > 19`, which would put a pole on the circle; and near the stability triangle's corner
/// `(a1, a2) = (0, -1)` a pole's distance from the circle shrinks as the *square* of
/// `1 - |k|`, so the margin must be large enough that its square still shows in a double.
/// `1 - 1e-7` keeps every pole at least about `1e-14` inside, and still reaches a
/// resonance as low as 10 Hz at 48 kHz (its `|k_1|` is `1 - 9e-7`).
const K_MAX: f64 = 1.0 - 1e-7;

/// Inverse of the reflection map, clamped so that it stays finite.
fn to_u(k: f64) -> f64 {
    (k / K_MAX).clamp(-1.0 + 1e-15, 1.0 - 1e-15).atanh()
}

/// The reflection map and its derivative.
fn to_k(u: f64) -> (f64, f64) {
    let t = u.tanh();
    (K_MAX * t, K_MAX * (1.0 - t * t))
}

/// What the refinement minimises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Objective {
    /// Relative complex output error, equation (2).
    OutputError,
    /// Squared log-magnitude error.
    LogMagnitude,
    /// Both metrics at once: per frequency, the magnitude error over `lin_scale` and the
    /// natural-log magnitude error over `log_scale`.
    Balanced {
        /// Magnitude error that counts as one unit.
        lin_scale: f64,
        /// Log-magnitude error (nepers) that counts as one unit.
        log_scale: f64,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Den {
    Two,
    One,
    None,
}

impl Den {
    fn of(s: &Biquad) -> Self {
        if s.a[2] != 0.0 {
            Den::Two
        } else if s.a[1] != 0.0 {
            Den::One
        } else {
            Den::None
        }
    }

    fn params(self) -> usize {
        match self {
            Den::Two => 2,
            Den::One => 1,
            Den::None => 0,
        }
    }
}

/// The parameter layout of a cascade: per section, 1-3 numerator and 0-2 denominator values,
/// every pole inside `|z| < rho`.
struct Layout {
    nums: Vec<usize>,
    dens: Vec<Den>,
    rho: f64,
}

impl Layout {
    fn of(sos: &Sos, rho: f64) -> Self {
        let nums = sos
            .sections
            .iter()
            .map(|s| {
                if s.b[2] != 0.0 {
                    3
                } else if s.b[1] != 0.0 {
                    2
                } else {
                    1
                }
            })
            .collect();
        Self {
            nums,
            dens: sos.sections.iter().map(Den::of).collect(),
            rho,
        }
    }

    fn len(&self) -> usize {
        self.nums.iter().sum::<usize>() + self.dens.iter().map(|d| d.params()).sum::<usize>()
    }

    fn pack(&self, sos: &Sos) -> Vec<f64> {
        let mut p = Vec::with_capacity(self.len());
        for ((s, d), &nb) in sos.sections.iter().zip(&self.dens).zip(&self.nums) {
            p.extend_from_slice(&s.b[..nb]);
            match d {
                Den::Two => {
                    let k2 = s.a[2] / (self.rho * self.rho);
                    p.push(to_u(s.a[1] / (self.rho * (1.0 + k2))));
                    p.push(to_u(k2));
                }
                Den::One => p.push(to_u(s.a[1] / self.rho)),
                Den::None => {}
            }
        }
        p
    }

    fn unpack(&self, p: &[f64]) -> Vec<Biquad> {
        let mut out = Vec::with_capacity(self.dens.len());
        let mut i = 0;
        for (d, &nb) in self.dens.iter().zip(&self.nums) {
            let mut b = [0.0; 3];
            b[..nb].copy_from_slice(&p[i..i + nb]);
            i += nb;
            let a = match d {
                Den::Two => {
                    let (k1, k2) = (to_k(p[i]).0, to_k(p[i + 1]).0);
                    i += 2;
                    let rho = self.rho;
                    [1.0, rho * k1 * (1.0 + k2), rho * rho * k2]
                }
                Den::One => {
                    i += 1;
                    [1.0, self.rho * to_k(p[i - 1]).0, 0.0]
                }
                Den::None => [1.0, 0.0, 0.0],
            };
            out.push(Biquad { b, a });
        }
        out
    }
}

/// Residual rows per frequency.
fn rows_per(objective: Objective) -> usize {
    match objective {
        Objective::LogMagnitude => 1,
        Objective::OutputError | Objective::Balanced { .. } => 2,
    }
}

/// Residuals, and optionally the Jacobian, stored transposed (`params x rows`) so that each
/// frequency writes contiguous memory and `J^T J` is a symmetric rank update.
fn evaluate(
    layout: &Layout,
    p: &[f64],
    target: &Target,
    powers: &[(Complex64, Complex64)],
    objective: Objective,
    mut jac: Option<&mut DMatrix<f64>>,
) -> Vec<f64> {
    let sections = layout.unpack(p);
    let np = layout.len();
    let per = rows_per(objective);
    let mut r = Vec::with_capacity(per * target.len());
    if let Some(j) = jac.as_deref_mut()
        && j.shape() != (np, per * target.len())
    {
        *j = DMatrix::zeros(np, per * target.len());
    }
    let mut dlog = vec![Complex64::new(0.0, 0.0); np];
    let one = Complex64::new(1.0, 0.0);
    let want_jac = jac.is_some();
    // The reflection map is the same at every frequency: evaluate it once per parameter.
    let kmap: Vec<(f64, f64)> = p.iter().map(|&u| to_k(u)).collect();
    for (k, &(z1, z2)) in powers.iter().enumerate() {
        let h = target.h[k];
        let mut hm = one;
        let mut col = 0;
        for ((s, d), &nb) in sections.iter().zip(&layout.dens).zip(&layout.nums) {
            let bz = s.b[0] + s.b[1] * z1 + s.b[2] * z2;
            let az = s.a[0] + s.a[1] * z1 + s.a[2] * z2;
            // A zero exactly on the grid would make ln|B| infinite; nudge it.
            let bz = if bz.norm_sqr() < 1e-300 {
                Complex64::new(1e-150, 0.0)
            } else {
                bz
            };
            let ia = az.inv();
            hm *= bz * ia;
            // Residual-only evaluations (the trial steps) skip the derivatives.
            if !want_jac {
                continue;
            }
            let ib = bz.inv();
            for (j, zp) in [one, z1, z2].iter().take(nb).enumerate() {
                dlog[col + j] = zp * ib;
            }
            col += nb;
            match d {
                Den::Two => {
                    let ((k1, dk1), (k2, dk2)) = (kmap[col], kmap[col + 1]);
                    let rho = layout.rho;
                    let (da1, da2) = (-z1 * ia, -z2 * ia);
                    dlog[col] = da1 * (rho * dk1 * (1.0 + k2));
                    dlog[col + 1] = da1 * (rho * k1 * dk2) + da2 * (rho * rho * dk2);
                    col += 2;
                }
                Den::One => {
                    dlog[col] = -z1 * ia * (layout.rho * kmap[col].1);
                    col += 1;
                }
                Den::None => {}
            }
        }
        let w = target.weight[k].sqrt();
        // `hypot` is exact but slow; magnitudes here are far from overflow.
        let want = h.norm_sqr().sqrt().max(1e-300);
        match objective {
            Objective::OutputError => {
                let w = w / want;
                let e = (hm - h) * w;
                r.push(e.re);
                r.push(e.im);
                if let Some(j) = jac.as_deref_mut() {
                    let mut column = j.column_mut(2 * k);
                    for (c, dl) in dlog.iter().enumerate() {
                        column[c] = (hm * dl * w).re;
                    }
                    let mut column = j.column_mut(2 * k + 1);
                    for (c, dl) in dlog.iter().enumerate() {
                        column[c] = (hm * dl * w).im;
                    }
                }
            }
            Objective::LogMagnitude => {
                let mag2 = hm.norm_sqr().max(1e-300);
                r.push(w * 0.5 * (mag2 / (want * want)).ln());
                if let Some(j) = jac.as_deref_mut() {
                    let mut column = j.column_mut(k);
                    for (c, dl) in dlog.iter().enumerate() {
                        column[c] = w * dl.re;
                    }
                }
            }
            Objective::Balanced {
                lin_scale,
                log_scale,
            } => {
                let mag = hm.norm_sqr().sqrt().max(1e-300);
                let (wl, wg) = (w / lin_scale, w / log_scale);
                r.push(wl * (mag - want));
                r.push(wg * (mag / want).ln());
                if let Some(j) = jac.as_deref_mut() {
                    let mut column = j.column_mut(2 * k);
                    for (c, dl) in dlog.iter().enumerate() {
                        column[c] = wl * mag * dl.re;
                    }
                    let mut column = j.column_mut(2 * k + 1);
                    for (c, dl) in dlog.iter().enumerate() {
                        column[c] = wg * dl.re;
                    }
                }
            }
        }
    }
    r
}

/// `(z^-1, z^-2)` on the unit circle at each target frequency.
fn unit_powers(target: &Target) -> Vec<(Complex64, Complex64)> {
    target
        .omega
        .iter()
        .map(|&w| {
            let z1 = Complex64::from_polar(1.0, -w);
            (z1, z1 * z1)
        })
        .collect()
}

fn cost(r: &[f64]) -> f64 {
    let c: f64 = r.iter().map(|v| v * v).sum();
    if c.is_finite() { c } else { f64::INFINITY }
}

/// The outcome of a refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct Refined {
    /// The refined, stable cascade.
    pub sos: Sos,
    /// Final cost (sum of squared residuals).
    pub cost: f64,
    /// Accepted steps.
    pub steps: usize,
}

/// Refines a stable cascade for `objective`, for at most `max_iter` Jacobian evaluations,
/// keeping every pole inside `|z| < max_radius` (`1.0`: stability only; see
/// [`super::decay_radius`] for the decay limit a fit uses).
///
/// The result is never worse than the start.
///
/// # Errors
/// [`FitError::Unstable`] when a pole of the starting cascade lies outside `max_radius`,
/// or `max_radius` is not in `(0, 1]`.
pub fn refine(
    sos: &Sos,
    target: &Target,
    objective: Objective,
    max_iter: usize,
    max_radius: f64,
) -> Result<Refined, FitError> {
    if !(max_radius > 0.0 && max_radius <= 1.0 && sos.is_stable())
        || sos.poles().iter().any(|p| p.norm() >= max_radius)
    {
        return Err(FitError::Unstable);
    }
    let layout = Layout::of(sos, max_radius);
    let np = layout.len();
    let mut p = layout.pack(sos);
    let powers = unit_powers(target);
    let mut jac = DMatrix::<f64>::zeros(0, 0);
    let mut r = evaluate(&layout, &p, target, &powers, objective, Some(&mut jac));
    let mut c = cost(&r);
    let mut lambda = 1e-3;
    let mut steps = 0;
    'outer: for _ in 0..max_iter {
        let jtj = &jac * jac.transpose();
        let g = &jac * DVector::from_column_slice(&r);
        let diag: Vec<f64> = (0..np)
            .map(|a| jtj[(a, a)].max(1e-12 * (1.0 + jtj[(a, a)])))
            .collect();
        loop {
            let mut m = jtj.clone();
            for (a, d) in diag.iter().enumerate() {
                m[(a, a)] += lambda * d;
            }
            let Some(chol) = m.cholesky() else {
                lambda *= 10.0;
                if lambda > 1e16 {
                    break 'outer;
                }
                continue;
            };
            let delta = chol.solve(&(-&g));
            let trial: Vec<f64> = p.iter().zip(delta.iter()).map(|(x, d)| x + d).collect();
            let r_trial = evaluate(&layout, &trial, target, &powers, objective, None);
            let c_trial = cost(&r_trial);
            if c_trial < c {
                let gain = (c - c_trial) / c.max(1e-300);
                p = trial;
                r = evaluate(&layout, &p, target, &powers, objective, Some(&mut jac));
                c = c_trial;
                steps += 1;
                lambda = (lambda / 3.0).max(1e-15);
                if gain < 1e-7 {
                    break 'outer;
                }
                break;
            }
            lambda *= 4.0;
            if lambda > 1e16 {
                break 'outer;
            }
        }
    }
    let sos = Sos::new(layout.unpack(&p));
    debug_assert!(sos.poles().iter().all(|z| z.norm() < max_radius));
    Ok(Refined {
        sos,
        cost: c,
        steps,
    })
}

/// The cost of `sos` on `target` for `objective` without refining.
#[must_use]
pub fn objective_cost(sos: &Sos, target: &Target, objective: Objective) -> f64 {
    // The cost does not depend on the parametrisation: any radius that holds the poles.
    let layout = Layout::of(sos, 1.0);
    let p = layout.pack(sos);
    cost(&evaluate(
        &layout,
        &p,
        target,
        &unit_powers(target),
        objective,
        None,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{Band, Hz, SampleRate};

    fn target_of(truth: &Sos, rate: SampleRate, freqs: &[Hz]) -> Target {
        let h = freqs
            .iter()
            .map(|&f| truth.response(rate.omega(f)))
            .collect();
        Target::from_response(rate, freqs, h).unwrap()
    }

    /// A numerical check of the analytic Jacobian.
    #[test]
    fn jacobian_matches_finite_differences() {
        let rate = SampleRate(2000);
        let sos = Sos::new(vec![
            Biquad {
                b: [0.5, 0.1, -0.2],
                a: [1.0, -1.5, 0.8],
            },
            Biquad {
                b: [1.0, 0.3, 0.0],
                a: [1.0, -0.4, 0.0],
            },
        ]);
        let freqs = Band::new(20.0, 900.0).log_grid(17);
        let other = Sos::new(vec![
            Biquad {
                b: [0.4, 0.2, -0.1],
                a: [1.0, -1.4, 0.7],
            },
            Biquad {
                b: [1.0, 0.2, 0.1],
                a: [1.0, -0.3, 0.0],
            },
        ]);
        let t = target_of(&other, rate, &freqs);
        for (rho, obj) in [1.0, 0.95].into_iter().flat_map(|rho| {
            [
                Objective::OutputError,
                Objective::LogMagnitude,
                Objective::Balanced {
                    lin_scale: 0.3,
                    log_scale: 0.05,
                },
            ]
            .map(|o| (rho, o))
        }) {
            let layout = Layout::of(&sos, rho);
            let p = layout.pack(&sos);
            let mut jac = DMatrix::zeros(0, 0);
            let zp = unit_powers(&t);
            let r0 = evaluate(&layout, &p, &t, &zp, obj, Some(&mut jac));
            let np = layout.len();
            for c in 0..np {
                let mut q = p.clone();
                let h = 1e-6;
                q[c] += h;
                let r1 = evaluate(&layout, &q, &t, &zp, obj, None);
                for row in 0..r0.len() {
                    let fd = (r1[row] - r0[row]) / h;
                    let an = jac[(c, row)];
                    assert!(
                        (fd - an).abs() < 1e-4 * (1.0 + an.abs()),
                        "{obj:?} col {c} row {row}: {fd} vs {an}"
                    );
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
        /// Every point of the search space is a stable filter, so no step of any search can
        /// leave the unit circle, however large.
        #[test]
        fn every_parameter_vector_is_a_stable_filter(u in proptest::collection::vec(-60.0f64..60.0, 13)) {
            let shape = Sos::new(vec![
                Biquad { b: [1.0, 0.5, 0.2], a: [1.0, -1.0, 0.5] },
                Biquad { b: [1.0, 0.5, 0.2], a: [1.0, 0.3, 0.2] },
                Biquad { b: [1.0, 0.5, 0.0], a: [1.0, -0.5, 0.0] },
            ]);
            for rho in [1.0, 0.999, 0.9] {
                let layout = Layout::of(&shape, rho);
                proptest::prop_assert_eq!(layout.len(), u.len());
                let sos = Sos::new(layout.unpack(&u));
                proptest::prop_assert!(sos.is_stable(), "{:?}", sos);
                proptest::prop_assert!(sos.poles().iter().all(|p| p.norm() < rho), "{rho}: {:?}", sos.poles());
                // And back: the packing inverts the unpacking.
                let again = Sos::new(layout.unpack(&layout.pack(&sos)));
                for (x, y) in again.sections.iter().zip(&sos.sections) {
                    for (p, q) in x.a.iter().zip(&y.a) {
                        proptest::prop_assert!((p - q).abs() < 1e-6, "{rho}: {:?} vs {:?}", x, y);
                    }
                }
            }
        }
    }

    #[test]
    fn refinement_converges_from_a_perturbed_start_and_stays_stable() {
        let rate = SampleRate(2000);
        let truth = Sos::new(vec![
            Biquad {
                b: [0.5, 0.1, -0.2],
                a: [1.0, -1.7, 0.9],
            },
            Biquad {
                b: [1.0, 0.3, 0.2],
                a: [1.0, 0.2, 0.5],
            },
        ]);
        let freqs = Band::new(20.0, 900.0).log_grid(120);
        let t = target_of(&truth, rate, &freqs);
        let start = Sos::new(vec![
            Biquad {
                b: [0.4, 0.2, -0.1],
                a: [1.0, -1.6, 0.85],
            },
            Biquad {
                b: [0.9, 0.2, 0.1],
                a: [1.0, 0.1, 0.4],
            },
        ]);
        let out = refine(&start, &t, Objective::OutputError, 200, 1.0).unwrap();
        assert!(out.sos.is_stable());
        for &f in &freqs {
            let (x, y) = (
                out.sos.response(rate.omega(f)),
                truth.response(rate.omega(f)),
            );
            assert!((x - y).norm() < 1e-6 * y.norm(), "{f}: {x} vs {y}");
        }
    }
}
