//! A streaming FIR filter, and the minimum-phase design that turns spectral weights into
//! one: the low-delay realisation of the equalizer.
//!
//! # Why minimum phase
//!
//! The uniform filter bank ([`FilterBank`](super::filterbank::FilterBank)) applies its
//! sub-band gains with a delay of `N - 1` samples, and the resolution the device's
//! resonances need (bins of about 10 Hz, `N = 4096` at 48 kHz) makes that 85 ms: far
//! above the one or two milliseconds between a heel strike and the vibration that users
//! expect. The low-delay filter-bank equalizer (Löllmann & Vary, the paper's reference
//! \[2\]) keeps the bank's weights but applies them with a time-domain filter. Of all
//! causal filters with a given magnitude response, the minimum-phase one concentrates its
//! energy earliest: it has no bulk delay, only the group delay the resonances it corrects
//! need. So the weights are realised as a minimum-phase FIR.
//!
//! # The design (homomorphic, via the real cepstrum)
//!
//! With `|W[k]|` the magnitude on the `M/2 + 1` bins of an `M`-point DFT:
//!
//! 1. the real cepstrum `c[n] = IDFT(ln |W[k]|)`, real and even;
//! 2. folding onto positive quefrency, `ĉ[0] = c[0]`, `ĉ[n] = 2c[n]` for `0 < n < M/2`,
//!    `ĉ[M/2] = c[M/2]`, zero after: the cepstrum of the minimum-phase filter with the
//!    same magnitude (its log-spectrum is analytic outside the unit circle);
//! 3. `H[k] = exp(DFT(ĉ)[k])` and `h = IDFT(H)`;
//! 4. `h` is kept for `L` taps, with a half-Hann fade over its last quarter so that the
//!    truncation does not ripple the response.
//!
//! The cepstrum is time-aliased by the `M`-point DFT, which is negligible when `M` is
//! several times the filter's decay; the designer uses `M ≥ 8L`. Truncation smooths the
//! response on a scale of `fs / L` (11.7 Hz for 4096 taps at 48 kHz); the iterative
//! equalizer measures through the realised filter, so what truncation misses at the
//! first pass, the next pass corrects.
//!
//! # Real time
//!
//! [`Fir::process`] and [`Fir::set_taps`] never allocate, lock or panic, nor does
//! [`MinPhaseDesigner::design`], whose FFT plans and buffers are made up front: a new
//! set of weights can be designed and swapped in on the audio thread. A tap change is
//! cross-faded over [`Fir::FADE`] samples (both filters run meanwhile), so it cannot
//! click. The history is stored twice over so that every output is one contiguous dot
//! product, which the compiler vectorises.

use std::f64::consts::PI;
use std::fmt;
use std::sync::Arc;

use num_complex::Complex;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};

use super::CompensationError;

/// A streaming FIR filter in `f32`, with cross-faded coefficient changes.
#[derive(Clone)]
pub struct Fir {
    /// Current taps, time-reversed so that the dot product runs over the history in order.
    reversed: Vec<f32>,
    /// Taps faded in, time-reversed; swapped with `reversed` when the fade completes.
    next: Vec<f32>,
    /// The last `L` inputs twice: `history[pos + 1 ..= pos + L]` is oldest to newest.
    history: Vec<f32>,
    pos: usize,
    /// Samples into the current fade, or `None`.
    fade: Option<usize>,
    non_finite: u64,
}

impl fmt::Debug for Fir {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Fir")
            .field("taps", &self.reversed.len())
            .field("fading", &self.fade.is_some())
            .field("non_finite", &self.non_finite)
            .finish_non_exhaustive()
    }
}

impl Fir {
    /// Length of the cross-fade of a tap change, in samples (10 ms at 48 kHz).
    pub const FADE: usize = 480;

    /// A filter with impulse response `taps`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] when `taps` is empty or holds a non-finite
    /// value.
    pub fn new(taps: &[f64]) -> Result<Self, CompensationError> {
        check_taps(taps)?;
        let len = taps.len();
        let reversed: Vec<f32> = taps.iter().rev().map(|&t| t as f32).collect();
        Ok(Self {
            next: reversed.clone(),
            reversed,
            history: vec![0.0; 2 * len],
            pos: 0,
            fade: None,
            non_finite: 0,
        })
    }

    /// Number of taps.
    #[must_use]
    pub fn len(&self) -> usize {
        self.reversed.len()
    }

    /// Whether the filter has no taps (never: [`Fir::new`] refuses that).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.reversed.is_empty()
    }

    /// The current impulse response (the one being faded in, during a fade).
    pub fn taps(&self) -> impl Iterator<Item = f32> + '_ {
        let source = if self.fade.is_some() {
            &self.next
        } else {
            &self.reversed
        };
        source.iter().rev().copied()
    }

    /// Starts a cross-fade to `taps`, over [`Fir::FADE`] samples. Taps beyond the filter's
    /// length are ignored and missing ones are zero; a non-finite tap makes the call a
    /// no-op (returns `false`). A change requested during a fade restarts it from the
    /// taps currently faded in. Real-time safe.
    pub fn set_taps(&mut self, taps: impl IntoIterator<Item = f64> + Clone) -> bool {
        if taps.clone().into_iter().any(|t| !t.is_finite()) {
            return false;
        }
        if self.fade.is_some() {
            std::mem::swap(&mut self.reversed, &mut self.next);
        }
        let len = self.next.len();
        self.next.fill(0.0);
        for (i, t) in taps.into_iter().take(len).enumerate() {
            self.next[len - 1 - i] = t as f32;
        }
        self.fade = Some(0);
        true
    }

    /// How many non-finite input samples were replaced by 0.
    #[must_use]
    pub fn non_finite_inputs(&self) -> u64 {
        self.non_finite
    }

    /// Forgets the signal; a fade in progress completes at once.
    pub fn reset(&mut self) {
        self.history.fill(0.0);
        self.pos = 0;
        if self.fade.take().is_some() {
            std::mem::swap(&mut self.reversed, &mut self.next);
        }
    }

    /// Filters `input` into `output`, over the shorter of the two. Streaming, so the
    /// result does not depend on the block size. Never allocates, locks or panics.
    pub fn process(&mut self, input: &[f32], output: &mut [f32]) {
        let len = self.reversed.len();
        for (&x, y) in input.iter().zip(output.iter_mut()) {
            let x = if x.is_finite() {
                x
            } else {
                self.non_finite += 1;
                0.0
            };
            self.history[self.pos] = x;
            self.history[self.pos + len] = x;
            let window = &self.history[self.pos + 1..=self.pos + len];
            // `window` ends with `x`, at `pos + len`; `pos + 1 + len - 1 = pos + len`.
            let current = dot(&self.reversed, window);
            *y = match self.fade {
                None => current,
                Some(n) => {
                    let t = (n + 1) as f32 / Self::FADE as f32;
                    let faded = dot(&self.next, window);
                    if n + 1 >= Self::FADE {
                        std::mem::swap(&mut self.reversed, &mut self.next);
                        self.fade = None;
                    } else {
                        self.fade = Some(n + 1);
                    }
                    current + t * (faded - current)
                }
            };
            self.pos = if self.pos + 1 == len { 0 } else { self.pos + 1 };
        }
    }
}

/// A dot product with eight partial sums, which the compiler turns into vector code.
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut sum: f32 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    for v in acc {
        sum += v;
    }
    sum
}

fn check_taps(taps: &[f64]) -> Result<(), CompensationError> {
    if taps.is_empty() {
        return Err(CompensationError::InvalidParameter {
            name: "taps",
            value: 0.0,
            expected: "at least one tap",
        });
    }
    if let Some(&bad) = taps.iter().find(|t| !t.is_finite()) {
        return Err(CompensationError::InvalidParameter {
            name: "taps",
            value: bad,
            expected: "finite coefficients",
        });
    }
    Ok(())
}

/// Designs minimum-phase FIR filters of a fixed length from magnitude responses; see the
/// [module documentation](self).
pub struct MinPhaseDesigner {
    taps: usize,
    /// The design DFT size `M`.
    size: usize,
    forward: Arc<dyn RealToComplex<f64>>,
    inverse: Arc<dyn ComplexToReal<f64>>,
    real: Vec<f64>,
    spectrum: Vec<Complex<f64>>,
    scratch_forward: Vec<Complex<f64>>,
    scratch_inverse: Vec<Complex<f64>>,
    fade: Vec<f64>,
}

impl fmt::Debug for MinPhaseDesigner {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MinPhaseDesigner")
            .field("taps", &self.taps)
            .field("size", &self.size)
            .finish_non_exhaustive()
    }
}

impl MinPhaseDesigner {
    /// A designer of `taps`-long filters, whose DFT has at least `min_size` points (the
    /// resolution of the magnitudes it will be given) and at least `8 · taps`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] when `taps` is 0 or above 2^20.
    pub fn new(taps: usize, min_size: usize) -> Result<Self, CompensationError> {
        if taps == 0 || taps > 1 << 20 {
            return Err(CompensationError::InvalidParameter {
                name: "taps",
                value: taps as f64,
                expected: "1 to 2^20",
            });
        }
        let size = (8 * taps).max(min_size).max(16).next_power_of_two();
        let mut planner = RealFftPlanner::<f64>::new();
        let forward = planner.plan_fft_forward(size);
        let inverse = planner.plan_fft_inverse(size);
        let quarter = (taps / 4).max(1);
        // Half-Hann from 1 down to (almost) 0 over the last quarter of the taps.
        let fade = (0..taps)
            .map(|i| {
                let from_end = taps - i;
                if from_end > quarter {
                    1.0
                } else {
                    let x = from_end as f64 / (quarter + 1) as f64;
                    (0.5 * PI * x).sin().powi(2)
                }
            })
            .collect();
        Ok(Self {
            taps,
            size,
            real: forward.make_input_vec(),
            spectrum: forward.make_output_vec(),
            scratch_forward: forward.make_scratch_vec(),
            scratch_inverse: inverse.make_scratch_vec(),
            forward,
            inverse,
            fade,
        })
    }

    /// The design DFT size `M`.
    #[must_use]
    pub fn size(&self) -> usize {
        self.size
    }

    /// The filter length.
    #[must_use]
    pub fn taps(&self) -> usize {
        self.taps
    }

    /// Designs the minimum-phase filter whose magnitude at normalised frequency
    /// `ν ∈ [0, 1/2]` (cycles per sample) is `10^(gain_db(ν)/20)`, into `out` (its first
    /// `taps` values; the rest is zeroed). Gains are floored at -200 dB. Never allocates;
    /// returns `false` (and leaves `out` alone) if the design is not finite.
    pub fn design(&mut self, mut gain_db: impl FnMut(f64) -> f64, out: &mut [f64]) -> bool {
        let m = self.size;
        let bins = m / 2 + 1;
        // 1. ln|W| on the bins, as a real spectrum.
        for (k, s) in self.spectrum.iter_mut().enumerate().take(bins) {
            let db = gain_db(k as f64 / m as f64).max(-200.0);
            *s = Complex::new(db * (std::f64::consts::LN_10 / 20.0), 0.0);
        }
        if self
            .inverse
            .process_with_scratch(
                &mut self.spectrum,
                &mut self.real,
                &mut self.scratch_inverse,
            )
            .is_err()
        {
            return false;
        }
        // 2. Fold onto positive quefrency (the 1/M of the inverse DFT included).
        let scale = 1.0 / m as f64;
        for (n, c) in self.real.iter_mut().enumerate() {
            *c *= scale
                * match n {
                    0 => 1.0,
                    n if n < m / 2 => 2.0,
                    n if n == m / 2 => 1.0,
                    _ => 0.0,
                };
        }
        // 3. exp of its spectrum, and back.
        if self
            .forward
            .process_with_scratch(
                &mut self.real,
                &mut self.spectrum,
                &mut self.scratch_forward,
            )
            .is_err()
        {
            return false;
        }
        for s in &mut self.spectrum {
            *s = s.exp();
        }
        self.spectrum[0].im = 0.0;
        self.spectrum[bins - 1].im = 0.0;
        if self
            .inverse
            .process_with_scratch(
                &mut self.spectrum,
                &mut self.real,
                &mut self.scratch_inverse,
            )
            .is_err()
        {
            return false;
        }
        // 4. Truncate with the fade.
        if self.real[..self.taps].iter().any(|v| !v.is_finite()) {
            return false;
        }
        for (o, (&h, &w)) in out.iter_mut().zip(self.real.iter().zip(&self.fade)) {
            *o = h * scale * w;
        }
        let used = self.taps.min(out.len());
        out[used..].fill(0.0);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64;

    fn response(taps: &[f64], nu: f64) -> Complex64 {
        taps.iter()
            .enumerate()
            .map(|(n, &h)| h * Complex64::from_polar(1.0, -2.0 * PI * nu * n as f64))
            .sum()
    }

    #[test]
    fn minimum_phase_design_follows_the_magnitude() {
        // A smooth bump: +6 dB around 0.05 cycles/sample, 0 dB elsewhere.
        let target = |nu: f64| 6.0 * (-((nu - 0.05) / 0.01).powi(2)).exp();
        let mut d = MinPhaseDesigner::new(512, 0).unwrap();
        let mut taps = vec![0.0; 512];
        assert!(d.design(target, &mut taps));
        for i in 1..50 {
            let nu = i as f64 * 0.005;
            let got = 20.0 * response(&taps, nu).norm().log10();
            assert!(
                (got - target(nu)).abs() < 0.05,
                "{nu}: {got} vs {}",
                target(nu)
            );
        }
        // Minimum phase: the energy comes first. Half of it within the first 2% of taps.
        let total: f64 = taps.iter().map(|t| t * t).sum();
        let early: f64 = taps[..10].iter().map(|t| t * t).sum();
        assert!(early > 0.5 * total, "{early} of {total}");
    }

    #[test]
    fn a_flat_magnitude_is_an_impulse() {
        let mut d = MinPhaseDesigner::new(64, 0).unwrap();
        let mut taps = vec![0.0; 64];
        assert!(d.design(|_| 0.0, &mut taps));
        assert!((taps[0] - 1.0).abs() < 1e-12);
        assert!(taps[1..].iter().all(|t| t.abs() < 1e-12));
    }

    #[test]
    fn fir_matches_direct_convolution_for_any_block_size() {
        let taps: Vec<f64> = (0..37)
            .map(|i| ((i * 7 % 11) as f64 - 5.0) / 10.0)
            .collect();
        let input: Vec<f32> = (0..700)
            .map(|i| ((i * 13 % 17) as f32 - 8.0) / 8.0)
            .collect();
        let direct: Vec<f32> = (0..input.len())
            .map(|n| {
                (0..taps.len())
                    .filter(|&j| j <= n)
                    .map(|j| taps[j] * f64::from(input[n - j]))
                    .sum::<f64>() as f32
            })
            .collect();
        for block in [1, 7, 64, 512] {
            let mut fir = Fir::new(&taps).unwrap();
            let mut out = vec![0.0f32; input.len()];
            for (x, y) in input.chunks(block).zip(out.chunks_mut(block)) {
                fir.process(x, y);
            }
            for (a, b) in out.iter().zip(&direct) {
                assert!((a - b).abs() < 1e-5, "block {block}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn tap_changes_cross_fade() {
        let mut fir = Fir::new(&[1.0]).unwrap();
        assert!(fir.set_taps([0.0]));
        let input = vec![1.0f32; Fir::FADE + 10];
        let mut out = vec![0.0f32; input.len()];
        fir.process(&input, &mut out);
        // Falls smoothly from 1 to 0 over the fade, then stays at 0.
        assert!(out.windows(2).all(|w| w[1] <= w[0]));
        assert!((out[Fir::FADE / 2] - 0.5).abs() < 0.01);
        assert!(out[Fir::FADE..].iter().all(|&v| v == 0.0));
        assert!(!fir.set_taps([f64::NAN]));
    }

    #[test]
    fn non_finite_input_is_zeroed_and_counted() {
        let mut fir = Fir::new(&[0.5, 0.5]).unwrap();
        let mut out = [0.0f32; 3];
        fir.process(&[f32::NAN, 1.0, f32::INFINITY], &mut out);
        assert_eq!(out, [0.0, 0.5, 0.5]);
        assert_eq!(fir.non_finite_inputs(), 2);
        assert!(Fir::new(&[]).is_err());
        assert!(Fir::new(&[f64::NAN]).is_err());
    }
}
