//! Butterworth low-pass, high-pass and band-pass filters, designed directly as
//! second-order sections.
//!
//! # Analog prototype
//!
//! The normalised analog Butterworth low-pass of order `N` has `|H(jΩ)|² = 1/(1 + Ω^{2N})`
//! and its poles on the left half of the unit circle,
//!
//! ```math
//! p_k = -\sin\theta_k + j\cos\theta_k,\qquad \theta_k = \frac{(2k+1)\pi}{2N},\quad k = 0..N-1,
//! ```
//!
//! with no finite zeros: `H(s) = Π_k (-p_k)/(s - p_k)`, so `H(0) = 1`.
//!
//! # Frequency transforms (applied to the pre-warped edges)
//!
//! The bilinear transform used here is `s = (z - 1)/(z + 1)` (sample period folded into
//! the analog frequency axis), which maps the analog frequency `Ω` to the digital
//! `ω = 2 atan Ω`. Each edge frequency `f` is therefore pre-warped to `W = tan(π f / fs)`
//! so that it lands exactly where asked.
//!
//! * low-pass, cutoff `Wc`: `s → s / Wc`, poles `s_k = Wc p_k`, all zeros at `s = ∞`;
//! * high-pass, cutoff `Wc`: `s → Wc / s`, poles `s_k = Wc / p_k`, `N` zeros at `s = 0`;
//! * band-pass, edges `Wl < Wh`: `s → (s² + W0²)/(B s)` with `W0² = Wl Wh`, `B = Wh - Wl`.
//!   Each prototype pole `p` becomes the two roots of `s² - p B s + W0² = 0`, and there are
//!   `N` zeros at `s = 0` and `N` at `s = ∞`: `2N` poles in all.
//!
//! The resulting magnitudes are, with `W = tan(ω/2)`,
//!
//! ```math
//! |H_{lp}|^2 = \frac{1}{1 + (W/W_c)^{2N}},\quad |H_{hp}|^2 = \frac{1}{1 + (W_c/W)^{2N}},\quad
//!   |H_{bp}|^2 = \frac{1}{1 + \left(\frac{W^2 - W_0^2}{W B}\right)^{2N}},
//! ```
//!
//! so every edge is at exactly `-10 log10 2 ≈ -3.01 dB`.
//!
//! # Bilinear map, one section at a time
//!
//! An analog factor `s - s_i` becomes `((1 - s_i) z - (1 + s_i)) / (z + 1)`: a digital pole
//! `z_i = (1 + s_i)/(1 - s_i)` and the constant `1 - s_i`. A zero at `s = ∞` becomes a zero at
//! `z = -1`, a zero at `s = 0` a zero at `z = 1`. Collecting the constants exactly gives each
//! section its own positive gain:
//!
//! * low-pass pair: `b = |s_i|²/|1 - s_i|² · [1, 2, 1]`; real pole: `-s/(1 - s) · [1, 1, 0]`;
//! * high-pass pair: `b = 1/|1 - s_i|² · [1, -2, 1]`; real pole: `1/(1 - s) · [1, -1, 0]`;
//! * band-pass pair: `b = B/|1 - s_i|² · [1, 0, -1]` (one zero at each of `z = ±1`);
//!   for odd `N` the real prototype pole gives `s² + B s + W0² = 0`, whose roots are a
//!   conjugate pair, or two real poles when the band is very wide (`B > 2 W0`), both handled.
//!
//! Denominators are `[1, -2 Re z_i, |z_i|²]` (or `[1, -z, 0]` for a first-order section).
//! Nothing is ever expanded into one long polynomial: a 20 Hz edge at 48 kHz puts poles
//! within 3·10⁻³ of `z = 1`, where an expanded polynomial loses all precision.
//!
//! These constants give the cascade unity gain where the prototype has it: DC (low-pass),
//! Nyquist (high-pass), and the pre-warped centre `ω0 = 2 atan W0`, `W0 = sqrt(Wl Wh)`
//! (band-pass). Rounding the denominators shifts each pole by an ulp, and a pole near
//! `z = 1` turns that into a gain error of order 10⁻¹²; so low- and high-pass sections
//! take their gain from the stored denominator instead (`b = (1 + a1 + a2)/4 · [1, 2, 1]`,
//! `b = (1 - a1 + a2)/4 · [1, -2, 1]`, which equals the constant above in exact
//! arithmetic), and the band-pass folds the residual at `ω0` into its first section.
//!
//! Sections come in the order of the prototype poles, from the most resonant pair (the
//! one nearest the imaginary axis) to the real pole of an odd order. The order of a
//! cascade does not change its response.

use num_complex::Complex64;

use super::SignalError;
use super::sos::{Biquad, Sos};
use crate::units::{Band, Hz, SampleRate};

/// The highest prototype order accepted.
pub const MAX_BUTTERWORTH_ORDER: usize = 20;

/// A Butterworth low-pass filter of order `order` with its -3.01 dB point at `cutoff`.
///
/// # Errors
/// [`SignalError::InvalidParameter`] if `order` is not in `1..=20`;
/// [`SignalError::CutoffOutOfRange`] unless `0 < cutoff < rate / 2`.
pub fn lowpass(order: usize, cutoff: Hz, rate: SampleRate) -> Result<Sos, SignalError> {
    check_order(order)?;
    let wc = prewarp_cutoff(cutoff, rate)?;
    let sections = prototype_poles(order)
        .into_iter()
        .map(|p| {
            let s = p * wc;
            if p.im == 0.0 {
                let sec = first_order(s, [1.0, 1.0, 0.0]);
                with_gain(sec, (1.0 + sec.a[1]) / 2.0)
            } else {
                let sec = second_order(s, [1.0, 2.0, 1.0]);
                with_gain(sec, (1.0 + sec.a[1] + sec.a[2]) / 4.0)
            }
        })
        .collect();
    Ok(Sos::new(sections))
}

/// A Butterworth high-pass filter of order `order` with its -3.01 dB point at `cutoff`.
///
/// # Errors
/// [`SignalError::InvalidParameter`] if `order` is not in `1..=20`;
/// [`SignalError::CutoffOutOfRange`] unless `0 < cutoff < rate / 2`.
pub fn highpass(order: usize, cutoff: Hz, rate: SampleRate) -> Result<Sos, SignalError> {
    check_order(order)?;
    let wc = prewarp_cutoff(cutoff, rate)?;
    let sections = prototype_poles(order)
        .into_iter()
        .map(|p| {
            // wc/p lies below the real axis when p lies above; a section depends only on
            // the pair.
            let s = wc / p;
            if p.im == 0.0 {
                let sec = first_order(s, [1.0, -1.0, 0.0]);
                with_gain(sec, (1.0 - sec.a[1]) / 2.0)
            } else {
                let sec = second_order(s, [1.0, -2.0, 1.0]);
                with_gain(sec, (1.0 - sec.a[1] + sec.a[2]) / 4.0)
            }
        })
        .collect();
    Ok(Sos::new(sections))
}

/// A Butterworth band-pass filter from a prototype of order `order` (so `2 * order` poles
/// in `order` sections), with its -3.01 dB points at the band edges and unity gain at the
/// pre-warped geometric centre.
///
/// # Errors
/// [`SignalError::InvalidParameter`] if `order` is not in `1..=20`;
/// [`SignalError::BandOutOfRange`] unless `0 < lo < hi < rate / 2`.
pub fn bandpass(order: usize, band: Band, rate: SampleRate) -> Result<Sos, SignalError> {
    check_order(order)?;
    if !band.fits(rate) {
        return Err(SignalError::BandOutOfRange { band, rate });
    }
    let wl = prewarp(band.lo, rate);
    let wh = prewarp(band.hi, rate);
    let w0_sq = wl * wh;
    let bw = wh - wl;
    let mut sections = Vec::with_capacity(order);
    for p in prototype_poles(order) {
        // Roots of s² - p B s + W0² = 0.
        let half = p * (bw / 2.0);
        let disc = (half * half - w0_sq).sqrt();
        if p.im == 0.0 {
            // The real prototype pole gives a real quadratic: one section, whatever its roots.
            let (r1, r2) = (half + disc, half - disc);
            if disc.im != 0.0 || disc.re == 0.0 {
                let s = if r1.im >= 0.0 { r1 } else { r2 };
                let sec = second_order(s, [1.0, 0.0, -1.0]);
                sections.push(with_gain(sec, bw / (1.0 - s).norm_sqr()));
            } else {
                let (s1, s2) = (r1.re, r2.re);
                let (z1, z2) = ((1.0 + s1) / (1.0 - s1), (1.0 + s2) / (1.0 - s2));
                let k = bw / ((1.0 - s1) * (1.0 - s2));
                sections.push(Biquad {
                    b: [k, 0.0, -k],
                    a: [1.0, -(z1 + z2), z1 * z2],
                });
            }
        } else {
            // Two distinct complex poles; their conjugates come from the conjugate prototype
            // pole, which prototype_poles leaves out.
            for s in [half + disc, half - disc] {
                let sec = second_order(s, [1.0, 0.0, -1.0]);
                sections.push(with_gain(sec, bw / (1.0 - s).norm_sqr()));
            }
        }
    }
    // The exact gains give unity at the centre up to the rounding of the denominators,
    // which near z = 1 is amplified; fold the last 1e-12 or so into the first section.
    let centre = 2.0 * w0_sq.sqrt().atan();
    let mut sos = Sos::new(sections);
    let residual = sos.response(centre).norm();
    if let (Some(first), true) = (sos.sections.first_mut(), residual.is_normal()) {
        *first = with_gain(*first, 1.0 / residual);
    }
    Ok(sos)
}

fn check_order(order: usize) -> Result<(), SignalError> {
    if (1..=MAX_BUTTERWORTH_ORDER).contains(&order) {
        Ok(())
    } else {
        Err(SignalError::InvalidParameter(format!(
            "Butterworth order {order} is outside 1..={MAX_BUTTERWORTH_ORDER}"
        )))
    }
}

fn prewarp(f: Hz, rate: SampleRate) -> f64 {
    crate::numeric::bilinear::warped(f, rate)
}

fn prewarp_cutoff(cutoff: Hz, rate: SampleRate) -> Result<f64, SignalError> {
    if cutoff.0.is_finite() && cutoff.0 > 0.0 && cutoff.0 < rate.nyquist().0 {
        Ok(prewarp(cutoff, rate))
    } else {
        Err(SignalError::CutoffOutOfRange { cutoff, rate })
    }
}

/// One member of each conjugate pair of prototype poles (the one with positive imaginary
/// part), then the real pole `-1` for odd `order`.
fn prototype_poles(order: usize) -> Vec<Complex64> {
    let n = order as f64;
    let mut poles: Vec<Complex64> = (0..order / 2)
        .map(|k| {
            let theta = (2 * k + 1) as f64 * std::f64::consts::PI / (2.0 * n);
            Complex64::new(-theta.sin(), theta.cos())
        })
        .collect();
    if order % 2 == 1 {
        poles.push(Complex64::new(-1.0, 0.0));
    }
    poles
}

/// The section for the analog pair `s, conj(s)` after the bilinear map, numerator unscaled.
fn second_order(s: Complex64, numerator: [f64; 3]) -> Biquad {
    let z = (1.0 + s) / (1.0 - s);
    Biquad {
        b: numerator,
        a: [1.0, -2.0 * z.re, z.norm_sqr()],
    }
}

/// The first-order section for the real analog pole `s` after the bilinear map, numerator
/// unscaled.
fn first_order(s: Complex64, numerator: [f64; 3]) -> Biquad {
    let z = (1.0 + s.re) / (1.0 - s.re);
    Biquad {
        b: numerator,
        a: [1.0, -z, 0.0],
    }
}

fn with_gain(section: Biquad, gain: f64) -> Biquad {
    Biquad {
        b: section.b.map(|c| c * gain),
        ..section
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::PI;

    fn power(sos: &Sos, omega: f64) -> f64 {
        sos.response(omega).norm_sqr()
    }

    /// Frequencies spread over (0, pi), avoiding the exact ends.
    fn grid(n: usize) -> impl Iterator<Item = f64> {
        (1..n).map(move |i| PI * i as f64 / n as f64)
    }

    #[test]
    fn lowpass_matches_closed_form() {
        let rate = SampleRate(2000);
        for order in 1..=MAX_BUTTERWORTH_ORDER {
            for fc in [5.0, 100.0, 333.0, 900.0, 990.0] {
                let sos = lowpass(order, Hz(fc), rate).unwrap();
                assert_eq!(sos.order(), order);
                assert_eq!(sos.sections.len(), order.div_ceil(2));
                let wc = (PI * fc / 2000.0).tan();
                for w in grid(400) {
                    let ratio = (w / 2.0).tan() / wc;
                    let expect = 1.0 / (1.0 + ratio.powi(2 * order as i32));
                    let got = power(&sos, w);
                    assert!(
                        (got - expect).abs() < 1e-9,
                        "N={order} fc={fc} w={w}: {got} vs {expect}"
                    );
                }
                let dc = power(&sos, 0.0);
                assert!((dc - 1.0).abs() < 1e-12, "N={order} fc={fc} dc={dc}");
                assert!(sos.is_stable());
            }
        }
    }

    #[test]
    fn highpass_matches_closed_form() {
        let rate = SampleRate(48_000);
        for order in 1..=MAX_BUTTERWORTH_ORDER {
            for fc in [20.0, 440.0, 12_000.0, 23_000.0] {
                let sos = highpass(order, Hz(fc), rate).unwrap();
                assert_eq!(sos.order(), order);
                let wc = (PI * fc / 48_000.0).tan();
                for w in grid(400) {
                    let ratio = wc / (w / 2.0).tan();
                    let expect = 1.0 / (1.0 + ratio.powi(2 * order as i32));
                    let got = power(&sos, w);
                    assert!(
                        (got - expect).abs() < 1e-9,
                        "N={order} fc={fc} w={w}: {got} vs {expect}"
                    );
                }
                assert!((power(&sos, PI) - 1.0).abs() < 1e-12);
                assert!(sos.is_stable());
            }
        }
    }

    fn bandpass_power(order: usize, band: Band, rate: SampleRate, w: f64) -> f64 {
        let wl = (PI * band.lo.0 / rate.hz()).tan();
        let wh = (PI * band.hi.0 / rate.hz()).tan();
        let ww = (w / 2.0).tan();
        let x = (ww * ww - wl * wh) / (ww * (wh - wl));
        1.0 / (1.0 + x.powi(2 * order as i32))
    }

    #[test]
    fn bandpass_matches_closed_form() {
        let cases = [
            (SampleRate(2000), Band::new(35.0, 120.0)),
            (SampleRate(2000), Band::new(20.0, 900.0)),
            // Wider than 2 W0: the odd-order real pole splits into two real poles.
            (SampleRate(2000), Band::new(1.0, 990.0)),
            (SampleRate(48_000), Band::new(20.0, 900.0)),
            (SampleRate(48_000), Band::new(1000.0, 1010.0)),
        ];
        for (rate, band) in cases {
            for order in 1..=MAX_BUTTERWORTH_ORDER {
                let sos = bandpass(order, band, rate).unwrap();
                assert_eq!(sos.order(), 2 * order);
                assert_eq!(sos.sections.len(), order);
                assert!(sos.is_stable(), "N={order} {band} @ {rate}");
                for w in grid(1000) {
                    let expect = bandpass_power(order, band, rate, w);
                    let got = power(&sos, w);
                    assert!(
                        (got - expect).abs() < 1e-9,
                        "N={order} {band} w={w}: {got} vs {expect}"
                    );
                }
                let wl = (PI * band.lo.0 / rate.hz()).tan();
                let wh = (PI * band.hi.0 / rate.hz()).tan();
                let centre = 2.0 * (wl * wh).sqrt().atan();
                assert!(
                    (power(&sos, centre) - 1.0).abs() < 1e-10,
                    "centre gain N={order} {band}"
                );
            }
        }
    }

    #[test]
    fn edges_are_minus_3_01_db() {
        let half_power_db = -10.0 * 2f64.log10();
        let rate = SampleRate(48_000);
        let db = |sos: &Sos, f: f64| 10.0 * power(sos, rate.omega(Hz(f))).log10();
        for order in [1, 2, 5, 8, 20] {
            let lp = lowpass(order, Hz(120.0), rate).unwrap();
            assert!((db(&lp, 120.0) - half_power_db).abs() < 1e-9);
            let hp = highpass(order, Hz(35.0), rate).unwrap();
            assert!((db(&hp, 35.0) - half_power_db).abs() < 1e-9);
            let bp = bandpass(order, Band::new(35.0, 120.0), rate).unwrap();
            assert!((db(&bp, 35.0) - half_power_db).abs() < 1e-9);
            assert!((db(&bp, 120.0) - half_power_db).abs() < 1e-9);
        }
    }

    #[test]
    fn low_edge_at_high_rate_is_stable_and_settles() {
        let rate = SampleRate(48_000);
        let bp = bandpass(8, Band::new(20.0, 900.0), rate).unwrap();
        assert!(bp.is_stable());
        assert!(bp.poles().iter().all(|p| p.norm() < 1.0));
        let hp = highpass(8, Hz(20.0), rate).unwrap();
        assert!(hp.is_stable());
        // A stable filter's impulse response decays: after 10 s nothing is left.
        for sos in [&bp, &hp] {
            let h = sos.impulse_response(480_000);
            let tail = h[470_000..].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(tail < 1e-12, "tail {tail}");
        }
    }

    #[test]
    fn bad_parameters_are_errors() {
        let rate = SampleRate(2000);
        assert!(matches!(
            lowpass(0, Hz(100.0), rate),
            Err(SignalError::InvalidParameter(_))
        ));
        assert!(matches!(
            lowpass(21, Hz(100.0), rate),
            Err(SignalError::InvalidParameter(_))
        ));
        for f in [0.0, -1.0, 1000.0, 1500.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                lowpass(4, Hz(f), rate),
                Err(SignalError::CutoffOutOfRange { .. })
            ));
            assert!(matches!(
                highpass(4, Hz(f), rate),
                Err(SignalError::CutoffOutOfRange { .. })
            ));
        }
        for band in [
            Band::new(0.0, 100.0),
            Band::new(200.0, 100.0),
            Band::new(10.0, 1000.0),
        ] {
            assert!(matches!(
                bandpass(4, band, rate),
                Err(SignalError::BandOutOfRange { .. })
            ));
        }
        assert!(lowpass(4, Hz(10.0), SampleRate(0)).is_err());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Any valid band at any common rate: stable, 2N poles, closed-form magnitude.
        #[test]
        fn bandpass_any_band(order in 1usize..=12, lo_frac in 0.001f64..0.45, width in 0.01f64..0.99,
                             rate in prop::sample::select(vec![2000u32, 8000, 44_100, 48_000])) {
            let rate = SampleRate(rate);
            let lo = lo_frac * rate.hz() / 2.0;
            let hi = lo + width * (rate.hz() / 2.0 - lo);
            let band = Band::new(lo, hi);
            prop_assume!(band.fits(rate));
            let sos = bandpass(order, band, rate).unwrap();
            prop_assert!(sos.is_stable());
            for w in grid(97) {
                let expect = bandpass_power(order, band, rate, w);
                prop_assert!((power(&sos, w) - expect).abs() < 1e-9);
            }
        }
    }
}
