//! TODO(helper): heel-strike onset detection.

use crate::units::{Decibels, SampleRate, Seconds};

/// Parameters of heel-strike detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnsetConfig {
    /// Length of the RMS envelope window.
    pub envelope_window: Seconds,
    /// Two strikes closer than this are one strike.
    pub min_interval: Seconds,
    /// An onset is where the envelope rises to within this many dB of the recording's peak.
    pub threshold_below_peak: Decibels,
    /// The envelope must fall this many dB below the threshold before another onset can fire.
    pub hysteresis: Decibels,
}

impl Default for OnsetConfig {
    fn default() -> Self {
        Self {
            envelope_window: Seconds(0.002),
            min_interval: Seconds(0.3),
            threshold_below_peak: Decibels(20.0),
            hysteresis: Decibels(6.0),
        }
    }
}

/// Sample indices of the heel-strike onsets in `x`.
#[must_use]
pub fn find_onsets(x: &[f64], rate: SampleRate, cfg: &OnsetConfig) -> Vec<usize> {
    let _ = (x, rate, cfg);
    todo!()
}
