//! The estimate of the loaded device: which frames count, and the Welch H1 estimate
//! from them.
//!
//! # The estimator (Welch, H1)
//!
//! Both signals are cut into frames of `N` samples ([`AdaptConfig::frame`], by default
//! the weights' own `bins`, so the estimate lands on the equalizer's bins), hop `N/2`,
//! Hann-windowed (50 % overlap: the Hann window's overlap-add is flat, so every sample
//! weighs the same). For frame `m` with spectra `X_m(f)` (drive) and `A_m(f)` (accel),
//! the cross- and auto-spectra are exponential averages
//!
//! ```math
//! S_{xa} \leftarrow (1-\alpha) S_{xa} + \alpha X_m^* A_m, \quad
//!   S_{xx} \leftarrow (1-\alpha) S_{xx} + \alpha |X_m|^2, \quad
//!   S_{aa} \leftarrow (1-\alpha) S_{aa} + \alpha |A_m|^2,
//! ```
//!
//! with `α = 1 - exp(-(N/2) / (fs · memory))` ([`AdaptConfig::memory`], 3 s of analysed
//! signal by default: the average forgets a stance that has changed within a few steps,
//! and holds about `(2 - α)/α ≈ 140` frames at `N = 4096`, 48 kHz, enough for a stable
//! estimate). The loaded device is
//! the H1 estimate and its trust the magnitude-squared coherence:
//!
//! ```math
//! \hat D(f) = \frac{S_{xa}(f)}{S_{xx}(f)}, \qquad
//!   \gamma^2(f) = \frac{|S_{xa}(f)|^2}{S_{xx}(f)\, S_{aa}(f)} \in [0, 1].
//! ```
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
//! [`AdaptConfig::coherence`]: super::AdaptConfig::coherence
//! [`AdaptConfig::frame`]: super::AdaptConfig::frame
//! [`AdaptConfig::load_threshold`]: super::AdaptConfig::load_threshold
//! [`AdaptConfig::memory`]: super::AdaptConfig::memory
//! [`AdaptConfig::min_drive`]: super::AdaptConfig::min_drive
//! [`AdaptConfig::min_frames`]: super::AdaptConfig::min_frames

use num_complex::Complex64;
use underfoot_fft::RealToComplex;

use super::Adapter;
use crate::units::Newtons;

impl Adapter {
    /// Feeds one block: `drive` is what reached the actuator (after the equalizer and
    /// the limiter), `accel` what the accelerometer read at the same samples, `force` the
    /// total vertical force on the tile during the block. Uses the shorter of the two
    /// signals. Returns the new weights (for
    /// [`EqualizerFilter::set_weights`](crate::compensation::equalizer::EqualizerFilter::set_weights))
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
    pub(super) fn spectra_at(&self, k: usize) -> (f64, f64, Complex64) {
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
