//! The adapter's settings: how it estimates the loaded device and moves the weights.

use serde::{Deserialize, Serialize};

use crate::compensation::CompensationError;
use crate::units::{Decibels, Newtons, SampleRate, Seconds};

/// How the adapter estimates the loaded device and moves the weights; see the
/// [module documentation](super).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdaptConfig {
    /// Analysis frame `N` (a power of two); `None` uses the weights' `bins`. The hop is
    /// `N/2`, the window Hann.
    pub frame: Option<usize>,
    /// Time constant of the exponential average of the spectra, in counted signal.
    pub memory: Seconds,
    /// Counted signal between updates.
    pub interval: Seconds,
    /// Frames averaged before the first update.
    pub min_frames: usize,
    /// Relaxation `μ` of the update, in (0, 1].
    pub step: f64,
    /// Largest change of any bin per update (`δ`, positive).
    pub max_change: Decibels,
    /// Coherence `γ²` below which a bin is not trusted, in (0, 1].
    pub coherence: f64,
    /// Total vertical force at or above which the tile counts as loaded.
    pub load_threshold: Newtons,
    /// Drive RMS (re full scale) below which a frame is ignored.
    pub min_drive: Decibels,
}

impl Default for AdaptConfig {
    /// The weights' bins, 3 s memory, updates every 0.5 s, 16 frames first, `μ = 0.3`,
    /// 0.5 dB per update, `γ² ≥ 0.8`, loaded from 150 N, drive from -60 dBFS.
    fn default() -> Self {
        Self {
            frame: None,
            memory: Seconds(3.0),
            interval: Seconds(0.5),
            min_frames: 16,
            step: 0.3,
            max_change: Decibels(0.5),
            coherence: 0.8,
            load_threshold: Newtons(150.0),
            min_drive: Decibels(-60.0),
        }
    }
}

impl AdaptConfig {
    /// The analysis frame for weights of `bins`.
    #[must_use]
    pub fn frame_for(&self, bins: usize) -> usize {
        self.frame.unwrap_or(bins)
    }

    /// Checks every field, for weights of `bins` at `rate`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] naming the first bad field.
    pub fn validate(&self, bins: usize, rate: SampleRate) -> Result<(), CompensationError> {
        let bad = |name, value, expected| {
            Err(CompensationError::InvalidParameter {
                name,
                value,
                expected,
            })
        };
        if rate.0 == 0 {
            return bad("rate", 0.0, "a positive sample rate");
        }
        let n = self.frame_for(bins);
        if n < 64 || !n.is_power_of_two() || n > 1 << 20 {
            return bad("frame", n as f64, "a power of two from 64 to 2^20");
        }
        let hop = rate.duration_of(n / 2).0;
        if !(self.memory.0.is_finite() && self.memory.0 >= hop) {
            return bad("memory", self.memory.0, "finite, at least one hop");
        }
        if !(self.interval.0.is_finite() && self.interval.0 > 0.0) {
            return bad("interval", self.interval.0, "finite, > 0 s");
        }
        if self.min_frames < 2 {
            return bad("min_frames", self.min_frames as f64, ">= 2");
        }
        if !(self.step > 0.0 && self.step <= 1.0) {
            return bad("step", self.step, "0 < step <= 1");
        }
        if !(self.max_change.0.is_finite() && self.max_change.0 > 0.0) {
            return bad("max_change", self.max_change.0, "finite, > 0 dB");
        }
        if !(self.coherence > 0.0 && self.coherence <= 1.0) {
            return bad("coherence", self.coherence, "0 < coherence <= 1");
        }
        if !(self.load_threshold.0.is_finite() && self.load_threshold.0 >= 0.0) {
            return bad("load_threshold", self.load_threshold.0, "finite, >= 0 N");
        }
        if !(self.min_drive.0.is_finite() && self.min_drive.0 <= 0.0) {
            return bad("min_drive", self.min_drive.0, "finite, <= 0 dBFS");
        }
        Ok(())
    }
}
