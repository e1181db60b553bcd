//! TODO(lead): the measured response of a material.

use crate::recording::strikes::OnsetConfig;
use crate::units::{Band, SampleRate, Seconds};

/// How recordings are turned into a measured response.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalysisConfig {
    /// The analysis rate every recording is resampled to (default 2000 Hz).
    pub rate: SampleRate,
    /// The band of interest (default 20-900 Hz).
    pub band: Band,
    /// How much of each strike is taken before its onset (default 10 ms).
    pub pre_onset: Seconds,
    /// Length of each strike's analysis window (default 0.5 s, zero-padded).
    pub strike_length: Seconds,
    /// Smoothing bandwidth as a fraction of an octave: 6 means 1/6 octave.
    pub smoothing_fraction: f64,
    /// Savitzky-Golay denoising.
    pub savgol: SavgolSetting,
    /// Order of the Butterworth band-pass prototype (each pass; run forward and back).
    pub bandpass_order: usize,
    /// Heel-strike detection.
    pub onsets: OnsetConfig,
}

/// How the Savitzky-Golay smoother is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SavgolSetting {
    /// The widest window of this polynomial order whose response stays within 0.1 dB
    /// of unity over the band.
    Auto {
        /// Polynomial order.
        polyorder: usize,
    },
    /// A fixed window (samples at the recording's rate, odd) and polynomial order.
    Fixed {
        /// Window length in samples.
        window: usize,
        /// Polynomial order.
        polyorder: usize,
    },
    /// No smoothing.
    Off,
}

impl Default for AnalysisConfig {
    fn default() -> Self {
        Self {
            rate: SampleRate(2000),
            band: Band::new(20.0, 900.0),
            pre_onset: Seconds(0.010),
            strike_length: Seconds(0.5),
            smoothing_fraction: 6.0,
            savgol: SavgolSetting::Auto { polyorder: 3 },
            bandpass_order: 4,
            onsets: OnsetConfig::default(),
        }
    }
}

/// What went wrong turning recordings into a measured response.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    /// Placeholder.
    #[error("todo")]
    Todo,
}
