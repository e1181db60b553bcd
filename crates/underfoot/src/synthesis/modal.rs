//! A material filter as a sum of modes, and the same filter at another sample rate.
//!
//! # Modal (partial-fraction) form
//!
//! A fitted filter `H(z) = B(z^-1) / A(z^-1)` with `N` distinct poles `p_k` and a numerator
//! of degree at most `N` splits into
//!
//! ```math
//! H(z) = d + \sum_{k=1}^{N} \frac{r_k}{1 - p_k z^{-1}}, \qquad
//!   r_k = \frac{B(p_k^{-1})}{\prod_{j \ne k} (1 - p_j p_k^{-1})}, \qquad
//!   d = \frac{b_N}{a_N},
//! ```
//!
//! so its impulse response is `h[n] = d δ[n] + Σ r_k p_k^n`: one damped sinusoid per
//! conjugate pair, one damped exponential per real pole. Each mode is a physical resonance
//! of the ground-and-foot system, with a frequency and a decay time.
//!
//! # Changing the sample rate: impulse invariance
//!
//! Materials are fitted at a low analysis rate (2 kHz) and played at an audio rate
//! (48 kHz). A pole `p = e^{s T}` is the sampled form of a continuous mode `e^{s t}`;
//! sampling the same mode at the audio period `T'` gives `q = e^{s T'} = p^{T'/T}`. With
//! the residues kept, the audio-rate impulse response passes through every sample of the
//! analysis-rate one: `h'[m T/T'] = h[m]`. So a unit impulse at either rate gives the same
//! waveform at the same amplitude, which is how a step reproduces the recorded level, and
//! every mode keeps its frequency and decay exactly (Jackson, *Digital Filters and Signal
//! Processing*, impulse invariance). In spectral terms the audio-rate response is
//! `T/T'` times the analysis-rate one (24 for 2 kHz to 48 kHz), because the same
//! energy is spread over that many more samples.
//!
//! A negative real pole has no continuous counterpart below the analysis Nyquist
//! frequency; it is the sampled form of a mode at exactly that frequency, and maps to a
//! conjugate pair at it, each with half the residue (its samples at the analysis instants
//! are unchanged). The direct term `d` is one analysis-rate sample; it maps to one
//! audio-rate sample of `d T/T'`, which keeps its (flat) spectral level.
//!
//! Impulse invariance is exact for the waveform but not for the spectrum: the
//! analysis-rate response contains the aliases of every mode, the audio-rate one does not.
//! A fit at 2 kHz leans on those aliases (broad modes near the Nyquist frequency shape its
//! upper band), and the in-band response of the bare impulse-invariant filter can be off by
//! 10 dB or more there. So the poles are kept, being the physics, and the residues are
//! re-solved ([`ModalFilter::fit_residues`]): the response is linear in them, and a few
//! rounds of linear least squares on the magnitude (the phase taken from the previous
//! round) bring the built-in materials within 0.5 dB RMS of their models across the band,
//! except the two fits that lean hardest on those aliases: glass 0.72 dB and wood 1.26 dB
//! (`voice` tests it).

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

use crate::signal::Sos;
use crate::signal::sos::degree;
use crate::units::{Band, Hz, SampleRate, Seconds};

/// One mode of a [`ModalFilter`]: a pole and its residue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoleResidue {
    /// The pole. For a conjugate pair, the member with positive imaginary part.
    pub pole: Complex64,
    /// The residue at [`pole`](Self::pole).
    pub residue: Complex64,
    /// Whether the mode stands for a conjugate pair (its contribution is
    /// `2 Re(r p^n)`) rather than one real pole (`r p^n`).
    pub pair: bool,
}

impl PoleResidue {
    /// The mode's frequency in hertz at `rate`.
    #[must_use]
    pub fn frequency(&self, rate: SampleRate) -> f64 {
        self.pole.arg().abs() * rate.hz() / std::f64::consts::TAU
    }

    /// The time for the mode to decay by a factor `e` (infinite for a pole on the circle).
    #[must_use]
    pub fn decay(&self, rate: SampleRate) -> Seconds {
        Seconds(-1.0 / (rate.hz() * self.pole.norm().ln()))
    }
}

/// A filter in modal form: `d + Σ modes`.
#[derive(Debug, Clone, PartialEq)]
pub struct ModalFilter {
    /// The rate it runs at.
    pub rate: SampleRate,
    /// The modes.
    pub modes: Vec<PoleResidue>,
    /// The direct (feed-through) term `d`.
    pub direct: f64,
}

/// Why a filter has no modal form.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ModalError {
    /// The numerator's degree exceeds the number of poles (an FIR part longer than one sample).
    #[error("the numerator has degree {numerator} but the filter has only {poles} poles")]
    ImproperFilter {
        /// Degree of the numerator.
        numerator: usize,
        /// Number of poles.
        poles: usize,
    },
    /// Two poles coincide, so the partial fractions do not exist.
    #[error("poles {a} and {b} coincide; the filter has no modal form")]
    RepeatedPole {
        /// One pole.
        a: Complex64,
        /// The other.
        b: Complex64,
    },
    /// A pole lies on or outside the unit circle.
    #[error("pole {0} is not inside the unit circle")]
    Unstable(Complex64),
    /// The residues could not be solved for.
    #[error("cannot solve for the residues: {0}")]
    Unsolvable(&'static str),
}

/// Poles closer than this (relative) are treated as repeated: their residues would be
/// huge and of opposite sign, and their sum would be lost to rounding.
const REPEATED_POLE_TOLERANCE: f64 = 1e-9;

impl ModalFilter {
    /// The modal form of a cascade of second-order sections running at `rate`.
    ///
    /// # Errors
    /// An unstable filter, repeated poles, or a numerator of higher degree than the
    /// denominator.
    pub fn from_sos(sos: &Sos, rate: SampleRate) -> Result<Self, ModalError> {
        let mut poles = Vec::new();
        let mut numerator_degree = 0;
        for s in &sos.sections {
            numerator_degree += degree(&s.b);
            // A section's poles at the origin (a first-order section's padding) are delays,
            // not modes: only the non-zero roots of 1 + a1 w + a2 w^2 count.
            match degree(&s.a) {
                2 => poles.extend(s.poles()),
                1 => poles.push(Complex64::new(-s.a[1], 0.0)),
                _ => {}
            }
        }
        if numerator_degree > poles.len() {
            return Err(ModalError::ImproperFilter {
                numerator: numerator_degree,
                poles: poles.len(),
            });
        }
        if let Some(p) = poles.iter().find(|p| p.norm() >= 1.0 || !p.is_finite()) {
            return Err(ModalError::Unstable(*p));
        }
        for (i, a) in poles.iter().enumerate() {
            for b in &poles[i + 1..] {
                if (a - b).norm() <= REPEATED_POLE_TOLERANCE * a.norm().max(1e-3) {
                    return Err(ModalError::RepeatedPole { a: *a, b: *b });
                }
            }
        }

        // B(w) evaluated section by section, in w = z^-1: accurate at any order.
        let numerator = |w: Complex64| {
            sos.sections
                .iter()
                .fold(Complex64::new(1.0, 0.0), |acc, s| {
                    acc * (s.b[0] + s.b[1] * w + s.b[2] * w * w)
                })
        };
        let mut modes = Vec::new();
        for (k, &p) in poles.iter().enumerate() {
            let pair = p.im.abs() > 0.0;
            if pair && p.im < 0.0 {
                continue; // represented by its conjugate
            }
            let w = p.inv();
            let denom = poles
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != k)
                .fold(Complex64::new(1.0, 0.0), |acc, (_, &q)| acc * (1.0 - q * w));
            let residue = numerator(w) / denom;
            modes.push(PoleResidue {
                pole: p,
                residue: if pair {
                    residue
                } else {
                    Complex64::new(residue.re, 0.0)
                },
                pair,
            });
        }
        // The direct term is the limit of H as w -> infinity: the ratio of the leading
        // coefficients, zero when the numerator has lower degree.
        let direct = if numerator_degree == poles.len() {
            // The coefficient of the highest power (`a0 = 1` for a constant denominator).
            let lead = |c: &[f64; 3]| c[degree(c)];
            let b: f64 = sos.sections.iter().map(|s| lead(&s.b)).product();
            let a: f64 = sos.sections.iter().map(|s| lead(&s.a)).product();
            b / a
        } else {
            0.0
        };
        Ok(Self {
            rate,
            modes,
            direct,
        })
    }

    /// The same modes sampled at `rate` (impulse invariance; see the module docs).
    #[must_use]
    pub fn at_rate(&self, rate: SampleRate) -> Self {
        let ratio = self.rate.hz() / rate.hz();
        let mut modes = Vec::with_capacity(self.modes.len() + 1);
        for m in &self.modes {
            if !m.pair && m.pole.re < 0.0 {
                // A negative real pole: a mode at the Nyquist frequency of the old rate.
                let q =
                    Complex64::from_polar(m.pole.norm().powf(ratio), std::f64::consts::PI * ratio);
                modes.push(PoleResidue {
                    pole: q,
                    residue: m.residue * 0.5,
                    pair: true,
                });
            } else {
                let q = if m.pole.norm() == 0.0 {
                    m.pole
                } else {
                    (m.pole.ln() * ratio).exp()
                };
                modes.push(PoleResidue {
                    pole: if m.pair { q } else { Complex64::new(q.re, 0.0) },
                    residue: m.residue,
                    pair: m.pair,
                });
            }
        }
        Self {
            rate,
            modes,
            direct: self.direct / ratio,
        }
    }

    /// Re-solves the residues and direct term, poles fixed, so that the response matches
    /// `target` over `band` in relative (near-logarithmic) least squares.
    ///
    /// With the poles fixed the response is linear in the residues, so this is one linear
    /// solve (the residue step of vector fitting). It is what makes the rate change exact
    /// in the band: a fit at 2 kHz may lean on the aliases of broad modes near its Nyquist
    /// frequency, which impulse invariance does not carry over. The solution is pulled
    /// towards the current residues with weight `regularisation`, so that the response
    /// outside the band stays that of the impulse-invariant modes.
    ///
    /// # Errors
    /// [`ModalError::Unsolvable`] if the system is singular or the target is zero.
    pub fn fit_residues(
        &mut self,
        band: Band,
        target: &dyn Fn(Hz) -> Complex64,
        points: usize,
        regularisation: f64,
    ) -> Result<(), ModalError> {
        let columns = 1 + self
            .modes
            .iter()
            .map(|m| if m.pair { 2 } else { 1 })
            .sum::<usize>();
        let grid = band.log_grid(points.max(columns));
        let rows = 2 * grid.len() + columns;
        let mut a = DMatrix::<f64>::zeros(rows, columns);
        let mut rhs = DVector::<f64>::zeros(rows);
        for (g, f) in grid.iter().enumerate() {
            let t = target(*f);
            if !t.is_finite() || t.norm() == 0.0 {
                return Err(ModalError::Unsolvable("the target is zero or not finite"));
            }
            let weight = 1.0 / t.norm();
            let w = Complex64::from_polar(1.0, -self.rate.omega(*f));
            // Column entries: d(response)/d(parameter), each parameter real.
            let mut entries = Vec::with_capacity(columns);
            entries.push(Complex64::new(1.0, 0.0));
            for m in &self.modes {
                let e = 1.0 / (1.0 - m.pole * w);
                if m.pair {
                    let c = 1.0 / (1.0 - m.pole.conj() * w);
                    // r e + conj(r) c, with r = x + i y.
                    entries.push(e + c);
                    entries.push(Complex64::i() * (e - c));
                } else {
                    entries.push(e);
                }
            }
            for (j, e) in entries.iter().enumerate() {
                a[(2 * g, j)] = e.re * weight;
                a[(2 * g + 1, j)] = e.im * weight;
            }
            rhs[2 * g] = t.re * weight;
            rhs[2 * g + 1] = t.im * weight;
        }
        // Tikhonov rows pulling each parameter towards its current value, scaled by the
        // size of its column so that the pull is comparable across modes.
        let current = self.parameters();
        let base = 2 * grid.len();
        let lambda = regularisation.max(0.0).sqrt() * (grid.len() as f64).sqrt();
        for j in 0..columns {
            let norm = a.view((0, j), (base, 1)).norm() / (grid.len() as f64).sqrt();
            a[(base + j, j)] = lambda * norm;
            rhs[base + j] = lambda * norm * current[j];
        }
        let x = crate::numeric::solve_scaled(a, &rhs)
            .map_err(|_| ModalError::Unsolvable("the least-squares system is singular"))?;
        self.set_parameters(x.as_slice());
        Ok(())
    }

    fn parameters(&self) -> Vec<f64> {
        let mut p = vec![self.direct];
        for m in &self.modes {
            p.push(m.residue.re);
            if m.pair {
                p.push(m.residue.im);
            }
        }
        p
    }

    fn set_parameters(&mut self, p: &[f64]) {
        self.direct = p[0];
        let mut i = 1;
        for m in &mut self.modes {
            if m.pair {
                m.residue = Complex64::new(p[i], p[i + 1]);
                i += 2;
            } else {
                m.residue = Complex64::new(p[i], 0.0);
                i += 1;
            }
        }
    }

    /// Complex response at `omega` radians per sample.
    #[must_use]
    pub fn response(&self, omega: f64) -> Complex64 {
        let w = Complex64::from_polar(1.0, -omega);
        let mut h = Complex64::new(self.direct, 0.0);
        for m in &self.modes {
            h += m.residue / (1.0 - m.pole * w);
            if m.pair {
                h += m.residue.conj() / (1.0 - m.pole.conj() * w);
            }
        }
        h
    }

    /// The first `n` samples of the impulse response.
    #[must_use]
    pub fn impulse_response(&self, n: usize) -> Vec<f64> {
        let mut h = vec![0.0; n];
        if n > 0 {
            h[0] = self.direct;
        }
        for m in &self.modes {
            let mut pk = Complex64::new(1.0, 0.0);
            for v in h.iter_mut() {
                let term = m.residue * pk;
                *v += if m.pair { 2.0 * term.re } else { term.re };
                pk *= m.pole;
            }
        }
        h
    }

    /// Limits every mode's decay time to `longest`, moving poles inward along their ray.
    ///
    /// A fit can park a pole at the edge of the stable region (a mode that would ring for
    /// hours); under a foot, no ground rings that long, and the actuator must not either.
    /// Returns how many modes were changed.
    pub fn limit_decay(&mut self, longest: Seconds) -> usize {
        let max_radius = crate::fit::decay_radius(self.rate, longest);
        let mut changed = 0;
        for m in &mut self.modes {
            let r = m.pole.norm();
            if r > max_radius {
                m.pole *= max_radius / r;
                changed += 1;
            }
        }
        changed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::builtin::builtin;
    use crate::signal::Biquad;
    use crate::signal::sos::RootPair;

    fn resonant(rate: SampleRate) -> Sos {
        let pole = |f: f64, tau: f64| {
            Complex64::from_polar(
                (-1.0 / (tau * rate.hz())).exp(),
                rate.omega(crate::units::Hz(f)),
            )
        };
        Sos::new(vec![
            Biquad::from_roots(
                RootPair::Conjugate(Complex64::from_polar(0.9, 2.0)),
                RootPair::Conjugate(pole(60.0, 0.05)),
                0.3,
            ),
            Biquad::from_roots(
                RootPair::Real(0.5, -0.7),
                RootPair::Conjugate(pole(240.0, 0.02)),
                1.0,
            ),
            Biquad::from_roots(RootPair::Single(-0.2), RootPair::Single(-0.6), 0.8),
        ])
    }

    #[test]
    fn modal_form_has_the_same_response_and_impulse_response() {
        let rate = SampleRate(2000);
        let sos = resonant(rate);
        let modal = ModalFilter::from_sos(&sos, rate).unwrap();
        assert_eq!(modal.modes.len(), 3);
        for k in 0..200 {
            let omega = std::f64::consts::PI * k as f64 / 200.0;
            let (a, b) = (sos.response(omega), modal.response(omega));
            assert!(
                (a - b).norm() < 1e-9 * a.norm().max(1.0),
                "{omega}: {a} {b}"
            );
        }
        let mut x = vec![0.0; 400];
        x[0] = 1.0;
        sos.filter_in_place(&mut x);
        let h = modal.impulse_response(400);
        for (a, b) in x.iter().zip(&h) {
            assert!((a - b).abs() < 1e-9, "{a} {b}");
        }
    }

    #[test]
    fn impulse_invariance_keeps_the_waveform_at_shared_instants() {
        let slow = SampleRate(2000);
        let modal = ModalFilter::from_sos(&resonant(slow), slow).unwrap();
        let fast = modal.at_rate(SampleRate(48_000));
        // A negative real pole became a pair at 1 kHz: still three modes.
        assert_eq!(fast.modes.len(), 3);
        let h = modal.impulse_response(200);
        let g = fast.impulse_response(200 * 24);
        // Sample 0 holds the direct term, which is not a sampled waveform.
        for n in 1..200 {
            assert!(
                (h[n] - g[24 * n]).abs() < 1e-9,
                "{n}: {} {}",
                h[n],
                g[24 * n]
            );
        }
        for (m, f) in modal.modes.iter().zip(&fast.modes) {
            if m.pole.re > 0.0 {
                assert!((m.frequency(slow) - f.frequency(fast.rate)).abs() < 1e-9);
                assert!((m.decay(slow).0 - f.decay(fast.rate).0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn every_builtin_material_has_a_modal_form_that_matches_its_response() {
        for m in &builtin().materials {
            let sos = m.sos().unwrap();
            let modal = ModalFilter::from_sos(&sos, m.sample_rate).unwrap();
            for f in m.band_hz.log_grid(50) {
                let omega = m.sample_rate.omega(f);
                let (a, b) = (sos.response(omega), modal.response(omega));
                assert!((a - b).norm() < 1e-6 * a.norm(), "{}: {f}: {a} {b}", m.name);
            }
        }
    }

    #[test]
    fn decay_limit_moves_only_the_long_modes() {
        let rate = SampleRate(2000);
        let mut modal = ModalFilter::from_sos(&resonant(rate), rate).unwrap();
        let before = modal.clone();
        assert_eq!(modal.limit_decay(Seconds(0.03)), 1);
        assert!((modal.modes[0].decay(rate).0 - 0.03).abs() < 1e-9);
        assert_eq!(modal.modes[1], before.modes[1]);
    }
}
