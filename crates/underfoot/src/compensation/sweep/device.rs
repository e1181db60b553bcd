//! The device under measurement: anything that plays an excitation and records the
//! result ([`Device`]), the measurement itself ([`measure`]), and a replay of a measured
//! response ([`MeasuredDevice`]).
//!
//! The simulated tile and user, which stand in for the hardware and a person in tests and
//! on the command line, are in [`crate::sim`].

use num_complex::Complex64;
use underfoot_fft::RealFftPlanner;

use super::deconvolve::spectrum;
use super::excitation::Sweep;
use super::response::{FrequencyResponse, interpolate_log};
use crate::compensation::CompensationError;
use crate::compensation::fir::MinPhaseDesigner;
use crate::units::{Hz, SampleRate};

/// Anything that can play an excitation and record the result from the start of playback.
pub trait Device {
    /// Plays `excitation` and returns the recording, at least as long.
    ///
    /// # Errors
    /// [`CompensationError::Device`] when the device cannot play or record.
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError>;
}

/// Plays the sweep programme through `device` and measures its response.
///
/// # Errors
/// The device's own error, or as [`Sweep::response`] when it returns too little or
/// non-finite data.
pub fn measure<D: Device + ?Sized>(
    device: &mut D,
    sweep: &Sweep,
) -> Result<FrequencyResponse, CompensationError> {
    let recorded = device.play(sweep.excitation())?;
    sweep.response(&recorded)
}

/// A device that replays a measured response: a minimum-phase filter with its magnitude.
///
/// The magnitude in dB is interpolated linearly against log-frequency between the
/// measured points and held at the end values beyond them; the phase is not kept (an
/// equalizer of magnitudes does not need it, and a measured phase holds the audio path's
/// latency, which a replay must not). It has no noise: equalizing against it corrects the
/// equalizer's own realisation, not the measurement.
#[derive(Debug, Clone)]
pub struct MeasuredDevice {
    taps: Vec<f64>,
}

impl MeasuredDevice {
    /// Filter length: 170 ms at 48 kHz, 5.9 Hz of resolution.
    pub const TAPS: usize = 8192;

    /// A replay of `measured` at `rate`.
    ///
    /// # Errors
    /// [`CompensationError::TooShort`] for fewer than two points,
    /// [`CompensationError::NonFinite`] for a non-finite value.
    pub fn new(measured: &FrequencyResponse, rate: SampleRate) -> Result<Self, CompensationError> {
        measured.check()?;
        let freqs: Vec<f64> = measured.freqs.iter().map(|f| f.0).collect();
        let db: Vec<f64> = measured.magnitude_db().iter().map(|d| d.0).collect();
        let fs = rate.hz();
        let mut designer = MinPhaseDesigner::new(Self::TAPS, 0)?;
        let mut taps = vec![0.0; Self::TAPS];
        let at = |nu: f64| interpolate_log(&freqs, &db, Hz(nu * fs));
        if !designer.design(at, &mut taps) {
            return Err(CompensationError::NonFinite {
                what: "replayed response",
                index: 0,
            });
        }
        Ok(Self { taps })
    }
}

impl Device for MeasuredDevice {
    /// Convolves with the replayed response (by FFT), as long as the excitation.
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        let n = (excitation.len() + self.taps.len()).next_power_of_two();
        let x = spectrum(excitation, n);
        let h = spectrum(&self.taps, n);
        let mut product: Vec<Complex64> = x.iter().zip(&h).map(|(a, b)| a * b).collect();
        let mut out = vec![0.0; n];
        let inverse = RealFftPlanner::<f64>::new().plan_fft_inverse(n);
        if let Some(first) = product.first_mut() {
            first.im = 0.0;
        }
        if let Some(last) = product.last_mut() {
            last.im = 0.0;
        }
        if inverse.process(&mut product, &mut out).is_err() {
            return Err(CompensationError::Device {
                reason: "the replay's inverse FFT failed".into(),
            });
        }
        out.truncate(excitation.len());
        for v in &mut out {
            *v /= n as f64;
        }
        Ok(out)
    }
}
