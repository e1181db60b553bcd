//! Bounded non-linear least squares by the trust-region-reflective method (Branch, Coleman
//! and Li, 1999).
//!
//! # Problem
//!
//! $$ \min_x\; F(x) = \tfrac12 \lVert f(x) \rVert^2 \quad\text{subject to}\quad l \le x \le u, $$
//!
//! with `f: R^n -> R^m`, `m >= n` typical but not required, bounds possibly infinite.
//!
//! # Coleman-Li scaling
//!
//! With the gradient `g = J^T f`, the first-order conditions of the bounded problem are
//! `v_i g_i = 0` for every `i`, where
//!
//! $$ v_i = \begin{cases} u_i - x_i & g_i < 0,\ u_i < \infty \\ x_i - l_i & g_i > 0,\ l_i > -\infty \\ 1 & \text{otherwise,} \end{cases} $$
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
//! $$ q(p) = ĝ^T p + \tfrac12 p^T (\hat J^T \hat J + C) p, \qquad \hat J = J D,\quad C = \operatorname{diag}(g \circ \partial v), $$
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

use nalgebra::{DMatrix, DVector};

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

/// The bounds as a box.
struct Bounds<'a> {
    lo: &'a [f64],
    hi: &'a [f64],
}

impl Bounds<'_> {
    /// The Coleman-Li scaling `v` and its derivative `∂v`.
    fn scaling(&self, x: &[f64], g: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let n = x.len();
        let mut v = vec![1.0; n];
        let mut dv = vec![0.0; n];
        for i in 0..n {
            if g[i] < 0.0 && self.hi[i].is_finite() {
                v[i] = self.hi[i] - x[i];
                dv[i] = -1.0;
            } else if g[i] > 0.0 && self.lo[i].is_finite() {
                v[i] = x[i] - self.lo[i];
                dv[i] = 1.0;
            }
        }
        (v, dv)
    }

    /// The largest `t >= 0` with `x + t d` in the box, and the components that meet a
    /// bound there (empty when the ray never leaves the box).
    fn stride(&self, x: &[f64], d: &[f64]) -> (f64, Vec<usize>) {
        let mut t = f64::INFINITY;
        let mut hits = Vec::new();
        for i in 0..x.len() {
            let ti = if d[i] > 0.0 {
                (self.hi[i] - x[i]) / d[i]
            } else if d[i] < 0.0 {
                (self.lo[i] - x[i]) / d[i]
            } else {
                f64::INFINITY
            };
            let ti = ti.max(0.0);
            if ti < t {
                t = ti;
                hits.clear();
                hits.push(i);
            } else if ti == t && ti.is_finite() {
                hits.push(i);
            }
        }
        (t, hits)
    }

    fn contains_strictly(&self, x: &[f64]) -> bool {
        x.iter()
            .zip(self.lo.iter().zip(self.hi))
            .all(|(&v, (&l, &h))| v > l && v < h)
    }

    /// `x` moved strictly inside: a value on (or within a relative `1e-10` of) a bound is
    /// pushed that far in, or to the middle of a box narrower than that.
    fn interior(&self, x: &mut [f64]) {
        for ((xi, &l), &h) in x.iter_mut().zip(self.lo).zip(self.hi) {
            // An infinite bound needs no margin (and would make an infinite one).
            let lo_in = if l.is_finite() {
                l + 1e-10 * l.abs().max(1.0)
            } else {
                l
            };
            let hi_in = if h.is_finite() {
                h - 1e-10 * h.abs().max(1.0)
            } else {
                h
            };
            if lo_in >= hi_in {
                *xi = 0.5 * (l + h);
            } else if *xi < lo_in {
                *xi = lo_in;
            } else if *xi > hi_in {
                *xi = hi_in;
            }
        }
    }
}

/// The quadratic model: `q(p) = ĝ·p + ½ p^T B p`.
struct Model {
    gh: DVector<f64>,
    b: DMatrix<f64>,
}

impl Model {
    fn value(&self, p: &DVector<f64>) -> f64 {
        self.gh.dot(p) + 0.5 * p.dot(&(&self.b * p))
    }

    /// The minimiser of `q(a + t d)` for `t` in `[t0, t1]`, and its value.
    fn line_min(&self, a: &DVector<f64>, d: &DVector<f64>, t0: f64, t1: f64) -> (f64, f64) {
        let bd = &self.b * d;
        let curv = d.dot(&bd);
        let slope = self.gh.dot(d) + a.dot(&bd);
        let q = |t: f64| self.value(&(a + d * t));
        let mut best = if q(t0) <= q(t1) { t0 } else { t1 };
        if curv > 0.0 {
            let t = (-slope / curv).clamp(t0, t1);
            if q(t) < q(best) {
                best = t;
            }
        }
        (best, q(best))
    }
}

/// Most trial steps from one point before the search gives up.
const MAX_STEP_TRIES: usize = 2_000;

/// `p(α)` for the SVD data: `−V (s/(s² + α)) uf`.
fn tr_step(v: &DMatrix<f64>, s: &DVector<f64>, uf: &DVector<f64>, alpha: f64) -> DVector<f64> {
    let mut c = DVector::zeros(s.len());
    for i in 0..s.len() {
        let den = s[i] * s[i] + alpha;
        c[i] = if den > 0.0 { -s[i] * uf[i] / den } else { 0.0 };
    }
    v * c
}

/// The exact minimiser of `½‖A p + f‖²` over `‖p‖ <= Δ`, and whether the constraint is active.
fn solve_trust_region(a: &DMatrix<f64>, f: &DVector<f64>, delta: f64) -> Option<DVector<f64>> {
    let svd = super::svd(a.clone()).ok()?;
    let u = svd.u?;
    let vt = svd.v_t?;
    let v = vt.transpose();
    let s = svd.singular_values;
    let uf = u.transpose() * f;
    let smax = s.iter().copied().fold(0.0, f64::max);
    let full_rank = s.iter().all(|&si| si > smax * 1e-12 * s.len() as f64);
    if full_rank {
        let p = tr_step(&v, &s, &uf, 0.0);
        if p.norm() <= delta {
            return Some(p);
        }
    }
    // ‖p(α)‖ decreases from ‖p(0)‖ (possibly infinite) to 0. Bracket: at α_hi = ‖A^T f‖/Δ,
    // ‖p‖ <= ‖A^T f‖/α = Δ.
    let atf = (a.transpose() * f).norm();
    if atf == 0.0 {
        return Some(DVector::zeros(s.len()));
    }
    let (mut lo, mut hi) = (0.0f64, atf / delta);
    let phi = |alpha: f64| -> (f64, f64) {
        // ‖p‖ and d‖p‖/dα.
        let mut n2 = 0.0;
        let mut d = 0.0;
        for i in 0..s.len() {
            let den = s[i] * s[i] + alpha;
            let c = s[i] * uf[i];
            n2 += c * c / (den * den);
            d -= c * c / (den * den * den);
        }
        let n = n2.sqrt();
        (n, if n > 0.0 { d / n } else { 0.0 })
    };
    let mut alpha = (lo * hi).sqrt().max(1e-3 * hi);
    for _ in 0..60 {
        if !(alpha > lo && alpha < hi) {
            alpha = (1e-3 * hi).max((lo * hi).sqrt());
        }
        let (n, dn) = phi(alpha);
        if (n - delta).abs() <= 1e-3 * delta {
            break;
        }
        if n > delta {
            lo = alpha;
        } else {
            hi = alpha;
        }
        // Newton on 1/‖p‖ − 1/Δ, which is close to linear in α.
        if dn < 0.0 && n > 0.0 {
            alpha -= (n - delta) / dn * (n / delta);
        } else {
            alpha = 0.5 * (lo + hi);
        }
    }
    let mut p = tr_step(&v, &s, &uf, alpha);
    let pn = p.norm();
    if pn > delta {
        p *= delta / pn;
    }
    Some(p)
}

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

/// The step (in scaled variables) to take from the trust-region solution `ph`, reflecting
/// off the bounds if it leaves the box, and its model value.
fn select_step(
    bounds: &Bounds<'_>,
    x: &[f64],
    d: &[f64],
    model: &Model,
    ph: DVector<f64>,
    delta: f64,
    theta: f64,
) -> (DVector<f64>, f64) {
    let n = x.len();
    let to_x = |p: &DVector<f64>| -> Vec<f64> { p.iter().zip(d).map(|(a, b)| a * b).collect() };
    let step = to_x(&ph);
    let trial: Vec<f64> = x.iter().zip(&step).map(|(a, b)| a + b).collect();
    if bounds.contains_strictly(&trial) {
        let q = model.value(&ph);
        return (ph, q);
    }
    // 1. Cut back to the first bound, then θ of that.
    let (t_hit, hits) = bounds.stride(x, &step);
    let t_hit = t_hit.min(1.0);
    let cut = &ph * (theta * t_hit);
    let mut best = (model.value(&cut), cut);

    // 2. The reflected path from the point on the bound.
    let on_bound_h = &ph * t_hit;
    let mut rh = ph.clone();
    for &i in &hits {
        rh[i] = -rh[i];
    }
    let x_on: Vec<f64> = x
        .iter()
        .zip(&to_x(&on_bound_h))
        .map(|(a, b)| a + b)
        .collect();
    let (t_box, _) = bounds.stride(&x_on, &to_x(&rh));
    // Largest t with ‖on + t r‖ <= Δ.
    let (a2, a1, a0) = (
        rh.dot(&rh),
        2.0 * on_bound_h.dot(&rh),
        on_bound_h.dot(&on_bound_h) - delta * delta,
    );
    let t_region = if a2 > 0.0 {
        let disc = (a1 * a1 - 4.0 * a2 * a0).max(0.0);
        ((-a1 + disc.sqrt()) / (2.0 * a2)).max(0.0)
    } else {
        0.0
    };
    let t_max = t_box.min(t_region);
    if t_max.is_finite() && t_max > 0.0 {
        let (t, q) = model.line_min(&on_bound_h, &rh, (1.0 - theta) * t_max, theta * t_max);
        if q < best.0 {
            best = (q, &on_bound_h + &rh * t);
        }
    }

    // 3. The scaled anti-gradient (a Cauchy point).
    let gh_norm = model.gh.norm();
    if gh_norm > 0.0 {
        let dir = -&model.gh;
        let (t_box, _) = bounds.stride(x, &to_x(&dir));
        let t_max = t_box.min(delta / gh_norm);
        if t_max.is_finite() && t_max > 0.0 {
            let (t, q) = model.line_min(&DVector::zeros(n), &dir, 0.0, theta * t_max);
            if q < best.0 {
                best = (q, dir * t);
            }
        }
    }
    (best.1, best.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `y = a e^{-b t} + c`, with its analytic Jacobian.
    struct Decay {
        t: Vec<f64>,
        y: Vec<f64>,
        analytic: bool,
    }

    impl LeastSquares for Decay {
        fn residual_count(&self) -> usize {
            self.t.len()
        }
        fn residuals(&self, x: &[f64], r: &mut [f64]) {
            for ((ri, t), y) in r.iter_mut().zip(&self.t).zip(&self.y) {
                *ri = x[0] * (-x[1] * t).exp() + x[2] - y;
            }
        }
        fn jacobian(&self, x: &[f64], j: &mut DMatrix<f64>) -> bool {
            if !self.analytic {
                return false;
            }
            for (i, t) in self.t.iter().enumerate() {
                let e = (-x[1] * t).exp();
                j[(i, 0)] = e;
                j[(i, 1)] = -x[0] * t * e;
                j[(i, 2)] = 1.0;
            }
            true
        }
    }

    fn decay(analytic: bool) -> Decay {
        let t: Vec<f64> = (0..40).map(|i| f64::from(i) * 0.1).collect();
        let y = t.iter().map(|t| 2.5 * (-1.3 * t).exp() + 0.4).collect();
        Decay { t, y, analytic }
    }

    #[test]
    fn recovers_exponential_decay_exactly() {
        for analytic in [true, false] {
            let p = decay(analytic);
            let sol = least_squares_bounded(
                &p,
                &[1.0, 0.5, 0.0],
                &[0.0, 0.0, -10.0],
                &[10.0, 10.0, 10.0],
                &TrfOptions::default(),
            )
            .unwrap();
            eprintln!(
                "decay (analytic {analytic}): x = {:?}, cost {:.2e}, {} iterations, {:?}",
                sol.x, sol.cost, sol.iterations, sol.status
            );
            for (got, want) in sol.x.iter().zip([2.5, 1.3, 0.4]) {
                assert!((got - want).abs() < 1e-7, "{got} vs {want}");
            }
            assert!(sol.cost < 1e-18);
            assert_ne!(sol.status, TrfStatus::MaxIterations);
        }
    }

    fn rosenbrock() -> FnResiduals<impl Fn(&[f64], &mut [f64])> {
        FnResiduals {
            m: 2,
            f: |x: &[f64], r: &mut [f64]| {
                r[0] = 10.0 * (x[1] - x[0] * x[0]);
                r[1] = 1.0 - x[0];
            },
        }
    }

    #[test]
    fn optimum_on_a_bound_satisfies_kkt() {
        // x1 <= 0.5 excludes (1, 1); the constrained optimum is (≈0.7071, 0.5).
        let p = rosenbrock();
        let lo = [-2.0, -1.0];
        let hi = [2.0, 0.5];
        let sol =
            least_squares_bounded(&p, &[-1.2, 0.0], &lo, &hi, &TrfOptions::default()).unwrap();
        eprintln!(
            "bounded rosenbrock: x = {:?}, g = {:?}, {} iterations, {:?}",
            sol.x, sol.gradient, sol.iterations, sol.status
        );
        assert!((sol.x[1] - 0.5).abs() < 1e-6, "{:?}", sol.x);
        assert!(sol.x[1] < 0.5, "strictly interior");
        // On the upper bound the gradient of the cost must point out of the box's interior
        // (g < 0: decreasing x1 would raise the cost), and vanish in the free component.
        assert!(sol.gradient[1] < -1e-3, "{:?}", sol.gradient);
        assert!(sol.gradient[0].abs() < 1e-6, "{:?}", sol.gradient);
        // The free component's optimum along x1 = 0.5: d/dx0 of the cost is zero.
        let x0 = sol.x[0];
        let grad0 = -400.0 * x0 * (0.5 - x0 * x0) - 2.0 * (1.0 - x0);
        assert!(grad0.abs() < 1e-5, "{grad0}");

        // Lower bound active: x0 >= 1.2 excludes (1, 1).
        let sol = least_squares_bounded(
            &p,
            &[1.5, 2.0],
            &[1.2, -5.0],
            &[3.0, 5.0],
            &TrfOptions::default(),
        )
        .unwrap();
        assert!((sol.x[0] - 1.2).abs() < 1e-6, "{:?}", sol.x);
        assert!(sol.gradient[0] > 1e-3 && sol.gradient[1].abs() < 1e-6);
        assert!((sol.x[1] - 1.44).abs() < 1e-5, "{:?}", sol.x);
    }

    #[test]
    fn unconstrained_rosenbrock_converges() {
        let p = rosenbrock();
        let inf = f64::INFINITY;
        let sol = least_squares_bounded(
            &p,
            &[-1.2, 1.0],
            &[-inf, -inf],
            &[inf, inf],
            &Default::default(),
        )
        .unwrap();
        assert!((sol.x[0] - 1.0).abs() < 1e-8 && (sol.x[1] - 1.0).abs() < 1e-8);
    }

    #[test]
    fn malformed_problems_are_errors() {
        let p = rosenbrock();
        let o = TrfOptions::default();
        assert!(matches!(
            least_squares_bounded(&p, &[3.0, 0.0], &[-2.0, -1.0], &[2.0, 1.0], &o),
            Err(TrfError::Infeasible { index: 0, .. })
        ));
        assert!(matches!(
            least_squares_bounded(&p, &[0.0, 0.0], &[1.0, -1.0], &[1.0, 1.0], &o),
            Err(TrfError::InvalidBounds { index: 0, .. })
        ));
        assert!(matches!(
            least_squares_bounded(&p, &[0.0], &[-1.0, -1.0], &[1.0, 1.0], &o),
            Err(TrfError::Dimension { .. })
        ));
        assert!(matches!(
            least_squares_bounded(&p, &[f64::NAN, 0.0], &[-1.0, -1.0], &[1.0, 1.0], &o),
            Err(TrfError::Infeasible { .. })
        ));
        let bad = TrfOptions {
            ftol: f64::NAN,
            ..o
        };
        assert!(least_squares_bounded(&p, &[0.0, 0.0], &[-1.0, -1.0], &[1.0, 1.0], &bad).is_err());
        // A start on a bound is moved inside, not refused.
        let sol = least_squares_bounded(&p, &[2.0, 0.5], &[-2.0, -1.0], &[2.0, 0.5], &o).unwrap();
        assert!((sol.x[1] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn non_finite_residuals_are_errors() {
        let nan = FnResiduals {
            m: 3,
            f: |_: &[f64], r: &mut [f64]| r.fill(f64::NAN),
        };
        assert_eq!(
            least_squares_bounded(&nan, &[0.5], &[0.0], &[1.0], &TrfOptions::default()),
            Err(TrfError::NonFinite {
                what: "residual vector"
            })
        );
        // Finite at the start, NaN beyond x > 0.6: the search retreats and still ends well.
        let cliff = FnResiduals {
            m: 1,
            f: |x: &[f64], r: &mut [f64]| {
                r[0] = if x[0] > 0.6 { f64::NAN } else { x[0] - 2.0 };
            },
        };
        let sol = least_squares_bounded(&cliff, &[0.1], &[0.0], &[10.0], &TrfOptions::default());
        match sol {
            Ok(s) => assert!(s.x[0] <= 0.6 && s.cost.is_finite()),
            Err(e) => assert!(matches!(
                e,
                TrfError::Numerical(_) | TrfError::NonFinite { .. }
            )),
        }
    }
}
