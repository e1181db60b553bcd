//! Step 7 of the estimation: the modal gains.
//!
//! A mode of unit gain, struck by a unit impulse, moves at
//! `V_k(s) = s ω_k / ((s + 1/τ_k)^2 + ω_k^2)`; the hammer's force pulse on a rigid
//! surface has the spectrum `F(f)` (simulated, [`super::hammer`]). The gains solve, on 192
//! log-spaced frequencies of the band,
//!
//! ```math
//! \min_{g} \sum_i \left| \frac{|F(f_i)| \sum_k g_k V_k(f_i) - M(f_i) e^{j φ_i}}{M(f_i)} \right|^2
//!   + ρ \sum_k \lVert c_k \rVert^2 g_k^2 ,
//! ```
//!
//! linear least squares on unit-norm columns `c_k` with a small ridge `ρ = 10^{-4}`
//! (neighbouring poles of the dictionary are nearly parallel; without it their gains
//! grow large and cancel). Dividing by `M` makes the error relative, close to the
//! log-spectral distance. Only the magnitude is measured, so the phases `φ_i` start from
//! the minimum-phase response with magnitude `M` and are then replaced by the model's
//! own for 30 rounds; the round with the lowest log-spectral distance is kept. When the
//! dictionary holds more than `max_modes` (32) modes, the 32 that carry most of the fit
//! (`|g_k| ‖c_k‖`) are kept and refitted.
//!
//! **Signs.** A gain at the point struck is positive, but the recordings were made
//! elsewhere (a microphone, the shoe), where a mode's gain `φ_k(a) φ_k(b) / m_k` may be
//! negative. The gains are therefore signed: their magnitudes are what the contact sees
//! (the driving point), their signs shape what is felt (see
//! [`crate::physical::resonator`]). Restricting them to be positive (non-negative least
//! squares) was tried: the best fits were then 2-8 dB from the measurement instead of
//! under 2.

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

use super::EstimateError;
use crate::fit::metrics::lsd_db;
use crate::physical::SurfaceMode;
use crate::units::Hz;

/// The velocity response of a unit-gain mode to a unit impulse, at `f`.
fn mode_velocity(mode: &SurfaceMode, f: Hz) -> Complex64 {
    let s = Complex64::new(0.0, std::f64::consts::TAU * f.0);
    let wd = std::f64::consts::TAU * mode.frequency.0;
    let sigma = 1.0 / mode.decay.0;
    s * wd / ((s + sigma).powi(2) + wd * wd)
}

/// The modal-gain fit over a fixed dictionary of candidate modes.
pub(super) struct GainFit<'a> {
    /// The candidate modes (unit gain).
    pub(super) dictionary: &'a [SurfaceMode],
    /// The frequencies of the fit.
    pub(super) freqs: &'a [Hz],
    /// `|F(f)|` of the hammer's pulse at `freqs`.
    pub(super) pulse: &'a [f64],
    /// The phases `φ_i` the iteration starts from.
    pub(super) initial_phase: &'a [f64],
    /// The most modes kept.
    pub(super) max_modes: usize,
}

impl GainFit<'_> {
    /// Modes with gains (unscaled) whose response matches `goal` in magnitude, at most
    /// `max_modes` of them.
    pub(super) fn modes(&self, goal: &[f64]) -> Result<Vec<SurfaceMode>, EstimateError> {
        let mut poles = self.dictionary.to_vec();
        let mut gains = self.gains(&poles, goal)?;
        if poles.len() > self.max_modes {
            // Keep the modes that carry the most of the fitted (relative) response, refit.
            let mut ranked: Vec<(f64, SurfaceMode)> = poles
                .iter()
                .zip(&gains)
                .map(|(m, g)| (g.abs() * self.column(m, goal).norm(), *m))
                .collect();
            ranked.sort_by(|p, q| q.0.total_cmp(&p.0));
            poles = ranked
                .into_iter()
                .take(self.max_modes)
                .map(|(_, m)| m)
                .collect();
            poles.sort_by(|p, q| p.frequency.0.total_cmp(&q.frequency.0));
            gains = self.gains(&poles, goal)?;
        }
        let modes: Vec<SurfaceMode> = poles
            .iter()
            .zip(&gains)
            .filter(|(_, g)| **g != 0.0)
            .map(|(m, g)| SurfaceMode { gain: *g, ..*m })
            .collect();
        if modes.is_empty() {
            return Err(EstimateError::Gains("every modal gain came out zero"));
        }
        Ok(modes)
    }

    /// A mode's response relative to `goal`, stacked real over imaginary parts.
    fn column(&self, mode: &SurfaceMode, goal: &[f64]) -> DVector<f64> {
        let n = self.freqs.len();
        let c: Vec<Complex64> = self
            .freqs
            .iter()
            .zip(self.pulse)
            .zip(goal)
            .map(|((f, p), t)| mode_velocity(mode, *f) * (p / t))
            .collect();
        DVector::from_fn(2 * n, |i, _| if i < n { c[i].re } else { c[i - n].im })
    }

    /// Ridge-regularised least-squares gains with phase iteration, best round kept.
    fn gains(&self, modes: &[SurfaceMode], goal: &[f64]) -> Result<Vec<f64>, EstimateError> {
        let (n, k) = (self.freqs.len(), modes.len());
        if goal.iter().any(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(EstimateError::Gains(
                "the measured magnitude is not positive",
            ));
        }
        let columns: Vec<DVector<f64>> = modes.iter().map(|m| self.column(m, goal)).collect();
        let norms: Vec<f64> = columns.iter().map(|c| c.norm().max(1e-300)).collect();
        // Unit-norm columns and a small ridge: neighbouring poles of the dictionary are
        // nearly parallel, and without it their gains grow large and cancel.
        let ridge = RIDGE.sqrt();
        let mut a = DMatrix::zeros(2 * n + k, k);
        for (j, c) in columns.iter().enumerate() {
            a.view_mut((0, j), (2 * n, 1)).copy_from(&(c / norms[j]));
            a[(2 * n + j, j)] = ridge;
        }
        let svd = crate::numeric::svd(a).map_err(|e| EstimateError::Gains(e.0))?;
        let mut phase = self.initial_phase.to_vec();
        let mut best: Option<(f64, Vec<f64>)> = None;
        for _ in 0..PHASE_ROUNDS {
            let b = DVector::from_fn(2 * n + k, |i, _| match i {
                i if i < n => phase[i].cos(),
                i if i < 2 * n => phase[i - n].sin(),
                _ => 0.0,
            });
            let x = svd
                .solve(&b, 1e-12)
                .map_err(|_| EstimateError::Gains("least squares failed"))?;
            let gains: Vec<f64> = x.iter().zip(&norms).map(|(v, s)| v / s).collect();
            let mut model = vec![Complex64::new(0.0, 0.0); n];
            for (c, g) in columns.iter().zip(&gains) {
                for (i, m) in model.iter_mut().enumerate() {
                    *m += Complex64::new(c[i], c[n + i]) * g;
                }
            }
            let ratio: Vec<f64> = model.iter().map(|m| m.norm().max(1e-300)).collect();
            let score = lsd_db(&vec![1.0; n], &ratio);
            if best.as_ref().is_none_or(|(s, _)| score < *s) {
                best = Some((score, gains));
            }
            for (p, m) in phase.iter_mut().zip(&model) {
                if m.norm() > 0.0 {
                    *p = m.arg();
                }
            }
        }
        best.map(|(_, g)| g)
            .ok_or(EstimateError::Gains("no round of the fit finished"))
    }
}

/// Rounds of the phase iteration of the gain fit.
const PHASE_ROUNDS: usize = 30;

/// The ridge on unit-norm columns, relative to a column's squared norm.
const RIDGE: f64 = 1e-4;
