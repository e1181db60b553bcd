//! A measured response: complex values on a set of frequencies, and its flatness.
//!
//! [`FrequencyResponse::deviation_from_flat_db`] is the RMS over the log grid of the
//! magnitude in dB minus its mean: the compensation paper's "deviation from a flat response", zero for
//! a device that only scales.

use num_complex::Complex64;

use crate::compensation::CompensationError;
use crate::units::{Decibels, Hz};

/// A complex frequency response on a set of frequencies.
#[derive(Debug, Clone, PartialEq)]
pub struct FrequencyResponse {
    /// The frequencies, ascending.
    pub freqs: Vec<Hz>,
    /// The response at each: output over input, magnitude and phase.
    pub response: Vec<Complex64>,
}

impl FrequencyResponse {
    /// Checks that there are at least two frequencies, one response each, all finite, at
    /// positive frequencies: what anything computed from a measurement needs.
    ///
    /// # Errors
    /// [`CompensationError::TooShort`] or [`CompensationError::NonFinite`].
    pub fn check(&self) -> Result<(), CompensationError> {
        if self.freqs.len() < 2 || self.freqs.len() != self.response.len() {
            return Err(CompensationError::TooShort {
                what: "measured response",
                len: self.freqs.len().min(self.response.len()),
                needed: 2,
            });
        }
        if let Some(index) = self
            .response
            .iter()
            .zip(&self.freqs)
            .position(|(h, f)| !(h.re.is_finite() && h.im.is_finite() && f.0 > 0.0))
        {
            return Err(CompensationError::NonFinite {
                what: "measured response",
                index,
            });
        }
        Ok(())
    }

    /// Magnitude in dB at each frequency (a zero response is floored, not `-inf`).
    #[must_use]
    pub fn magnitude_db(&self) -> Vec<Decibels> {
        self.response
            .iter()
            .map(|h| Decibels::from_amplitude(h.norm().max(f64::MIN_POSITIVE)))
            .collect()
    }

    /// Phase in degrees at each frequency, wrapped to `(-180, 180]`.
    #[must_use]
    pub fn phase_deg(&self) -> Vec<f64> {
        self.response.iter().map(|h| h.arg().to_degrees()).collect()
    }

    /// RMS of the dB magnitude minus its mean over the frequencies; zero when empty.
    #[must_use]
    pub fn deviation_from_flat_db(&self) -> Decibels {
        let db = self.magnitude_db();
        if db.is_empty() {
            return Decibels(0.0);
        }
        let n = db.len() as f64;
        let mean = db.iter().map(|d| d.0).sum::<f64>() / n;
        Decibels((db.iter().map(|d| (d.0 - mean).powi(2)).sum::<f64>() / n).sqrt())
    }
}

/// `y` at `f`, linear between the points `(ln x, y)`, held constant past the ends; `x`
/// ascending and positive, in Hz.
pub(crate) fn interpolate_log(x: &[f64], y: &[f64], f: Hz) -> f64 {
    let i = x.partition_point(|&v| v < f.0);
    if i == 0 {
        return y[0];
    }
    if i >= x.len() {
        return y[y.len() - 1];
    }
    let (x0, x1) = (x[i - 1].ln(), x[i].ln());
    let t = if x1 > x0 {
        (f.0.ln() - x0) / (x1 - x0)
    } else {
        0.0
    };
    y[i - 1] + t * (y[i] - y[i - 1])
}
