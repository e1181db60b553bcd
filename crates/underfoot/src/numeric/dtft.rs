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

/// [`dtft`] at every frequency of `omegas` at once: the sequence is read once, and for
/// each sample the phasors of all frequencies advance together, in arrays the compiler
/// vectorises (real and imaginary parts apart), with the same renormalisation every 1024
/// samples. The same sums as one [`dtft`] per frequency, to round-off.
#[must_use]
pub fn dtft_many(x: &[f64], omegas: &[f64]) -> Vec<Complex64> {
    let k = omegas.len();
    let (step_re, step_im): (Vec<f64>, Vec<f64>) =
        omegas.iter().map(|w| (w.cos(), -w.sin())).unzip();
    let mut p_re = vec![1.0; k];
    let mut p_im = vec![0.0; k];
    let mut s_re = vec![0.0; k];
    let mut s_im = vec![0.0; k];
    for (block, chunk) in x.chunks(1024).enumerate() {
        if block > 0 {
            let n = (block * 1024) as f64;
            for ((pr, pi), w) in p_re.iter_mut().zip(&mut p_im).zip(omegas) {
                let (sin, cos) = (-w * n).sin_cos();
                (*pr, *pi) = (cos, sin);
            }
        }
        for &v in chunk {
            for i in 0..k {
                s_re[i] += p_re[i] * v;
                s_im[i] += p_im[i] * v;
                let re = p_re[i] * step_re[i] - p_im[i] * step_im[i];
                p_im[i] = p_re[i] * step_im[i] + p_im[i] * step_re[i];
                p_re[i] = re;
            }
        }
    }
    s_re.into_iter()
        .zip(s_im)
        .map(|(re, im)| Complex64::new(re, im))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn many_frequencies_at_once_are_each_one_s_dtft() {
        let x: Vec<f64> = (0..5000)
            .map(|n| 0.999f64.powi(n) * (0.37 * f64::from(n)).sin())
            .collect();
        let omegas: Vec<f64> = (0..37).map(|i| 0.001 + 0.085 * f64::from(i)).collect();
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
