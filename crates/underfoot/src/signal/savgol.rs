//! Savitzky-Golay smoothing: a moving least-squares polynomial fit.
//!
//! # Least squares
//!
//! For an odd window of `w = 2h + 1` samples and a polynomial order `p < w`, each output
//! sample is the value at the window centre of the degree-`p` polynomial that fits the
//! `w` samples around it in the least-squares sense. With the design matrix
//! `A_{ij} = φ_j(t_i)`, `t_i = i - h` (`i = 0..w`, `j = 0..=p`) the fitted coefficients
//! are `c = (AᵀA)⁻¹Aᵀ y = P y`, and the value at `t` is `φ(t)ᵀ P y`. The value at the
//! centre is linear in `y` and the same for every window position, so the interior is a
//! convolution with the kernel `k = φ(0)ᵀ P` (symmetric, since the points are).
//!
//! Choices where texts differ:
//!
//! * **Basis.** `φ_j(t) = T_j(t/h)`, Chebyshev polynomials of the scaled position, rather
//!   than monomials `t^j`: the span is the same (so is the fit), but the design matrix stays
//!   well conditioned for wide windows and high orders. `P = R⁻¹Qᵀ` from a thin QR
//!   factorisation of `A`, never from the normal equations.
//! * **Edges** follow scipy's default `mode = "interp"`: the first `h` outputs are the
//!   polynomial fitted to the first `w` samples, evaluated at `t = -h..-1`; the last `h` the
//!   polynomial fitted to the last `w` samples at `t = 1..=h`. No padding is invented.
//!
//! # Frequency response
//!
//! The interior is a symmetric FIR filter, so its response is real:
//! `H(ω) = k_0 + 2 Σ_{m=1}^{h} k_m cos(mω)` (index from the centre). It is exactly 1 at
//! `ω = 0` and flat there to order `p + 1` (`p + 2` for even `p`); the wider the window
//! the earlier it falls. [`SavitzkyGolay::widest_within`] finds the widest window that
//! keeps `|H|` within a given droop over the band of interest.

use nalgebra::DMatrix;

use super::SignalError;
use crate::units::{Decibels, Hz, SampleRate};

/// A Savitzky-Golay smoother for one window length and polynomial order.
#[derive(Debug, Clone, PartialEq)]
pub struct SavitzkyGolay {
    window: usize,
    polyorder: usize,
    /// The interior (0th-derivative) kernel, `window` taps.
    kernel: Vec<f64>,
    /// `P`, row-major `(polyorder + 1) × window`: samples of one window to basis coefficients.
    fit: Vec<f64>,
    /// `φ_j(t_i)` for the positions of one window, row-major `window × (polyorder + 1)`.
    basis: Vec<f64>,
}

impl SavitzkyGolay {
    /// The smoother fitting polynomials of order `polyorder` over `window` samples.
    ///
    /// # Errors
    /// [`SignalError::InvalidParameter`] if `window` is even or zero, or `polyorder >= window`.
    pub fn new(window: usize, polyorder: usize) -> Result<Self, SignalError> {
        if window.is_multiple_of(2) {
            return Err(SignalError::InvalidParameter(format!(
                "Savitzky-Golay window must be odd and positive, got {window}"
            )));
        }
        if polyorder >= window {
            return Err(SignalError::InvalidParameter(format!(
                "Savitzky-Golay polyorder {polyorder} must be less than the window {window}"
            )));
        }
        let h = window / 2;
        let cols = polyorder + 1;
        // Scale positions into [-1, 1]; a one-sample window has only t = 0.
        let scale = h.max(1) as f64;
        let mut basis = Vec::with_capacity(window * cols);
        for i in 0..window {
            basis.extend(chebyshev((i as f64 - h as f64) / scale, polyorder));
        }
        let a = DMatrix::from_row_slice(window, cols, &basis);
        let qr = a.qr();
        let pinv = qr
            .r()
            .solve_upper_triangular(&qr.q().transpose())
            .ok_or_else(|| {
                SignalError::InvalidParameter(format!(
                    "Savitzky-Golay fit of order {polyorder} over {window} samples is singular"
                ))
            })?;
        let mut fit = Vec::with_capacity(cols * window);
        for j in 0..cols {
            fit.extend((0..window).map(|i| pinv[(j, i)]));
        }
        let at_centre = &basis[h * cols..(h + 1) * cols];
        let kernel = (0..window)
            .map(|i| (0..cols).map(|j| at_centre[j] * fit[j * window + i]).sum())
            .collect();
        Ok(Self {
            window,
            polyorder,
            kernel,
            fit,
            basis,
        })
    }

    /// The window length in samples (odd).
    #[must_use]
    pub fn window(&self) -> usize {
        self.window
    }

    /// The order of the fitted polynomials.
    #[must_use]
    pub fn polyorder(&self) -> usize {
        self.polyorder
    }

    /// The interior smoothing kernel (`window` taps, symmetric, summing to 1).
    #[must_use]
    pub fn coefficients(&self) -> &[f64] {
        &self.kernel
    }

    /// The smoothed signal, same length as `x`: the kernel in the interior, the polynomial
    /// fitted to the first or last `window` samples at each end (scipy's `mode="interp"`).
    ///
    /// # Errors
    /// [`SignalError::TooShort`] if `x` is shorter than the window.
    pub fn apply(&self, x: &[f64]) -> Result<Vec<f64>, SignalError> {
        let (w, n) = (self.window, x.len());
        if n < w {
            return Err(SignalError::TooShort {
                len: n,
                needed: w,
                what: "Savitzky-Golay smoothing",
            });
        }
        let h = w / 2;
        let mut out = vec![0.0; n];
        for (o, frame) in out[h..n - h].iter_mut().zip(x.windows(w)) {
            *o = frame.iter().zip(&self.kernel).map(|(a, b)| a * b).sum();
        }
        let left = self.fit_coefficients(&x[..w]);
        for (i, o) in out[..h].iter_mut().enumerate() {
            *o = self.evaluate(i, &left);
        }
        let right = self.fit_coefficients(&x[n - w..]);
        for (i, o) in out[n - w + h + 1..].iter_mut().enumerate() {
            *o = self.evaluate(h + 1 + i, &right);
        }
        Ok(out)
    }

    /// The magnitude of the interior response at `omega` radians per sample.
    #[must_use]
    pub fn magnitude(&self, omega: f64) -> f64 {
        let h = self.window / 2;
        let centre = self.kernel[h];
        let sides: f64 = self.kernel[h + 1..]
            .iter()
            .enumerate()
            .map(|(m, k)| k * ((m + 1) as f64 * omega).cos())
            .sum();
        (centre + 2.0 * sides).abs()
    }

    /// The widest odd window (at most `max_window`) of polynomial order `polyorder` whose
    /// interior magnitude stays within `max_droop` of unity, `10^(-|droop|/20) <= |H| <=
    /// 10^(|droop|/20)`, for every frequency in `(0, top]` at `rate`.
    ///
    /// The band is checked on a grid of at least `max(256, 4 window)` frequencies, fine
    /// enough to resolve the kernel's ripple. Windows are tried from the narrowest upwards.
    /// `(0, top]` maps to `(0, h ω_top]` of the kernel's continuous shape, which grows with
    /// the window, so once windows start failing wider ones fail too; to stay safe against
    /// the discrete kernels of short windows the scan continues a margin of
    /// `max(8, h/2)` windows past the last one that passed.
    ///
    /// Returns `None` if no window qualifies (for an even `polyorder` the narrowest window,
    /// `polyorder + 1`, interpolates exactly and always qualifies), or if `top` is not in
    /// `(0, rate/2]`, or the droop is not finite.
    #[must_use]
    pub fn widest_within(
        rate: SampleRate,
        top: Hz,
        max_droop: Decibels,
        polyorder: usize,
        max_window: usize,
    ) -> Option<Self> {
        if !(top.0.is_finite()
            && top.0 > 0.0
            && top.0 <= rate.nyquist().0
            && max_droop.0.is_finite())
        {
            return None;
        }
        let omega_top = rate.omega(top);
        let hi = Decibels(max_droop.0.abs()).to_amplitude();
        let lo = 1.0 / hi;
        let narrowest = (polyorder + 1) | 1;
        let mut best = None;
        let mut failures = 0usize;
        let mut window = narrowest;
        while window <= max_window {
            let sg = Self::new(window, polyorder).ok()?;
            if sg.stays_within(omega_top, lo, hi) {
                failures = 0;
                best = Some(sg);
            } else {
                failures += 1;
                if failures > (window / 4).max(8) {
                    break;
                }
            }
            window += 2;
        }
        best
    }

    /// Whether `lo <= |H(ω)| <= hi` on a grid over `(0, omega_top]`, checked from the top
    /// down because a window that fails usually fails there first.
    fn stays_within(&self, omega_top: f64, lo: f64, hi: f64) -> bool {
        let n = (4 * self.window).max(256);
        (1..=n).rev().all(|i| {
            let m = self.magnitude(omega_top * i as f64 / n as f64);
            (lo..=hi).contains(&m)
        })
    }

    /// Basis coefficients of the least-squares fit to one window of samples.
    fn fit_coefficients(&self, frame: &[f64]) -> Vec<f64> {
        self.fit
            .chunks_exact(self.window)
            .map(|row| row.iter().zip(frame).map(|(a, b)| a * b).sum())
            .collect()
    }

    /// The fitted polynomial at position `i` of the window.
    fn evaluate(&self, i: usize, coefficients: &[f64]) -> f64 {
        let cols = self.polyorder + 1;
        self.basis[i * cols..(i + 1) * cols]
            .iter()
            .zip(coefficients)
            .map(|(a, b)| a * b)
            .sum()
    }
}

/// `[T_0(u), ..., T_p(u)]` by the three-term recurrence.
fn chebyshev(u: f64, p: usize) -> Vec<f64> {
    let mut t = Vec::with_capacity(p + 1);
    t.push(1.0);
    if p >= 1 {
        t.push(u);
    }
    for j in 2..=p {
        let next = 2.0 * u * t[j - 1] - t[j - 2];
        t.push(next);
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::PI;

    use crate::signal::noise::SplitMix64;

    fn assert_kernel(window: usize, polyorder: usize, numerators: &[f64], denominator: f64) {
        let sg = SavitzkyGolay::new(window, polyorder).unwrap();
        assert_eq!(sg.coefficients().len(), window);
        for (got, n) in sg.coefficients().iter().zip(numerators) {
            assert!(
                (got - n / denominator).abs() < 1e-13,
                "w={window} p={polyorder}: {got} vs {}",
                n / denominator
            );
        }
    }

    #[test]
    fn closed_form_kernels() {
        assert_kernel(5, 2, &[-3.0, 12.0, 17.0, 12.0, -3.0], 35.0);
        assert_kernel(5, 3, &[-3.0, 12.0, 17.0, 12.0, -3.0], 35.0);
        assert_kernel(7, 2, &[-2.0, 3.0, 6.0, 7.0, 6.0, 3.0, -2.0], 21.0);
        assert_kernel(
            9,
            2,
            &[-21.0, 14.0, 39.0, 54.0, 59.0, 54.0, 39.0, 14.0, -21.0],
            231.0,
        );
        assert_kernel(
            9,
            4,
            &[15.0, -55.0, 30.0, 135.0, 179.0, 135.0, 30.0, -55.0, 15.0],
            429.0,
        );
        assert_kernel(7, 0, &[1.0; 7], 7.0);
        assert_kernel(1, 0, &[1.0], 1.0);
        // p = w - 1 interpolates: the kernel is a unit impulse.
        assert_kernel(5, 4, &[0.0, 0.0, 1.0, 0.0, 0.0], 1.0);
    }

    #[test]
    fn polynomials_pass_exactly_including_edges() {
        let mut rng = SplitMix64::new(11);
        for (window, polyorder) in [(5, 2), (7, 3), (17, 3), (31, 5), (101, 4), (9, 8)] {
            let sg = SavitzkyGolay::new(window, polyorder).unwrap();
            for _ in 0..3 {
                let coeffs: Vec<f64> = (0..=polyorder).map(|_| rng.symmetric()).collect();
                let n = window + 40;
                // Evaluate around the middle so the polynomial stays of moderate size.
                let x: Vec<f64> = (0..n)
                    .map(|i| {
                        let t = (i as f64 - n as f64 / 2.0) / n as f64;
                        coeffs.iter().rev().fold(0.0, |acc, c| acc * t + c)
                    })
                    .collect();
                let y = sg.apply(&x).unwrap();
                for (i, (a, b)) in x.iter().zip(&y).enumerate() {
                    assert!(
                        (a - b).abs() < 1e-10,
                        "w={window} p={polyorder} i={i}: {a} vs {b}"
                    );
                }
            }
        }
    }

    /// Solve the normal equations of a monomial fit in raw positions, by Gaussian elimination
    /// with partial pivoting: an independent route to the same least-squares polynomial.
    #[expect(
        clippy::needless_range_loop,
        reason = "the textbook index form, kept recognisable"
    )]
    fn naive_fit(t: &[f64], y: &[f64], p: usize) -> Vec<f64> {
        let m = p + 1;
        let mut a = vec![vec![0.0; m + 1]; m];
        for (ti, yi) in t.iter().zip(y) {
            for r in 0..m {
                for c in 0..m {
                    a[r][c] += ti.powi((r + c) as i32);
                }
                a[r][m] += ti.powi(r as i32) * yi;
            }
        }
        for col in 0..m {
            let piv = (col..m)
                .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
                .unwrap();
            a.swap(col, piv);
            for r in 0..m {
                if r != col {
                    let f = a[r][col] / a[col][col];
                    for c in col..=m {
                        a[r][c] -= f * a[col][c];
                    }
                }
            }
        }
        (0..m).map(|r| a[r][m] / a[r][r]).collect()
    }

    #[test]
    fn edges_equal_independent_least_squares() {
        let mut rng = SplitMix64::new(3);
        for (window, polyorder) in [(5, 2), (7, 3), (11, 4), (15, 2), (21, 5)] {
            let sg = SavitzkyGolay::new(window, polyorder).unwrap();
            let x: Vec<f64> = (0..window + 13).map(|_| rng.symmetric()).collect();
            let y = sg.apply(&x).unwrap();
            let n = x.len();
            let t: Vec<f64> = (0..window).map(|i| i as f64).collect();
            let left = naive_fit(&t, &x[..window], polyorder);
            let right = naive_fit(&t, &x[n - window..], polyorder);
            let eval = |c: &[f64], t: f64| c.iter().rev().fold(0.0, |acc, v| acc * t + v);
            let h = window / 2;
            for i in 0..h {
                assert!((y[i] - eval(&left, i as f64)).abs() < 1e-9, "left {i}");
                let j = window - 1 - i;
                assert!(
                    (y[n - window + j] - eval(&right, j as f64)).abs() < 1e-9,
                    "right {j}"
                );
            }
            // The interior is the same fit evaluated at the centre.
            for centre in h..n - h {
                let c = naive_fit(&t, &x[centre - h..=centre + h], polyorder);
                assert!(
                    (y[centre] - eval(&c, h as f64)).abs() < 1e-9,
                    "interior {centre}"
                );
            }
        }
    }

    #[test]
    fn magnitude_is_the_kernel_dtft() {
        let sg = SavitzkyGolay::new(21, 3).unwrap();
        let h = 10.0;
        for i in 0..50 {
            let w = PI * i as f64 / 49.0;
            let re: f64 = sg
                .coefficients()
                .iter()
                .enumerate()
                .map(|(k, c)| c * (w * (k as f64 - h)).cos())
                .sum();
            let im: f64 = sg
                .coefficients()
                .iter()
                .enumerate()
                .map(|(k, c)| c * (w * (k as f64 - h)).sin())
                .sum();
            assert!(im.abs() < 1e-12);
            assert!((sg.magnitude(w) - re.hypot(im)).abs() < 1e-12);
        }
        assert!((sg.magnitude(0.0) - 1.0).abs() < 1e-12);
    }

    fn brute_force_widest(
        rate: SampleRate,
        top: Hz,
        droop: f64,
        p: usize,
        max_window: usize,
    ) -> Option<usize> {
        let hi = 10f64.powf(droop / 20.0);
        let w_top = rate.omega(top);
        (p + 1..=max_window)
            .rev()
            .filter(|w| w % 2 == 1)
            .find(|&w| {
                let sg = SavitzkyGolay::new(w, p).unwrap();
                (1..=4000).all(|i| {
                    let m = sg.magnitude(w_top * i as f64 / 4000.0);
                    m <= hi && m >= 1.0 / hi
                })
            })
    }

    #[test]
    fn widest_within_matches_brute_force() {
        let cases = [
            (SampleRate(2000), Hz(900.0), 0.1, 2, 41),
            (SampleRate(2000), Hz(900.0), 0.1, 3, 41),
            (SampleRate(8000), Hz(900.0), 0.1, 3, 121),
            (SampleRate(8000), Hz(900.0), 0.5, 4, 121),
            (SampleRate(48_000), Hz(900.0), 0.1, 3, 301),
            (SampleRate(48_000), Hz(300.0), 0.5, 2, 301),
            (SampleRate(44_100), Hz(250.0), 0.1, 5, 301),
            (SampleRate(48_000), Hz(120.0), 1.0, 2, 301),
        ];
        for (rate, top, droop, p, max_w) in cases {
            let got = SavitzkyGolay::widest_within(rate, top, Decibels(droop), p, max_w)
                .map(|s| s.window());
            let want = brute_force_widest(rate, top, droop, p, max_w);
            assert_eq!(got, want, "{rate} {top} {droop} dB p={p}");
        }
    }

    #[test]
    fn widest_within_edge_cases() {
        // p odd near Nyquist: even the narrowest window (p + 2) droops too much.
        assert!(
            SavitzkyGolay::widest_within(SampleRate(2000), Hz(990.0), Decibels(0.1), 3, 101)
                .is_none()
        );
        // p even: the interpolating window always qualifies.
        let sg = SavitzkyGolay::widest_within(SampleRate(2000), Hz(990.0), Decibels(0.1), 2, 101)
            .unwrap();
        assert_eq!(sg.window(), 3);
        assert!(
            SavitzkyGolay::widest_within(SampleRate(2000), Hz(0.0), Decibels(0.1), 2, 101)
                .is_none()
        );
        assert!(
            SavitzkyGolay::widest_within(SampleRate(2000), Hz(1200.0), Decibels(0.1), 2, 101)
                .is_none()
        );
        assert!(
            SavitzkyGolay::widest_within(SampleRate(2000), Hz(100.0), Decibels(0.1), 4, 3)
                .is_none()
        );
        // A cap that binds: the widest allowed window is returned.
        let capped =
            SavitzkyGolay::widest_within(SampleRate(48_000), Hz(100.0), Decibels(0.1), 3, 15)
                .unwrap();
        assert_eq!(capped.window(), 15);
    }

    #[test]
    fn bad_parameters_are_errors() {
        assert!(matches!(
            SavitzkyGolay::new(4, 2),
            Err(SignalError::InvalidParameter(_))
        ));
        assert!(matches!(
            SavitzkyGolay::new(0, 0),
            Err(SignalError::InvalidParameter(_))
        ));
        assert!(matches!(
            SavitzkyGolay::new(5, 5),
            Err(SignalError::InvalidParameter(_))
        ));
        let sg = SavitzkyGolay::new(5, 2).unwrap();
        assert_eq!((sg.window(), sg.polyorder()), (5, 2));
        assert!(matches!(
            sg.apply(&[1.0; 4]),
            Err(SignalError::TooShort {
                len: 4,
                needed: 5,
                ..
            })
        ));
        assert_eq!(sg.apply(&[2.0; 5]).unwrap().len(), 5);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn linearity(seed in any::<u64>(), extra in 0usize..50, half in 0usize..8, p in 0usize..6,
                     a in -5.0f64..5.0, b in -5.0f64..5.0) {
            let window = 2 * half + 1;
            prop_assume!(p < window);
            let sg = SavitzkyGolay::new(window, p).unwrap();
            let mut rng = SplitMix64::new(seed);
            let n = window + extra;
            let x: Vec<f64> = (0..n).map(|_| rng.symmetric()).collect();
            let y: Vec<f64> = (0..n).map(|_| rng.symmetric()).collect();
            let mix: Vec<f64> = x.iter().zip(&y).map(|(u, v)| a * u + b * v).collect();
            let (sx, sy, sm) = (sg.apply(&x).unwrap(), sg.apply(&y).unwrap(), sg.apply(&mix).unwrap());
            for i in 0..n {
                prop_assert!((sm[i] - (a * sx[i] + b * sy[i])).abs() < 1e-10);
            }
        }
    }
}
