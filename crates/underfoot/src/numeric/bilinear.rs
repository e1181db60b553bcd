//! The bilinear transform of a second-order analogue section.
//!
//! With `$s = c\,\frac{1 - z^{-1}}{1 + z^{-1}}$`, an analogue section
//! `$\frac{p_2 s^2 + p_1 s + p_0}{q_2 s^2 + q_1 s + q_0}$` becomes a digital biquad whose
//! numerator (and, with `$q$`, denominator) coefficients are
//!
//! ```math
//! \big(p_2 c^2 + p_1 c + p_0,\; 2(p_0 - p_2 c^2),\; p_2 c^2 - p_1 c + p_0\big).
//! ```
//!
//! The transform maps the whole `$j\Omega$` axis onto the unit circle, warping frequency
//! as `$\Omega = c \tan(\omega / 2)$`. Choosing `$c = \frac{2\pi f}{\tan(\pi f / f_s)}$`
//! ([`prewarp_constant`]) makes the analogue frequency `$f$` land on itself.
//!
//! A first-order ratio (both `$s^2$` coefficients zero) stays first-order, rather than
//! gaining a cancelling pole-zero pair at `$z = -1$` on the unit circle.

use core::f64::consts::PI;

use crate::units::{Hz, SampleRate};

/// `tan(π f / fs)`: the analogue frequency (in units of `c`) that the transform with
/// `c = 1` maps onto the digital frequency `f`. A design in `s / c` prewarps its edges
/// with it; `1 / warped(f)` is the constant that lands an `s` normalised to `f` on `f`.
///
/// [`crate::signal::butterworth`] maps its poles one by one, `z = (1 + s)/(1 − s)`,
/// rather than the coefficients (precision near `z = 1`), and prewarps with this.
#[must_use]
pub fn warped(f: Hz, rate: SampleRate) -> f64 {
    (PI * f.0 / rate.hz()).tan()
}

/// `c` of `s = c (1 − z⁻¹)/(1 + z⁻¹)` that maps `f` to itself, or `None` unless
/// `0 < f < Nyquist`.
#[must_use]
pub fn prewarp_constant(rate: SampleRate, f: Hz) -> Option<f64> {
    if !(f.0.is_finite() && f.0 > 0.0 && f.0 < rate.nyquist().0) {
        return None;
    }
    let w = 2.0 * PI * f.0;
    Some(w / (w / (2.0 * rate.hz())).tan())
}

/// The bilinear transform of `num(s)/den(s)` (coefficients of `[s², s, 1]`) with
/// constant `c`: the digital section as a row `[b0, b1, b2, a0, a1, a2]`, not
/// normalised (`a0` may be anything, zero included; the caller decides what that means).
#[must_use]
pub fn bilinear(num: [f64; 3], den: [f64; 3], c: f64) -> [f64; 6] {
    let first = num[0] == 0.0 && den[0] == 0.0;
    let map = |[p2, p1, p0]: [f64; 3]| {
        if first {
            [p1 * c + p0, p0 - p1 * c, 0.0]
        } else {
            let c2 = c * c;
            [
                p2 * c2 + p1 * c + p0,
                2.0 * (p0 - p2 * c2),
                p2 * c2 - p1 * c + p0,
            ]
        }
    };
    let (b, a) = (map(num), map(den));
    [b[0], b[1], b[2], a[0], a[1], a[2]]
}

#[cfg(test)]
mod tests {
    use num_complex::Complex64;

    use super::*;

    fn analogue(p: [f64; 3], s: Complex64) -> Complex64 {
        p[0] * s * s + p[1] * s + p[2]
    }

    fn digital(row: &[f64; 6], w: f64) -> Complex64 {
        let z1 = Complex64::from_polar(1.0, -w);
        (row[0] + row[1] * z1 + row[2] * z1 * z1) / (row[3] + row[4] * z1 + row[5] * z1 * z1)
    }

    #[test]
    fn the_prewarped_frequency_lands_on_itself() {
        let rate = SampleRate(8000);
        let f0 = 1234.0;
        let w0 = 2.0 * PI * f0;
        // A resonance at f0 with Q = 4.
        let (num, den) = ([0.0, w0 / 4.0, 0.0], [1.0, w0 / 4.0, w0 * w0]);
        let c = prewarp_constant(rate, Hz(f0)).unwrap();
        let row = bilinear(num, den, c);
        let a = analogue(num, Complex64::new(0.0, w0)) / analogue(den, Complex64::new(0.0, w0));
        let d = digital(&row, 2.0 * PI * f0 / 8000.0);
        assert!((a - d).norm() < 1e-12, "{a} vs {d}");
        // Elsewhere the frequency axis is warped by Ω = c tan(ω/2).
        for f in [50.0, 700.0, 3000.0] {
            let w = 2.0 * PI * f / 8000.0;
            let s = Complex64::new(0.0, c * (w / 2.0).tan());
            let a = analogue(num, s) / analogue(den, s);
            assert!((a - digital(&row, w)).norm() < 1e-12);
        }
    }

    #[test]
    fn first_order_stays_first_order() {
        let c = prewarp_constant(SampleRate(48_000), Hz(100.0)).unwrap();
        let row = bilinear([0.0, 0.0, 1.0], [0.0, 1.0, 2.0 * PI * 100.0], c);
        assert_eq!((row[2], row[5]), (0.0, 0.0));
    }

    #[test]
    fn prewarping_refuses_frequencies_off_the_axis() {
        let rate = SampleRate(1000);
        for f in [0.0, -1.0, 500.0, 600.0, f64::NAN, f64::INFINITY] {
            assert_eq!(prewarp_constant(rate, Hz(f)), None, "{f}");
        }
    }
}
