//! Magnitude spectra of a planned real FFT.
//!
//! [`SpectrumPlan::magnitude`] writes `|X_k|`, `k = 0..=N/2`, of the unnormalised DFT
//!
//! ```math
//! X_k = \sum_{n=0}^{N-1} x_n\, e^{-2\pi j k n / N}
//! ```
//!
//! of `x` zero-padded to `N = n_fft`. Zero padding does not change the DTFT of a finite
//! signal, it samples it more finely: `X_k = X(e^{jω})` at `ω = 2πk/N`. No window and no
//! normalisation are applied; Parseval reads `Σ|x|² = (1/N) Σ_{k=0}^{N-1} |X_k|²`, the
//! bins `0 < k < N/2` counting twice in the one-sided half.

use std::fmt;
use std::sync::Arc;

use num_complex::Complex64;
use underfoot_fft::{RealFftPlanner, RealToComplex};

use crate::signal::SignalError;

/// A planned real FFT of one length with its buffers: plan once, then take as many
/// magnitude spectra as needed without allocating.
#[derive(Clone)]
pub struct SpectrumPlan {
    n_fft: usize,
    /// `None` for `n_fft == 0`, which has no transform to plan.
    fft: Option<Arc<dyn RealToComplex<f64>>>,
    input: Vec<f64>,
    output: Vec<Complex64>,
    scratch: Vec<Complex64>,
}

impl fmt::Debug for SpectrumPlan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SpectrumPlan")
            .field("n_fft", &self.n_fft)
            .finish_non_exhaustive()
    }
}

impl SpectrumPlan {
    /// A plan for FFTs of length `n_fft` (any length; fastest for products of small primes).
    #[must_use]
    pub fn new(n_fft: usize) -> Self {
        let fft = (n_fft > 0).then(|| RealFftPlanner::<f64>::new().plan_fft_forward(n_fft));
        let (input, output, scratch) = match &fft {
            Some(f) => (
                f.make_input_vec(),
                f.make_output_vec(),
                f.make_scratch_vec(),
            ),
            None => (Vec::new(), vec![Complex64::new(0.0, 0.0)], Vec::new()),
        };
        Self {
            n_fft,
            fft,
            input,
            output,
            scratch,
        }
    }

    /// The FFT length.
    #[must_use]
    pub fn n_fft(&self) -> usize {
        self.n_fft
    }

    /// The number of one-sided bins, `n_fft / 2 + 1`.
    #[must_use]
    pub fn bins(&self) -> usize {
        self.n_fft / 2 + 1
    }

    /// Writes `|X_k|` for `k = 0..=n_fft/2` into `out`, the unnormalised DFT of `x`
    /// zero-padded to `n_fft`.
    ///
    /// # Errors
    /// [`SignalError::TooLong`] if `x` is longer than `n_fft`;
    /// [`SignalError::WrongLength`] if `out` does not have `n_fft / 2 + 1` values.
    pub fn magnitude(&mut self, x: &[f64], out: &mut [f64]) -> Result<(), SignalError> {
        const WHAT: &str = "magnitude spectrum";
        if x.len() > self.n_fft {
            return Err(SignalError::TooLong {
                len: x.len(),
                max: self.n_fft,
                what: WHAT,
            });
        }
        if out.len() != self.bins() {
            return Err(SignalError::WrongLength {
                len: out.len(),
                expected: self.bins(),
                what: WHAT,
            });
        }
        if let Some(fft) = &self.fft {
            self.input[..x.len()].copy_from_slice(x);
            self.input[x.len()..].fill(0.0);
            // The buffers were made by this plan, so the lengths always agree.
            fft.process_with_scratch(&mut self.input, &mut self.output, &mut self.scratch)
                .map_err(|e| {
                    SignalError::InvalidParameter(format!("FFT of length {}: {e}", self.n_fft))
                })?;
        }
        for (o, c) in out.iter_mut().zip(&self.output) {
            *o = c.norm();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    use crate::signal::noise::SplitMix64;

    fn naive_dft_magnitude(x: &[f64], n_fft: usize) -> Vec<f64> {
        (0..=n_fft / 2)
            .map(|k| {
                let (mut re, mut im) = (0.0, 0.0);
                for (n, v) in x.iter().enumerate() {
                    // Reduce k n mod N first so the angle stays small and exact.
                    let ang = -2.0 * PI * ((k * n) % n_fft) as f64 / n_fft as f64;
                    re += v * ang.cos();
                    im += v * ang.sin();
                }
                re.hypot(im)
            })
            .collect()
    }

    #[test]
    fn magnitude_matches_naive_dft() {
        let mut rng = SplitMix64::new(42);
        for (len, n_fft) in [
            (1, 1),
            (5, 8),
            (64, 64),
            (100, 256),
            (333, 1000),
            (97, 97),
            (250, 1023),
        ] {
            let x: Vec<f64> = (0..len).map(|_| rng.symmetric()).collect();
            let mut plan = SpectrumPlan::new(n_fft);
            assert_eq!(plan.n_fft(), n_fft);
            let mut out = vec![0.0; n_fft / 2 + 1];
            plan.magnitude(&x, &mut out).unwrap();
            let want = naive_dft_magnitude(&x, n_fft);
            let scale = want.iter().fold(0.0f64, |m, v| m.max(*v));
            for (k, (g, w)) in out.iter().zip(&want).enumerate() {
                assert!(
                    (g - w).abs() <= 1e-9 * scale.max(1e-300),
                    "len={len} N={n_fft} k={k}: {g} vs {w}"
                );
            }
        }
    }

    #[test]
    fn parseval() {
        let mut rng = SplitMix64::new(9);
        for n_fft in [512, 1001] {
            let x: Vec<f64> = (0..400).map(|_| rng.symmetric()).collect();
            let mut plan = SpectrumPlan::new(n_fft);
            let mut out = vec![0.0; plan.bins()];
            plan.magnitude(&x, &mut out).unwrap();
            let energy: f64 = x.iter().map(|v| v * v).sum();
            // Bins strictly between DC and Nyquist stand for a pair of conjugate bins.
            let nyquist = if n_fft % 2 == 0 {
                n_fft / 2
            } else {
                usize::MAX
            };
            let spectral: f64 = out
                .iter()
                .enumerate()
                .map(|(k, m)| {
                    if k == 0 || k == nyquist {
                        m * m
                    } else {
                        2.0 * m * m
                    }
                })
                .sum::<f64>()
                / n_fft as f64;
            assert!(
                (energy - spectral).abs() < 1e-10 * energy,
                "{energy} vs {spectral}"
            );
        }
    }

    #[test]
    fn magnitude_rejects_bad_lengths_and_reuses_buffers() {
        let mut plan = SpectrumPlan::new(8);
        let mut out = vec![0.0; 5];
        assert!(matches!(
            plan.magnitude(&[0.0; 9], &mut out),
            Err(SignalError::TooLong { len: 9, max: 8, .. })
        ));
        assert!(matches!(
            plan.magnitude(&[0.0; 4], &mut [0.0; 4]),
            Err(SignalError::WrongLength {
                len: 4,
                expected: 5,
                ..
            })
        ));
        // A long signal then a short one: the padding must be zeroed again.
        plan.magnitude(&[1.0; 8], &mut out).unwrap();
        plan.magnitude(&[1.0], &mut out).unwrap();
        assert!(out.iter().all(|m| (m - 1.0).abs() < 1e-12));
        let mut empty = SpectrumPlan::new(0);
        let mut one = [5.0];
        empty.magnitude(&[], &mut one).unwrap();
        assert_eq!(one, [0.0]);
    }
}
