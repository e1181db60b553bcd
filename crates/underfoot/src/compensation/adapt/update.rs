//! The update: the weights moved towards the inverse of the estimated loaded device,
//! slowly and within bounds.
//!
//! Every [`AdaptConfig::interval`] of counted signal (0.5 s), each trusted bin `k` of the
//! band moves towards the weights that would flatten the loaded device, what equations
//! (4)-(5) converge to:
//!
//! ```math
//! t_k = c - 20\log_{10}|\hat D_k|, \qquad
//!   \Delta_k = \mathrm{clip}\big(\mu (t_k - w_k) - s,\; l_k,\; h_k\big),
//! ```
//!
//! with relaxation `μ` ([`AdaptConfig::step`], 0.3), `c` the level that makes the target's
//! mean over the trusted bins equal the weights' (so the update reshapes, it does not
//! move the level), `l_k = max(-δ, -max_cut - w_k)`, `h_k = min(δ, max_boost - w_k)`
//! with the per-update bound `δ` ([`AdaptConfig::max_change`], 0.5 dB), and `s` the
//! shift, found by bisection, that makes `Σ Δ_k = 0`. Untrusted bins have `Δ_k = 0`.
//! The weights then go through the same re-level, bounds and out-of-band taper as after a
//! sweep ([`SpectralWeights`]' finishing step, which finds the mean already at 0 dB).
//!
//! Why: `μ < 1` averages the estimate's noise over several updates (a first-order
//! smoother of the target with time constant `interval / μ`); `δ` makes any change
//! slow and small enough to be unnoticed (0.5 dB is at the lower end of the 0.45-3 dB
//! intensity discrimination threshold the compensation paper cites), however wrong an estimate; the
//! zero-sum shift keeps the in-band mean exactly without moving untrusted bins, which a
//! plain re-level would.
//!
//! [`AdaptConfig::interval`]: super::AdaptConfig::interval
//! [`AdaptConfig::max_change`]: super::AdaptConfig::max_change
//! [`AdaptConfig::step`]: super::AdaptConfig::step
//! [`SpectralWeights`]: crate::compensation::equalizer::SpectralWeights

use num_complex::Complex64;

use super::Adapter;

impl Adapter {
    /// Estimates, decides trust, and moves the weights; returns whether they moved.
    pub(super) fn update(&mut self) -> bool {
        let corrected = self.weights.corrected();
        let first = *corrected.start();
        let mut level = 0.0;
        let mut trusted = 0usize;
        for k in corrected.clone() {
            let (sxx, saa, sxa) = self.spectra_at(k);
            let (d, coh) = if sxx > 0.0 && saa > 0.0 {
                (sxa / sxx, sxa.norm_sqr() / (sxx * saa))
            } else {
                (Complex64::new(0.0, 0.0), 0.0)
            };
            self.estimate[k] = d;
            self.coh[k] = coh;
            let ok = coh >= self.cfg.coherence && d.norm() > 0.0 && d.norm().is_finite();
            self.trusted[k] = ok;
            if ok {
                level += self.weights.gains_db[k] + db(d);
                trusted += 1;
            }
        }
        self.trusted_count = trusted;
        if trusted == 0 {
            return false;
        }
        let c = level / trusted as f64;
        let (mu, bound) = (self.cfg.step, self.cfg.max_change.0);
        let (boost, cut) = (
            self.weights.config.max_boost.0,
            self.weights.config.max_cut.0,
        );
        for (i, k) in corrected.clone().enumerate() {
            let w = self.weights.gains_db[k];
            if self.trusted[k] {
                self.delta[i] = mu * (c - db(self.estimate[k]) - w);
                // Containing 0 keeps lo <= hi even for a weight already past a bound.
                self.lo[i] = (-bound).max(-cut - w).min(0.0);
                self.hi[i] = bound.min(boost - w).max(0.0);
            } else {
                self.delta[i] = 0.0;
                self.lo[i] = 0.0;
                self.hi[i] = 0.0;
            }
        }
        balance(&mut self.delta, &self.lo, &self.hi);
        self.previous.copy_from_slice(&self.weights.gains_db);
        for (i, d) in self.delta.iter().enumerate() {
            self.weights.gains_db[first + i] += d;
        }
        self.weights.finish();
        self.last_change = self
            .previous
            .iter()
            .zip(&self.weights.gains_db)
            .map(|(p, w)| (w - p).abs())
            .fold(0.0, f64::max);
        self.updates += 1;
        true
    }
}

/// `20 log10 |d|`.
fn db(d: Complex64) -> f64 {
    20.0 * d.norm().log10()
}

/// Replaces `v_k` by `clip(v_k - s, lo_k, hi_k)` with the shift `s` that makes the sum
/// zero. Needs `lo_k <= 0 <= hi_k`, so the sum falls from `Σ hi ≥ 0` to `Σ lo ≤ 0` as
/// `s` rises and a root exists; bisection, as the sum is only piecewise linear.
pub(super) fn balance(values: &mut [f64], lo: &[f64], hi: &[f64]) {
    let sum = |s: f64| -> f64 {
        values
            .iter()
            .zip(lo.iter().zip(hi))
            .map(|(v, (l, h))| (v - s).max(*l).min(*h))
            .sum()
    };
    let mut s = 0.0;
    if sum(0.0) != 0.0 {
        let mut below = f64::INFINITY;
        let mut above = f64::NEG_INFINITY;
        for (v, (l, h)) in values.iter().zip(lo.iter().zip(hi)) {
            below = below.min(v - h);
            above = above.max(v - l);
        }
        if below.is_finite() && above.is_finite() {
            for _ in 0..200 {
                let mid = 0.5 * (below + above);
                if sum(mid) > 0.0 {
                    below = mid;
                } else {
                    above = mid;
                }
                if above - below <= 1e-13 * (1.0 + above.abs()) {
                    break;
                }
            }
            s = 0.5 * (below + above);
        }
    }
    for (v, (l, h)) in values.iter_mut().zip(lo.iter().zip(hi)) {
        *v = (*v - s).max(*l).min(*h);
    }
}
