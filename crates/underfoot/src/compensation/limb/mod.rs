//! The rheological model of the user's lower limb, its fit, and its inverse as a filter.
//!
//! # Model (equations (1)-(3) of the compensation paper)
//!
//! The leg with the elastomer suspension is a first-order low-pass, the skin with the shoe
//! a resonant second-order high-pass, and the two act in parallel:
//!
//! ```math
//! H_l(s) = \frac{k_3}{k_3 + b_3 s} = \frac{1}{1 + \tau s}, \qquad
//!   H_s(s) = \frac{g_2 s^2}{s^2 + (b_2/m_2) s + k_2/m_2}, \qquad
//!   H_u = H_l + H_s, \qquad Z_c = H_u^{-1},
//! ```
//!
//! with `τ = b3/k3` in seconds, `k2/m2` in s⁻², `b2/m2` in s⁻¹ (the three fitted values,
//! [`LimbParams`]), and `g2 = 0.005` fixed (a sensor gain). Over a common denominator,
//!
//! ```math
//! H_u(s) = \frac{g_2 \tau s^3 + (1 + g_2) s^2 + (b_2/m_2) s + k_2/m_2}
//!                 {(1 + \tau s)\,\big(s^2 + (b_2/m_2) s + k_2/m_2\big)}.
//! ```
//!
//! The denominator is always stable. `H_u` is biproper: `H_u(0) = 1`, `H_u(∞) = g2`.
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the model: [`LimbParams`], [`LimbModel`] and its response |
//! | [`fit`] | the bounded fit of the model to a loaded-over-unloaded sweep: [`fit_limb`] |
//! | [`inverse`] | the model as second-order sections, and its inverse `Z_c`: [`LimbModel::compensation`] |
//!
//! A simulated user standing on the simulated tile, with a limb of this model, is
//! [`crate::sim::SimulatedUser`].

pub mod fit;
pub mod inverse;

use std::f64::consts::PI;

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::CompensationError;
use crate::units::{Hz, Seconds};

pub use fit::{LimbBounds, LimbFit, LimbFitConfig, fit_limb};

/// The compensation paper's sensor gain `g2` of the skin term.
pub const DEFAULT_G2: f64 = 0.005;

/// The three fitted parameters of the limb model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LimbParams {
    /// `b3/k3 = τ`, the leg's time constant, in seconds.
    pub b3_k3: f64,
    /// `k2/m2`, the skin's squared natural angular frequency, in s⁻² (rad²/s²).
    pub k2_m2: f64,
    /// `b2/m2`, the skin's damping rate (twice `ζ ω0`), in s⁻¹.
    pub b2_m2: f64,
}

impl LimbParams {
    /// Table 1's mean over the ten participants.
    pub const TABLE1_MEAN: Self = Self {
        b3_k3: 0.0037,
        k2_m2: 5.8e6,
        b2_m2: 2402.0,
    };

    /// Table 1's standard deviations.
    pub const TABLE1_STD: Self = Self {
        b3_k3: 0.0016,
        k2_m2: 4.1e6,
        b2_m2: 1.5e3,
    };

    /// Table 1's mean user and a user one standard deviation below and above it in
    /// every parameter: the spread the compensation paper measured, for tests and
    /// simulations.
    pub const TABLE1_SPREAD: [(&'static str, Self); 3] = {
        let (m, s) = (Self::TABLE1_MEAN, Self::TABLE1_STD);
        [
            ("mean", m),
            (
                "mean - std",
                Self {
                    b3_k3: m.b3_k3 - s.b3_k3,
                    k2_m2: m.k2_m2 - s.k2_m2,
                    b2_m2: m.b2_m2 - s.b2_m2,
                },
            ),
            (
                "mean + std",
                Self {
                    b3_k3: m.b3_k3 + s.b3_k3,
                    k2_m2: m.k2_m2 + s.k2_m2,
                    b2_m2: m.b2_m2 + s.b2_m2,
                },
            ),
        ]
    };

    /// The leg's time constant.
    #[must_use]
    pub fn tau(&self) -> Seconds {
        Seconds(self.b3_k3)
    }

    /// The leg's corner frequency `1/(2πτ)`.
    #[must_use]
    pub fn leg_corner(&self) -> Hz {
        Hz(1.0 / (2.0 * PI * self.b3_k3))
    }

    /// The skin's natural frequency `√(k2/m2) / 2π`.
    #[must_use]
    pub fn skin_resonance(&self) -> Hz {
        Hz(self.k2_m2.sqrt() / (2.0 * PI))
    }

    /// The parameters as an array `[b3/k3, k2/m2, b2/m2]`.
    #[must_use]
    pub fn to_array(&self) -> [f64; 3] {
        [self.b3_k3, self.k2_m2, self.b2_m2]
    }

    /// The parameters from an array `[b3/k3, k2/m2, b2/m2]`.
    #[must_use]
    pub fn from_array([b3_k3, k2_m2, b2_m2]: [f64; 3]) -> Self {
        Self {
            b3_k3,
            k2_m2,
            b2_m2,
        }
    }

    /// Checks that every parameter is finite and positive.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] naming the first one that is not.
    pub fn validate(&self) -> Result<(), CompensationError> {
        for (name, v) in [
            ("b3_k3", self.b3_k3),
            ("k2_m2", self.k2_m2),
            ("b2_m2", self.b2_m2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(CompensationError::invalid(name, v, "finite, > 0"));
            }
        }
        Ok(())
    }
}

/// A user's limb: `level · H_u` with the skin gain `g2`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LimbModel {
    /// The fitted parameters.
    pub params: LimbParams,
    /// The skin term's gain `g2` (dimensionless).
    pub g2: f64,
    /// Overall gain (linear, dimensionless): measurements are in arbitrary units.
    pub level: f64,
}

impl LimbModel {
    /// A model, validated.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] unless every value is finite and positive.
    pub fn new(params: LimbParams, g2: f64, level: f64) -> Result<Self, CompensationError> {
        let m = Self { params, g2, level };
        m.validate()?;
        Ok(m)
    }

    /// Checks that every value is finite and positive.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] naming the first one that is not.
    pub fn validate(&self) -> Result<(), CompensationError> {
        self.params.validate()?;
        if !(self.g2.is_finite() && self.g2 > 0.0) {
            return Err(CompensationError::invalid("g2", self.g2, "finite, > 0"));
        }
        if !(self.level.is_finite() && self.level > 0.0) {
            return Err(CompensationError::invalid(
                "level",
                self.level,
                "finite, > 0",
            ));
        }
        Ok(())
    }

    /// The leg term `H_l(j 2π f)`, equation (1).
    #[must_use]
    pub fn h_l(&self, f: Hz) -> Complex64 {
        let s = jw(f);
        1.0 / (1.0 + self.params.b3_k3 * s)
    }

    /// The skin term `H_s(j 2π f)`, equation (2).
    #[must_use]
    pub fn h_s(&self, f: Hz) -> Complex64 {
        let s = jw(f);
        self.g2 * s * s / (s * s + self.params.b2_m2 * s + self.params.k2_m2)
    }

    /// `level · H_u(j 2π f)`, equation (3).
    #[must_use]
    pub fn response(&self, f: Hz) -> Complex64 {
        self.level * (self.h_l(f) + self.h_s(f))
    }

    /// The cubic numerator of `H_u`, `[g2 τ, 1 + g2, b2/m2, k2/m2]` (highest power first).
    #[must_use]
    pub fn numerator(&self) -> [f64; 4] {
        let p = &self.params;
        [self.g2 * p.b3_k3, 1.0 + self.g2, p.b2_m2, p.k2_m2]
    }
}

/// `j 2π f`.
fn jw(f: Hz) -> Complex64 {
    Complex64::new(0.0, 2.0 * PI * f.0)
}

#[cfg(test)]
mod tests;
