//! The frequency response of a device from exponential sine sweeps (Farina, 2000).
//!
//! # Excitation
//!
//! An exponential sine sweep from `f1` to `f2` over `T` seconds is
//!
//! $$ x(t) = a \sin\big(2\pi f_1 L (e^{t/L} - 1)\big), \qquad L = \frac{T}{\ln(f_2/f_1)}, $$
//!
//! whose instantaneous frequency `f1 e^{t/L}` rises by a constant number of octaves per
//! second. It spends equal time per octave, so its spectrum is pink: `|X(f)|^2 ∝ 1/f`.
//! The sweep spans the measurement band widened by [`GUARD_OCTAVES`] on each side, so the
//! band edges lie where the excitation is strong and the edge fades (half-Hann, `fade`
//! long) only touch the guard. The programme is `repeats` sweeps, each followed by `gap`
//! seconds of silence in which the device's tail dies out.
//!
//! # Deconvolution
//!
//! Each repeat's period of the recording, `y`, is divided by the sweep in the frequency
//! domain, with Kirkeby regularisation:
//!
//! $$ \hat H(f) = Y(f)\, \frac{X^*(f)}{|X(f)|^2 + \varepsilon(f)}, $$
//!
//! with `ε = 1e-10 max|X|^2` from the band out to halfway (in octaves) through each guard
//! (exact division, up to round-off), rising on a log-frequency raised cosine through the
//! outer half of the guard to `ε = max|X|^2` outside the swept range, where `X` is too weak
//! to divide by and the quotient would be amplified noise. The guard is a whole octave
//! because the window (below) smears the spectrum: the roll-off of the quotient must lie
//! far enough from the band edges that the smear does not reach them (with a quarter
//! octave, 40 Hz came out 1.8 dB low). The FFT is at least one period long, so the
//! circular division equals the linear one.
//!
//! This is spectral division rather than convolution with Farina's time-reversed,
//! `-6 dB/octave` enveloped inverse sweep: the latter only makes `x * x_inv` a band-pass
//! pulse, whose ripple and edge roll-off would bias the response by more than the 0.1 dB
//! we want; dividing by `X` is exact in the band.
//!
//! # Harmonic distortion
//!
//! A weakly non-linear device answers the `k`-th harmonic of the sweep `L ln k` seconds
//! *before* the linear response: after deconvolution its impulse response sits at negative
//! time. The linear response is cut from `-PRE_WINDOW` to `window` (both after time zero of
//! the period), so harmonics are left out as long as `L ln 2` exceeds the pre-window plus
//! the length of the second harmonic's tail; [`Sweep::new`] checks `L ln 2 > 2 PRE_WINDOW`.
//!
//! # Window and averaging
//!
//! The impulse response is kept from `-PRE_WINDOW` (which holds the zero-phase pre-ringing
//! of the regularisation) to `window`, with a half-Hann fade-in across the pre-window and a
//! half-Hann fade-out over the last half of `window`: long smooth tapers keep the window's
//! spectral sidelobes, and so the smear, small. A shorter window keeps less noise
//! (the noise spreads over the whole period, the response does not) but must hold the
//! device's decay and any latency of the audio path. Its spectrum is evaluated exactly
//! (a direct DTFT) at `points` frequencies on a log grid of the band, so no FFT-bin
//! interpolation enters the result. The repeats are averaged as complex numbers: the
//! response is the same in each, the noise is not, so its power falls as `1/repeats`.
//!
//! # Flatness
//!
//! [`FrequencyResponse::deviation_from_flat_db`] is the RMS over the log grid of the
//! magnitude in dB minus its mean: the paper's "deviation from a flat response", zero for
//! a device that only scales.

use std::f64::consts::{PI, TAU};

use num_complex::Complex64;
use realfft::RealFftPlanner;

use super::CompensationError;
use crate::signal::noise::SplitMix64;
use crate::signal::{Biquad, Sos, butterworth};
use crate::units::{Band, Decibels, Hz, SampleRate, Seconds};

/// How far the sweep extends beyond each edge of the measurement band, in octaves.
pub const GUARD_OCTAVES: f64 = 1.0;

/// How far before time zero the impulse response is kept, in seconds.
pub const PRE_WINDOW: Seconds = Seconds(0.05);

/// Regularisation inside the band, relative to the peak of `|X|^2`.
const EPS_IN: f64 = 1e-10;
/// Regularisation outside the swept range, relative to the peak of `|X|^2`.
const EPS_OUT: f64 = 1.0;

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
    cfg: SweepConfig,
    /// One sweep, faded.
    sweep: Vec<f64>,
    /// The whole programme: `repeats` times (sweep, gap).
    excitation: Vec<f64>,
    /// Samples per period (sweep plus gap).
    period: usize,
    /// FFT size.
    n_fft: usize,
    /// `X* / (|X|^2 + ε)` over the `n_fft / 2 + 1` bins.
    inverse: Vec<Complex64>,
}

fn invalid(name: &'static str, value: f64, expected: &'static str) -> CompensationError {
    CompensationError::InvalidParameter {
        name,
        value,
        expected,
    }
}

/// Half-Hann rising from 0 (at `i = 0`) towards 1 (at `i = n`).
fn rise(i: usize, n: usize) -> f64 {
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
            return Err(invalid("rate", fs, "> 0 Hz"));
        }
        let guard = 2f64.powf(GUARD_OCTAVES);
        let (f1, f2) = (cfg.band.lo.0 / guard, cfg.band.hi.0 * guard);
        if !Band::new(f1, f2).fits(cfg.rate) {
            return Err(invalid(
                "band.hi",
                cfg.band.hi.0,
                "0 < lo < hi, hi a quarter octave below Nyquist",
            ));
        }
        let t = cfg.duration.0;
        // Bounded so that the sweep's samples are a bounded allocation.
        if !(t.is_finite() && t > 0.0 && t <= MAX_SWEEP_DURATION.0) {
            return Err(invalid("duration", t, "finite, > 0 s and at most 60 s"));
        }
        if !(cfg.fade.0.is_finite() && cfg.fade.0 >= 0.0 && 2.0 * cfg.fade.0 < t) {
            return Err(invalid(
                "fade",
                cfg.fade.0,
                ">= 0 s, under half the duration",
            ));
        }
        if cfg.repeats == 0 || cfg.repeats > MAX_SWEEP_REPEATS {
            return Err(invalid("repeats", cfg.repeats as f64, "1 to 100"));
        }
        if !(cfg.window.0.is_finite() && cfg.window.0 > 0.0) {
            return Err(invalid("window", cfg.window.0, "finite, > 0 s"));
        }
        if !(cfg.gap.0.is_finite() && cfg.gap.0 >= cfg.window.0) {
            return Err(invalid("gap", cfg.gap.0, "finite, >= window"));
        }
        if !cfg.level.0.is_finite() || cfg.level.0 > 0.0 {
            return Err(invalid("level", cfg.level.0, "finite, <= 0 dBFS"));
        }
        if cfg.points < 2 {
            return Err(invalid("points", cfg.points as f64, ">= 2"));
        }
        let l = t / (f2 / f1).ln();
        if l * 2f64.ln() <= 2.0 * PRE_WINDOW.0 {
            return Err(invalid(
                "duration",
                t,
                "long enough that the 2nd harmonic lies before the pre-window",
            ));
        }
        let n = cfg.rate.samples_in(cfg.duration);
        let n_fade = cfg.rate.samples_in(cfg.fade);
        let n_gap = cfg.rate.samples_in(cfg.gap);
        if n < 16 || cfg.rate.samples_in(cfg.window) < 16 {
            return Err(invalid(
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
        let x = spectrum(&sweep, n_fft);
        let peak = x.iter().map(Complex64::norm_sqr).fold(0.0, f64::max);
        let bin_hz = fs / n_fft as f64;
        let inverse = x
            .iter()
            .enumerate()
            .map(|(k, xk)| {
                let eps = peak * regularisation(k as f64 * bin_hz, f1, f2);
                xk.conj() / (xk.norm_sqr() + eps)
            })
            .collect();

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

    /// The response of the device that turned the programme into `recorded`.
    ///
    /// `recorded` starts with the programme and may run on past it; the surplus is
    /// ignored. A latency of the audio path shows as a linear phase and must fit, with the
    /// device's decay, in `window`.
    ///
    /// # Errors
    /// [`CompensationError::TooShort`] when `recorded` is shorter than the programme,
    /// [`CompensationError::NonFinite`] when a sample of it is not finite.
    pub fn response(&self, recorded: &[f64]) -> Result<FrequencyResponse, CompensationError> {
        let needed = self.excitation.len();
        if recorded.len() < needed {
            return Err(CompensationError::TooShort {
                what: "recording",
                len: recorded.len(),
                needed,
            });
        }
        if let Some(index) = recorded[..needed].iter().position(|v| !v.is_finite()) {
            return Err(CompensationError::NonFinite {
                what: "recording",
                index,
            });
        }

        let freqs = self.cfg.band.log_grid(self.cfg.points);
        let omegas: Vec<f64> = freqs.iter().map(|&f| self.cfg.rate.omega(f)).collect();
        let pre = self.cfg.rate.samples_in(PRE_WINDOW);
        let post = self.cfg.rate.samples_in(self.cfg.window);
        let fade_out = (post / 2).max(1);

        let mut planner = RealFftPlanner::<f64>::new();
        let fwd = planner.plan_fft_forward(self.n_fft);
        let inv = planner.plan_fft_inverse(self.n_fft);
        let mut buf = vec![0.0; self.n_fft];
        let mut spec = fwd.make_output_vec();
        let mut ir = vec![0.0; self.n_fft];
        let mut acc = vec![Complex64::new(0.0, 0.0); freqs.len()];
        // Windowed impulse response from -pre to post, index 0 being time -pre.
        let mut h = vec![0.0; pre + post];

        for rep in 0..self.cfg.repeats {
            let seg = &recorded[rep * self.period..(rep + 1) * self.period];
            buf.fill(0.0);
            buf[..seg.len()].copy_from_slice(seg);
            // Sizes come from the plans, so the transforms cannot fail.
            let _ = fwd.process(&mut buf, &mut spec);
            let scale = 1.0 / self.n_fft as f64;
            for (s, g) in spec.iter_mut().zip(&self.inverse) {
                *s *= g * scale;
            }
            // realfft insists on real DC and Nyquist bins, which they are up to round-off.
            spec[0].im = 0.0;
            if let Some(last) = spec.last_mut() {
                last.im = 0.0;
            }
            let _ = inv.process(&mut spec, &mut ir);

            for (j, hj) in h.iter_mut().enumerate() {
                let w = if j < pre {
                    rise(j, pre)
                } else if j >= pre + post - fade_out {
                    rise(pre + post - j, fade_out)
                } else {
                    1.0
                };
                *hj = w * ir[(self.n_fft + j - pre) % self.n_fft];
            }
            for (a, &om) in acc.iter_mut().zip(&omegas) {
                *a += crate::numeric::dtft(&h, om) * Complex64::from_polar(1.0, om * pre as f64);
            }
        }
        let k = 1.0 / self.cfg.repeats as f64;
        Ok(FrequencyResponse {
            freqs,
            response: acc.into_iter().map(|a| a * k).collect(),
        })
    }
}

/// `ε(f) / max|X|^2`: tiny in the band, large outside the swept range `[f1, f2]`, and a
/// raised cosine in log frequency across each guard so the quotient has no sharp edge to
/// ring at.
fn regularisation(f: f64, f1: f64, f2: f64) -> f64 {
    // The exact region reaches halfway (in octaves) into each guard.
    let half = 2f64.powf(GUARD_OCTAVES / 2.0);
    let (lo, hi) = (f1 * half, f2 / half);
    let t = if f <= f1 {
        1.0
    } else if f < lo {
        (lo / f).ln() / (lo / f1).ln()
    } else if f <= hi {
        0.0
    } else if f < f2 {
        (f / hi).ln() / (f2 / hi).ln()
    } else {
        1.0
    };
    let s = 0.5 - 0.5 * (PI * t).cos();
    // Interpolating the logarithm spans the ten decades between the two evenly.
    (EPS_IN.ln() + s * (EPS_OUT.ln() - EPS_IN.ln())).exp()
}

/// Real FFT of `x` zero-padded to `n`.
fn spectrum(x: &[f64], n: usize) -> Vec<Complex64> {
    let fwd = RealFftPlanner::<f64>::new().plan_fft_forward(n);
    let mut buf = vec![0.0; n];
    buf[..x.len()].copy_from_slice(x);
    let mut out = fwd.make_output_vec();
    let _ = fwd.process(&mut buf, &mut out);
    out
}

/// A complex frequency response on a set of frequencies.
#[derive(Debug, Clone, PartialEq)]
pub struct FrequencyResponse {
    /// The frequencies, ascending.
    pub freqs: Vec<Hz>,
    /// The response at each: output over input, magnitude and phase.
    pub response: Vec<Complex64>,
}

impl FrequencyResponse {
    /// Checks that there are at least two frequencies, one response each, all finite, at
    /// positive frequencies: what anything computed from a measurement needs.
    ///
    /// # Errors
    /// [`CompensationError::TooShort`] or [`CompensationError::NonFinite`].
    pub fn check(&self) -> Result<(), CompensationError> {
        if self.freqs.len() < 2 || self.freqs.len() != self.response.len() {
            return Err(CompensationError::TooShort {
                what: "measured response",
                len: self.freqs.len().min(self.response.len()),
                needed: 2,
            });
        }
        if let Some(index) = self
            .response
            .iter()
            .zip(&self.freqs)
            .position(|(h, f)| !(h.re.is_finite() && h.im.is_finite() && f.0 > 0.0))
        {
            return Err(CompensationError::NonFinite {
                what: "measured response",
                index,
            });
        }
        Ok(())
    }

    /// Magnitude in dB at each frequency (a zero response is floored, not `-inf`).
    #[must_use]
    pub fn magnitude_db(&self) -> Vec<Decibels> {
        self.response
            .iter()
            .map(|h| Decibels::from_amplitude(h.norm().max(f64::MIN_POSITIVE)))
            .collect()
    }

    /// Phase in degrees at each frequency, wrapped to `(-180, 180]`.
    #[must_use]
    pub fn phase_deg(&self) -> Vec<f64> {
        self.response.iter().map(|h| h.arg().to_degrees()).collect()
    }

    /// RMS of the dB magnitude minus its mean over the frequencies; zero when empty.
    #[must_use]
    pub fn deviation_from_flat_db(&self) -> Decibels {
        let db = self.magnitude_db();
        if db.is_empty() {
            return Decibels(0.0);
        }
        let n = db.len() as f64;
        let mean = db.iter().map(|d| d.0).sum::<f64>() / n;
        Decibels((db.iter().map(|d| (d.0 - mean).powi(2)).sum::<f64>() / n).sqrt())
    }
}

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

/// A resonance of the tile: a peaking section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Centre frequency.
    pub freq: Hz,
    /// Quality factor.
    pub q: f64,
    /// Gain at the centre relative to off-resonance.
    pub gain: Decibels,
}

/// Settings of a [`SimulatedTile`].
#[derive(Debug, Clone, PartialEq)]
pub struct TileConfig {
    /// The tile's plate modes.
    pub modes: Vec<Mode>,
    /// Frequency of the notch the elastomer suspension makes.
    pub suspension: Hz,
    /// Quality factor of that notch.
    pub suspension_q: f64,
    /// Corner of the actuator's second-order Butterworth high-pass.
    pub highpass: Hz,
    /// Corner of the actuator's second-order Butterworth low-pass.
    pub lowpass: Hz,
    /// Overall gain, accelerometer units per unit of drive.
    pub gain: f64,
    /// Sensor noise relative to the RMS of the noiseless output of each call, or none.
    pub noise: Option<Decibels>,
    /// Seed of the sensor noise.
    pub seed: u64,
}

impl Default for TileConfig {
    /// Three plate modes (180 Hz Q 5 +9 dB, 420 Hz Q 6 +6 dB, 760 Hz Q 8 +7 dB), a 20 Hz
    /// Q 2 suspension notch, a 50-900 Hz actuator, gain 0.5, no noise.
    fn default() -> Self {
        Self {
            modes: vec![
                Mode {
                    freq: Hz(180.0),
                    q: 5.0,
                    gain: Decibels(9.0),
                },
                Mode {
                    freq: Hz(420.0),
                    q: 6.0,
                    gain: Decibels(6.0),
                },
                Mode {
                    freq: Hz(760.0),
                    q: 8.0,
                    gain: Decibels(7.0),
                },
            ],
            suspension: Hz(20.0),
            suspension_q: 2.0,
            highpass: Hz(50.0),
            lowpass: Hz(900.0),
            gain: 0.5,
            noise: None,
            seed: 0x5EED,
        }
    }
}

/// A floor tile on its suspension, driven by an actuator and read by an accelerometer:
/// a cascade of second-order sections plus Gaussian sensor noise.
#[derive(Debug, Clone)]
pub struct SimulatedTile {
    rate: SampleRate,
    sos: Sos,
    gain: f64,
    noise: Option<Decibels>,
    rng: SplitMix64,
    state: Vec<[f64; 2]>,
}

/// The bilinear transform of `(b2 s^2 + b1 s + b0) / (a2 s^2 + a1 s + a0)`, `s` normalised
/// to `f0`, prewarped so `f0` lands exactly: [`crate::numeric::bilinear`] with
/// `c = 1 / tan(π f0 / fs)` ([`warped`](crate::numeric::bilinear::warped)), the
/// prewarping constant of `s / (2π f0)`.
fn bilinear(
    b: [f64; 3],
    a: [f64; 3],
    f0: f64,
    rate: SampleRate,
) -> Result<Biquad, CompensationError> {
    let c = 1.0 / crate::numeric::bilinear::warped(Hz(f0), rate);
    Biquad::from_row(crate::numeric::bilinear(b, a, c))
        .ok_or_else(|| invalid("frequency", f0, "0 < f < Nyquist"))
}

impl SimulatedTile {
    /// A tile at `rate`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] for a frequency not strictly between 0 and
    /// Nyquist, a non-positive or non-finite Q or gain, or a non-finite noise level.
    pub fn new(cfg: &TileConfig, rate: SampleRate) -> Result<Self, CompensationError> {
        let nyq = rate.nyquist().0;
        let freq_ok = |f: Hz| f.0.is_finite() && f.0 > 0.0 && f.0 < nyq;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let mut sections = Vec::with_capacity(cfg.modes.len() + 3);
        for m in &cfg.modes {
            if !freq_ok(m.freq) {
                return Err(invalid("mode.freq", m.freq.0, "0 < f < Nyquist"));
            }
            if !pos(m.q) {
                return Err(invalid("mode.q", m.q, "finite, > 0"));
            }
            if !m.gain.0.is_finite() {
                return Err(invalid("mode.gain", m.gain.0, "finite dB"));
            }
            // Peak gain A^2 at the centre: the zeros' damping is A^2 times the poles'.
            let a = 10f64.powf(m.gain.0 / 40.0);
            sections.push(bilinear(
                [1.0, a / m.q, 1.0],
                [1.0, 1.0 / (a * m.q), 1.0],
                m.freq.0,
                rate,
            )?);
        }
        if !freq_ok(cfg.suspension) {
            return Err(invalid("suspension", cfg.suspension.0, "0 < f < Nyquist"));
        }
        if !pos(cfg.suspension_q) {
            return Err(invalid("suspension_q", cfg.suspension_q, "finite, > 0"));
        }
        sections.push(bilinear(
            [1.0, 0.0, 1.0],
            [1.0, 1.0 / cfg.suspension_q, 1.0],
            cfg.suspension.0,
            rate,
        )?);
        if !freq_ok(cfg.highpass) {
            return Err(invalid("highpass", cfg.highpass.0, "0 < f < Nyquist"));
        }
        // The actuator's roll-offs are the crate's own Butterworth designs.
        let highpass = butterworth::highpass(2, cfg.highpass, rate)
            .map_err(|_| invalid("highpass", cfg.highpass.0, "0 < f < Nyquist"))?;
        sections.extend(highpass.sections);
        if !freq_ok(cfg.lowpass) {
            return Err(invalid("lowpass", cfg.lowpass.0, "0 < f < Nyquist"));
        }
        let lowpass = butterworth::lowpass(2, cfg.lowpass, rate)
            .map_err(|_| invalid("lowpass", cfg.lowpass.0, "0 < f < Nyquist"))?;
        sections.extend(lowpass.sections);
        if !pos(cfg.gain) {
            return Err(invalid("gain", cfg.gain, "finite, > 0"));
        }
        if let Some(n) = cfg.noise {
            if !n.0.is_finite() {
                return Err(invalid("noise", n.0, "finite dB"));
            }
        }
        let sos = Sos::new(sections);
        let state = vec![[0.0; 2]; sos.sections.len()];
        Ok(Self {
            rate,
            sos,
            gain: cfg.gain,
            noise: cfg.noise,
            rng: SplitMix64::new(cfg.seed),
            state,
        })
    }

    /// The sections of the noiseless device, gain excluded.
    #[must_use]
    pub fn sos(&self) -> &Sos {
        &self.sos
    }

    /// The noiseless response at `f`, as the oracle for measurements.
    #[must_use]
    pub fn true_response(&self, f: Hz) -> Complex64 {
        self.sos.response(self.rate.omega(f)) * self.gain
    }

    /// Returns the filters to rest; the noise stream runs on.
    pub fn reset(&mut self) {
        self.state.fill([0.0; 2]);
    }

    /// Runs `input` through the tile, continuing from the previous call's state, and adds
    /// the sensor noise.
    pub fn process(&mut self, input: &[f64]) -> Vec<f64> {
        let mut out: Vec<f64> = input.iter().map(|v| v * self.gain).collect();
        self.sos.filter_with_state(&mut out, &mut self.state);
        if let Some(level) = self.noise {
            if !out.is_empty() {
                let rms = (out.iter().map(|v| v * v).sum::<f64>() / out.len() as f64).sqrt();
                let sigma = rms * level.to_amplitude();
                for v in &mut out {
                    *v += sigma * self.rng.normal();
                }
            }
        }
        out
    }
}

impl Device for SimulatedTile {
    /// Plays from rest.
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        self.reset();
        Ok(self.process(excitation))
    }
}

/// `y` at `f`, linear between the points `(ln x, y)`, held constant past the ends; `x`
/// ascending and positive, in Hz.
pub(crate) fn interpolate_log(x: &[f64], y: &[f64], f: Hz) -> f64 {
    let i = x.partition_point(|&v| v < f.0);
    if i == 0 {
        return y[0];
    }
    if i >= x.len() {
        return y[y.len() - 1];
    }
    let (x0, x1) = (x[i - 1].ln(), x[i].ln());
    let t = if x1 > x0 {
        (f.0.ln() - x0) / (x1 - x0)
    } else {
        0.0
    };
    y[i - 1] + t * (y[i] - y[i - 1])
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
        let mut designer = super::fir::MinPhaseDesigner::new(Self::TAPS, 0)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: SampleRate = SampleRate(48_000);

    struct Wire;
    impl Device for Wire {
        fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
            Ok(excitation.to_vec())
        }
    }

    /// Largest magnitude error (dB) and phase error (degrees) against the tile's oracle.
    fn errors(tile: &SimulatedTile, fr: &FrequencyResponse) -> (f64, f64, f64) {
        let mut max_db = 0.0f64;
        let mut max_deg = 0.0f64;
        let mut sq = 0.0;
        for (f, h) in fr.freqs.iter().zip(&fr.response) {
            let t = tile.true_response(*f);
            let db = 20.0 * (h.norm() / t.norm()).log10();
            let deg = (h / t).arg().to_degrees();
            max_db = max_db.max(db.abs());
            max_deg = max_deg.max(deg.abs());
            sq += db * db;
        }
        (max_db, max_deg, (sq / fr.freqs.len() as f64).sqrt())
    }

    fn tile(noise: Option<Decibels>, seed: u64) -> SimulatedTile {
        let cfg = TileConfig {
            noise,
            seed,
            ..TileConfig::default()
        };
        SimulatedTile::new(&cfg, RATE).unwrap()
    }

    #[test]
    fn a_replayed_measurement_has_the_measured_magnitude() {
        let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
        let mut device = tile(Some(Decibels(-40.0)), 3);
        let measured = measure(&mut device, &sweep).unwrap();
        let mut replay = MeasuredDevice::new(&measured, RATE).unwrap();
        let again = measure(&mut replay, &sweep).unwrap();
        for (a, b) in again.magnitude_db().iter().zip(measured.magnitude_db()) {
            assert!((a.0 - b.0).abs() < 0.2, "{} vs {}", a.0, b.0);
        }
    }

    #[test]
    fn noiseless_tile_matches_oracle() {
        let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
        let mut t = tile(None, 1);
        let fr = measure(&mut t, &sweep).unwrap();
        let (db, deg, rms) = errors(&t, &fr);
        eprintln!("noiseless: max {db:.2e} dB, max {deg:.2e} deg, rms {rms:.2e} dB");
        assert_eq!(fr.freqs.len(), 128);
        assert!(db < 0.1, "{db} dB");
        assert!(deg < 2.0, "{deg} deg");
    }

    #[test]
    fn noisy_tile_and_averaging() {
        let mut one = SweepConfig::new(RATE);
        one.repeats = 1;
        let sweep1 = Sweep::new(one).unwrap();
        let sweep3 = Sweep::new(SweepConfig::new(RATE)).unwrap();
        let mut rms1 = 0.0;
        let mut rms3 = 0.0;
        let seeds = 4;
        for seed in 0..seeds {
            let mut t = tile(Some(Decibels(-40.0)), seed);
            let fr1 = measure(&mut t, &sweep1).unwrap();
            let (db1, _, r1) = errors(&t, &fr1);
            let fr3 = measure(&mut t, &sweep3).unwrap();
            let (db3, _, r3) = errors(&t, &fr3);
            eprintln!(
                "-40 dB noise, seed {seed}: 1 repeat max {db1:.3} rms {r1:.4}; 3 repeats max {db3:.3} rms {r3:.4} dB"
            );
            assert!(db3 < 0.5 && db1 < 0.5, "{db1} {db3}");
            rms1 += r1 / seeds as f64;
            rms3 += r3 / seeds as f64;
        }
        eprintln!("mean rms error: 1 repeat {rms1:.4} dB, 3 repeats {rms3:.4} dB");
        assert!(rms3 < 0.8 * rms1, "{rms3} vs {rms1}");
    }

    #[test]
    fn flatness() {
        let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
        let flat = measure(&mut Wire, &sweep).unwrap();
        let dev = flat.deviation_from_flat_db().0;
        let level = flat.magnitude_db()[0].0;
        eprintln!("wire: deviation {dev:.2e} dB, level {level:.2e} dB");
        assert!(dev < 0.05, "{dev}");
        assert!(level.abs() < 0.05);
        let mut t = tile(None, 0);
        let dev_tile = measure(&mut t, &sweep).unwrap().deviation_from_flat_db().0;
        eprintln!("tile: deviation {dev_tile:.2} dB");
        assert!(dev_tile > 2.0, "{dev_tile}");
    }

    #[test]
    fn bad_recordings_are_errors() {
        let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
        let n = sweep.excitation().len();
        assert!(matches!(
            sweep.response(&[]),
            Err(CompensationError::TooShort { len: 0, .. })
        ));
        assert!(matches!(
            sweep.response(&vec![0.0; n - 1]),
            Err(CompensationError::TooShort { .. })
        ));
        let mut rec = sweep.excitation().to_vec();
        rec[1234] = f64::NAN;
        assert_eq!(
            sweep.response(&rec),
            Err(CompensationError::NonFinite {
                what: "recording",
                index: 1234
            })
        );
        rec[1234] = f64::INFINITY;
        assert!(sweep.response(&rec).is_err());
        // Longer is fine; silence gives a zero response, not a panic.
        let fr = sweep.response(&vec![0.0; n + 100]).unwrap();
        assert!(fr.response.iter().all(|h| h.norm() == 0.0));
        assert!(fr.deviation_from_flat_db().0.is_finite());
    }

    #[test]
    fn bad_configs_are_errors() {
        let ok = SweepConfig::new(RATE);
        let bad = [
            SweepConfig {
                rate: SampleRate(0),
                ..ok
            },
            SweepConfig {
                band: Band::new(0.0, 1024.0),
                ..ok
            },
            SweepConfig {
                band: Band::new(500.0, 100.0),
                ..ok
            },
            SweepConfig {
                band: Band::new(40.0, 23_000.0),
                ..ok
            },
            SweepConfig {
                band: Band::new(f64::NAN, 1024.0),
                ..ok
            },
            SweepConfig {
                duration: Seconds(0.0),
                ..ok
            },
            SweepConfig {
                duration: Seconds(0.05),
                ..ok
            },
            SweepConfig {
                duration: Seconds(f64::INFINITY),
                ..ok
            },
            SweepConfig {
                fade: Seconds(1.5),
                ..ok
            },
            SweepConfig {
                fade: Seconds(-0.1),
                ..ok
            },
            SweepConfig { repeats: 0, ..ok },
            SweepConfig {
                gap: Seconds(0.1),
                ..ok
            },
            SweepConfig {
                window: Seconds(0.0),
                ..ok
            },
            SweepConfig {
                level: Decibels(3.0),
                ..ok
            },
            SweepConfig { points: 1, ..ok },
        ];
        for cfg in bad {
            assert!(
                matches!(
                    Sweep::new(cfg),
                    Err(CompensationError::InvalidParameter { .. })
                ),
                "{cfg:?}"
            );
        }
        let tc = TileConfig::default();
        for t in [
            TileConfig {
                highpass: Hz(0.0),
                ..tc.clone()
            },
            TileConfig {
                lowpass: Hz(30_000.0),
                ..tc.clone()
            },
            TileConfig {
                gain: f64::NAN,
                ..tc.clone()
            },
            TileConfig {
                suspension_q: 0.0,
                ..tc.clone()
            },
            TileConfig {
                noise: Some(Decibels(f64::NAN)),
                ..tc.clone()
            },
        ] {
            assert!(SimulatedTile::new(&t, RATE).is_err());
        }
    }

    #[test]
    fn excitation_layout() {
        let cfg = SweepConfig::new(RATE);
        let sweep = Sweep::new(cfg).unwrap();
        let n = RATE.samples_in(cfg.duration);
        let g = RATE.samples_in(cfg.gap);
        assert_eq!(sweep.excitation().len(), 3 * (n + g));
        assert!(sweep.excitation()[n..n + g].iter().all(|&v| v == 0.0));
        let peak = sweep.single().iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((peak - cfg.level.to_amplitude()).abs() < 1e-3);
        assert_eq!(sweep.single()[0], 0.0);
    }
}
