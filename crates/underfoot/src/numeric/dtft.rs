//! The discrete-time Fourier transform of a finite sequence at one frequency,
//! `$X(\omega) = \sum_n x_n e^{-j\omega n}$`.
//!
//! The phasor `$e^{-j\omega n}$` is advanced by one complex multiplication per sample
//! instead of a sine and a cosine, and recomputed from `$\omega n$` every 1024 samples so
//! its round-off does not grow with the length.

use num_complex::Complex64;

/// `Σ x[n] e^{-jωn}`, `omega` in radians per sample.
#[must_use]
pub fn dtft(x: &[f64], omega: f64) -> Complex64 {
    let step = Complex64::from_polar(1.0, -omega);
    let mut phasor = Complex64::new(1.0, 0.0);
    let mut sum = Complex64::new(0.0, 0.0);
    for (n, &v) in x.iter().enumerate() {
        sum += phasor * v;
        phasor *= step;
        if n % 1024 == 1023 {
            phasor = Complex64::from_polar(1.0, -omega * (n + 1) as f64);
        }
    }
    sum
}

/// Samples per block of [`dtft_many`]: Goertzel's round-off grows with the square of the
/// length it runs over, so it restarts at each block.
const BLOCK: usize = 1024;

/// Frequencies run together, their recursions' state held in registers.
const LANES: usize = 16;

/// [`dtft`] at every frequency of `omegas` at once, by Goertzel's recursion in blocks.
///
/// Within a block of `$L$` samples starting at `$b$`, the real recursion
/// `$s_n = x_{b+n} + 2\cos\omega\, s_{n-1} - s_{n-2}$` costs one multiply-add per sample
/// and frequency (a quarter of a rotating phasor's work), 16 frequencies together
/// in registers; it ends with
/// `$y = s_{L-1} - e^{-j\omega} s_{L-2} = \sum_{n<L} x_{b+n} e^{j\omega(L-1-n)}$`, so the
/// block adds `$e^{-j\omega(b+L-1)}\, y$` to the sum, its phase computed afresh from
/// `$\omega(b+L-1)$`. Goertzel's round-off grows as the square of the length near
/// `$\omega = 0$`; restarting every 1024 samples bounds it, at one sine and cosine
/// per block and frequency. The same sums as one [`dtft`] per frequency, to round-off.
#[must_use]
pub fn dtft_many(x: &[f64], omegas: &[f64]) -> Vec<Complex64> {
    let k = omegas.len();
    let two_cos: Vec<f64> = omegas.iter().map(|w| 2.0 * w.cos()).collect();
    let back: Vec<Complex64> = omegas
        .iter()
        .map(|w| Complex64::from_polar(1.0, -w))
        .collect();
    let mut sum = vec![Complex64::new(0.0, 0.0); k];
    for (block, chunk) in x.chunks(BLOCK).enumerate() {
        let last = (block * BLOCK + chunk.len() - 1) as f64;
        for start in (0..k).step_by(LANES) {
            let n = LANES.min(k - start);
            let mut c = [0.0; LANES];
            c[..n].copy_from_slice(&two_cos[start..start + n]);
            let (mut s1, mut s2) = ([0.0; LANES], [0.0; LANES]);
            for &v in chunk {
                for l in 0..LANES {
                    let s = v + c[l] * s1[l] - s2[l];
                    s2[l] = s1[l];
                    s1[l] = s;
                }
            }
            for l in 0..n {
                let i = start + l;
                // y = s1 - e^{-jω} s2, turned back by e^{-jω·last}.
                let y = s1[l] - back[i] * s2[l];
                sum[i] += y * Complex64::from_polar(1.0, -omegas[i] * last);
            }
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn many_frequencies_at_once_are_each_one_s_dtft() {
        let x: Vec<f64> = (0..20_000)
            .map(|n| 0.9997f64.powi(n) * (0.37 * f64::from(n)).sin() + 0.3 * 0.999f64.powi(n))
            .collect();
        // From near 0 (Goertzel's worst) to near π, and the edges of the export's bands
        // (20 Hz and 900 Hz at 48 kHz).
        let mut omegas: Vec<f64> = (0..37).map(|i| 0.001 + 0.085 * f64::from(i)).collect();
        omegas.extend([
            0.0,
            1e-5,
            2.0 * std::f64::consts::PI * 20.0 / 48_000.0,
            0.1178,
            3.1,
        ]);
        for (w, got) in omegas.iter().zip(dtft_many(&x, &omegas)) {
            let want = dtft(&x, *w);
            assert!(
                (got - want).norm() <= 1e-10 * want.norm().max(1.0),
                "{w}: {got} vs {want}"
            );
        }
        assert!(dtft_many(&[], &omegas).iter().all(|c| c.norm() == 0.0));
    }

    #[test]
    fn matches_the_definition_over_long_sequences() {
        let x: Vec<f64> = (0..10_000)
            .map(|n| ((n * 7919) % 113) as f64 / 56.0 - 1.0)
            .collect();
        for omega in [0.0, 0.001, 1.0, 3.0, std::f64::consts::PI] {
            let naive: Complex64 = x
                .iter()
                .enumerate()
                .map(|(n, &v)| v * Complex64::from_polar(1.0, -omega * n as f64))
                .sum();
            let fast = dtft(&x, omega);
            assert!(
                (fast - naive).norm() < 1e-9 * naive.norm().max(1.0),
                "{omega}"
            );
        }
    }

    #[test]
    fn dtft_of_a_decaying_exponential_is_its_closed_form() {
        let x: Vec<f64> = (0..5000).map(|n| 0.99f64.powi(n)).collect();
        for w in [0.01, 0.5, 3.0] {
            let exact = 1.0 / (Complex64::new(1.0, 0.0) - Complex64::from_polar(0.99, -w));
            assert!((dtft(&x, w) - exact).norm() < 1e-9 * exact.norm());
        }
    }
}
