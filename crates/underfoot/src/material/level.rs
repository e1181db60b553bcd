//! The playback level: every material as loud as the others relative to its recording, and
//! a nominal step well under the limiter's ceiling.
//!
//! A model reproduces its recordings' level: a recording that peaks at full scale plays at
//! full scale. Recordings are made at whatever gain the microphone or accelerometer had,
//! so their levels say nothing absolute, but they do say how loud one material is
//! against another when they were recorded alike. Played as recorded, some would be limited
//! at every step: the limiter would then shape the step instead of the material (a
//! limited step's spectrum is no longer the fitted one). So each material gets a playback
//! level `L` (`level_db` in a library):
//!
//! ```math
//! L = \min\big(L_{ref},\; c - m - p\big)
//! ```
//!
//! with `L_ref` = [`REFERENCE`] (the level a recording's full scale plays at, the same for
//! every material: relative loudness kept), `c` the default ceiling
//! ([`crate::safety::DEFAULT_CEILING`], -6 dBFS), `m` = [`HEADROOM`] (3 dB) and `p` the
//! peak of a nominal step in dB re the recording's full scale: the largest sample over
//! [`NOMINAL_STEPS`] nominal steps of the material's excitation (its random trains drawn
//! from a fixed seed) through its filter at the analysis rate, upsampled 8 times so that
//! a peak between samples counts; the physical model's, when it is louder. A material
//! that would still come within 3 dB of the ceiling is turned down alone, and `fit` says
//! so. The limiter is then a safety net, not the normal path.
//!
//! `L_ref` is -16 dB: at it, every material of the built-in library (the shared
//! recordings) keeps its nominal step 3 dB under the ceiling, the loudest (snow's physical
//! model) with 0.6 dB to spare, so all of them keep their recorded loudness relative to
//! one another (at -12 dB snow, metal and sand would be turned down by 0.3-3.4 dB). The
//! quietest recordings then play quietly (grass's steps peak near -40 dBFS): that is how
//! loud they were recorded; `--gain-db` raises everything alike.

use crate::excitation::{ExcitationModel, Generator, Tables, clock};
use crate::signal::resample::Resampler;
use crate::signal::{SignalError, Sos};
use crate::units::{Decibels, SampleRate};

/// The level a recording's full scale plays at.
pub const REFERENCE: Decibels = Decibels(-16.0);

/// How far under the default ceiling a nominal step peaks at least.
pub const HEADROOM: Decibels = Decibels(3.0);

/// Nominal steps whose largest sample is the nominal peak.
pub const NOMINAL_STEPS: usize = 32;

/// The seed of the nominal steps' trains.
const SEED: u64 = 0x1E7E1;

/// The playback level for a nominal step that peaks at `peak` (re the recording's full
/// scale) at the recorded level.
#[must_use]
pub fn level_for(peak: f64) -> Decibels {
    let p = Decibels::from_amplitude(peak.max(1e-12)).0;
    Decibels(
        REFERENCE
            .0
            .min(crate::safety::DEFAULT_CEILING.0 - HEADROOM.0 - p),
    )
}

/// The largest sample of [`NOMINAL_STEPS`] nominal steps of `excitation` through `sos` at
/// `rate` (the model's), upsampled 8 times.
///
/// # Errors
/// The excitation is invalid, or the rate cannot be upsampled.
pub fn nominal_peak(
    sos: &Sos,
    rate: SampleRate,
    excitation: &ExcitationModel,
) -> Result<f64, LevelError> {
    let tables = Tables::new(excitation, rate).map_err(LevelError::Excitation)?;
    let speeds = clock::nominal_speeds(rate);
    let tail = rate.samples_in(crate::units::Seconds(0.5));
    let up =
        Resampler::new(rate, SampleRate(rate.0.saturating_mul(8))).map_err(LevelError::Signal)?;
    let mut generator = Generator::new(SEED);
    let mut peak = 0.0f64;
    let mut x = vec![0.0f32; speeds.len()];
    for _ in 0..NOMINAL_STEPS {
        generator.strike(&tables, 1.0);
        generator.process(&tables, &speeds, &mut x);
        generator.stop();
        let mut y: Vec<f64> = x.iter().map(|v| f64::from(*v)).collect();
        y.resize(x.len() + tail, 0.0);
        sos.filter_in_place(&mut y);
        peak = peak.max(up.peak(&y));
    }
    Ok(peak)
}

/// Why a nominal peak could not be found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LevelError {
    /// The excitation is invalid.
    #[error(transparent)]
    Excitation(crate::excitation::ExcitationError),
    /// The upsampler refused the rate.
    #[error("upsampling the nominal steps: {0}")]
    Signal(SignalError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quiet_materials_keep_the_reference_and_loud_ones_are_turned_down() {
        assert_eq!(level_for(0.01), REFERENCE);
        assert_eq!(level_for(1.0), REFERENCE);
        // A step at four times full scale (+12 dB) played 21 dB down: 9 dB under full
        // scale, the ceiling's -6 less 3.
        assert!((level_for(4.0).0 + 9.0 + Decibels::from_amplitude(4.0).0).abs() < 1e-12);
    }

    #[test]
    fn an_impulse_peaks_where_its_filter_does() {
        // A one-pole smoother's impulse response peaks at its first sample: b0.
        let sos = Sos::new(vec![
            crate::signal::Biquad::from_row([0.5, 0.0, 0.0, 1.0, -0.5, 0.0]).unwrap(),
        ]);
        let p = nominal_peak(&sos, SampleRate(2000), &ExcitationModel::heel_only()).unwrap();
        assert!((p - 0.5).abs() < 0.02, "{p}");
    }
}
