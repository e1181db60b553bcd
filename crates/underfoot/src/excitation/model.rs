//! The excitation as a library stores it.

use serde::{Deserialize, Serialize};

use super::generator::MAX_BINS;

/// What is wrong with an excitation model (as read from a file, or fitted).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ExcitationError {
    /// A value is out of its range.
    #[error("excitation: {name} = {value} is out of range: {expected}")]
    OutOfRange {
        /// The field.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The range.
        expected: &'static str,
    },
    /// The profile's tables disagree or are too long.
    #[error("excitation: {0}")]
    Profile(String),
    /// The recordings hold nothing to fit a train to.
    #[error("excitation: {0}")]
    Recordings(String),
}

/// The magnitudes' shape of files that predate it: exponential energies.
fn rayleigh() -> f64 {
    2.0
}

/// A material's excitation: the heel impact and the micro-impacts' profile over the step
/// clock (see the [module documentation](super)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExcitationModel {
    /// The heel impact's share of a nominal step's energy, `h` in `[0, 1]`.
    pub heel: f64,
    /// Width `Δ` of a bin of the profile, in seconds of step clock.
    pub bin_s: f64,
    /// Micro-events per second of step clock in each bin, `λ_b`.
    pub rate_hz: Vec<f64>,
    /// Each bin's expected share of a nominal step's energy, `E_b` (with `heel`, they sum
    /// to 1).
    pub energy: Vec<f64>,
    /// Standard deviation `σ_D` of the natural log of a step's time scale.
    pub duration_spread: f64,
    /// The shape `κ` of the micro-impacts' magnitudes: `q ∝ X^{1/κ}`, `X ~ Exp(1)` (a
    /// Weibull law). 2 makes their energies exponential (the default); 1 heavier-tailed
    /// (a few loud clicks among many faint ones), 4 or more nearly alike.
    #[serde(default = "rayleigh")]
    pub amplitude_shape: f64,
    /// The spread between steps (dB, gain-aligned log-spectral distance between two steps)
    /// that the train leaves to the numerator perturbation: 0 when the train alone varies
    /// as much as the recordings. The voice turns it into a perturbation size for its own
    /// filter ([`crate::synthesis::PreparedMaterial`]).
    pub perturbation_db: f64,
}

impl ExcitationModel {
    /// One impulse per step and nothing else: the IIR paper's drive, and what a material
    /// fitted before the excitation existed plays.
    #[must_use]
    pub fn heel_only() -> Self {
        Self {
            heel: 1.0,
            bin_s: 0.005,
            rate_hz: Vec::new(),
            energy: Vec::new(),
            duration_spread: 0.0,
            amplitude_shape: 2.0,
            perturbation_db: 0.0,
        }
    }

    /// The span of the profile, in seconds of step clock.
    #[must_use]
    pub fn span_s(&self) -> f64 {
        self.bin_s * self.energy.len() as f64
    }

    /// The expected number of micro-events in a nominal step.
    #[must_use]
    pub fn expected_events(&self) -> f64 {
        self.rate_hz.iter().sum::<f64>() * self.bin_s
    }

    /// Checks everything a file could get wrong.
    ///
    /// # Errors
    /// [`ExcitationError`] naming the first bad value.
    pub fn validate(&self) -> Result<(), ExcitationError> {
        let range = |name, value: f64, ok: bool, expected| {
            if ok {
                Ok(())
            } else {
                Err(ExcitationError::OutOfRange {
                    name,
                    value,
                    expected,
                })
            }
        };
        range(
            "heel",
            self.heel,
            (0.0..=1.0).contains(&self.heel),
            "a share in [0, 1]",
        )?;
        range(
            "bin_s",
            self.bin_s,
            self.bin_s.is_finite() && (1e-4..=0.1).contains(&self.bin_s),
            "0.1 ms to 100 ms",
        )?;
        range(
            "duration_spread",
            self.duration_spread,
            self.duration_spread.is_finite() && (0.0..=1.0).contains(&self.duration_spread),
            "0 to 1 (natural log units)",
        )?;
        range(
            "amplitude_shape",
            self.amplitude_shape,
            self.amplitude_shape.is_finite() && (0.5..=16.0).contains(&self.amplitude_shape),
            "0.5 to 16",
        )?;
        range(
            "perturbation_db",
            self.perturbation_db,
            self.perturbation_db.is_finite() && (0.0..=20.0).contains(&self.perturbation_db),
            "0 to 20 dB",
        )?;
        if self.rate_hz.len() != self.energy.len() {
            return Err(ExcitationError::Profile(format!(
                "{} rates for {} energies: one of each per bin",
                self.rate_hz.len(),
                self.energy.len()
            )));
        }
        if self.energy.len() > MAX_BINS {
            return Err(ExcitationError::Profile(format!(
                "{} bins; at most {MAX_BINS}",
                self.energy.len()
            )));
        }
        for (b, (&r, &e)) in self.rate_hz.iter().zip(&self.energy).enumerate() {
            if !(r.is_finite() && (0.0..=1e5).contains(&r)) {
                return Err(ExcitationError::Profile(format!(
                    "bin {b}: rate {r} must be 0 to 100000 events/s"
                )));
            }
            if !(e.is_finite() && e >= 0.0) || (e > 0.0 && r == 0.0) {
                return Err(ExcitationError::Profile(format!(
                    "bin {b}: energy {e} must be non-negative, and zero where no event comes"
                )));
            }
        }
        let total = self.heel + self.energy.iter().sum::<f64>();
        if (total - 1.0).abs() > 1e-6 {
            return Err(ExcitationError::Profile(format!(
                "the heel and the bins hold {total} of a step's energy; they must hold 1"
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heel_only_is_valid_and_bad_values_are_named() {
        assert_eq!(ExcitationModel::heel_only().validate(), Ok(()));
        let mut m = ExcitationModel::heel_only();
        m.heel = 0.5;
        assert!(matches!(m.validate(), Err(ExcitationError::Profile(_))));
        m.energy = vec![0.5];
        m.rate_hz = vec![100.0];
        assert_eq!(m.validate(), Ok(()));
        assert!((m.expected_events() - 0.5).abs() < 1e-12);
        m.rate_hz = vec![0.0];
        assert!(m.validate().is_err());
        m.rate_hz = vec![f64::NAN];
        assert!(m.validate().is_err());
        let mut m = ExcitationModel::heel_only();
        m.duration_spread = 3.0;
        assert!(matches!(
            m.validate(),
            Err(ExcitationError::OutOfRange {
                name: "duration_spread",
                ..
            })
        ));
    }
}
