//! Zero-phase forward-backward filtering of a second-order-section cascade, with the
//! defaults of `scipy.signal.sosfiltfilt`.
//!
//! # Algorithm
//!
//! Running `H` forward, then running `H` over the time-reversed result and reversing back,
//! applies `H(e^{jω}) · conj(H(e^{jω})) = |H(e^{jω})|²`: the magnitude is squared and the
//! phase cancels exactly.
//!
//! The start-up transients at both ends are tamed exactly as scipy does by default:
//!
//! 1. **Odd extension.** With `n_s` sections, of which `n_b` have `b2 = 0` and `n_a` have
//!    `a2 = 0`, `padlen = 3 (2 n_s + 1 - min(n_b, n_a))`. The signal is extended by
//!    `padlen` samples at each end, reflected through its end point:
//!    `x[-i] = 2 x[0] - x[i]` and `x[L-1+i] = 2 x[L-1] - x[L-1-i]`, `i = 1..=padlen`.
//!    This keeps the value and the slope continuous at the joins.
//! 2. **Steady-state initial conditions** ([`sosfilt_zi`]). For a section
//!    `(b0 + b1 z⁻¹ + b2 z⁻²)/(1 + a1 z⁻¹ + a2 z⁻²)` in transposed direct form II,
//!    `y = b0 x + s1`, `s1' = b1 x - a1 y + s2`, `s2' = b2 x - a2 y`, the state that a
//!    constant input `u` holds fixed is, with `g = Σb / Σa` the section's DC gain,
//!    `s2 = u (b2 - a2 g)`, `s1 = u (b1 - a1 g) + s2`. In a cascade the input of section
//!    `i` is `u` times the DC gains of the sections before it. Each pass starts from this
//!    state scaled by its own first sample, so a signal that starts at a constant level
//!    produces no transient at all.
//! 3. Forward pass, backward pass, then the padding is cut off.
//!
//! # Where this differs from scipy
//!
//! scipy refuses inputs not longer than `padlen`. Here `padlen` is clamped to `L - 1`
//! (the longest odd extension the signal supports), so any input of at least 2 samples
//! is filtered; for inputs longer than the default `padlen` the output is identical to
//! scipy's. A section with a pole exactly at `z = 1` has no steady state: its initial
//! state, and that of every later section, is zero.

use super::SignalError;
use super::sos::Sos;

/// The steady-state of each section of `sos` under a unit step input, one `[s1, s2]` per
/// section (transposed direct form II, as [`Sos::filter_with_state`] runs it).
///
/// Scaling it by a constant `u` and filtering the constant signal `u` from that state
/// leaves the state unchanged and outputs `u` times the DC gain of the cascade.
#[must_use]
pub fn sosfilt_zi(sos: &Sos) -> Vec<[f64; 2]> {
    let mut scale = 1.0_f64;
    sos.sections
        .iter()
        .map(|s| {
            let [b0, b1, b2] = s.b;
            let [_, a1, a2] = s.a;
            let gain = (b0 + b1 + b2) / (1.0 + a1 + a2);
            if !gain.is_finite() || !scale.is_finite() {
                scale = f64::NAN;
                return [0.0, 0.0];
            }
            let s2 = scale * (b2 - a2 * gain);
            let s1 = scale * (b1 - a1 * gain) + s2;
            scale *= gain;
            [s1, s2]
        })
        .collect()
}

/// The number of samples [`filtfilt`] pads each end with for an input long enough
/// (scipy's default `padlen`).
#[must_use]
pub fn default_padlen(sos: &Sos) -> usize {
    let n = sos.sections.len();
    let b2_zero = sos.sections.iter().filter(|s| s.b[2] == 0.0).count();
    let a2_zero = sos.sections.iter().filter(|s| s.a[2] == 0.0).count();
    3 * (2 * n + 1 - b2_zero.min(a2_zero))
}

/// Zero-phase filtering of `x` by `sos`, run forward and backward: the result has the
/// magnitude response `|H|²` and no phase shift. Same semantics as
/// `scipy.signal.sosfiltfilt(sos, x)` (odd padding, steady-state initial conditions),
/// except that the padding is clamped to `x.len() - 1` for short inputs.
///
/// # Errors
/// [`SignalError::TooShort`] if `x` has fewer than 2 samples.
pub fn filtfilt(sos: &Sos, x: &[f64]) -> Result<Vec<f64>, SignalError> {
    let len = x.len();
    if len < 2 {
        return Err(SignalError::TooShort {
            len,
            needed: 2,
            what: "zero-phase filtering",
        });
    }
    let pad = default_padlen(sos).min(len - 1);
    let (first, last) = (x[0], x[len - 1]);

    let mut ext = Vec::with_capacity(len + 2 * pad);
    ext.extend((1..=pad).rev().map(|i| 2.0 * first - x[i]));
    ext.extend_from_slice(x);
    ext.extend((1..=pad).map(|i| 2.0 * last - x[len - 1 - i]));

    let zi = sosfilt_zi(sos);
    let run = |buf: &mut [f64]| {
        let start = buf.first().copied().unwrap_or(0.0);
        let mut state: Vec<[f64; 2]> = zi
            .iter()
            .map(|&[s1, s2]| [s1 * start, s2 * start])
            .collect();
        sos.filter_with_state(buf, &mut state);
    };
    run(&mut ext);
    ext.reverse();
    run(&mut ext);
    ext.reverse();
    ext.truncate(pad + len);
    ext.drain(..pad);
    Ok(ext)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::butterworth::{bandpass, lowpass};
    use crate::signal::sos::Biquad;
    use crate::units::{Band, Hz, SampleRate};
    use proptest::prelude::*;
    use std::f64::consts::PI;

    use crate::signal::noise::SplitMix64;

    /// Naive reference: each section run as its own direct-form-I difference equation,
    /// initial conditions found by running a long constant input to steady state.
    fn naive_filtfilt(sos: &Sos, x: &[f64], pad: usize) -> Vec<f64> {
        let len = x.len() as isize;
        let at = |i: isize| -> f64 {
            if i < 0 {
                2.0 * x[0] - x[(-i) as usize]
            } else if i >= len {
                2.0 * x[len as usize - 1] - x[(2 * (len - 1) - i) as usize]
            } else {
                x[i as usize]
            }
        };
        let padded: Vec<f64> = (-(pad as isize)..len + pad as isize).map(at).collect();
        let once = |input: &[f64]| -> Vec<f64> {
            // Warm every section up on a constant equal to the first sample, so its
            // delay line holds the steady state: that is what the zi is meant to emulate.
            let mut signal = input.to_vec();
            for s in &sos.sections {
                let warm = 200_000;
                let mut hist_x = [0.0; 2];
                let mut hist_y = [0.0; 2];
                let step = |xin: f64, hx: &mut [f64; 2], hy: &mut [f64; 2]| {
                    let y = s.b[0] * xin + s.b[1] * hx[0] + s.b[2] * hx[1]
                        - s.a[1] * hy[0]
                        - s.a[2] * hy[1];
                    *hx = [xin, hx[0]];
                    *hy = [y, hy[0]];
                    y
                };
                let level = signal[0];
                for _ in 0..warm {
                    step(level, &mut hist_x, &mut hist_y);
                }
                for v in signal.iter_mut() {
                    *v = step(*v, &mut hist_x, &mut hist_y);
                }
            }
            signal
        };
        let fwd = once(&padded);
        let mut rev: Vec<f64> = fwd.into_iter().rev().collect();
        rev = once(&rev);
        rev.reverse();
        rev[pad..pad + x.len()].to_vec()
    }

    #[test]
    fn matches_naive_reference() {
        let rate = SampleRate(2000);
        let mut rng = SplitMix64::new(7);
        let x: Vec<f64> = (0..600).map(|_| rng.symmetric() + 0.3).collect();
        for sos in [
            lowpass(3, Hz(200.0), rate).unwrap(),
            lowpass(4, Hz(50.0), rate).unwrap(),
            bandpass(2, Band::new(35.0, 120.0), rate).unwrap(),
        ] {
            let got = filtfilt(&sos, &x).unwrap();
            let want = naive_filtfilt(&sos, &x, default_padlen(&sos));
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() < 1e-9, "{g} vs {w}");
            }
        }
    }

    #[test]
    fn padlen_follows_scipy() {
        let rate = SampleRate(2000);
        // Odd low-pass: 2 sections, one first-order (b2 = a2 = 0): 3 * (5 - 1) = 12.
        assert_eq!(default_padlen(&lowpass(3, Hz(100.0), rate).unwrap()), 12);
        // Band-pass sections have b = [k, 0, -k]: no zero b2: 3 * (2*4 + 1) = 27.
        assert_eq!(
            default_padlen(&bandpass(4, Band::new(35.0, 120.0), rate).unwrap()),
            27
        );
        // Sections with b2 = 0 but a2 != 0 and vice versa: min counts.
        let mixed = Sos::new(vec![
            Biquad {
                b: [1.0, 0.5, 0.0],
                a: [1.0, -0.5, 0.2],
            },
            Biquad {
                b: [1.0, 0.5, 0.1],
                a: [1.0, -0.5, 0.0],
            },
            Biquad {
                b: [1.0, 0.5, 0.0],
                a: [1.0, -0.5, 0.0],
            },
        ]);
        assert_eq!(default_padlen(&mixed), 3 * (7 - 2));
    }

    #[test]
    fn zi_is_the_steady_state_of_a_step() {
        let rate = SampleRate(2000);
        for sos in [
            lowpass(5, Hz(100.0), rate).unwrap(),
            bandpass(3, Band::new(35.0, 120.0), rate).unwrap(),
        ] {
            let mut state = vec![[0.0; 2]; sos.sections.len()];
            let mut ones = vec![1.0; 100_000];
            sos.filter_with_state(&mut ones, &mut state);
            for (got, want) in sosfilt_zi(&sos).iter().zip(&state) {
                assert!((got[0] - want[0]).abs() < 1e-10 && (got[1] - want[1]).abs() < 1e-10);
            }
        }
    }

    #[test]
    fn constant_through_dc_unity_lowpass_is_unchanged() {
        let sos = lowpass(6, Hz(40.0), SampleRate(2000)).unwrap();
        for len in [2, 3, 10, 39, 40, 1000] {
            let x = vec![-3.25; len];
            let y = filtfilt(&sos, &x).unwrap();
            assert_eq!(y.len(), len);
            for v in y {
                assert!((v + 3.25).abs() < 1e-12, "{v}");
            }
        }
    }

    #[test]
    fn sine_in_passband_has_zero_phase() {
        let rate = SampleRate(2000);
        let sos = bandpass(4, Band::new(35.0, 120.0), rate).unwrap();
        let f = 70.0;
        let w = rate.omega(Hz(f));
        let gain = sos.response(w).norm_sqr();
        let x: Vec<f64> = (0..8000).map(|n| (w * n as f64 + 0.4).sin()).collect();
        let y = filtfilt(&sos, &x).unwrap();
        // Away from the ends the start-up transients have decayed.
        for (n, got) in y.iter().enumerate().take(6000).skip(2000) {
            let want = gain * (w * n as f64 + 0.4).sin();
            assert!((got - want).abs() < 1e-6, "n={n}: {got} vs {want}");
        }
    }

    #[test]
    fn short_inputs() {
        let sos = lowpass(2, Hz(100.0), SampleRate(2000)).unwrap();
        assert!(matches!(
            filtfilt(&sos, &[]),
            Err(SignalError::TooShort { len: 0, .. })
        ));
        assert!(matches!(
            filtfilt(&sos, &[1.0]),
            Err(SignalError::TooShort { len: 1, .. })
        ));
        // Shorter than padlen: padding is clamped, the naive reference agrees.
        let x = [0.5, -1.0, 2.0, 0.25, 1.5];
        let got = filtfilt(&sos, &x).unwrap();
        let want = naive_filtfilt(&sos, &x, x.len() - 1);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-9);
        }
        assert_eq!(filtfilt(&Sos::default(), &x).unwrap(), x.to_vec());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Padding, initial states and both passes are all linear in the input.
        #[test]
        fn linearity(seed in any::<u64>(), len in 2usize..300, a in -3.0f64..3.0, b in -3.0f64..3.0) {
            let sos = bandpass(3, Band::new(35.0, 120.0), SampleRate(2000)).unwrap();
            let mut rng = SplitMix64::new(seed);
            let x: Vec<f64> = (0..len).map(|_| rng.symmetric()).collect();
            let y: Vec<f64> = (0..len).map(|_| rng.symmetric()).collect();
            let mix: Vec<f64> = x.iter().zip(&y).map(|(p, q)| a * p + b * q).collect();
            let fx = filtfilt(&sos, &x).unwrap();
            let fy = filtfilt(&sos, &y).unwrap();
            let fm = filtfilt(&sos, &mix).unwrap();
            for i in 0..len {
                prop_assert!((fm[i] - (a * fx[i] + b * fy[i])).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn frequency_response_is_magnitude_squared() {
        // An impulse in the middle of a long buffer: its zero-phase output is the
        // symmetric impulse response of |H|², whose DTFT is |H|² itself.
        let rate = SampleRate(2000);
        let sos = lowpass(3, Hz(200.0), rate).unwrap();
        let n = 4001;
        let mut x = vec![0.0; n];
        x[n / 2] = 1.0;
        let y = filtfilt(&sos, &x).unwrap();
        for f in [10.0, 100.0, 200.0, 400.0] {
            let w = 2.0 * PI * f / 2000.0;
            let dtft: f64 = y
                .iter()
                .enumerate()
                .map(|(k, v)| v * (w * (k as f64 - (n / 2) as f64)).cos())
                .sum();
            let want = sos.response(w).norm_sqr();
            assert!((dtft - want).abs() < 1e-9, "f={f}: {dtft} vs {want}");
        }
    }
}
