//! Bounded non-linear least squares by the trust-region-reflective method (Branch, Coleman
//! and Li, 1999).
//!
//! # Problem
//!
//! ```math
//! \min_x\; F(x) = \tfrac12 \lVert f(x) \rVert^2 \quad\text{subject to}\quad l \le x \le u,
//! ```
//!
//! with `f: R^n -> R^m`, `m >= n` typical but not required, bounds possibly infinite.
//!
//! # Coleman-Li scaling
//!
//! With the gradient `g = J^T f`, the first-order conditions of the bounded problem are
//! `v_i g_i = 0` for every `i`, where
//!
//! ```math
//! v_i = \begin{cases} u_i - x_i & g_i < 0,\ u_i < \infty \\ x_i - l_i & g_i > 0,\ l_i > -\infty \\ 1 & \text{otherwise,} \end{cases}
//! ```
//!
//! the distance to the bound the anti-gradient points at. A component whose anti-gradient
//! pushes it into a bound may keep a non-zero gradient (its multiplier) as `v_i -> 0`;
//! everywhere else the gradient must vanish. The iteration works in the scaled variables
//! `x = x_k + D p`, `D = diag(v^{1/2})`, in which the bounds the gradient points at recede as
//! the iterate approaches them, so that steps do not stall against them. The scaled
//! gradient is `ĝ = D g`; convergence is declared when `‖v ∘ g‖_∞ < gtol`.
//!
//! # Subproblem
//!
//! Each iteration minimises the quadratic model
//!
//! ```math
//! q(p) = ĝ^T p + \tfrac12 p^T (\hat J^T \hat J + C) p, \qquad \hat J = J D,\quad C = \operatorname{diag}(g \circ \partial v),
//! ```
//!
//! inside the trust region `‖p‖ <= Δ`, where `∂v_i ∈ {−1, 0, 1}` is the derivative of
//! `v_i` (zero where `v_i = 1`): `C >= 0` is the curvature the scaling itself adds. This is
//! a linear least-squares problem with the augmented matrix `[Ĵ; C^{1/2}]` and right-hand
//! side `[−f; 0]`, solved exactly (Moré, 1978): from the SVD `U S V^T` of the augmented
//! matrix, `p(α) = −V (S² + α)^{-1} S U^T [f; 0]` is the minimiser of the model plus
//! `α ‖p‖²/2`; `α = 0` if the Gauss-Newton step fits in the region, else the `α > 0` with
//! `‖p(α)‖ = Δ`, found by safeguarded Newton iteration on `1/‖p(α)‖ − 1/Δ` (nearly linear
//! in `α`, so a few iterations suffice). Problems here are small (`n` up to ten or so),
//! so the dense SVD is cheap.
//!
//! # Reflection
//!
//! The trial point `x + D p` may leave the box. Then three candidates are compared on the
//! model `q`, the best taken:
//!
//! 1. the step cut back to where it first meets a bound, times `θ = max(0.995, 1 − ‖v ∘ g‖_∞)`
//!    (strictly interior, approaching the bound as the iteration converges);
//! 2. the reflected path: from that point on the bound, the step with the components that
//!    hit the bound negated (mirrored off it), followed as far as the box and the trust
//!    region allow, stopping at the minimum of `q` along it;
//! 3. the scaled anti-gradient `−D ĝ`, followed to the minimum of `q` along it within the box
//!    and the region (a Cauchy point, which guarantees enough decrease for convergence).
//!
//! Every iterate is strictly inside the bounds: a trial point within a relative `1e-10` of
//! a bound is nudged inside.
//!
//! # Radius update and termination
//!
//! `ρ = (F(x) − F(x + s)) / (−q(p))`. If `ρ < 0.25` the radius shrinks to `‖p‖/4`; if
//! `ρ > 0.75` and the step reached the region's edge it doubles. A step is accepted only
//! if it lowers `F`; otherwise the step is recomputed with the smaller radius and the same
//! Jacobian. The solver stops when
//!
//! - `‖v ∘ g‖_∞ < gtol` ([`TrfStatus::Gtol`]);
//! - an accepted step lowers `F` by less than `ftol F` with `ρ > 0.25` ([`TrfStatus::Ftol`]);
//! - an accepted step has `‖s‖ < xtol (xtol + ‖x‖)` ([`TrfStatus::Xtol`]);
//! - or after `max_iterations` Jacobians ([`TrfStatus::MaxIterations`], still a result).
//!
//! Without an analytic Jacobian, forward differences with step `√ε max(1, |x_i|)` are
//! used, taken backwards where the forward point would leave the box.

mod bounds;
mod subproblem;
#[cfg(test)]
mod tests;

use nalgebra::{DMatrix, DVector};

use bounds::{Bounds, select_step};
use subproblem::{Model, solve_trust_region};

/// A least-squares problem: `m` residuals of `n` parameters.
pub trait LeastSquares {
    /// The number of residuals `m`.
    fn residual_count(&self) -> usize;

    /// Writes the `m` residuals at `x` into `r`.
    fn residuals(&self, x: &[f64], r: &mut [f64]);

    /// Writes the `m x n` Jacobian at `x` into `j` and returns `true`, or returns `false`
    /// (the default) to have it estimated by forward differences.
    fn jacobian(&self, _x: &[f64], _j: &mut DMatrix<f64>) -> bool {
        false
    }
}

/// A [`LeastSquares`] problem from a residual closure, its Jacobian by finite differences.
pub struct FnResiduals<F> {
    /// The number of residuals.
    pub m: usize,
    /// `(x, r)`: writes the residuals at `x` into `r`.
    pub f: F,
}

impl<F: Fn(&[f64], &mut [f64])> LeastSquares for FnResiduals<F> {
    fn residual_count(&self) -> usize {
        self.m
    }
    fn residuals(&self, x: &[f64], r: &mut [f64]) {
        (self.f)(x, r);
    }
}

/// Settings of the solver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrfOptions {
    /// Relative decrease of the cost below which an accepted step ends the search.
    pub ftol: f64,
    /// Relative step length below which the search ends.
    pub xtol: f64,
    /// Scaled first-order optimality `‖v ∘ g‖_∞` below which the search ends.
    pub gtol: f64,
    /// Jacobian evaluations (iterations) allowed.
    pub max_iterations: usize,
}

impl Default for TrfOptions {
    /// `ftol = xtol = gtol = 1e-10`, 200 iterations.
    fn default() -> Self {
        Self {
            ftol: 1e-10,
            xtol: 1e-10,
            gtol: 1e-10,
            max_iterations: 200,
        }
    }
}

/// Why the search stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrfStatus {
    /// The scaled gradient vanished.
    Gtol,
    /// The cost stopped decreasing.
    Ftol,
    /// The step became negligible.
    Xtol,
    /// The iteration limit was reached first.
    MaxIterations,
}

/// The result of a search.
#[derive(Debug, Clone, PartialEq)]
pub struct TrfSolution {
    /// The parameters, strictly inside the bounds.
    pub x: Vec<f64>,
    /// `½‖f(x)‖²`.
    pub cost: f64,
    /// The residuals at `x`.
    pub residuals: Vec<f64>,
    /// The gradient `J^T f` at `x` (at the last Jacobian, for the KKT conditions).
    pub gradient: Vec<f64>,
    /// Jacobian evaluations made.
    pub iterations: usize,
    /// Residual evaluations made, Jacobian differences excluded.
    pub evaluations: usize,
    /// Why it stopped.
    pub status: TrfStatus,
}

/// What is wrong with a bounded least-squares problem.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TrfError {
    /// `x0`, `lower` and `upper` differ in length, or there are no parameters.
    #[error("{what} has {len} entries, {expected} expected")]
    Dimension {
        /// Which vector.
        what: &'static str,
        /// Its length.
        len: usize,
        /// The length expected.
        expected: usize,
    },
    /// A lower bound is not below its upper bound, or a bound is NaN.
    #[error("bounds of parameter {index}: [{lower}, {upper}] is empty")]
    InvalidBounds {
        /// The parameter.
        index: usize,
        /// Its lower bound.
        lower: f64,
        /// Its upper bound.
        upper: f64,
    },
    /// The start lies outside the bounds, or is not finite.
    #[error("x0[{index}] = {value} is outside [{lower}, {upper}]")]
    Infeasible {
        /// The parameter.
        index: usize,
        /// Its start.
        value: f64,
        /// Its lower bound.
        lower: f64,
        /// Its upper bound.
        upper: f64,
    },
    /// A setting is out of range.
    #[error("option {name} = {value} is out of range")]
    InvalidOption {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// The residuals or the Jacobian at the start, or the Jacobian later, are not finite.
    #[error("the {what} is not finite at the current point")]
    NonFinite {
        /// `"residual vector"` or `"Jacobian"`.
        what: &'static str,
    },
    /// A linear-algebra step failed, or every trial point had non-finite residuals.
    #[error("numerical failure: {0}")]
    Numerical(&'static str),
}

/// Most trial steps from one point before the search gives up.
const MAX_STEP_TRIES: usize = 2_000;

/// Minimises `½‖f(x)‖²` over `lower <= x <= upper` by the trust-region-reflective method
/// (see the module docs).
///
/// `x0` must lie within the bounds (a start on a bound is moved just inside); infinite
/// bounds are allowed.
///
/// # Errors
/// [`TrfError::Dimension`], [`TrfError::InvalidBounds`], [`TrfError::Infeasible`] and
/// [`TrfError::InvalidOption`] for a malformed problem; [`TrfError::NonFinite`] when the
/// residuals at the start (or a Jacobian) are not finite; [`TrfError::Numerical`] when the
/// SVD fails or every trial point down to a vanishing radius had non-finite residuals.
pub fn least_squares_bounded<P: LeastSquares + ?Sized>(
    problem: &P,
    x0: &[f64],
    lower: &[f64],
    upper: &[f64],
    opts: &TrfOptions,
) -> Result<TrfSolution, TrfError> {
    let n = x0.len();
    if n == 0 {
        return Err(TrfError::Dimension {
            what: "x0",
            len: 0,
            expected: 1,
        });
    }
    for (what, v) in [("lower", lower), ("upper", upper)] {
        if v.len() != n {
            return Err(TrfError::Dimension {
                what,
                len: v.len(),
                expected: n,
            });
        }
    }
    for (name, value) in [
        ("ftol", opts.ftol),
        ("xtol", opts.xtol),
        ("gtol", opts.gtol),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(TrfError::InvalidOption { name, value });
        }
    }
    if opts.max_iterations == 0 {
        return Err(TrfError::InvalidOption {
            name: "max_iterations",
            value: 0.0,
        });
    }
    for i in 0..n {
        let (l, h) = (lower[i], upper[i]);
        if l.is_nan() || h.is_nan() || l >= h || l == f64::INFINITY || h == f64::NEG_INFINITY {
            return Err(TrfError::InvalidBounds {
                index: i,
                lower: l,
                upper: h,
            });
        }
        if !(x0[i].is_finite() && x0[i] >= l && x0[i] <= h) {
            return Err(TrfError::Infeasible {
                index: i,
                value: x0[i],
                lower: l,
                upper: h,
            });
        }
    }
    let m = problem.residual_count();
    if m == 0 {
        return Err(TrfError::Dimension {
            what: "residual vector",
            len: 0,
            expected: 1,
        });
    }
    let bounds = Bounds {
        lo: lower,
        hi: upper,
    };
    let mut x = x0.to_vec();
    bounds.interior(&mut x);

    let eval = |x: &[f64], r: &mut [f64]| -> bool {
        problem.residuals(x, r);
        r.iter().all(|v| v.is_finite())
    };
    let mut f = vec![0.0; m];
    if !eval(&x, &mut f) {
        return Err(TrfError::NonFinite {
            what: "residual vector",
        });
    }
    let mut evaluations = 1;
    let mut cost = 0.5 * f.iter().map(|v| v * v).sum::<f64>();
    let mut jac = DMatrix::<f64>::zeros(m, n);
    let mut f_try = vec![0.0; m];
    let x_norm0 = x.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mut delta = if x_norm0 > 0.0 { x_norm0 } else { 1.0 };
    let mut status = TrfStatus::MaxIterations;
    let mut iterations = 0;
    let mut g = vec![0.0; n];

    while iterations < opts.max_iterations {
        jacobian(problem, &bounds, &x, &f, &mut jac, &mut f_try)?;
        iterations += 1;
        let fv = DVector::from_column_slice(&f);
        let gv = jac.transpose() * &fv;
        g.copy_from_slice(gv.as_slice());
        let (v, dv) = bounds.scaling(&x, &g);
        let opt = v
            .iter()
            .zip(&g)
            .map(|(vi, gi)| (vi * gi).abs())
            .fold(0.0, f64::max);
        if opt < opts.gtol {
            status = TrfStatus::Gtol;
            break;
        }
        let d: Vec<f64> = v.iter().map(|vi| vi.sqrt()).collect();
        let mut jh = jac.clone();
        for (j, dj) in d.iter().enumerate() {
            jh.column_mut(j).scale_mut(*dj);
        }
        let c: Vec<f64> = g.iter().zip(&dv).map(|(gi, dvi)| gi * dvi).collect();
        let mut aug = DMatrix::<f64>::zeros(m + n, n);
        aug.view_mut((0, 0), (m, n)).copy_from(&jh);
        for j in 0..n {
            aug[(m + j, j)] = c[j].max(0.0).sqrt();
        }
        let mut faug = DVector::<f64>::zeros(m + n);
        faug.rows_mut(0, m).copy_from(&fv);
        let mut bmat = jh.transpose() * &jh;
        for j in 0..n {
            bmat[(j, j)] += c[j].max(0.0);
        }
        let model = Model {
            gh: DVector::from_iterator(n, g.iter().zip(&d).map(|(gi, di)| gi * di)),
            b: bmat,
        };
        let theta = (1.0 - opt).max(0.995);

        let mut accepted = false;
        let mut stop = None;
        let mut tries = 0usize;
        while !accepted {
            // A failed try shrinks the radius fourfold, so ~500 reach the 1e-300 floor; a
            // NaN ratio (leaving the radius alone) must not hold the loop forever.
            tries += 1;
            if tries > MAX_STEP_TRIES {
                return Err(TrfError::Numerical(
                    "no acceptable step within the iteration limit",
                ));
            }
            let ph = solve_trust_region(&aug, &faug, delta)
                .ok_or(TrfError::Numerical("SVD of the Jacobian failed"))?;
            let (ph, predicted) = select_step(&bounds, &x, &d, &model, ph, delta, theta);
            let step: Vec<f64> = ph.iter().zip(&d).map(|(p, di)| p * di).collect();
            let mut x_try: Vec<f64> = x.iter().zip(&step).map(|(a, b)| a + b).collect();
            bounds.interior(&mut x_try);
            let step_norm = x_try
                .iter()
                .zip(&x)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt();
            let ph_norm = ph.norm();
            let ok = eval(&x_try, &mut f_try);
            evaluations += 1;
            let cost_try = if ok {
                0.5 * f_try.iter().map(|v| v * v).sum::<f64>()
            } else {
                f64::INFINITY
            };
            let actual = cost - cost_try;
            let ratio = if predicted < 0.0 {
                actual / -predicted
            } else {
                -1.0
            };
            if ratio < 0.25 || !ok {
                delta = 0.25 * ph_norm.min(delta);
            } else if ratio > 0.75 && ph_norm >= 0.95 * delta {
                delta *= 2.0;
            }
            let x_norm = x.iter().map(|v| v * v).sum::<f64>().sqrt();
            if actual > 0.0 {
                accepted = true;
                if actual < opts.ftol * cost && ratio > 0.25 {
                    stop = Some(TrfStatus::Ftol);
                } else if step_norm < opts.xtol * (opts.xtol + x_norm) {
                    stop = Some(TrfStatus::Xtol);
                }
                x = x_try;
                std::mem::swap(&mut f, &mut f_try);
                cost = cost_try;
            } else if step_norm < opts.xtol * (opts.xtol + x_norm) || delta < 1e-300 {
                // No decrease from a step too small to matter: the point is as good as the
                // arithmetic allows, unless the failures were all non-finite residuals.
                if !ok && delta < 1e-300 {
                    return Err(TrfError::Numerical(
                        "the residuals are not finite anywhere near the current point",
                    ));
                }
                stop = Some(TrfStatus::Xtol);
                break;
            }
        }
        if let Some(s) = stop {
            status = s;
            break;
        }
    }
    Ok(TrfSolution {
        x,
        cost,
        residuals: f,
        gradient: g,
        iterations,
        evaluations,
        status,
    })
}

/// The Jacobian, analytic if the problem has one, else by forward differences.
fn jacobian<P: LeastSquares + ?Sized>(
    problem: &P,
    bounds: &Bounds<'_>,
    x: &[f64],
    f: &[f64],
    jac: &mut DMatrix<f64>,
    scratch: &mut [f64],
) -> Result<(), TrfError> {
    if !problem.jacobian(x, jac) {
        let mut xp = x.to_vec();
        for j in 0..x.len() {
            let mut h = f64::EPSILON.sqrt() * x[j].abs().max(1.0);
            if x[j] + h > bounds.hi[j] {
                h = -h;
            }
            xp[j] = x[j] + h;
            problem.residuals(&xp, scratch);
            let h = xp[j] - x[j];
            xp[j] = x[j];
            for i in 0..f.len() {
                jac[(i, j)] = (scratch[i] - f[i]) / h;
            }
        }
    }
    if jac.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(TrfError::NonFinite { what: "Jacobian" })
    }
}
