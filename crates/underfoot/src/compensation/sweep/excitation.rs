//! The excitation: an exponential sine sweep, repeated with gaps.
//!
//! An exponential sine sweep from `f1` to `f2` over `T` seconds is
//!
//! ```math
//! x(t) = a \sin\big(2\pi f_1 L (e^{t/L} - 1)\big), \qquad L = \frac{T}{\ln(f_2/f_1)},
//! ```
//!
//! whose instantaneous frequency `f1 e^{t/L}` rises by a constant number of octaves per
//! second. It spends equal time per octave, so its spectrum is pink: `|X(f)|^2 ∝ 1/f`.
//! The sweep spans the measurement band widened by [`GUARD_OCTAVES`] on each side, so the
//! band edges lie where the excitation is strong and the edge fades (half-Hann, `fade`
//! long) only touch the guard. The programme is `repeats` sweeps, each followed by `gap`
//! seconds of silence in which the device's tail dies out.
//!
//! [`Sweep::new`] also prepares the regularised inverse that [`Sweep::response`] divides
//! the recording by ([`deconvolve`](mod@super::deconvolve)).

use std::f64::consts::{PI, TAU};

use num_complex::Complex64;

use super::deconvolve::{PRE_WINDOW, regularised_inverse};
use crate::compensation::CompensationError;
use crate::units::{Band, Decibels, SampleRate, Seconds};

/// How far the sweep extends beyond each edge of the measurement band, in octaves.
pub const GUARD_OCTAVES: f64 = 1.0;

/// The longest sweep: a minute (the default is 2 s).
pub const MAX_SWEEP_DURATION: Seconds = Seconds(60.0);
/// Most sweeps averaged per measurement.
pub const MAX_SWEEP_REPEATS: usize = 100;

/// Settings of a sweep measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepConfig {
    /// The measurement band; the sweep itself spans [`GUARD_OCTAVES`] more on each side.
    pub band: Band,
    /// Duration of one sweep.
    pub duration: Seconds,
    /// Sample rate of the excitation and the recording.
    pub rate: SampleRate,
    /// Half-Hann fade at each end of the sweep.
    pub fade: Seconds,
    /// Number of sweeps, averaged.
    pub repeats: usize,
    /// Silence after each sweep, in which the device's response dies out.
    pub gap: Seconds,
    /// Length of the impulse response kept after time zero; at most `gap`.
    pub window: Seconds,
    /// Peak level of the sweep relative to full scale (1.0).
    pub level: Decibels,
    /// Number of frequencies of the returned response, log-spaced over the band.
    pub points: usize,
}

impl SweepConfig {
    /// The defaults at `rate`: 40-1024 Hz, three 2 s sweeps with 10 ms fades, 0.5 s gaps,
    /// a 0.25 s window, -6 dBFS, 128 points.
    #[must_use]
    pub fn new(rate: SampleRate) -> Self {
        Self {
            band: Band::new(40.0, 1024.0),
            duration: Seconds(2.0),
            rate,
            fade: Seconds(0.01),
            repeats: 3,
            gap: Seconds(0.5),
            window: Seconds(0.25),
            level: Decibels(-6.0),
            points: 128,
        }
    }
}

/// A sweep programme and its regularised inverse.
#[derive(Debug, Clone)]
pub struct Sweep {
    pub(super) cfg: SweepConfig,
    /// One sweep, faded.
    pub(super) sweep: Vec<f64>,
    /// The whole programme: `repeats` times (sweep, gap).
    pub(super) excitation: Vec<f64>,
    /// Samples per period (sweep plus gap).
    pub(super) period: usize,
    /// FFT size.
    pub(super) n_fft: usize,
    /// `X* / (|X|^2 + ε)` over the `n_fft / 2 + 1` bins.
    pub(super) inverse: Vec<Complex64>,
}

/// Half-Hann rising from 0 (at `i = 0`) towards 1 (at `i = n`).
pub(super) fn rise(i: usize, n: usize) -> f64 {
    0.5 - 0.5 * (PI * i as f64 / n as f64).cos()
}

impl Sweep {
    /// Generates the programme and its inverse.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] when a setting is out of range, including a
    /// widened band that does not fit below Nyquist or a sweep too short to keep its second
    /// harmonic out of the pre-window.
    pub fn new(cfg: SweepConfig) -> Result<Self, CompensationError> {
        let fs = f64::from(cfg.rate.0);
        if cfg.rate.0 == 0 {
            return Err(CompensationError::invalid("rate", fs, "> 0 Hz"));
        }
        let guard = 2f64.powf(GUARD_OCTAVES);
        let (f1, f2) = (cfg.band.lo.0 / guard, cfg.band.hi.0 * guard);
        if !Band::new(f1, f2).fits(cfg.rate) {
            return Err(CompensationError::invalid(
                "band.hi",
                cfg.band.hi.0,
                "0 < lo < hi, hi a quarter octave below Nyquist",
            ));
        }
        let t = cfg.duration.0;
        // Bounded so that the sweep's samples are a bounded allocation.
        if !(t.is_finite() && t > 0.0 && t <= MAX_SWEEP_DURATION.0) {
            return Err(CompensationError::invalid(
                "duration",
                t,
                "finite, > 0 s and at most 60 s",
            ));
        }
        if !(cfg.fade.0.is_finite() && cfg.fade.0 >= 0.0 && 2.0 * cfg.fade.0 < t) {
            return Err(CompensationError::invalid(
                "fade",
                cfg.fade.0,
                ">= 0 s, under half the duration",
            ));
        }
        if cfg.repeats == 0 || cfg.repeats > MAX_SWEEP_REPEATS {
            return Err(CompensationError::invalid(
                "repeats",
                cfg.repeats as f64,
                "1 to 100",
            ));
        }
        if !(cfg.window.0.is_finite() && cfg.window.0 > 0.0) {
            return Err(CompensationError::invalid(
                "window",
                cfg.window.0,
                "finite, > 0 s",
            ));
        }
        if !(cfg.gap.0.is_finite() && cfg.gap.0 >= cfg.window.0) {
            return Err(CompensationError::invalid(
                "gap",
                cfg.gap.0,
                "finite, >= window",
            ));
        }
        if !cfg.level.0.is_finite() || cfg.level.0 > 0.0 {
            return Err(CompensationError::invalid(
                "level",
                cfg.level.0,
                "finite, <= 0 dBFS",
            ));
        }
        if cfg.points < 2 {
            return Err(CompensationError::invalid(
                "points",
                cfg.points as f64,
                ">= 2",
            ));
        }
        let l = t / (f2 / f1).ln();
        if l * 2f64.ln() <= 2.0 * PRE_WINDOW.0 {
            return Err(CompensationError::invalid(
                "duration",
                t,
                "long enough that the 2nd harmonic lies before the pre-window",
            ));
        }
        let n = cfg.rate.samples_in(cfg.duration);
        let n_fade = cfg.rate.samples_in(cfg.fade);
        let n_gap = cfg.rate.samples_in(cfg.gap);
        if n < 16 || cfg.rate.samples_in(cfg.window) < 16 {
            return Err(CompensationError::invalid(
                "duration",
                t,
                "at least 16 samples of sweep and window",
            ));
        }

        let amp = cfg.level.to_amplitude();
        let sweep: Vec<f64> = (0..n)
            .map(|i| {
                let ti = i as f64 / fs;
                let env = if i < n_fade {
                    rise(i, n_fade)
                } else if n - 1 - i < n_fade {
                    rise(n - 1 - i, n_fade)
                } else {
                    1.0
                };
                amp * env * (TAU * f1 * l * ((ti / l).exp() - 1.0)).sin()
            })
            .collect();

        let period = n + n_gap;
        let mut excitation = Vec::with_capacity(period * cfg.repeats);
        for _ in 0..cfg.repeats {
            excitation.extend_from_slice(&sweep);
            excitation.resize(excitation.len() + n_gap, 0.0);
        }

        let n_fft = period.next_power_of_two();
        let inverse = regularised_inverse(&sweep, n_fft, fs, f1, f2);

        Ok(Self {
            cfg,
            sweep,
            excitation,
            period,
            n_fft,
            inverse,
        })
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &SweepConfig {
        &self.cfg
    }

    /// The programme to play: `repeats` times one sweep then `gap` of silence.
    #[must_use]
    pub fn excitation(&self) -> &[f64] {
        &self.excitation
    }

    /// One sweep, faded.
    #[must_use]
    pub fn single(&self) -> &[f64] {
        &self.sweep
    }

    /// The regularised inverse `X*/(|X|^2 + ε)` on the bins of an FFT of
    /// [`Sweep::fft_len`] samples.
    #[must_use]
    pub fn inverse_spectrum(&self) -> &[Complex64] {
        &self.inverse
    }

    /// The FFT size of the deconvolution.
    #[must_use]
    pub fn fft_len(&self) -> usize {
        self.n_fft
    }
}
