//! The delay between two recordings of one signal: how far behind the drive an
//! accelerometer's samples are, when the two come from separate streams whose sample
//! counts started at different moments and pass through unknown buffering.
//!
//! # The estimator (generalised cross-correlation, smoothed phase transform)
//!
//! For windows `x` (the reference, the drive) and `y` (the delayed copy, the sensor) of
//! equal length `L` taken over the same sample indices of their own streams, with
//! `y[n] ≈ (h * x)[n − τ]` for a plant `h` and a delay `τ` (either sign), both are
//! zero-padded to `2L` (no circular wrap for any lag within the window) and transformed;
//! the weighted cross-spectrum
//!
//! ```math
//! G(f) = \frac{X^*(f)\, Y(f)}{|X^*(f)\, Y(f)| + \varepsilon \max_f |X^*(f)\, Y(f)|}
//! ```
//!
//! is transformed back to `r[k]`, and `τ` is the lag of the largest `|r[k]|` for
//! `|k| ≤ max_lag`. Dividing by the magnitude (the phase transform) keeps only the
//! cross-spectrum's phase, `−2π f τ` plus the plant's phase: the peak is as sharp as the
//! band allows, at `τ` plus the plant's group delay where it has energy, instead of a
//! peak smeared over the plant's impulse response (a resonant leg's would ring for tens
//! of milliseconds). `ε` (`1e-3`) keeps empty bins, where the phase is noise, from
//! counting as much as the bins with signal.
//!
//! The peak's *prominence* is its height over the RMS of `r` across the searched lags:
//! for noise alone it is about `sqrt(2 ln(2 max_lag))` (4.4 for 10^4 lags); a real
//! alignment stands far above that. [`DelayEstimator::estimate`] reports it and the
//! caller decides (the live adaptation wants 8 or more, and two estimates in a row that
//! agree).
//!
//! The estimate is used to pair each drive sample with the sensor sample it caused, for
//! the equalizer's online adaptation ([`crate::compensation::adapt`]): there an error of a
//! few samples costs nothing (the cross-spectrum keeps the phase; the window's bias is
//! `1 − 6.6 (τ/N)²`), while an error of a buffer would.

use std::sync::Arc;

use num_complex::Complex64;
use underfoot_fft::{ComplexToReal, RealFftPlanner, RealToComplex};

/// A delay found by [`DelayEstimator::estimate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Delay {
    /// `y`'s samples are this many behind `x`'s (negative: ahead).
    pub lag: i64,
    /// The peak's height over the RMS of the correlation across the searched lags.
    pub prominence: f64,
}

/// Estimates the delay between two windows of a fixed length; plans its transforms once.
pub struct DelayEstimator {
    len: usize,
    max_lag: usize,
    forward: Arc<dyn RealToComplex<f64>>,
    inverse: Arc<dyn ComplexToReal<f64>>,
    buf: Vec<f64>,
    spec_x: Vec<Complex64>,
    spec_y: Vec<Complex64>,
    scratch_fwd: Vec<Complex64>,
    scratch_inv: Vec<Complex64>,
}

impl std::fmt::Debug for DelayEstimator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DelayEstimator")
            .field("len", &self.len)
            .field("max_lag", &self.max_lag)
            .finish_non_exhaustive()
    }
}

/// Regularisation of the phase transform, relative to the largest cross-spectrum bin.
const EPSILON: f64 = 1e-3;

impl DelayEstimator {
    /// An estimator for windows of `len` samples, searching lags up to `max_lag` either
    /// way (clamped to `len / 2`: the windows must overlap for the lag to show).
    /// Allocates.
    #[must_use]
    pub fn new(len: usize, max_lag: usize) -> Self {
        let len = len.max(2);
        let n = 2 * len;
        let mut planner = RealFftPlanner::<f64>::new();
        let forward = planner.plan_fft_forward(n);
        let inverse = planner.plan_fft_inverse(n);
        Self {
            len,
            max_lag: max_lag.min(len / 2),
            buf: forward.make_input_vec(),
            spec_x: forward.make_output_vec(),
            spec_y: forward.make_output_vec(),
            scratch_fwd: forward.make_scratch_vec(),
            scratch_inv: inverse.make_scratch_vec(),
            forward,
            inverse,
        }
    }

    /// The window length it takes.
    #[must_use]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Never: a window has at least two samples.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The largest lag it searches, either way.
    #[must_use]
    pub fn max_lag(&self) -> usize {
        self.max_lag
    }

    /// The delay of `y` behind `x`, both windows of [`len`](Self::len) samples over the
    /// same indices (extra samples are ignored, missing ones are zeros); `None` when
    /// either window is silent or non-finite. Does not allocate.
    pub fn estimate(&mut self, x: &[f32], y: &[f32]) -> Option<Delay> {
        let n = 2 * self.len;
        let mut load = |src: &[f32], spec: &mut Vec<Complex64>, buf: &mut Vec<f64>| {
            buf.fill(0.0);
            for (b, &s) in buf.iter_mut().zip(src.iter().take(self.len)) {
                *b = f64::from(s);
            }
            if buf.iter().any(|v| !v.is_finite()) || buf.iter().all(|&v| v == 0.0) {
                return false;
            }
            self.forward
                .process_with_scratch(buf, spec, &mut self.scratch_fwd)
                .is_ok()
        };
        if !load(x, &mut self.spec_x, &mut self.buf) || !load(y, &mut self.spec_y, &mut self.buf) {
            return None;
        }
        let mut peak = 0.0f64;
        for (gx, gy) in self.spec_x.iter_mut().zip(&self.spec_y) {
            *gx = gx.conj() * gy;
            peak = peak.max(gx.norm());
        }
        if !(peak > 0.0 && peak.is_finite()) {
            return None;
        }
        let floor = EPSILON * peak;
        for g in &mut self.spec_x {
            *g /= g.norm() + floor;
        }
        // The inverse transform wants real DC and Nyquist bins.
        self.spec_x[0].im = 0.0;
        if let Some(last) = self.spec_x.last_mut() {
            last.im = 0.0;
        }
        self.inverse
            .process_with_scratch(&mut self.spec_x, &mut self.buf, &mut self.scratch_inv)
            .ok()?;
        // r[k] for k >= 0 sits at k, for k < 0 at n + k.
        let at = |k: i64| -> usize {
            if k >= 0 {
                k as usize
            } else {
                (n as i64 + k) as usize
            }
        };
        let max_lag = self.max_lag as i64;
        let (mut best, mut best_abs, mut sum_sq) = (0i64, -1.0f64, 0.0f64);
        for k in -max_lag..=max_lag {
            let v = self.buf[at(k)];
            sum_sq += v * v;
            if v.abs() > best_abs {
                best_abs = v.abs();
                best = k;
            }
        }
        let rms = (sum_sq / (2 * max_lag + 1) as f64).sqrt();
        (rms > 0.0).then_some(Delay {
            lag: best,
            prominence: best_abs / rms,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;
    use crate::signal::{Biquad, Sos};

    /// A resonant plant (a 120 Hz mode, Q 8, at 48 kHz) and sensor noise 30 dB down: the
    /// peak must still fall on the delay, not on the ringing.
    fn observe(x: &[f64], delay: i64, seed: u64) -> Vec<f32> {
        let w = std::f64::consts::TAU * 120.0 / 48_000.0;
        let r = 1.0 - w / 16.0;
        let plant = Sos::new(vec![Biquad {
            b: [1.0 - r, 0.0, -(1.0 - r)],
            a: [1.0, -2.0 * r * w.cos(), r * r],
        }]);
        let mut y: Vec<f64> = (0..x.len() as i64)
            .map(|n| {
                let m = n - delay;
                if (0..x.len() as i64).contains(&m) {
                    x[m as usize]
                } else {
                    0.0
                }
            })
            .collect();
        let mut state = vec![[0.0; 2]];
        plant.filter_with_state(&mut y, &mut state);
        let rms = (y.iter().map(|v| v * v).sum::<f64>() / y.len() as f64).sqrt();
        let mut rng = SplitMix64::new(seed);
        y.iter()
            .map(|v| (v + 0.03 * rms * rng.normal()) as f32)
            .collect()
    }

    /// Bursts of noise with silences between, as footsteps are.
    fn bursts(len: usize, seed: u64) -> Vec<f64> {
        let mut rng = SplitMix64::new(seed);
        (0..len)
            .map(|n| {
                if (n / 4000) % 3 == 0 {
                    rng.normal()
                } else {
                    0.0
                }
            })
            .collect()
    }

    #[test]
    fn it_finds_known_delays_either_way_through_a_resonance() {
        let len = 1 << 15;
        let mut est = DelayEstimator::new(len, 6000);
        for (i, delay) in [0i64, 1, 257, 3072, -64, -5000].into_iter().enumerate() {
            let x = bursts(len, 40 + i as u64);
            let y = observe(&x, delay, 7 + i as u64);
            let xs: Vec<f32> = x.iter().map(|&v| v as f32).collect();
            let got = est.estimate(&xs, &y).expect("an estimate");
            assert!((got.lag - delay).abs() <= 2, "delay {delay}: found {got:?}");
            assert!(got.prominence > 20.0, "delay {delay}: {got:?}");
        }
    }

    #[test]
    fn unrelated_signals_have_no_prominent_peak_and_silence_has_none() {
        let len = 1 << 14;
        let mut est = DelayEstimator::new(len, 4000);
        let x: Vec<f32> = bursts(len, 1).iter().map(|&v| v as f32).collect();
        let y: Vec<f32> = bursts(len, 2).iter().map(|&v| v as f32).collect();
        let got = est.estimate(&x, &y).expect("an estimate");
        assert!(got.prominence < 7.0, "{got:?}");
        assert_eq!(est.estimate(&x, &vec![0.0; len]), None);
        let mut bad = x.clone();
        bad[10] = f32::NAN;
        assert_eq!(est.estimate(&bad, &y), None);
        // Short windows are zero-padded, not a panic.
        assert!(est.estimate(&x[..100], &y[..50]).is_some());
    }
}
