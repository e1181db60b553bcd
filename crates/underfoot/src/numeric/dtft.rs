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

#[cfg(test)]
mod tests {
    use super::*;

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
