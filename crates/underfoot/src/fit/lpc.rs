//! Linear prediction for the modal analysis of isolated impacts.
//!
//! The tile paper (section 2.2) extracts "modal resonances ... by linear predictive coding, from
//! periods containing few, isolated impacts". A freely decaying sum of `M` damped modes
//!
//! ```math
//! x[n] = \sum_{m=1}^{M} A_m\, r_m^n \cos(\omega_m n + \phi_m)
//! ```
//!
//! obeys exactly a linear recursion of order `2M`: `x[n] + a_1 x[n-1] + ... + a_p x[n-p] = 0`
//! for `n >= p`, whose characteristic polynomial
//!
//! ```math
//! A(z) = 1 + \sum_{k=1}^{p} a_k z^{-k}
//! ```
//!
//! has the poles `p_m = r_m e^{\pm j\omega_m}` as its roots. A mode's frequency and decay
//! (the time to fall by `e`) follow from its pole:
//!
//! ```math
//! f = \frac{\arg p\, f_s}{2\pi}, \qquad \tau = \frac{-1}{f_s \ln|p|}.
//! ```
//!
//! # Finding the predictor
//!
//! **Autocorrelation method** ([`Method::Autocorrelation`]). The biased autocorrelation
//! `r[k] = (1/N) \sum_{n=0}^{N-1-k} x[n] x[n+k]` fills a Toeplitz system solved by the
//! Levinson-Durbin recursion: with `E_0 = r[0]`, for `i = 1..=p`
//!
//! ```math
//! k_i = -\frac{r[i] + \sum_{j=1}^{i-1} a_j^{(i-1)} r[i-j]}{E_{i-1}}, \quad
//!   a_i^{(i)} = k_i, \quad a_j^{(i)} = a_j^{(i-1)} + k_i a_{i-j}^{(i-1)}, \quad
//!   E_i = (1 - k_i^2) E_{i-1}.
//! ```
//!
//! The reflection coefficients satisfy `|k_i| < 1` for any signal that is not a sum of
//! undamped sinusoids, so the predictor is always minimum phase; `|k_i| >= 1` means the
//! recursion has lost its conditioning and is reported as an error. The price of that
//! guarantee is bias: the method implicitly windows the signal to `[0, N)` and pads it with
//! zeros, which on a decay of a few hundred samples pulls the poles inward and shortens the
//! decay times by several percent, and more at low orders.
//!
//! **Covariance method** ([`Method::Covariance`]). The forward prediction error is
//! minimised only where the predictor sees real samples,
//!
//! ```math
//! \min_a \sum_{n=p}^{N-1} \Big( x[n] + \sum_{k=1}^{p} a_k x[n-k] \Big)^2,
//! ```
//!
//! a linear least-squares problem solved by SVD of the `(N - p) x p` data matrix (not the
//! normal equations, whose condition number is the square). On a noiseless decay it is
//! exact, but noise in the regressors acts as a ridge term that erases the weak signal
//! directions: modes close together relative to `fs / p` merge. At -60 dB of noise, 45 and
//! 120 Hz at 2 kHz with `p = 8` come out as one mode at 90 Hz.
//!
//! **Minimum-norm method** ([`Method::MinimumNorm`], the default; Kumaresan and Tufts).
//! A long *backward* predictor of length `L = clamp(N / 3, p, 256)`,
//!
//! ```math
//! \min_b \sum_{n=0}^{N-1-L} \Big( x[n] + \sum_{k=1}^{L} b_k x[n+k] \Big)^2,
//! ```
//!
//! is solved with the data matrix truncated to its `p` largest singular values (the
//! order `p` is the rank of the signal model, i.e. the number of poles), taking the
//! minimum-norm solution. Its length gives resolution, the truncation removes most of the
//! noise, and the backward form separates the roots: the signal zeros of
//! `B(z) = 1 + \sum b_k z^{-k}` lie at `1 / p_m^*`, outside the unit circle, while the
//! `L - p` extraneous zeros of a minimum-norm solution lie inside it. The poles are taken
//! as `1 / z^*` of the zeros, so that the extraneous ones land outside the circle and are
//! discarded by the same rule as unstable poles. Spare rank (`p > 2M`) yields weak extra
//! modes that the amplitudes reveal.
//!
//! The forward-backward ("modified covariance") variant is not used: it assumes that the
//! same coefficients predict backwards, true of undamped sinusoids but not of decays,
//! whose backward poles are `1 / p*`.
//!
//! # Amplitudes
//!
//! With the kept poles fixed, the amplitudes are linear: the signal is fitted in least
//! squares by the damped cosines and sines `r^n cos(ωn)`, `r^n sin(ωn)` of every kept mode,
//! and a mode's amplitude is the norm of its pair of coefficients, its envelope at `n = 0`
//! (the first sample of the signal given).

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

use crate::units::{Band, Hz, SampleRate, Seconds};

/// The largest prediction order accepted.
pub const MAX_PREDICTOR_ORDER: usize = 128;

/// Singular values below this fraction of the largest carry no information at the order
/// asked for (a noiseless signal with fewer modes than `order / 2`); they are dropped so the
/// solution stays the minimum-norm one instead of amplifying rounding.
const SVD_TOLERANCE: f64 = 1e-10;

/// What went wrong in a linear-prediction analysis.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LpcError {
    /// The order is zero or above [`MAX_PREDICTOR_ORDER`].
    #[error("prediction order {order} is out of range (1..={MAX_PREDICTOR_ORDER})")]
    InvalidOrder {
        /// The order asked for.
        order: usize,
    },
    /// The signal has too few samples for the order.
    #[error("signal of {len} samples is too short: order {order} needs at least {needed}")]
    TooShort {
        /// Samples given.
        len: usize,
        /// The order asked for.
        order: usize,
        /// Samples needed.
        needed: usize,
    },
    /// The signal holds a NaN or an infinity.
    #[error("signal sample {index} is not finite")]
    NonFinite {
        /// Index of the first bad sample.
        index: usize,
    },
    /// The signal is all zeros.
    #[error("signal is silent")]
    Silent,
    /// The Levinson-Durbin recursion met a reflection coefficient of modulus 1 or more.
    #[error("ill-conditioned recursion: reflection coefficient {k} at stage {stage}")]
    IllConditioned {
        /// The stage (1-based) where it happened.
        stage: usize,
        /// The reflection coefficient.
        k: f64,
    },
    /// The band does not fit the sample rate.
    #[error("band {band} does not fit sample rate {rate}")]
    BandOutOfRange {
        /// The band asked for.
        band: Band,
        /// The sample rate.
        rate: SampleRate,
    },
    /// A least-squares step failed.
    #[error("numerical failure: {0}")]
    Numerical(&'static str),
}

/// How the predictor coefficients are estimated (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Biased autocorrelation and Levinson-Durbin: always stable, biased on short decays.
    Autocorrelation,
    /// Least squares over the samples the predictor fully sees: exact on clean decays,
    /// biased by noise when modes crowd together relative to the order.
    Covariance,
    /// Kumaresan-Tufts: a long backward predictor of rank `order`, whose signal zeros are
    /// the reflections `1 / p*` of the modes; robust to noise.
    #[default]
    MinimumNorm,
}

/// A linear predictor of order `p`.
#[derive(Debug, Clone, PartialEq)]
pub struct Predictor {
    /// `[1, a_1, ..., a_p]`: the coefficients of `A(z)` in powers of `z^-1`.
    pub coefficients: Vec<f64>,
    /// The reflection coefficients `k_1..=k_p` of the Levinson-Durbin recursion; `None`
    /// for the covariance method, which does not go through it.
    pub reflection: Option<Vec<f64>>,
    /// The mean squared prediction error per sample.
    pub error_power: f64,
}

/// One damped mode found in a decay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LpcMode {
    /// Its frequency.
    pub frequency: Hz,
    /// The time its envelope takes to fall by a factor `e`.
    pub decay: Seconds,
    /// Its envelope at the first sample.
    pub amplitude: f64,
}

/// Checks that `x` is usable for an order-`order` analysis needing `needed` samples.
fn check(x: &[f64], order: usize, needed: usize) -> Result<(), LpcError> {
    if order == 0 || order > MAX_PREDICTOR_ORDER {
        return Err(LpcError::InvalidOrder { order });
    }
    if x.len() < needed {
        return Err(LpcError::TooShort {
            len: x.len(),
            order,
            needed,
        });
    }
    if let Some(index) = x.iter().position(|v| !v.is_finite()) {
        return Err(LpcError::NonFinite { index });
    }
    if x.iter().all(|&v| v == 0.0) {
        return Err(LpcError::Silent);
    }
    Ok(())
}

/// The biased autocorrelation `r[0..=max_lag]` of `x`.
///
/// # Errors
/// [`LpcError::TooShort`] when `x` has `max_lag` samples or fewer, [`LpcError::NonFinite`]
/// and [`LpcError::Silent`] for a signal that is not finite or all zeros.
pub fn autocorrelation(x: &[f64], max_lag: usize) -> Result<Vec<f64>, LpcError> {
    check(x, max_lag.max(1), max_lag + 1)?;
    let n = x.len() as f64;
    Ok((0..=max_lag)
        .map(|k| x.iter().zip(&x[k..]).map(|(a, b)| a * b).sum::<f64>() / n)
        .collect())
}

/// The Levinson-Durbin recursion on the autocorrelation `r[0..=order]`.
///
/// # Errors
/// [`LpcError::InvalidOrder`] for order 0 or above [`MAX_PREDICTOR_ORDER`]; [`LpcError::TooShort`]
/// when `r` has fewer than `order + 1` lags; [`LpcError::NonFinite`] or
/// [`LpcError::Silent`] for a bad `r`; [`LpcError::IllConditioned`] when a reflection
/// coefficient reaches modulus 1 (or the error power stops being positive).
pub fn levinson_durbin(r: &[f64], order: usize) -> Result<Predictor, LpcError> {
    check(r, order, order + 1)?;
    if r[0] <= 0.0 {
        return Err(LpcError::Silent);
    }
    let mut a = vec![0.0; order + 1];
    a[0] = 1.0;
    let mut reflection = Vec::with_capacity(order);
    let mut err = r[0];
    let mut prev = a.clone();
    for i in 1..=order {
        let acc: f64 = (0..i).map(|j| a[j] * r[i - j]).sum();
        let k = -acc / err;
        if !k.is_finite() || k.abs() >= 1.0 {
            return Err(LpcError::IllConditioned { stage: i, k });
        }
        prev.copy_from_slice(&a);
        for j in 1..i {
            a[j] = prev[j] + k * prev[i - j];
        }
        a[i] = k;
        err *= 1.0 - k * k;
        if err <= 0.0 {
            return Err(LpcError::IllConditioned { stage: i, k });
        }
        reflection.push(k);
    }
    Ok(Predictor {
        coefficients: a,
        reflection: Some(reflection),
        error_power: err,
    })
}

/// Least squares `min |m x - rhs|` by SVD, dropping singular values below
/// [`SVD_TOLERANCE`] of the largest.
fn least_squares(m: DMatrix<f64>, rhs: &DVector<f64>) -> Result<DVector<f64>, LpcError> {
    if rhs.iter().any(|v| !v.is_finite()) {
        return Err(LpcError::Numerical("a least-squares target is not finite"));
    }
    let svd = crate::numeric::svd(m).map_err(|e| LpcError::Numerical(e.0))?;
    let tol = svd.singular_values.max() * SVD_TOLERANCE;
    let x = svd.solve(rhs, tol).map_err(LpcError::Numerical)?;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(LpcError::Numerical("least-squares solution is not finite"));
    }
    Ok(x)
}

/// The order-`order` forward predictor of `x` by `method`.
///
/// # Errors
/// [`LpcError::Numerical`] for [`Method::MinimumNorm`], whose predictor is a backward one
/// of a different length (see [`modes_with`]); otherwise
/// [`LpcError::InvalidOrder`], [`LpcError::TooShort`] (the covariance method needs
/// `2 order + 1` samples, the autocorrelation method `order + 1`), [`LpcError::NonFinite`],
/// [`LpcError::Silent`]; [`LpcError::IllConditioned`] from the recursion;
/// [`LpcError::Numerical`] when the least squares fail.
pub fn predictor(x: &[f64], order: usize, method: Method) -> Result<Predictor, LpcError> {
    match method {
        Method::MinimumNorm => Err(LpcError::Numerical(
            "the minimum-norm method has no order-p forward predictor",
        )),
        Method::Autocorrelation => {
            check(x, order, order + 1)?;
            levinson_durbin(&autocorrelation(x, order)?, order)
        }
        Method::Covariance => {
            check(x, order, 2 * order + 1)?;
            let rows = x.len() - order;
            let m = DMatrix::from_fn(rows, order, |i, k| x[order + i - k - 1]);
            let rhs = DVector::from_fn(rows, |i, _| -x[order + i]);
            let sol = least_squares(m, &rhs)?;
            let mut coefficients = Vec::with_capacity(order + 1);
            coefficients.push(1.0);
            coefficients.extend(sol.iter());
            let error_power = (order..x.len())
                .map(|n| {
                    (0..=order)
                        .map(|k| coefficients[k] * x[n - k])
                        .sum::<f64>()
                        .powi(2)
                })
                .sum::<f64>()
                / rows as f64;
            Ok(Predictor {
                coefficients,
                reflection: None,
                error_power,
            })
        }
    }
}

/// The damped modes of an isolated decay by the minimum-norm method, sorted by rising
/// frequency. See [`modes_with`].
///
/// # Errors
/// As [`modes_with`].
pub fn modes_from_lpc(
    signal: &[f64],
    rate: SampleRate,
    order: usize,
    band: Option<Band>,
) -> Result<Vec<LpcMode>, LpcError> {
    modes_with(signal, rate, order, band, Method::MinimumNorm)
}

/// The damped modes of an isolated decay `signal` (starting at the impact), sorted by
/// rising frequency.
///
/// The poles of the order-`order` model (the roots of the predictor polynomial, or their
/// reflections for [`Method::MinimumNorm`]) that have a positive imaginary
/// part, lie inside the unit circle and, if `band` is given, have their frequency within
/// it, are the modes; their amplitudes come from a least-squares fit of the signal by
/// damped sinusoids with those poles. The order should exceed twice the number of modes
/// expected, so that spare poles take up the noise. An empty list means that no pole
/// qualified.
///
/// # Errors
/// [`LpcError::BandOutOfRange`] for a band that does not fit `rate`; otherwise as
/// [`predictor`], and [`LpcError::Numerical`] when the roots cannot be found.
pub fn modes_with(
    signal: &[f64],
    rate: SampleRate,
    order: usize,
    band: Option<Band>,
    method: Method,
) -> Result<Vec<LpcMode>, LpcError> {
    if let Some(b) = band
        && !b.fits(rate)
    {
        return Err(LpcError::BandOutOfRange { band: b, rate });
    }
    let roots = match method {
        Method::MinimumNorm => minimum_norm_poles(signal, order)?,
        _ => {
            let pred = predictor(signal, order, method)?;
            crate::numeric::roots(&pred.coefficients)
                .ok_or(LpcError::Numerical("predictor roots did not converge"))?
        }
    };
    let fs = rate.hz();
    let mut poles: Vec<(Complex64, Hz)> = roots
        .into_iter()
        .filter(|p| p.im > 0.0 && p.norm() < 1.0)
        .map(|p| (p, Hz(p.arg() * fs / std::f64::consts::TAU)))
        .filter(|(_, f)| band.is_none_or(|b| f.0 >= b.lo.0 && f.0 <= b.hi.0))
        .collect();
    poles.sort_by(|x, y| x.1.0.total_cmp(&y.1.0));
    if poles.is_empty() {
        return Ok(Vec::new());
    }
    let amplitudes = mode_amplitudes(signal, &poles)?;
    Ok(poles
        .iter()
        .zip(amplitudes)
        .map(|((p, f), amplitude)| LpcMode {
            frequency: *f,
            decay: Seconds(-1.0 / (fs * p.norm().ln())),
            amplitude,
        })
        .collect())
}

/// The longest backward predictor of the minimum-norm method: resolution grows with it,
/// and so does the cost of its roots (cubic).
const MAX_PREDICTION_LENGTH: usize = 256;

/// Pole candidates by the Kumaresan-Tufts minimum-norm backward predictor: the zeros of
/// `B(z)` outside the unit circle, reflected to `1 / z*`; the zeros inside are the
/// extraneous ones and come back as their own reflections, outside, to be discarded.
fn minimum_norm_poles(x: &[f64], order: usize) -> Result<Vec<Complex64>, LpcError> {
    check(x, order, 2 * order + 1)?;
    let len = (x.len() / 3).min(MAX_PREDICTION_LENGTH).max(order);
    let rows = x.len() - len;
    let m = DMatrix::from_fn(rows, len, |i, k| x[i + k + 1]);
    let rhs = DVector::from_fn(rows, |i, _| -x[i]);
    let svd = crate::numeric::svd(m).map_err(|e| LpcError::Numerical(e.0))?;
    let (Some(u), Some(v_t)) = (&svd.u, &svd.v_t) else {
        return Err(LpcError::Numerical("SVD without singular vectors"));
    };
    let mut ranked: Vec<usize> = (0..svd.singular_values.len()).collect();
    ranked.sort_by(|&i, &j| svd.singular_values[j].total_cmp(&svd.singular_values[i]));
    let top = svd.singular_values.max();
    let mut b = DVector::<f64>::zeros(len);
    for &i in ranked.iter().take(order) {
        let s = svd.singular_values[i];
        if s <= top * SVD_TOLERANCE {
            break;
        }
        let coeff = u.column(i).dot(&rhs) / s;
        b += v_t.row(i).transpose() * coeff;
    }
    if b.iter().any(|v| !v.is_finite()) {
        return Err(LpcError::Numerical("backward predictor is not finite"));
    }
    let mut poly = Vec::with_capacity(len + 1);
    poly.push(1.0);
    poly.extend(b.iter());
    // Trailing zeros of the predictor are zeros at the origin, which have no reflection.
    while poly.len() > 1 && poly.last() == Some(&0.0) {
        poly.pop();
    }
    let zeros = crate::numeric::roots(&poly)
        .ok_or(LpcError::Numerical("predictor roots did not converge"))?;
    Ok(zeros
        .into_iter()
        .filter(|z| z.norm() > 0.0)
        .map(|z| 1.0 / z.conj())
        .collect())
}

/// Least-squares amplitudes of damped sinusoids with the given poles.
fn mode_amplitudes(x: &[f64], poles: &[(Complex64, Hz)]) -> Result<Vec<f64>, LpcError> {
    let m = DMatrix::from_fn(x.len(), 2 * poles.len(), |n, c| {
        let z = poles[c / 2].0.powu(n as u32);
        if c % 2 == 0 { z.re } else { z.im }
    });
    // Columns of fast decays shrink to nothing, so they are scaled to unit norm first.
    let mut scale = vec![1.0; m.ncols()];
    let mut m = m;
    for (j, s) in scale.iter_mut().enumerate() {
        let norm = m.column(j).norm();
        if norm > 0.0 {
            *s = 1.0 / norm;
            m.column_mut(j).scale_mut(*s);
        }
    }
    let sol = least_squares(m, &DVector::from_column_slice(x))?;
    Ok((0..poles.len())
        .map(|i| (sol[2 * i] * scale[2 * i]).hypot(sol[2 * i + 1] * scale[2 * i + 1]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;

    /// `(frequency, decay, amplitude, phase)` of the test modes.
    const MODES: [(f64, f64, f64, f64); 3] = [
        (45.0, 0.08, 1.0, 0.3),
        (120.0, 0.04, 0.7, 1.1),
        (310.0, 0.015, 0.5, -0.4),
    ];

    /// The three modes at `rate`, `n` samples, without noise.
    fn clean_decay(rate: SampleRate, n: usize) -> Vec<f64> {
        let fs = rate.hz();
        (0..n)
            .map(|i| {
                let t = i as f64 / fs;
                MODES
                    .iter()
                    .map(|&(f, tau, a, ph)| {
                        a * (-t / tau).exp() * (std::f64::consts::TAU * f * t + ph).cos()
                    })
                    .sum()
            })
            .collect()
    }

    /// The three modes at `rate` for `len` seconds, plus white noise at -60 dB of the peak.
    fn decay(rate: SampleRate, len: f64, seed: u64) -> Vec<f64> {
        let mut clean = clean_decay(rate, (len * rate.hz()) as usize);
        let peak = clean.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut rng = SplitMix64::new(seed);
        for v in &mut clean {
            *v += 1e-3 * peak * rng.normal();
        }
        clean
    }

    /// Worst relative errors in frequency and decay of the three test modes.
    fn worst_errors(modes: &[LpcMode]) -> (f64, f64) {
        let mut worst = (0.0f64, 0.0f64);
        for &(f, tau, _, _) in &MODES {
            let m = modes
                .iter()
                .min_by(|x, y| {
                    (x.frequency.0 - f)
                        .abs()
                        .total_cmp(&(y.frequency.0 - f).abs())
                })
                .expect("some mode");
            worst.0 = worst.0.max((m.frequency.0 - f).abs() / f);
            worst.1 = worst.1.max((m.decay.0 - tau).abs() / tau);
        }
        worst
    }

    #[test]
    #[ignore = "slow tier: refits"]
    fn three_mode_decay_is_recovered_at_2_and_8_khz() {
        for (rate, seed) in [(SampleRate(2000), 1), (SampleRate(8000), 2)] {
            let x = decay(rate, 0.4, seed);
            for order in [8, 12] {
                let band = Band::new(20.0, 0.45 * rate.hz());
                let modes = modes_from_lpc(&x, rate, order, Some(band)).unwrap();
                let (ef, ed) = worst_errors(&modes);
                eprintln!("{rate} order {order}: freq err {ef:.2e}, decay err {ed:.2e}");
                assert!(ef < 0.001, "{rate} order {order}: frequency error {ef}");
                assert!(ed < 0.01, "{rate} order {order}: decay error {ed}");
            }
        }
    }

    #[test]
    fn amplitudes_of_a_clean_decay_are_exact() {
        let rate = SampleRate(2000);
        let x = clean_decay(rate, 600);
        let modes = modes_from_lpc(&x, rate, 6, None).unwrap();
        assert_eq!(modes.len(), 3);
        for (m, &(f, tau, a, _)) in modes.iter().zip(&MODES) {
            assert!((m.frequency.0 - f).abs() < 1e-6 * f, "{m:?}");
            assert!((m.decay.0 - tau).abs() < 1e-6 * tau, "{m:?}");
            assert!((m.amplitude - a).abs() < 1e-6, "{m:?}");
        }
    }

    /// On the same noisy data the short forward predictors are far off, which is why the
    /// minimum-norm method is the default.
    #[test]
    fn minimum_norm_beats_short_predictors_on_noisy_decays() {
        let rate = SampleRate(8000);
        let x = decay(rate, 0.4, 3);
        let band = Some(Band::new(20.0, 3000.0));
        let err = |method| worst_errors(&modes_with(&x, rate, 12, band, method).unwrap()).1;
        let (mn, cov, auto) = (
            err(Method::MinimumNorm),
            err(Method::Covariance),
            err(Method::Autocorrelation),
        );
        eprintln!(
            "decay error: minimum-norm {mn:.2e}, covariance {cov:.2e}, autocorrelation {auto:.2e}"
        );
        assert!(mn < cov && mn < auto, "{mn} vs {cov}, {auto}");
    }

    #[test]
    fn levinson_matches_a_known_ar2_process() {
        // The autocorrelation of an AR(2) with poles 0.9 e^{±j0.5}: the recursion must give
        // back its coefficients and a zero third reflection coefficient.
        let (rho, w) = (0.9f64, 0.5f64);
        let (a1, a2) = (-2.0 * rho * w.cos(), rho * rho);
        // Yule-Walker: r1 = -a1 r0 / (1 + a2); r_k = -a1 r_{k-1} - a2 r_{k-2}.
        let mut r = vec![1.0, -a1 / (1.0 + a2)];
        for k in 2..4 {
            r.push(-a1 * r[k - 1] - a2 * r[k - 2]);
        }
        let p = levinson_durbin(&r, 3).unwrap();
        assert!((p.coefficients[1] - a1).abs() < 1e-12);
        assert!((p.coefficients[2] - a2).abs() < 1e-12);
        assert!(p.coefficients[3].abs() < 1e-12);
        let k = p.reflection.unwrap();
        assert!(k[2].abs() < 1e-12 && k.iter().all(|k| k.abs() < 1.0));
    }

    #[test]
    fn an_undamped_sinusoid_is_ill_conditioned_for_levinson() {
        // r[k] = cos(w k) is the autocorrelation of a pure tone: the second reflection
        // coefficient is exactly -1.
        let r: Vec<f64> = (0..3).map(|k| (0.7 * k as f64).cos()).collect();
        assert!(matches!(
            levinson_durbin(&r, 2),
            Err(LpcError::IllConditioned { stage: 2, .. })
        ));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let rate = SampleRate(8000);
        let silent = vec![0.0; 1000];
        let mut nan = decay(rate, 0.1, 4);
        nan[17] = f64::NAN;
        let short = decay(rate, 0.001, 5);
        for method in [Method::Covariance, Method::Autocorrelation] {
            assert_eq!(
                modes_with(&silent, rate, 8, None, method),
                Err(LpcError::Silent)
            );
            assert_eq!(
                modes_with(&nan, rate, 8, None, method),
                Err(LpcError::NonFinite { index: 17 })
            );
            assert!(matches!(
                modes_with(&short, rate, 8, None, method),
                Err(LpcError::TooShort { .. })
            ));
            assert!(matches!(
                modes_with(&[], rate, 8, None, method),
                Err(LpcError::TooShort { .. })
            ));
            assert!(matches!(
                modes_with(&nan[18..], rate, 0, None, method),
                Err(LpcError::InvalidOrder { order: 0 })
            ));
        }
        assert!(matches!(
            modes_from_lpc(&nan[18..], rate, 8, Some(Band::new(100.0, 5000.0))),
            Err(LpcError::BandOutOfRange { .. })
        ));
        assert!(matches!(
            autocorrelation(&[1.0], 3),
            Err(LpcError::TooShort { .. })
        ));
    }
}
