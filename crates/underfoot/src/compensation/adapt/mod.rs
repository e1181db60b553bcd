//! Online adaptation of the equalizer while a person stands and walks on the tile: the
//! compensation paper's future work ("adaptively changing the spectral weights in real time as the
//! user walks on the device").
//!
//! The [equalizer](super::equalizer) is tuned by sweeps on the *unloaded* tile. A foot on
//! it adds the leg's and the shoe's impedance: modes move and damp, the top of the band
//! is pulled down. The sweep cannot be played while someone walks, but the signal that
//! *is* played is known: [`Adapter`] watches the drive that reached the actuator and the
//! accelerometer, estimates the loaded device from them, and moves the weights towards
//! its inverse, slowly and within bounds.
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the [`Adapter`]: its state, set-up, and what it reports |
//! | [`config`] | its settings, [`AdaptConfig`] |
//! | [`estimate`] | which frames count, and the Welch H1 estimate of the loaded device from them ([`Adapter::push`]) |
//! | [`update`](mod@update) | how the weights move towards the estimate's inverse, within bounds |
//!
//! # Safety chain
//!
//! 1. The weights keep a 0 dB mean over the band and stay within `+max_boost` /
//!    `-max_cut` of it: adaptation cannot make the equalizer louder on average, nor boost
//!    any bin beyond the bound the sweeps were allowed.
//! 2. No bin changes by more than `δ` per update, and updates are at least
//!    `interval` of loaded signal apart.
//! 3. [`EqualizerFilter::set_weights`](super::equalizer::EqualizerFilter::set_weights)
//!    applies new weights cross-faded (the FIR) or from the next frame (the bank).
//! 4. The output path ends, as every output of the crate, in the hard
//!    [`Limiter`](crate::safety::Limiter): whatever the weights, no sample exceeds its
//!    ceiling. The adapter should see the drive *after* the limiter, so a limited burst
//!    is still estimated correctly.
//!
//! # Real time
//!
//! [`Adapter::new`] allocates everything (planned real FFTs with scratch, fixed history,
//! spectra and work buffers). [`Adapter::push`] never allocates, locks or panics, for any
//! block size; an update costs `O(bins)` plus a short bisection.

pub mod config;
pub mod estimate;
pub mod update;

use std::sync::Arc;

use num_complex::Complex64;
use underfoot_fft::{RealFftPlanner, RealToComplex};

use super::CompensationError;
use super::equalizer::SpectralWeights;
use super::sweep::FrequencyResponse;
use crate::units::{Decibels, Hz};

pub use config::AdaptConfig;
use update::balance;

/// Adapts spectral weights to the loaded device from the drive and the accelerometer;
/// see the [module documentation](self).
pub struct Adapter {
    cfg: AdaptConfig,
    weights: SpectralWeights,
    /// The weights before the last update, to measure its change.
    previous: Vec<f64>,
    frame: usize,
    hop: usize,
    alpha: f64,
    interval_frames: u64,
    min_power: f64,
    window: Vec<f64>,
    fft: Arc<dyn RealToComplex<f64>>,
    /// The last `N` samples of each signal, circular; `write` is the oldest.
    hist_x: Vec<f64>,
    hist_a: Vec<f64>,
    write: usize,
    /// Samples since the last frame, in `0..hop`.
    count: usize,
    /// Samples pushed.
    samples: u64,
    /// Index of the first sample after the latest unloaded or non-finite one.
    clean_since: u64,
    buf: Vec<f64>,
    spec_x: Vec<Complex64>,
    spec_a: Vec<Complex64>,
    scratch: Vec<Complex64>,
    sxx: Vec<f64>,
    saa: Vec<f64>,
    sxa: Vec<Complex64>,
    frames: u64,
    since_update: u64,
    /// Per weight bin: the last estimate, its coherence, whether it was trusted.
    estimate: Vec<Complex64>,
    coh: Vec<f64>,
    trusted: Vec<bool>,
    /// Per corrected bin: the step and its bounds.
    delta: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    updates: u64,
    trusted_count: usize,
    last_change: f64,
    non_finite: u64,
}

impl std::fmt::Debug for Adapter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Adapter")
            .field("cfg", &self.cfg)
            .field("frame", &self.frame)
            .field("frames", &self.frames)
            .field("updates", &self.updates)
            .field("trusted", &self.trusted_count)
            .field("non_finite", &self.non_finite)
            .finish_non_exhaustive()
    }
}

impl Adapter {
    /// An adapter starting from `weights`. Allocates everything `push` will use.
    ///
    /// Weights whose in-band mean is not 0 dB (a sweep's finishing step can leave a small
    /// offset when a bin hit a bound) are re-levelled within the bounds first; pass
    /// [`weights`](Self::weights) to the equalizer at the start to be exact.
    ///
    /// # Errors
    /// As [`SpectralWeights::validate`] and [`AdaptConfig::validate`].
    pub fn new(weights: &SpectralWeights, cfg: AdaptConfig) -> Result<Self, CompensationError> {
        weights.validate()?;
        let bins = weights.config.bins;
        cfg.validate(bins, weights.rate)?;
        let frame = cfg.frame_for(bins);
        let hop = frame / 2;
        let fs = weights.rate.hz();
        let alpha = 1.0 - (-(hop as f64) / (fs * cfg.memory.0)).exp();
        let interval_frames = ((cfg.interval.0 * fs / hop as f64).round() as u64).max(1);
        let mut planner = RealFftPlanner::<f64>::new();
        let fft = planner.plan_fft_forward(frame);
        // Periodic Hann: its overlap-add at N/2 is exactly flat.
        let window = (0..frame)
            .map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / frame as f64).cos())
            .collect();
        let mut weights = weights.clone();
        let corrected = weights.corrected();
        let len = corrected.end() - corrected.start() + 1;
        let (boost, cut) = (weights.config.max_boost.0, weights.config.max_cut.0);
        let mut lo = vec![-cut; len];
        let mut hi = vec![boost; len];
        balance(&mut weights.gains_db[corrected], &lo, &hi);
        weights.finish();
        lo.fill(0.0);
        hi.fill(0.0);
        let n_weights = weights.gains_db.len();
        let spec_len = frame / 2 + 1;
        Ok(Self {
            cfg,
            previous: weights.gains_db.clone(),
            weights,
            frame,
            hop,
            alpha,
            interval_frames,
            min_power: cfg.min_drive.to_amplitude().powi(2),
            window,
            hist_x: vec![0.0; frame],
            hist_a: vec![0.0; frame],
            write: 0,
            count: 0,
            samples: 0,
            clean_since: 0,
            buf: fft.make_input_vec(),
            spec_x: fft.make_output_vec(),
            spec_a: fft.make_output_vec(),
            scratch: fft.make_scratch_vec(),
            fft,
            sxx: vec![0.0; spec_len],
            saa: vec![0.0; spec_len],
            sxa: vec![Complex64::new(0.0, 0.0); spec_len],
            frames: 0,
            since_update: 0,
            estimate: vec![Complex64::new(0.0, 0.0); n_weights],
            coh: vec![0.0; n_weights],
            trusted: vec![false; n_weights],
            delta: vec![0.0; len],
            lo,
            hi,
            updates: 0,
            trusted_count: 0,
            last_change: 0.0,
            non_finite: 0,
        })
    }

    /// The current weights.
    #[must_use]
    pub fn weights(&self) -> &SpectralWeights {
        &self.weights
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &AdaptConfig {
        &self.cfg
    }

    /// Updates made so far.
    #[must_use]
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// Frames counted into the averages so far.
    #[must_use]
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Bins of the band trusted at the last update.
    #[must_use]
    pub fn trusted_bins(&self) -> usize {
        self.trusted_count
    }

    /// Whether weight bin `k` was trusted at the last update.
    #[must_use]
    pub fn is_trusted(&self, k: usize) -> bool {
        self.trusted.get(k).copied().unwrap_or(false)
    }

    /// The coherence `γ²` per weight bin at the last update (0 outside the band).
    #[must_use]
    pub fn coherence(&self) -> &[f64] {
        &self.coh
    }

    /// The largest change of any bin at the last update.
    #[must_use]
    pub fn last_change(&self) -> Decibels {
        Decibels(self.last_change)
    }

    /// Non-finite samples and force readings seen.
    #[must_use]
    pub fn non_finite(&self) -> u64 {
        self.non_finite
    }

    /// The loaded device as estimated at the last update, on the trusted bins of the band
    /// (drive to accelerometer). Allocates: for reports, not the audio thread.
    #[must_use]
    pub fn loaded_response(&self) -> FrequencyResponse {
        let (freqs, response) = self
            .weights
            .corrected()
            .filter(|&k| self.trusted[k])
            .map(|k| (self.weights.bin_frequency(k), self.estimate[k]))
            .unzip::<Hz, Complex64, Vec<Hz>, Vec<Complex64>>();
        FrequencyResponse { freqs, response }
    }
}

#[cfg(test)]
mod tests;
