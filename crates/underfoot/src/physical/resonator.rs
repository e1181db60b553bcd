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
//! warp them. Each sample of input is taken as the impulse `J[n]` (N·s) delivered during
//! that sample, at its start. One complex one-pole per mode runs it:
//!
//! $$ z_k\[n+1\] = p_k \left(z_k\[n\] + J\[n\]\right), \qquad
//!    y\[n\] = \sum_k g_k \operatorname{Im} z_k\[n\], \qquad
//!    \dot y\[n\] = \sum_k \operatorname{Im}\left(g_k s_k z_k\[n\]\right). $$
//!
//! `h[0] = 0`: an impulse moves the surface only from the next sample on, so a contact
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
    /// `h[1]`: the displacement one sample after a unit impulse.
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

    /// The displacement `y[n]` now, before this sample's input.
    #[must_use]
    pub fn displacement(&self) -> f64 {
        self.state
            .iter()
            .zip(&self.gain)
            .map(|(z, g)| g * z.im)
            .sum()
    }

    /// The velocity `ẏ[n]` now, before this sample's input (metres per second when the
    /// gains are in metres per newton-second).
    #[must_use]
    pub fn velocity(&self) -> f64 {
        self.state
            .iter()
            .zip(&self.gain_slope)
            .map(|(z, gs)| gs.re * z.im + gs.im * z.re)
            .sum()
    }

    /// Returns the displacement `y[n]`, then takes the impulse `J[n]` (N·s) of this
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

    /// The first `n` samples of the impulse response `h[n]`, from rest, leaving this
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
    /// zero: `Σ Im(g_k p_k z_k[n])`.
    pub(crate) fn free_next_displacement(&self) -> f64 {
        self.state
            .iter()
            .zip(&self.gain_pole)
            .map(|(z, gp)| gp.re * z.im + gp.im * z.re)
            .sum()
    }

    /// `h[1]`: how much the next displacement moves per unit impulse now.
    pub(crate) fn first_sample_gain(&self) -> f64 {
        self.first_sample
    }

    /// The bank as a cascade of second-order sections with the same impulse response.
    ///
    /// # Errors
    /// [`PhysicalError::Factorisation`] when the numerator cannot be factored: its leading
    /// coefficient `h[1]` is zero (gains that cancel), or the root finder fails.
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    fn three_modes() -> [Mode; 3] {
        [
            Mode {
                frequency: Hz(60.0),
                decay: Seconds(0.2),
                gain: 1.0,
            },
            Mode {
                frequency: Hz(250.0),
                decay: Seconds(0.08),
                gain: 0.5,
            },
            Mode {
                frequency: Hz(1200.0),
                decay: Seconds(0.03),
                gain: 0.2,
            },
        ]
    }

    /// Prony's method: the modes of a sum of damped sinusoids from its samples alone, by
    /// the least-squares linear recursion `y[n] = -Σ a_i y[n-i]` and its roots.
    fn prony(y: &[f64], modes: usize, rate: SampleRate) -> Vec<(f64, f64)> {
        let order = 2 * modes;
        let rows = y.len() - order;
        let m = DMatrix::from_fn(rows, order, |r, c| y[r + order - 1 - c]);
        let rhs = DVector::from_fn(rows, |r, _| -y[r + order]);
        let a = m.svd(true, true).solve(&rhs, 1e-300).unwrap();
        let mut poly = vec![1.0];
        poly.extend(a.iter());
        let mut found: Vec<(f64, f64)> = crate::fit::roots::roots(&poly)
            .unwrap()
            .into_iter()
            .filter(|p| p.im > 0.0)
            .map(|p| {
                (
                    p.arg() * rate.hz() / std::f64::consts::TAU,
                    -1.0 / (rate.hz() * p.norm().ln()),
                )
            })
            .collect();
        found.sort_by(|a, b| a.0.total_cmp(&b.0));
        found
    }

    #[test]
    fn impulse_response_has_the_requested_frequencies_and_decays() {
        for rate in [SampleRate(48_000), SampleRate(8_000)] {
            let bank = ResonatorBank::new(&three_modes(), rate).unwrap();
            // Long enough for the slowest mode, short of the fastest one's underflow.
            let h = bank.impulse_response(rate.samples_in(Seconds(0.5)));
            let found = prony(&h, 3, rate);
            assert_eq!(found.len(), 3, "at {rate}");
            for (m, (f, tau)) in three_modes().iter().zip(&found) {
                let df = (f / m.frequency.0 - 1.0).abs();
                let dtau = (tau / m.decay.0 - 1.0).abs();
                eprintln!(
                    "{rate}: {} -> f err {df:.2e}, tau err {dtau:.2e}",
                    m.frequency
                );
                assert!(
                    df < 0.01 && dtau < 0.01,
                    "{rate}: {m:?} measured {f} Hz, {tau} s"
                );
            }
        }
    }

    #[test]
    fn one_mode_zero_crossings_and_log_envelope() {
        for rate in [SampleRate(48_000), SampleRate(8_000)] {
            for m in three_modes() {
                let bank = ResonatorBank::new(&[m], rate).unwrap();
                let h = bank.impulse_response(rate.samples_in(Seconds(4.0 * m.decay.0)));
                // Upward zero crossings, interpolated: one per period.
                let ups: Vec<f64> = (1..h.len())
                    .filter(|&n| h[n - 1] < 0.0 && h[n] >= 0.0)
                    .map(|n| (n - 1) as f64 + h[n - 1] / (h[n - 1] - h[n]))
                    .collect();
                let periods = (ups.len() - 1) as f64;
                let f = periods * rate.hz() / (ups[ups.len() - 1] - ups[0]);
                // Log-envelope: the RMS over each whole period falls as e^{-t/tau}; the
                // slope of its logarithm, by least squares, is -1/tau.
                let (mut t, mut l) = (Vec::new(), Vec::new());
                for w in ups.windows(2) {
                    let (a, b) = (w[0].ceil() as usize, w[1].ceil() as usize);
                    let ms: f64 = h[a..b].iter().map(|v| v * v).sum::<f64>() / (b - a) as f64;
                    t.push(0.5 * (w[0] + w[1]) / rate.hz());
                    l.push(0.5 * ms.ln());
                }
                let n = t.len() as f64;
                let (mt, ml) = (t.iter().sum::<f64>() / n, l.iter().sum::<f64>() / n);
                let slope = t
                    .iter()
                    .zip(&l)
                    .map(|(a, b)| (a - mt) * (b - ml))
                    .sum::<f64>()
                    / t.iter().map(|a| (a - mt).powi(2)).sum::<f64>();
                let tau = -1.0 / slope;
                let df = (f / m.frequency.0 - 1.0).abs();
                let dtau = (tau / m.decay.0 - 1.0).abs();
                eprintln!(
                    "{rate}: {} -> crossings f err {df:.2e}, envelope tau err {dtau:.2e}",
                    m.frequency
                );
                assert!(df < 0.01, "{rate}: {m:?} measured {f} Hz");
                assert!(dtau < 0.01, "{rate}: {m:?} measured {tau} s");
            }
        }
    }

    #[test]
    fn sections_give_the_same_impulse_response() {
        for rate in [SampleRate(48_000), SampleRate(8_000)] {
            let bank = ResonatorBank::new(&three_modes(), rate).unwrap();
            let sos = bank.to_sos().unwrap();
            assert!(sos.is_stable());
            assert_eq!(sos.sections.len(), 3);
            let n = rate.samples_in(Seconds(0.3));
            let a = bank.impulse_response(n);
            let b = sos.impulse_response(n);
            let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let err = a
                .iter()
                .zip(&b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            eprintln!("{rate}: sos max error {:.2e} of peak", err / peak);
            assert!(err < 1e-8 * peak, "{rate}: {err} against {peak}");
        }
    }

    #[test]
    fn tick_and_block_agree_and_velocity_is_the_derivative() {
        let rate = SampleRate(48_000);
        let mut a = ResonatorBank::new(&three_modes(), rate).unwrap();
        let mut b = a.clone();
        let mut x: Vec<f64> = (0..500).map(|n| ((n * 7919) % 13) as f64 - 6.0).collect();
        let ticked: Vec<f64> = x.iter().map(|&v| a.tick(v)).collect();
        for chunk in x.chunks_mut(37) {
            b.process_in_place(chunk);
        }
        assert_eq!(ticked, x);
        // After an impulse the bank rings freely: its velocity is the slope of its path.
        let mut c = ResonatorBank::new(&three_modes(), rate).unwrap();
        c.tick(1.0);
        for _ in 0..100 {
            c.tick(0.0);
        }
        let (y0, v0) = (c.displacement(), c.velocity());
        let y1 = c.tick(0.0);
        let _ = y1;
        let y2 = c.displacement();
        let slope = (y2 - y0) * rate.hz();
        assert!(
            (slope - v0).abs() < 0.02 * v0.abs().max(1e-3),
            "{slope} vs {v0}"
        );
    }

    #[test]
    fn bad_modes_are_errors() {
        let rate = SampleRate(8000);
        let good = three_modes()[0];
        let with = |f: f64, tau: f64, g: f64| {
            ResonatorBank::new(
                &[
                    good,
                    Mode {
                        frequency: Hz(f),
                        decay: Seconds(tau),
                        gain: g,
                    },
                ],
                rate,
            )
        };
        assert!(matches!(
            with(4000.0, 0.1, 1.0),
            Err(PhysicalError::FrequencyOutOfRange { index: 1, .. })
        ));
        assert!(matches!(
            with(0.0, 0.1, 1.0),
            Err(PhysicalError::FrequencyOutOfRange { .. })
        ));
        assert!(matches!(
            with(f64::NAN, 0.1, 1.0),
            Err(PhysicalError::FrequencyOutOfRange { .. })
        ));
        assert!(matches!(
            with(100.0, 0.0, 1.0),
            Err(PhysicalError::BadDecay { .. })
        ));
        assert!(matches!(
            with(100.0, f64::INFINITY, 1.0),
            Err(PhysicalError::BadDecay { .. })
        ));
        assert!(matches!(
            with(100.0, 0.1, f64::NAN),
            Err(PhysicalError::BadGain { .. })
        ));
        assert_eq!(ResonatorBank::new(&[], rate), Err(PhysicalError::NoModes));
        assert_eq!(
            ResonatorBank::new(&[good], SampleRate(0)),
            Err(PhysicalError::ZeroRate)
        );
    }
}
