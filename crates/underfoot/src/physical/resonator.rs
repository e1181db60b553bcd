//! A surface as a bank of damped modes, discretised by impulse invariance.
//!
//! # The continuous model
//!
//! Struck at one point, a linear surface moves there as a sum of independent modes. Mode
//! `k` is a damped oscillator of modal mass `m_k`; a force impulse of `J` newton-seconds
//! at `t = 0` sets its velocity to `J / m_k` and leaves it ringing as
//!
//! $$ y_k(t) = g_k\, J\, e^{-t/\tau_k} \sin(2\pi f_k t), \qquad g_k = \frac{1}{2\pi f_k m_k}, $$
//!
//! a damped sine: it starts from rest at zero displacement, which is why the impulse
//! response of a mode to a force is a sine and not a cosine. `f_k` is the frequency one
//! observes (the damped one), `τ_k` the time for the envelope to fall by `e`, and the gain
//! `g_k` (metres per newton-second) the mode's share of the point's mobility. Writing
//! `s_k = -1/τ_k + i 2π f_k`, the displacement is `Im(g_k e^{s_k t})` and the velocity
//! is its derivative `Im(g_k s_k e^{s_k t})`.
//!
//! # Impulse invariance
//!
//! Sampling `y_k` at `t = n / f_s` gives, with the pole
//! `p_k = e^{s_k / f_s} = e^{-1/(τ_k f_s)} e^{i 2π f_k / f_s}`,
//!
//! $$ h\[n\] = \sum_k g_k \operatorname{Im} p_k^n , $$
//!
//! so the sampled response passes through the continuous one at every sample: each mode's
//! frequency and decay are exact at any rate, not warped as a bilinear transform would
//! warp them. Each sample of input is taken as the impulse `J\[n\]` (N·s) delivered during
//! that sample, at its start. One complex one-pole per mode runs it:
//!
//! $$ z_k\[n+1\] = p_k \left(z_k\[n\] + J\[n\]\right), \qquad
//!    y\[n\] = \sum_k g_k \operatorname{Im} z_k\[n\], \qquad
//!    \dot y\[n\] = \sum_k \operatorname{Im}\left(g_k s_k z_k\[n\]\right). $$
//!
//! `h\[0\] = 0`: an impulse moves the surface only from the next sample on, so a contact
//! force computed from the surface's position is never in a delay-free loop with it.
//! The velocity is the exact derivative of the continuous response between impulses.
//!
//! # Second-order sections
//!
//! Mode `k` alone is the section `g_k r_k \sin θ_k z^{-1} / (1 - 2 r_k \cos θ_k z^{-1} + r_k^2 z^{-2})`
//! (`p_k = r_k e^{iθ_k}`). The bank is their sum; [`ResonatorBank::to_sos`] brings it
//! over a common denominator and factors the numerator, giving a cascade with the same
//! impulse response, for firmware and interchange. The poles are kept exactly as
//! computed; only the zeros come from a root finder, whose accuracy falls as the number
//! of modes grows (the numerator has degree `2K - 1`). For real-time use, the parallel
//! form here is both cheaper and exact.

use num_complex::Complex64;

use super::PhysicalError;
use crate::signal::{Biquad, Sos};
use crate::units::{Hz, SampleRate, Seconds};

/// One damped mode of a surface at the point struck.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// The (damped) frequency of the ringing.
    pub frequency: Hz,
    /// The time for the ringing's envelope to decay by a factor `e`.
    pub decay: Seconds,
    /// Displacement per unit impulse, in metres per newton-second: `1 / (2π f m)` for a
    /// mode of modal mass `m` at the point struck.
    pub gain: f64,
}

/// A bank of damped modes running in parallel, one complex one-pole each.
///
/// Allocates at construction only; [`tick`](Self::tick) and
/// [`process_in_place`](Self::process_in_place) never allocate.
#[derive(Debug, Clone, PartialEq)]
pub struct ResonatorBank {
    rate: SampleRate,
    modes: Vec<Mode>,
    pole: Vec<Complex64>,
    /// `g_k`, to read the displacement from the state.
    gain: Vec<f64>,
    /// `g_k p_k`: the displacement one sample ahead, from the state before the input.
    gain_pole: Vec<Complex64>,
    /// `g_k s_k`: the velocity, from the state.
    gain_slope: Vec<Complex64>,
    state: Vec<Complex64>,
    /// `h\[1\]`: the displacement one sample after a unit impulse.
    first_sample: f64,
}

impl ResonatorBank {
    /// A bank of `modes` running at `rate`, at rest.
    ///
    /// # Errors
    /// No modes, a zero rate, a frequency outside `(0, f_s/2)`, a decay time that is not
    /// positive and finite, or a gain that is not finite.
    pub fn new(modes: &[Mode], rate: SampleRate) -> Result<Self, PhysicalError> {
        if rate.0 == 0 {
            return Err(PhysicalError::ZeroRate);
        }
        if modes.is_empty() {
            return Err(PhysicalError::NoModes);
        }
        let fs = rate.hz();
        for (index, m) in modes.iter().enumerate() {
            let f = m.frequency.0;
            if !(f.is_finite() && f > 0.0 && f < rate.nyquist().0) {
                return Err(PhysicalError::FrequencyOutOfRange {
                    index,
                    frequency: m.frequency,
                    nyquist: rate.nyquist(),
                });
            }
            if !(m.decay.0.is_finite() && m.decay.0 > 0.0) {
                return Err(PhysicalError::BadDecay {
                    index,
                    decay: m.decay,
                });
            }
            if !m.gain.is_finite() {
                return Err(PhysicalError::BadGain {
                    index,
                    gain: m.gain,
                });
            }
        }
        let slope = |m: &Mode| Complex64::new(-1.0 / m.decay.0, rate.omega(m.frequency) * fs);
        let pole: Vec<Complex64> = modes.iter().map(|m| (slope(m) / fs).exp()).collect();
        let gain: Vec<f64> = modes.iter().map(|m| m.gain).collect();
        let gain_pole = pole.iter().zip(&gain).map(|(p, g)| p * g).collect();
        let gain_slope = modes.iter().map(|m| slope(m) * m.gain).collect();
        let first_sample = pole.iter().zip(&gain).map(|(p, g)| g * p.im).sum();
        Ok(Self {
            rate,
            modes: modes.to_vec(),
            pole,
            gain,
            gain_pole,
            gain_slope,
            state: vec![Complex64::new(0.0, 0.0); modes.len()],
            first_sample,
        })
    }

    /// The rate the bank runs at.
    #[must_use]
    pub fn rate(&self) -> SampleRate {
        self.rate
    }

    /// The modes, as given.
    #[must_use]
    pub fn modes(&self) -> &[Mode] {
        &self.modes
    }

    /// The discrete poles `p_k`, one per mode (the member of each conjugate pair with
    /// positive imaginary part).
    #[must_use]
    pub fn poles(&self) -> &[Complex64] {
        &self.pole
    }

    /// Brings the bank to rest.
    pub fn reset(&mut self) {
        self.state.fill(Complex64::new(0.0, 0.0));
    }

    /// The displacement `y\[n\]` now, before this sample's input.
    #[must_use]
    pub fn displacement(&self) -> f64 {
        self.state
            .iter()
            .zip(&self.gain)
            .map(|(z, g)| g * z.im)
            .sum()
    }

    /// The velocity `ẏ\[n\]` now, before this sample's input (metres per second when the
    /// gains are in metres per newton-second).
    #[must_use]
    pub fn velocity(&self) -> f64 {
        self.state
            .iter()
            .zip(&self.gain_slope)
            .map(|(z, gs)| gs.re * z.im + gs.im * z.re)
            .sum()
    }

    /// Returns the displacement `y\[n\]`, then takes the impulse `J\[n\]` (N·s) of this
    /// sample and advances by one sample.
    pub fn tick(&mut self, impulse: f64) -> f64 {
        let mut y = 0.0;
        for ((z, p), g) in self.state.iter_mut().zip(&self.pole).zip(&self.gain) {
            y += g * z.im;
            *z = p * (*z + impulse);
        }
        y
    }

    /// Runs a block: each sample of `buffer` is an impulse in, replaced by the
    /// displacement out (as [`tick`](Self::tick)).
    pub fn process_in_place(&mut self, buffer: &mut [f64]) {
        for v in buffer.iter_mut() {
            *v = self.tick(*v);
        }
    }

    /// The first `n` samples of the impulse response `h\[n\]`, from rest, leaving this
    /// bank's state untouched.
    #[must_use]
    pub fn impulse_response(&self, n: usize) -> Vec<f64> {
        let mut bank = self.clone();
        bank.reset();
        let mut x = vec![0.0; n];
        if let Some(first) = x.first_mut() {
            *first = 1.0;
        }
        bank.process_in_place(&mut x);
        x
    }

    /// The displacement the bank will have at the next sample if this sample's impulse is
    /// zero: `Σ Im(g_k p_k z_k\[n\])`.
    pub(crate) fn free_next_displacement(&self) -> f64 {
        self.state
            .iter()
            .zip(&self.gain_pole)
            .map(|(z, gp)| gp.re * z.im + gp.im * z.re)
            .sum()
    }

    /// `h\[1\]`: how much the next displacement moves per unit impulse now.
    pub(crate) fn first_sample_gain(&self) -> f64 {
        self.first_sample
    }

    /// The bank as a cascade of second-order sections with the same impulse response.
    ///
    /// # Errors
    /// [`PhysicalError::Factorisation`] when the numerator cannot be factored: its leading
    /// coefficient `h\[1\]` is zero (gains that cancel), or the root finder fails.
    pub fn to_sos(&self) -> Result<Sos, PhysicalError> {
        let denominators: Vec<[f64; 3]> = self
            .pole
            .iter()
            .map(|p| [1.0, -2.0 * p.re, p.norm_sqr()])
            .collect();
        // H(w) = w N(w) / Π A_j(w) with N(w) = Σ_k g_k Im(p_k) Π_{j≠k} A_j(w), w = z^-1.
        let mut numerator = vec![0.0; 2 * self.pole.len() - 1];
        for (k, (p, g)) in self.pole.iter().zip(&self.gain).enumerate() {
            let mut term = vec![g * p.im];
            for (j, a) in denominators.iter().enumerate() {
                if j != k {
                    term = crate::signal::sos::poly_mul(&term, a);
                }
            }
            for (n, t) in numerator.iter_mut().zip(&term) {
                *n += t;
            }
        }
        let lead = numerator[0];
        if lead == 0.0 || !lead.is_finite() {
            return Err(PhysicalError::Factorisation(
                "the first sample of the impulse response is zero",
            ));
        }
        let zeros = crate::fit::roots::roots(&numerator).ok_or(PhysicalError::Factorisation(
            "the root finder did not converge",
        ))?;
        let mut sections = crate::fit::roots::sections_from_roots(&zeros, &self.pole, lead);
        // The numerator has one degree fewer than the denominator: the z^-1 of h[0] = 0.
        // It goes into a section with a spare numerator degree.
        let spare = sections
            .iter_mut()
            .filter(|s| s.b[2] == 0.0)
            .min_by_key(|s| usize::from(s.b[1] != 0.0))
            .ok_or(PhysicalError::Factorisation(
                "no section can take the delay",
            ))?;
        *spare = Biquad {
            b: [0.0, spare.b[0], spare.b[1]],
            a: spare.a,
        };
        Ok(Sos::new(sections))
    }
}
