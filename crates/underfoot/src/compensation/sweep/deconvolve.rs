//! Deconvolution: the device's response from its recording of the programme.
//!
//! # Deconvolution
//!
//! Each repeat's period of the recording, `y`, is divided by the sweep in the frequency
//! domain, with Kirkeby regularisation:
//!
//! ```math
//! \hat H(f) = Y(f)\, \frac{X^*(f)}{|X(f)|^2 + \varepsilon(f)},
//! ```
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

use std::f64::consts::PI;

use num_complex::Complex64;
use underfoot_fft::RealFftPlanner;

use super::excitation::{GUARD_OCTAVES, Sweep, rise};
use super::response::FrequencyResponse;
use crate::compensation::CompensationError;
use crate::units::Seconds;

/// How far before time zero the impulse response is kept, in seconds.
pub const PRE_WINDOW: Seconds = Seconds(0.05);

/// Regularisation inside the band, relative to the peak of `|X|^2`.
const EPS_IN: f64 = 1e-10;
/// Regularisation outside the swept range, relative to the peak of `|X|^2`.
const EPS_OUT: f64 = 1.0;

/// The regularised inverse `X*/(|X|^2 + ε)` of `sweep` on the bins of an FFT of `n_fft`
/// samples at `fs`, for a sweep spanning `[f1, f2]`.
pub(super) fn regularised_inverse(
    sweep: &[f64],
    n_fft: usize,
    fs: f64,
    f1: f64,
    f2: f64,
) -> Vec<Complex64> {
    let x = spectrum(sweep, n_fft);
    let peak = x.iter().map(Complex64::norm_sqr).fold(0.0, f64::max);
    let bin_hz = fs / n_fft as f64;
    x.iter()
        .enumerate()
        .map(|(k, xk)| {
            let eps = peak * regularisation(k as f64 * bin_hz, f1, f2);
            xk.conj() / (xk.norm_sqr() + eps)
        })
        .collect()
}

impl Sweep {
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
pub(super) fn spectrum(x: &[f64], n: usize) -> Vec<Complex64> {
    let fwd = RealFftPlanner::<f64>::new().plan_fft_forward(n);
    let mut buf = vec![0.0; n];
    buf[..x.len()].copy_from_slice(x);
    let mut out = fwd.make_output_vec();
    let _ = fwd.process(&mut buf, &mut out);
    out
}
