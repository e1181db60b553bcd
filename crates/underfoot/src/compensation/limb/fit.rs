//! The bounded fit of the limb model to a measured magnitude.
//!
//! [`fit_limb`] fits `20 log10 |level · H_u(f)|` to a measured magnitude in dB (the loaded
//! response over the unloaded one) by bounded least squares
//! ([trust-region-reflective](crate::numeric::trf)) in the logarithms of the three parameters,
//! with the logarithms of [`LimbBounds`] as bounds: the parameters span decades, and in
//! log space a unit step means the same relative change for each. The level (in dB) is a
//! free, unbounded fourth parameter by default, because the accelerometer's units are
//! arbitrary. The search starts from Table 1's mean and from a 3 x 3 x 3 grid spanning the
//! bounds, and keeps the best. The Jacobian is analytic: with `r_k = 20 log10|H_u(f_k)|
//! + L − y_k`, `∂r/∂θ = (20/ln 10) Re(∂_θ H_u / H_u)` and
//!
//! ```math
//! \partial_{\ln\tau} H_u = -\frac{\tau s}{(1+\tau s)^2},\quad
//!   \partial_{\ln K} H_u = -\frac{g_2 s^2 K}{D^2},\quad
//!   \partial_{\ln B} H_u = -\frac{g_2 s^3 B}{D^2},\qquad D = s^2 + B s + K.
//! ```
//!
//! **Identifiability.** Above the leg's corner `1/(2πτ)` (43 Hz for Table 1's mean),
//! `|H_l| ≈ 1/(ωτ)`, which is −19 dB at the skin's resonance `√(k2/m2)/2π` (383 Hz),
//! while `|H_s|` there is `g2 √(k2/m2) / (b2/m2) ≈ 0.005` (−46 dB): the skin only shows as
//! a ripple of a few tenths of a dB on the leg's slope. [`LimbFit::relative_std`] gives the
//! 1-σ relative uncertainty of each parameter that the residual noise implies (from
//! `σ² (J^T J)^{-1}` in log parameters), which says how far the skin parameters can be
//! trusted from a given measurement.

use std::f64::consts::{LN_10, PI};

use nalgebra::DMatrix;
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::{DEFAULT_G2, LimbModel, LimbParams};
use crate::compensation::CompensationError;
use crate::numeric::trf::{LeastSquares, TrfOptions, TrfSolution, least_squares_bounded};
use crate::units::Hz;

/// Bounds on the fitted parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LimbBounds {
    /// Lower bounds.
    pub lower: LimbParams,
    /// Upper bounds.
    pub upper: LimbParams,
}

impl Default for LimbBounds {
    /// Around Table 1's ranges: `b3/k3` in \[2e-4, 0.02\] s, `k2/m2` in \[1e5, 5e7\] s⁻²,
    /// `b2/m2` in \[50, 2e4\] s⁻¹.
    fn default() -> Self {
        Self {
            lower: LimbParams {
                b3_k3: 2e-4,
                k2_m2: 1e5,
                b2_m2: 50.0,
            },
            upper: LimbParams {
                b3_k3: 0.02,
                k2_m2: 5e7,
                b2_m2: 2e4,
            },
        }
    }
}

/// Settings of [`fit_limb`].
#[derive(Debug, Clone, PartialEq)]
pub struct LimbFitConfig {
    /// Bounds on the three parameters.
    pub bounds: LimbBounds,
    /// The skin gain `g2`, fixed.
    pub g2: f64,
    /// Whether the overall level is fitted (otherwise it is 1, 0 dB).
    pub fit_level: bool,
    /// The solver's settings, for each start.
    pub options: TrfOptions,
}

impl Default for LimbFitConfig {
    /// [`LimbBounds::default`], `g2 = 0.005`, level fitted, the solver's defaults.
    fn default() -> Self {
        Self {
            bounds: LimbBounds::default(),
            g2: DEFAULT_G2,
            fit_level: true,
            options: TrfOptions::default(),
        }
    }
}

/// The result of [`fit_limb`].
#[derive(Debug, Clone, PartialEq)]
pub struct LimbFit {
    /// The fitted model (level 1 unless fitted).
    pub model: LimbModel,
    /// RMS of the dB residuals.
    pub rms_error_db: f64,
    /// Iterations of the winning start.
    pub iterations: usize,
    /// Iterations over all starts.
    pub total_iterations: usize,
    /// Starts run.
    pub starts: usize,
    /// 1-σ relative uncertainty of `[b3/k3, k2/m2, b2/m2]` implied by the residuals:
    /// the square roots of the diagonal of `σ² (J^T J)^{-1}` in log parameters (level
    /// included in the fit), `σ²` the residual variance inflated by `(1 + ρ)/(1 − ρ)` for
    /// the residuals' lag-one correlation `ρ` between neighbouring frequencies. Infinite
    /// where `J^T J` is singular. It covers noise, not a systematic error of the model, and
    /// it is indicative only: sweep residuals are also heteroscedastic (noisier where the
    /// loaded response is weak) and correlated beyond one lag, and in the simulated tests
    /// the actual errors reached up to about four times this figure.
    pub relative_std: [f64; 3],
}

/// The fit's residuals in dB, in log parameters `[ln τ, ln K, ln B, (L dB)]`.
struct LimbProblem<'a> {
    omegas: Vec<f64>,
    y: &'a [f64],
    g2: f64,
    fit_level: bool,
}

impl LimbProblem<'_> {
    fn h(&self, x: &[f64], w: f64) -> (Complex64, [Complex64; 3]) {
        let (tau, k, b) = (x[0].exp(), x[1].exp(), x[2].exp());
        let s = Complex64::new(0.0, w);
        let l = 1.0 + tau * s;
        let d = s * s + b * s + k;
        let h = 1.0 / l + self.g2 * s * s / d;
        let dd = d * d;
        (
            h,
            [
                -tau * s / (l * l),
                -self.g2 * s * s * k / dd,
                -self.g2 * s * s * s * b / dd,
            ],
        )
    }

    fn level(&self, x: &[f64]) -> f64 {
        if self.fit_level { x[3] } else { 0.0 }
    }
}

const DB: f64 = 20.0 / LN_10;

impl LeastSquares for LimbProblem<'_> {
    fn residual_count(&self) -> usize {
        self.y.len()
    }

    fn residuals(&self, x: &[f64], r: &mut [f64]) {
        let l = self.level(x);
        for ((ri, &w), y) in r.iter_mut().zip(&self.omegas).zip(self.y) {
            let (h, _) = self.h(x, w);
            *ri = DB * h.norm().ln() + l - y;
        }
    }

    fn jacobian(&self, x: &[f64], j: &mut DMatrix<f64>) -> bool {
        for (i, &w) in self.omegas.iter().enumerate() {
            let (h, dh) = self.h(x, w);
            for (c, d) in dh.iter().enumerate() {
                j[(i, c)] = DB * (d / h).re;
            }
            if self.fit_level {
                j[(i, 3)] = 1.0;
            }
        }
        true
    }
}

/// Fits the limb model to a magnitude response in dB (see the module docs).
///
/// `magnitude_db[k]` is the loaded response over the unloaded one at `freqs[k]`.
///
/// # Errors
/// [`CompensationError::TooShort`] with fewer points than fitted parameters plus one,
/// [`CompensationError::Mismatch`] when the lengths differ, [`CompensationError::NonFinite`]
/// for a non-finite magnitude, [`CompensationError::InvalidParameter`] for a non-positive
/// frequency, invalid bounds or `g2`, and [`CompensationError::FitFailed`] when no start
/// could be fitted.
pub fn fit_limb(
    freqs: &[Hz],
    magnitude_db: &[f64],
    cfg: &LimbFitConfig,
) -> Result<LimbFit, CompensationError> {
    let n = if cfg.fit_level { 4 } else { 3 };
    if magnitude_db.len() != freqs.len() {
        return Err(CompensationError::Mismatch {
            what: "magnitude_db",
            len: magnitude_db.len(),
            expected: freqs.len(),
        });
    }
    if freqs.len() <= n {
        return Err(CompensationError::TooShort {
            what: "frequency response",
            len: freqs.len(),
            needed: n + 1,
        });
    }
    if let Some(index) = magnitude_db.iter().position(|v| !v.is_finite()) {
        return Err(CompensationError::NonFinite {
            what: "magnitude_db",
            index,
        });
    }
    if let Some(f) = freqs.iter().find(|f| !(f.0.is_finite() && f.0 > 0.0)) {
        return Err(CompensationError::invalid("freqs", f.0, "finite, > 0 Hz"));
    }
    if !(cfg.g2.is_finite() && cfg.g2 > 0.0) {
        return Err(CompensationError::invalid("g2", cfg.g2, "finite, > 0"));
    }
    cfg.bounds.lower.validate()?;
    cfg.bounds.upper.validate()?;
    let lo = cfg.bounds.lower.to_array().map(f64::ln);
    let hi = cfg.bounds.upper.to_array().map(f64::ln);
    if let Some(i) = (0..3).find(|&i| lo[i] >= hi[i]) {
        let names = [
            "bounds.upper.b3_k3",
            "bounds.upper.k2_m2",
            "bounds.upper.b2_m2",
        ];
        return Err(CompensationError::invalid(
            names[i],
            cfg.bounds.upper.to_array()[i],
            "above the lower bound",
        ));
    }

    let problem = LimbProblem {
        omegas: freqs.iter().map(|f| 2.0 * PI * f.0).collect(),
        y: magnitude_db,
        g2: cfg.g2,
        fit_level: cfg.fit_level,
    };
    let mut lower = lo.to_vec();
    let mut upper = hi.to_vec();
    if cfg.fit_level {
        lower.push(f64::NEG_INFINITY);
        upper.push(f64::INFINITY);
    }

    // Table 1's mean (moved inside the bounds), then a grid at 1/6, 1/2 and 5/6 of each
    // log range.
    let mut starts = vec![
        LimbParams::TABLE1_MEAN
            .to_array()
            .map(f64::ln)
            .iter()
            .zip(lo.iter().zip(&hi))
            .map(|(v, (l, h))| v.clamp(l + 0.01 * (h - l), h - 0.01 * (h - l)))
            .collect::<Vec<f64>>(),
    ];
    let at = |i: usize, t: f64| lo[i] + t * (hi[i] - lo[i]);
    let ts = [1.0 / 6.0, 0.5, 5.0 / 6.0];
    for &a in &ts {
        for &b in &ts {
            for &c in &ts {
                starts.push(vec![at(0, a), at(1, b), at(2, c)]);
            }
        }
    }

    let mut best: Option<TrfSolution> = None;
    let mut last_err = None;
    let mut total_iterations = 0;
    let mut resid = vec![0.0; magnitude_db.len()];
    for mut x0 in starts.iter().cloned() {
        if cfg.fit_level {
            // The best level for this start, in closed form (the residuals are linear in it).
            let mut probe = x0.clone();
            probe.push(0.0);
            problem.residuals(&probe, &mut resid);
            x0.push(-resid.iter().sum::<f64>() / resid.len() as f64);
        }
        match least_squares_bounded(&problem, &x0, &lower, &upper, &cfg.options) {
            Ok(sol) => {
                total_iterations += sol.iterations;
                if best.as_ref().is_none_or(|b| sol.cost < b.cost) {
                    best = Some(sol);
                }
            }
            Err(e) => last_err = Some(e),
        }
    }
    let Some(sol) = best else {
        return Err(match last_err {
            Some(e) => CompensationError::FitFailed(e),
            None => CompensationError::Empty { what: "fit starts" },
        });
    };

    let m = magnitude_db.len();
    let rms_error_db = (2.0 * sol.cost / m as f64).sqrt();
    let mut jac = DMatrix::zeros(m, n);
    problem.jacobian(&sol.x, &mut jac);
    // Sweep residuals are correlated between neighbouring frequencies (the impulse
    // response window smooths the spectrum), which the independent-noise formula ignores;
    // an AR(1) correction `(1 + ρ)/(1 − ρ)`, with `ρ` the residuals' lag-one correlation,
    // accounts for the fewer independent points.
    let r = &sol.residuals;
    let r0: f64 = r.iter().map(|v| v * v).sum();
    let rho = if r0 > 0.0 {
        (r.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / r0).clamp(0.0, 0.95)
    } else {
        0.0
    };
    let sigma2 = 2.0 * sol.cost / (m - n).max(1) as f64 * (1.0 + rho) / (1.0 - rho);
    let relative_std = match (jac.transpose() * &jac).try_inverse() {
        Some(inv) => [0, 1, 2].map(|i| (sigma2 * inv[(i, i)]).max(0.0).sqrt()),
        None => [f64::INFINITY; 3],
    };
    let params = LimbParams::from_array([sol.x[0].exp(), sol.x[1].exp(), sol.x[2].exp()]);
    let level = 10f64.powf(problem.level(&sol.x) / 20.0);
    Ok(LimbFit {
        model: LimbModel::new(params, cfg.g2, level)?,
        rms_error_db,
        iterations: sol.iterations,
        total_iterations,
        starts: starts.len(),
        relative_std,
    })
}
