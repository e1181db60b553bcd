//! Daubechies discrete wavelet transform.
//!
//! The tile paper (section 2.2) isolates impact onsets in the second detail band of a Daubechies
//! decomposition. One level of the transform splits a signal `x` of even length `N` into an
//! approximation and a detail, each of `N / 2` coefficients,
//!
//! ```math
//! a[k] = \sum_{n} h[n]\, x[(2k + n) \bmod N], \qquad
//!   d[k] = \sum_{n} g[n]\, x[(2k + n) \bmod N],
//! ```
//!
//! with the low-pass filter `h` of length `L` and the high-pass filter from the quadrature
//! mirror relation `g[n] = (-1)^n h[L - 1 - n]`. The Daubechies filters are orthonormal,
//!
//! ```math
//! \sum_n h[n] = \sqrt 2, \qquad \sum_n h[n]\, h[n + 2m] = \delta_m,
//! ```
//!
//! so each level is an orthogonal transform and its inverse is its transpose:
//!
//! ```math
//! x[m] = \sum_k a[k]\, h[(m - 2k) \bmod N] + d[k]\, g[(m - 2k) \bmod N].
//! ```
//!
//! Level `j + 1` splits the approximation of level `j`. At rate `fs` the detail of level
//! `j` covers roughly `fs / 2^{j+1} .. fs / 2^j` ([`detail_band`]); each of its
//! coefficients stands for `2^j` samples.
//!
//! **Extension.** The signal is extended periodically (the `mod N` above), which keeps the
//! transform orthogonal and exactly invertible with as many coefficients as samples. A
//! length that is not a multiple of `2^levels` is first padded at the end by mirroring its
//! last samples (reflection about the last sample), which avoids a jump at the seam; the
//! inverse drops the padding again, so reconstruction is exact on the original samples.

use super::SignalError;
use crate::units::{Band, SampleRate};

/// `(1 + √3) / (4√2)` and its siblings: the closed form of db2.
const DB2: [f64; 4] = {
    const S3: f64 = 1.732_050_807_568_877_2;
    const D: f64 = 4.0 * std::f64::consts::SQRT_2;
    [
        (1.0 + S3) / D,
        (3.0 + S3) / D,
        (3.0 - S3) / D,
        (1.0 - S3) / D,
    ]
};

/// db4 (eight taps): the minimum-phase spectral factor of
/// `|H(ω)|² = 2 cos^8(ω/2) P(sin²(ω/2))`, `P(y) = \sum_{k=0}^{3} C(3 + k, k) y^k`, normalised to
/// `sum h = sqrt 2` (evaluated to 20 digits; Daubechies 1992, table 6.1).
const DB4: [f64; 8] = [
    0.230_377_813_308_896_5,
    0.714_846_570_552_915_6,
    0.630_880_767_929_858_9,
    -0.027_983_769_416_859_854,
    -0.187_034_811_719_093_08,
    0.030_841_381_835_560_764,
    0.032_883_011_666_885_2,
    -0.010_597_401_785_069_032,
];

/// A Daubechies wavelet, named by its number of vanishing moments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Wavelet {
    /// Two vanishing moments, four taps.
    Db2,
    /// Four vanishing moments, eight taps: sharper bands, the default.
    #[default]
    Db4,
}

impl Wavelet {
    /// The low-pass (scaling) filter `h`.
    #[must_use]
    pub fn lowpass(self) -> &'static [f64] {
        match self {
            Self::Db2 => &DB2,
            Self::Db4 => &DB4,
        }
    }

    /// The high-pass (wavelet) filter `g[n] = (-1)^n h[L - 1 - n]`.
    #[must_use]
    pub fn highpass(self) -> Vec<f64> {
        let h = self.lowpass();
        h.iter()
            .rev()
            .enumerate()
            .map(|(n, &c)| if n % 2 == 0 { c } else { -c })
            .collect()
    }
}

/// A multi-level decomposition.
#[derive(Debug, Clone, PartialEq)]
pub struct Decomposition {
    /// The approximation at the coarsest level.
    pub approximation: Vec<f64>,
    /// The details, `details[0]` being level 1 (the finest, highest band).
    pub details: Vec<Vec<f64>>,
    /// The length of the signal before padding.
    pub len: usize,
    /// The wavelet used.
    pub wavelet: Wavelet,
}

/// The band covered by the detail of `level` (1-based) at `rate`: `fs / 2^{level+1} ..
/// fs / 2^level`. Level 1 reaches the Nyquist frequency, so its band does not pass
/// [`Band::fits`]; the edges are nominal, the filters overlapping their neighbours.
#[must_use]
pub fn detail_band(level: usize, rate: SampleRate) -> Band {
    let top = rate.hz() / 2f64.powi(level.min(1000) as i32);
    Band::new(top / 2.0, top)
}

/// The `levels`-level transform of `signal` (see the module documentation for the
/// extension and padding).
///
/// # Errors
/// [`SignalError::InvalidParameter`] for zero levels or a non-finite sample;
/// [`SignalError::TooShort`] when the signal has fewer than `2^levels` samples.
pub fn dwt(signal: &[f64], wavelet: Wavelet, levels: usize) -> Result<Decomposition, SignalError> {
    if levels == 0 || levels > 40 {
        return Err(SignalError::InvalidParameter(format!(
            "wavelet levels must be 1..=40, not {levels}"
        )));
    }
    let block = 1usize << levels;
    if signal.len() < block {
        return Err(SignalError::TooShort {
            len: signal.len(),
            needed: block,
            what: "a wavelet decomposition at this many levels",
        });
    }
    if signal.iter().any(|v| !v.is_finite()) {
        return Err(SignalError::InvalidParameter(
            "signal holds a non-finite sample".into(),
        ));
    }
    let padded_len = signal.len().div_ceil(block) * block;
    let mut approx = signal.to_vec();
    let last = signal.len() - 1;
    for i in signal.len()..padded_len {
        // Mirror about the last sample; a pad longer than the signal folds back again.
        let off = i - last;
        let period = 2 * last.max(1);
        let m = off % period;
        approx.push(signal[m.abs_diff(last)]);
    }
    let h = wavelet.lowpass();
    let g = wavelet.highpass();
    let mut details = Vec::with_capacity(levels);
    for _ in 0..levels {
        let n = approx.len();
        let half = n / 2;
        let mut a = vec![0.0; half];
        let mut d = vec![0.0; half];
        for k in 0..half {
            for (t, (&hc, &gc)) in h.iter().zip(&g).enumerate() {
                let x = approx[(2 * k + t) % n];
                a[k] += hc * x;
                d[k] += gc * x;
            }
        }
        details.push(d);
        approx = a;
    }
    Ok(Decomposition {
        approximation: approx,
        details,
        len: signal.len(),
        wavelet,
    })
}

/// The signal a decomposition came from (without its padding).
///
/// # Errors
/// [`SignalError::WrongLength`] when the bands' lengths are not those of a decomposition
/// (each detail twice the next, the coarsest as long as the approximation).
pub fn idwt(dec: &Decomposition) -> Result<Vec<f64>, SignalError> {
    let mut approx = dec.approximation.clone();
    let h = dec.wavelet.lowpass();
    let g = dec.wavelet.highpass();
    for d in dec.details.iter().rev() {
        if d.len() != approx.len() || d.is_empty() {
            return Err(SignalError::WrongLength {
                len: d.len(),
                expected: approx.len(),
                what: "a detail band of an inverse wavelet transform",
            });
        }
        let n = 2 * approx.len();
        let mut x = vec![0.0; n];
        for (k, (&ak, &dk)) in approx.iter().zip(d).enumerate() {
            for (t, (&hc, &gc)) in h.iter().zip(&g).enumerate() {
                x[(2 * k + t) % n] += hc * ak + gc * dk;
            }
        }
        approx = x;
    }
    if approx.len() < dec.len {
        return Err(SignalError::WrongLength {
            len: approx.len(),
            expected: dec.len,
            what: "an inverse wavelet transform",
        });
    }
    approx.truncate(dec.len);
    Ok(approx)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;

    #[test]
    fn filters_are_orthonormal() {
        for w in [Wavelet::Db2, Wavelet::Db4] {
            let h = w.lowpass();
            let g = w.highpass();
            assert!((h.iter().map(|c| c * c).sum::<f64>() - 1.0).abs() < 1e-14);
            assert!((h.iter().sum::<f64>() - std::f64::consts::SQRT_2).abs() < 1e-14);
            assert!(g.iter().sum::<f64>().abs() < 1e-14, "{w:?}: g has no DC");
            for m in 1..h.len() / 2 {
                let shifted: f64 = h.iter().zip(&h[2 * m..]).map(|(a, b)| a * b).sum();
                assert!(shifted.abs() < 1e-14, "{w:?} shift {m}: {shifted}");
            }
            for m in 0..h.len() / 2 {
                let cross: f64 = h.iter().zip(&g[2 * m..]).map(|(a, b)| a * b).sum();
                assert!(cross.abs() < 1e-14, "{w:?} h.g shift {m}: {cross}");
            }
        }
    }

    #[test]
    fn reconstruction_is_perfect_on_any_length() {
        let mut rng = SplitMix64::new(11);
        for (len, levels) in [(1000, 5), (1001, 3), (37, 4), (4096, 6), (9, 3)] {
            let x: Vec<f64> = (0..len).map(|_| rng.normal()).collect();
            for w in [Wavelet::Db2, Wavelet::Db4] {
                let dec = dwt(&x, w, levels).unwrap();
                let y = idwt(&dec).unwrap();
                let err = x
                    .iter()
                    .zip(&y)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                eprintln!("{w:?} len {len} levels {levels}: max error {err:.1e}");
                assert!(err < 1e-12, "{w:?} {len}: {err}");
            }
        }
    }

    #[test]
    fn a_tone_lands_in_its_detail_band() {
        let rate = SampleRate(48_000);
        for level in 1..=4 {
            let band = detail_band(level, rate);
            let f = (band.lo.0 * band.hi.0).sqrt();
            let x: Vec<f64> = (0..8192)
                .map(|n| (rate.omega(crate::units::Hz(f)) * n as f64).sin())
                .collect();
            let dec = dwt(&x, Wavelet::Db4, 5).unwrap();
            let energy = |v: &[f64]| v.iter().map(|c| c * c).sum::<f64>();
            let total: f64 =
                dec.details.iter().map(|d| energy(d)).sum::<f64>() + energy(&dec.approximation);
            let share = energy(&dec.details[level - 1]) / total;
            eprintln!("level {level} ({band}), tone {f:.0} Hz: {share:.3} of the energy");
            let most = dec.details.iter().map(|d| energy(d)).fold(0.0f64, f64::max);
            assert!(
                share > 0.85 && energy(&dec.details[level - 1]) == most,
                "level {level}: {share}"
            );
        }
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(dwt(&[], Wavelet::Db2, 1).is_err());
        assert!(dwt(&[1.0, 2.0, 3.0], Wavelet::Db2, 2).is_err());
        assert!(dwt(&[1.0, f64::NAN, 3.0, 4.0], Wavelet::Db2, 1).is_err());
        assert!(dwt(&[1.0; 16], Wavelet::Db2, 0).is_err());
        let mut dec = dwt(&[1.0; 16], Wavelet::Db2, 2).unwrap();
        dec.details[0].pop();
        assert!(idwt(&dec).is_err());
    }
}
