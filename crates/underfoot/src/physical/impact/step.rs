//! One sample of contact: a discrete gradient with an implicit force.
//!
//! Over a sample `T = 1/f_s` the force is taken constant at a value `F` that makes energy
//! bookkeeping exact. With the contact potential `U(x) = k x_+^{α+1} / (α+1)`:
//!
//! ```math
//! F = \max\left(0,\; \frac{U(x_1) - U(x_0)}{x_1 - x_0}
//!       + \lambda\, \frac{x_{0+}^{\alpha} + x_{1+}^{\alpha}}{2}\, \frac{x_1 - x_0}{T}\right)
//! ```
//!
//! (the elastic part is the discrete gradient of `U`; at `x_1 = x_0` it is `U'(x_0)`), and
//! the hammer moves by the trapezoidal rule:
//!
//! ```math
//! v_1 = v_0 - \frac{T F}{m}, \qquad y_{h1} = y_{h0} + T \frac{v_0 + v_1}{2}
//!   = y_{h0} + T v_0 - \frac{T^2 F}{2m}.
//! ```
//!
//! The surface takes the impulse `J = F T` ([`ResonatorBank`]: `h[0] = 0`), so its next
//! displacement is `y_{s1} = y_s^{free} + h[1] F T`, with `y_s^{free}` its ringing alone.
//! The compression at the end of the step is therefore linear in `F`:
//!
//! ```math
//! x_1 = x_{pred} - C F, \qquad x_{pred} = x_0 + T v_0 - (y_s^{free} - y_{s0}),
//!   \qquad C = \frac{T^2}{2m} + T\, h[1] > 0,
//! ```
//!
//! and `F` depends on `x_1`: one scalar equation per sample in contact, solved by
//! bracketed regula falsi (Illinois). `F ≥ 0` bounds `x_1 ≤ x_pred`; the elastic part is
//! non-decreasing in `x_1` (`U` is convex), so `x_pred - C F(x_pred)` bounds it below
//! (widened should the damping part say otherwise), and the root is found to rounding in a
//! handful of iterations. Out of contact (`x_0 ≤ 0` and `x_pred ≤ 0`) the force is zero and nothing
//! is solved. The surface never sees the force of the sample it is computed in, so there
//! is no delay-free loop to break, unlike a bilinear discretisation of the surface.
//!
//! # Energy
//!
//! On a rigid surface `x = y_h`, and with `E = m v^2/2 + U(x)` and `Δx = T (v_0+v_1)/2`,
//!
//! ```math
//! E_1 - E_0 = -F\, Δx + U(x_1) - U(x_0).
//! ```
//!
//! Unclamped, `F Δx = U(x_1) - U(x_0) + λ \bar{x^α} Δx^2 / T`, so
//! `E_1 - E_0 = -λ \bar{x^α} Δx^2/T ≤ 0`; clamped (`F = 0`, which needs `Δx < 0`),
//! `E_1 - E_0 = U(x_1) - U(x_0) ≤ 0`. Energy never grows, and with `λ = 0` it is
//! conserved to the solver's rounding: the hammer leaves at the speed it arrived at, and
//! no stiffness or rate makes the step unstable (it is the discrete-gradient method of
//! Gonzalez, *Time integration and discrete Hamiltonian systems*, J. Nonlinear Sci. 6, 1996).

use super::{Impact, ImpactParams};
use crate::physical::ResonatorBank;

impl Impact {
    /// The step's force for compressions `x0` (now) and `x1` (next), with `u0 = U(x0)`
    /// and `a0 = x0_+^α` precomputed.
    fn force(&self, x0: f64, u0: f64, a0: f64, x1: f64) -> f64 {
        let ImpactParams {
            stiffness: k,
            alpha,
            damping,
            ..
        } = self.params;
        let a1 = if x1 > 0.0 { pow_alpha(x1, alpha) } else { 0.0 };
        let dx = x1 - x0;
        let elastic = if dx.abs() > 1e-7 * x0.abs().max(x1.abs()) {
            let u1 = if x1 > 0.0 {
                k * a1 * x1 / (alpha + 1.0)
            } else {
                0.0
            };
            (u1 - u0) / dx
        } else {
            // The difference quotient would lose its digits; its limit is U'.
            let mid = 0.5 * (x0 + x1);
            if mid > 0.0 {
                k * pow_alpha(mid, alpha)
            } else {
                0.0
            }
        };
        (elastic + damping * 0.5 * (a0 + a1) * dx / self.period).max(0.0)
    }

    /// Solves `x1 = x_pred - C F(x0, x1)` for the step's force.
    fn solve(&self, x0: f64, x_pred: f64) -> f64 {
        let c = self.compliance;
        let (u0, a0) = if x0 > 0.0 {
            let a0 = pow_alpha(x0, self.params.alpha);
            (
                self.params.stiffness * a0 * x0 / (self.params.alpha + 1.0),
                a0,
            )
        } else {
            (0.0, 0.0)
        };
        let phi = |x1: f64| x1 - x_pred + c * self.force(x0, u0, a0, x1);
        let mut hi = x_pred;
        let mut f_hi = phi(hi);
        if f_hi <= 0.0 {
            return 0.0;
        }
        // F >= 0 puts the root below x_pred; F non-decreasing puts it above
        // x_pred - C F(x_pred). Widen if rounding says otherwise.
        let mut width = f_hi;
        let mut lo = hi - width;
        let mut f_lo = phi(lo);
        let mut widen = 0;
        while f_lo > 0.0 && widen < 60 {
            width *= 2.0;
            lo = hi - width;
            f_lo = phi(lo);
            widen += 1;
        }
        let tol = 4.0 * f64::EPSILON * x0.abs().max(x_pred.abs());
        let mut x1 = lo;
        let mut side = 0i8;
        for _ in 0..60 {
            x1 = (lo * f_hi - hi * f_lo) / (f_hi - f_lo);
            if !x1.is_finite() {
                x1 = 0.5 * (lo + hi);
            }
            let f = phi(x1);
            if f.abs() <= tol || hi - lo <= tol {
                break;
            }
            if f > 0.0 {
                hi = x1;
                f_hi = f;
                if side == 1 {
                    f_lo *= 0.5;
                }
                side = 1;
            } else {
                lo = x1;
                f_lo = f;
                if side == -1 {
                    f_hi *= 0.5;
                }
                side = -1;
            }
        }
        // The force that moves the bodies is the one consistent with x1 exactly.
        ((x_pred - x1) / c).max(0.0)
    }

    pub(super) fn step(&mut self) -> f64 {
        // The surface rings freely first; the contact's impulse, found from where that
        // leaves it, is added after (`add_delayed_impulse`), so the modes are walked once
        // per sample out of contact and twice in it.
        let (out, free, h1) = match &mut self.surface {
            Some(bank) => {
                let (velocity, free) = bank.advance_free();
                (velocity, free, bank.first_sample_gain())
            }
            None => (0.0, 0.0, 0.0),
        };
        let mut force = 0.0;
        if self.armed {
            let x0 = self.x;
            let x_pred = x0 + self.period * self.v - (free - self.ys);
            force = if x0 > 0.0 || x_pred > 0.0 {
                self.solve(x0, x_pred)
            } else {
                0.0
            };
            let x1 = x_pred - self.compliance * force;
            self.v -= self.period * force / self.params.mass;
            self.x = x1;
            self.record(x0, x1, force);
        }
        if force != 0.0
            && let Some(bank) = &mut self.surface
        {
            bank.add_delayed_impulse(force * self.period);
        }
        self.ys = free + h1 * force * self.period;
        if self.surface.is_some() { out } else { force }
    }

    fn record(&mut self, x0: f64, x1: f64, force: f64) {
        let s = &mut self.stats;
        let n = s.samples as f64;
        if s.start.is_none() && x0 <= 0.0 && x1 > 0.0 {
            s.start = Some(n + x0 / (x0 - x1));
        } else if s.start.is_some() && s.end.is_none() && x0 > 0.0 && x1 <= 0.0 {
            s.end = Some(n + x0 / (x0 - x1));
        }
        s.peak = s.peak.max(force);
        s.samples += 1;
    }
}

/// `C = T^2/(2m) + T h[1]` for a surface whose first sample gain is `h[1]`.
pub(super) fn compliance_of(period: f64, mass: f64, h1: f64) -> f64 {
    period * period / (2.0 * mass) + period * h1
}

pub(super) fn compliance(period: f64, mass: f64, bank: &ResonatorBank) -> f64 {
    compliance_of(period, mass, bank.first_sample_gain())
}

/// `x^α` for `x > 0`, without the general power for the usual exponents: the contact
/// solve evaluates it a few times per iteration, and `powf` dominated its cost.
fn pow_alpha(x: f64, alpha: f64) -> f64 {
    if alpha == 1.5 {
        x * x.sqrt()
    } else if alpha == 1.0 {
        x
    } else if alpha == 2.0 {
        x * x
    } else {
        x.powf(alpha)
    }
}
