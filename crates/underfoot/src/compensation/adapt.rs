//! Online adaptation of the equalizer while a person stands and walks on the tile: the
//! paper's future work ("adaptively changing the spectral weights in real time as the
//! user walks on the device").
//!
//! The [equalizer](super::equalizer) is tuned by sweeps on the *unloaded* tile. A foot on
//! it adds the leg's and the shoe's impedance: modes move and damp, the top of the band
//! is pulled down. The sweep cannot be played while someone walks, but the signal that
//! *is* played is known: [`Adapter`] watches the drive that reached the actuator and the
//! accelerometer, estimates the loaded device from them, and moves the weights towards
//! its inverse, slowly and within bounds.
//!
//! # The estimator (Welch, H1)
//!
//! Both signals are cut into frames of `N` samples ([`AdaptConfig::frame`], by default
//! the weights' own `bins`, so the estimate lands on the equalizer's bins), hop `N/2`,
//! Hann-windowed (50 % overlap: the Hann window's overlap-add is flat, so every sample
//! weighs the same). For frame `m` with spectra `X_m(f)` (drive) and `A_m(f)` (accel),
//! the cross- and auto-spectra are exponential averages
//!
//! $$ S_{xa} \leftarrow (1-\alpha) S_{xa} + \alpha X_m^* A_m, \quad
//!    S_{xx} \leftarrow (1-\alpha) S_{xx} + \alpha |X_m|^2, \quad
//!    S_{aa} \leftarrow (1-\alpha) S_{aa} + \alpha |A_m|^2, $$
//!
//! with `α = 1 - exp(-(N/2) / (fs · memory))` ([`AdaptConfig::memory`], 3 s of analysed
//! signal by default: the average forgets a stance that has changed within a few steps,
//! and holds about `(2 - α)/α ≈ 140` frames at `N = 4096`, 48 kHz, enough for a stable
//! estimate). The loaded device is
//! the H1 estimate and its trust the magnitude-squared coherence:
//!
//! $$ \hat D(f) = \frac{S_{xa}(f)}{S_{xx}(f)}, \qquad
//!    \gamma^2(f) = \frac{|S_{xa}(f)|^2}{S_{xx}(f)\, S_{aa}(f)} \in [0, 1]. $$
//!
//! H1 is unbiased by noise on the *output* (the accelerometer's), which is where the
//! noise is: the drive is a digital signal known exactly. `γ²` is `SNR / (1 + SNR)` for
//! the bin; where the drive has no energy (a footstep signal without high content, the
//! silence of a swing phase) it is near `1/n` for `n` averaged frames, so a bin with
//! `γ² <` [`AdaptConfig::coherence`] (0.8 by default, an SNR of 6 dB) is not trusted and
//! keeps its weight. The first update waits for [`AdaptConfig::min_frames`] frames
//! because with few averages `γ²` is biased towards 1 (it is exactly 1 for one frame).
//!
//! Because the drive is taken *after* the equalizer and the limiter, `D̂` is the device
//! alone: changing the weights does not change what is being estimated, so old frames
//! stay valid across updates and the loop has no feedback through the estimate. A delay
//! between the two signals (audio interface latency) must be removed by the caller: a
//! misalignment of `τ` samples lowers `γ²` and biases `|D̂|` low by the Hann window's
//! normalised autocorrelation at lag `τ`, about `1 - 6.6 (τ/N)²` (-0.2 dB for 5 ms,
//! -0.8 dB for 10 ms at `N = 4096`, 48 kHz).
//!
//! **Resolution.** The Hann window's main lobe spans ±2 bins (±23 Hz for `N = 4096` at
//! 48 kHz), and `D̂` is the device smoothed over it. Where the response is steep, below
//! about 60 Hz (out of the suspension's notch and through the actuator's high-pass), the
//! smoothed estimate is biased low: in the simulated-user test, -1.1 dB at 47 Hz and
//! -0.4 dB at 59 Hz, against ±0.1 dB over most of the band, leaving a final deviation
//! of 0.32 dB RMS over 40-1024 Hz. A frame of `2N` halves the lobe (-0.4 dB at 47 Hz,
//! 0.15 dB final) at the price of averaging half as many frames, so settling later
//! (8.3 s instead of 6.5 s there); the default keeps the weights' own bins.
//!
//! # Which frames count
//!
//! Only frames in which the foot loads the tile describe the loaded device. `push` takes
//! the total vertical force in [`Newtons`]; a frame counts only if the force was at or
//! above [`AdaptConfig::load_threshold`] (150 N by default, about a third of a light
//! person's weight: the foot is flat on the tile, not brushing it) for every block it
//! spans, none of its samples was non-finite, and the drive's RMS over it is at least
//! [`AdaptConfig::min_drive`] (-60 dBFS): a silent frame carries no information and only
//! adds sensor noise to `S_aa`. The frames are fixed by the sample count, not by how the
//! signal is cut into blocks, so the result does not depend on the block size (as long
//! as the force is constant over the blocks concerned).
//!
//! # The update
//!
//! Every [`AdaptConfig::interval`] of counted signal (0.5 s), each trusted bin `k` of the
//! band moves towards the weights that would flatten the loaded device, what equations
//! (4)-(5) converge to:
//!
//! $$ t_k = c - 20\log_{10}|\hat D_k|, \qquad
//!    \Delta_k = \mathrm{clip}\big(\mu (t_k - w_k) - s,\; l_k,\; h_k\big), $$
//!
//! with relaxation `μ` ([`AdaptConfig::step`], 0.3), `c` the level that makes the target's
//! mean over the trusted bins equal the weights' (so the update reshapes, it does not
//! move the level), `l_k = max(-δ, -max_cut - w_k)`, `h_k = min(δ, max_boost - w_k)`
//! with the per-update bound `δ` ([`AdaptConfig::max_change`], 0.5 dB), and `s` the
//! shift, found by bisection, that makes `Σ Δ_k = 0`. Untrusted bins have `Δ_k = 0`.
//! The weights then go through the same re-level, bounds and out-of-band taper as after a
//! sweep ([`SpectralWeights`]' finishing step, which finds the mean already at 0 dB).
//!
//! Why: `μ < 1` averages the estimate's noise over several updates (a first-order
//! smoother of the target with time constant `interval / μ`); `δ` makes any change
//! slow and small enough to be unnoticed (0.5 dB is at the lower end of the 0.45-3 dB
//! intensity discrimination threshold the paper cites), however wrong an estimate; the
//! zero-sum shift keeps the in-band mean exactly without moving untrusted bins, which a
//! plain re-level would.
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

use std::sync::Arc;

use num_complex::Complex64;
use realfft::{RealFftPlanner, RealToComplex};
use serde::{Deserialize, Serialize};

use super::CompensationError;
use super::equalizer::SpectralWeights;
use super::sweep::FrequencyResponse;
use crate::units::{Decibels, Hz, Newtons, SampleRate, Seconds};

/// How the adapter estimates the loaded device and moves the weights; see the
/// [module documentation](self).
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

    /// Feeds one block: `drive` is what reached the actuator (after the equalizer and
    /// the limiter), `accel` what the accelerometer read at the same samples, `force` the
    /// total vertical force on the tile during the block. Uses the shorter of the two
    /// signals. Returns the new weights (for
    /// [`EqualizerFilter::set_weights`](super::equalizer::EqualizerFilter::set_weights))
    /// when an update happened in this block.
    ///
    /// Non-finite samples (and a non-finite force) are counted, and the frames holding
    /// them ignored. Never allocates, locks or panics.
    pub fn push(&mut self, drive: &[f32], accel: &[f32], force: Newtons) -> Option<&[f64]> {
        let len = drive.len().min(accel.len());
        let loaded = if force.0.is_finite() {
            force.0 >= self.cfg.load_threshold.0
        } else {
            self.non_finite += 1;
            false
        };
        let mut updated = false;
        for (&x, &a) in drive[..len].iter().zip(&accel[..len]) {
            let ok = x.is_finite() && a.is_finite();
            if !ok {
                self.non_finite += 1;
            }
            self.hist_x[self.write] = if ok { f64::from(x) } else { 0.0 };
            self.hist_a[self.write] = if ok { f64::from(a) } else { 0.0 };
            self.write = if self.write + 1 == self.frame {
                0
            } else {
                self.write + 1
            };
            self.samples += 1;
            if !(ok && loaded) {
                self.clean_since = self.samples;
            }
            self.count += 1;
            if self.count == self.hop {
                self.count = 0;
                updated |= self.frame_step();
            }
        }
        updated.then_some(self.weights.gains_db.as_slice())
    }

    /// Analyses the frame that just completed; returns whether the weights were updated.
    fn frame_step(&mut self) -> bool {
        let n = self.frame;
        if self.samples < n as u64 || self.samples - (n as u64) < self.clean_since {
            return false;
        }
        let (newer, older) = self.hist_x.split_at(self.write);
        let power = older.iter().chain(newer).map(|v| v * v).sum::<f64>() / n as f64;
        // The history holds only finite values, so the power is a number.
        if power < self.min_power {
            return false;
        }
        if !transform(
            &*self.fft,
            &self.hist_x,
            self.write,
            &self.window,
            &mut self.buf,
            &mut self.spec_x,
            &mut self.scratch,
        ) || !transform(
            &*self.fft,
            &self.hist_a,
            self.write,
            &self.window,
            &mut self.buf,
            &mut self.spec_a,
            &mut self.scratch,
        ) {
            return false;
        }
        let (a, keep) = (self.alpha, 1.0 - self.alpha);
        for (k, (x, y)) in self.spec_x.iter().zip(&self.spec_a).enumerate() {
            self.sxx[k] = keep * self.sxx[k] + a * x.norm_sqr();
            self.saa[k] = keep * self.saa[k] + a * y.norm_sqr();
            self.sxa[k] = self.sxa[k] * keep + x.conj() * y * a;
        }
        self.frames += 1;
        self.since_update += 1;
        if self.frames >= self.cfg.min_frames as u64 && self.since_update >= self.interval_frames {
            self.since_update = 0;
            return self.update();
        }
        false
    }

    /// The averaged spectra at weight bin `k`, linear between analysis bins.
    fn spectra_at(&self, k: usize) -> (f64, f64, Complex64) {
        let x = k as f64 * self.frame as f64 / self.weights.config.bins as f64;
        let last = self.sxx.len() - 1;
        let j = (x.floor() as usize).min(last);
        let t = (x - j as f64).clamp(0.0, 1.0);
        let j1 = (j + 1).min(last);
        let lerp = |p: f64, q: f64| p + t * (q - p);
        (
            lerp(self.sxx[j], self.sxx[j1]),
            lerp(self.saa[j], self.saa[j1]),
            self.sxa[j] + (self.sxa[j1] - self.sxa[j]) * t,
        )
    }

    /// Estimates, decides trust, and moves the weights; returns whether they moved.
    fn update(&mut self) -> bool {
        let corrected = self.weights.corrected();
        let first = *corrected.start();
        let mut level = 0.0;
        let mut trusted = 0usize;
        for k in corrected.clone() {
            let (sxx, saa, sxa) = self.spectra_at(k);
            let (d, coh) = if sxx > 0.0 && saa > 0.0 {
                (sxa / sxx, sxa.norm_sqr() / (sxx * saa))
            } else {
                (Complex64::new(0.0, 0.0), 0.0)
            };
            self.estimate[k] = d;
            self.coh[k] = coh;
            let ok = coh >= self.cfg.coherence && d.norm() > 0.0 && d.norm().is_finite();
            self.trusted[k] = ok;
            if ok {
                level += self.weights.gains_db[k] + db(d);
                trusted += 1;
            }
        }
        self.trusted_count = trusted;
        if trusted == 0 {
            return false;
        }
        let c = level / trusted as f64;
        let (mu, bound) = (self.cfg.step, self.cfg.max_change.0);
        let (boost, cut) = (
            self.weights.config.max_boost.0,
            self.weights.config.max_cut.0,
        );
        for (i, k) in corrected.clone().enumerate() {
            let w = self.weights.gains_db[k];
            if self.trusted[k] {
                self.delta[i] = mu * (c - db(self.estimate[k]) - w);
                // Containing 0 keeps lo <= hi even for a weight already past a bound.
                self.lo[i] = (-bound).max(-cut - w).min(0.0);
                self.hi[i] = bound.min(boost - w).max(0.0);
            } else {
                self.delta[i] = 0.0;
                self.lo[i] = 0.0;
                self.hi[i] = 0.0;
            }
        }
        balance(&mut self.delta, &self.lo, &self.hi);
        self.previous.copy_from_slice(&self.weights.gains_db);
        for (i, d) in self.delta.iter().enumerate() {
            self.weights.gains_db[first + i] += d;
        }
        self.weights.finish();
        self.last_change = self
            .previous
            .iter()
            .zip(&self.weights.gains_db)
            .map(|(p, w)| (w - p).abs())
            .fold(0.0, f64::max);
        self.updates += 1;
        true
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

/// `20 log10 |d|`.
fn db(d: Complex64) -> f64 {
    20.0 * d.norm().log10()
}

/// Windows the circular history (oldest at `start`) into `buf` and transforms it.
fn transform(
    fft: &dyn RealToComplex<f64>,
    history: &[f64],
    start: usize,
    window: &[f64],
    buf: &mut [f64],
    spectrum: &mut [Complex64],
    scratch: &mut [Complex64],
) -> bool {
    let (newer, older) = history.split_at(start);
    for ((b, &h), &w) in buf.iter_mut().zip(older.iter().chain(newer)).zip(window) {
        *b = h * w;
    }
    // Sizes come from the plan, so this cannot fail; if it did, the frame is dropped.
    fft.process_with_scratch(buf, spectrum, scratch).is_ok()
}

/// Replaces `v_k` by `clip(v_k - s, lo_k, hi_k)` with the shift `s` that makes the sum
/// zero. Needs `lo_k <= 0 <= hi_k`, so the sum falls from `Σ hi ≥ 0` to `Σ lo ≤ 0` as
/// `s` rises and a root exists; bisection, as the sum is only piecewise linear.
fn balance(values: &mut [f64], lo: &[f64], hi: &[f64]) {
    let sum = |s: f64| -> f64 {
        values
            .iter()
            .zip(lo.iter().zip(hi))
            .map(|(v, (l, h))| (v - s).max(*l).min(*h))
            .sum()
    };
    let mut s = 0.0;
    if sum(0.0) != 0.0 {
        let mut below = f64::INFINITY;
        let mut above = f64::NEG_INFINITY;
        for (v, (l, h)) in values.iter().zip(lo.iter().zip(hi)) {
            below = below.min(v - h);
            above = above.max(v - l);
        }
        if below.is_finite() && above.is_finite() {
            for _ in 0..200 {
                let mid = 0.5 * (below + above);
                if sum(mid) > 0.0 {
                    below = mid;
                } else {
                    above = mid;
                }
                if above - below <= 1e-13 * (1.0 + above.abs()) {
                    break;
                }
            }
            s = 0.5 * (below + above);
        }
    }
    for (v, (l, h)) in values.iter_mut().zip(lo.iter().zip(hi)) {
        *v = (*v - s).max(*l).min(*h);
    }
}

#[cfg(test)]
mod tests;
