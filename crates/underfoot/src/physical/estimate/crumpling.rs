//! The tile paper's crumpling measure and impact event rate (section 2.2).
//!
//! **Measure.** The detail band `d_j` of a Daubechies decomposition (level `j = 2`, 6-12 kHz
//! at 48 kHz, in the tile paper) isolates impact onsets. Each coefficient stands for `2^j`
//! samples, so the band is brought back to the signal's time axis by holding each
//! coefficient over its samples, `d(t) = d_j[⌊t / 2^j⌋]`. The crumpling measure is its
//! local RMS under a Gaussian window,
//!
//! ```math
//! I(t) = \big[ (g * d^2)(t) \big]^{1/2}, \qquad
//!   g(t) = \frac{e^{-t^2 / 2\sigma^2}}{\sum_s e^{-s^2 / 2\sigma^2}},
//! ```
//!
//! with `g` sampled out to `±4σ` and normalised to unit sum. Near the ends the window is
//! renormalised to the part that lies inside the signal, so `I` is a local RMS everywhere
//! rather than dipping at the edges. The convolution runs by FFT.
//!
//! **Event rate.** After Cook's ansatz, the rate of impacts per second is
//! `N(t) = e^{α I(t)} - 1` ([`event_rate`]).
//!
//! **Choosing α** ([`estimate_rate_scale`]). The tile paper leaves `α` free. Here it is fixed by
//! counting: the onsets of the same detail band are counted ([`impact_onsets`]), and `α`
//! is the unique value for which the expected number of events equals that count,
//!
//! ```math
//! \frac{1}{f_s} \sum_n \big( e^{\alpha I[n]} - 1 \big) = K,
//! ```
//!
//! i.e. the mean of `N` over the recording equals the onsets per second. The left side is
//! zero at `α = 0` and increases without bound for any non-silent `I`, so the root exists;
//! it is bracketed by doubling, then found by Newton's method from above the root (the
//! left side is convex in `α`, so the steps fall monotonically onto it).
//!
//! **Onsets.** The band's energy `d_j^2` is smoothed by a short moving average (0.5 ms by
//! default, to merge the oscillation within one burst), and an onset is a local maximum of
//! it that exceeds both `noise_factor` times its median (the noise floor, as impacts
//! occupy a minority of the time) and the loudest peak less `dynamic_range`, and is the
//! largest within `±separation`. Impacts closer than `separation` (1 ms by default) count once.

use num_complex::Complex64;
use underfoot_fft::RealFftPlanner;

use crate::signal::SignalError;
use crate::signal::wavelet::{Wavelet, dwt};
use crate::units::{Decibels, SampleRate, Seconds};

/// What went wrong in a crumpling analysis.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CrumplingError {
    /// The wavelet decomposition refused the signal.
    #[error(transparent)]
    Signal(#[from] SignalError),
    /// A parameter is out of range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(&'static str),
    /// Onsets were counted but the measure is zero everywhere, so no `α` fits.
    #[error("the crumpling measure is zero everywhere but {onsets} onsets were counted")]
    NoActivity {
        /// The onset count.
        onsets: usize,
    },
}

/// Parameters of the onset count (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImpactOnsetConfig {
    /// An onset's smoothed energy must exceed this many times the median.
    pub noise_factor: f64,
    /// ... and be within this much of the loudest onset.
    pub dynamic_range: Decibels,
    /// Length of the moving average applied to the band's energy.
    pub smoothing: Seconds,
    /// Onsets closer than this count once.
    pub separation: Seconds,
}

impl Default for ImpactOnsetConfig {
    fn default() -> Self {
        Self {
            noise_factor: 10.0,
            dynamic_range: Decibels(30.0),
            smoothing: Seconds(0.0005),
            separation: Seconds(0.001),
        }
    }
}

/// The detail band `level` of `signal` (its coefficients), after checking the parameters.
fn detail(signal: &[f64], level: usize, wavelet: Wavelet) -> Result<Vec<f64>, CrumplingError> {
    if level == 0 {
        return Err(CrumplingError::InvalidParameter("level must be at least 1"));
    }
    let mut dec = dwt(signal, wavelet, level)?;
    Ok(dec.details.swap_remove(level - 1))
}

/// The crumpling measure `I(t)` of `signal`, one value per sample, from the detail band
/// `level` and a Gaussian window of standard deviation `window`.
///
/// # Errors
/// [`CrumplingError::InvalidParameter`] for level 0 or a window that is not positive and
/// finite; [`CrumplingError::Signal`] when the signal is shorter than `2^level` samples
/// or not finite.
pub fn crumpling_measure(
    signal: &[f64],
    rate: SampleRate,
    level: usize,
    wavelet: Wavelet,
    window: Seconds,
) -> Result<Vec<f64>, CrumplingError> {
    if !(window.0.is_finite() && window.0 > 0.0) {
        return Err(CrumplingError::InvalidParameter(
            "window must be positive and finite",
        ));
    }
    let d = detail(signal, level, wavelet)?;
    let hold = 1usize << level;
    let energy: Vec<f64> = (0..signal.len()).map(|n| d[n / hold].powi(2)).collect();
    let sigma = (window.0 * rate.hz()).max(1e-3);
    let half = ((4.0 * sigma).ceil() as usize).min(signal.len());
    let kernel: Vec<f64> = (0..=2 * half)
        .map(|i| {
            let t = i as f64 - half as f64;
            (-t * t / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let smoothed = convolve_same(&energy, &kernel);
    // Kernel mass inside the signal at each output: renormalises the edges.
    let mut prefix = vec![0.0; kernel.len() + 1];
    for (i, k) in kernel.iter().enumerate() {
        prefix[i + 1] = prefix[i] + k;
    }
    let n = signal.len();
    Ok(smoothed
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            // Tap j (centred index j - half) reads sample i + half - j, inside iff
            // i + half + 1 - n <= j <= i + half.
            let lo = (i + half + 1).saturating_sub(n);
            let hi = (i + half).min(2 * half);
            let mass = prefix[hi + 1] - prefix[lo];
            (s / mass).max(0.0).sqrt()
        })
        .collect())
}

/// `y[i] = sum_j k[j] x[i + half - j]` for a kernel of odd length `2 half + 1`, zero outside `x`.
fn convolve_same(x: &[f64], k: &[f64]) -> Vec<f64> {
    let half = k.len() / 2;
    let size = (x.len() + k.len()).next_power_of_two();
    let mut planner = RealFftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(size);
    let inv = planner.plan_fft_inverse(size);
    let spectrum = |v: &[f64]| -> Vec<Complex64> {
        let mut buf = vec![0.0; size];
        buf[..v.len()].copy_from_slice(v);
        let mut out = fwd.make_output_vec();
        // Lengths come from the plan, so processing cannot fail.
        let _ = fwd.process(&mut buf, &mut out);
        out
    };
    let mut prod: Vec<Complex64> = spectrum(x)
        .iter()
        .zip(spectrum(k))
        .map(|(a, b)| a * b / size as f64)
        .collect();
    // The imaginary parts of DC and Nyquist are zero in exact arithmetic; realfft checks.
    if let Some(first) = prod.first_mut() {
        first.im = 0.0;
    }
    if let Some(last) = prod.last_mut() {
        last.im = 0.0;
    }
    let mut full = vec![0.0; size];
    let _ = inv.process(&mut prod, &mut full);
    full[half..half + x.len()].to_vec()
}

/// The event rate `N(t) = e^{a I(t)} - 1` in impacts per second, per sample of the measure.
#[must_use]
pub fn event_rate(measure: &[f64], a: f64) -> Vec<f64> {
    measure.iter().map(|&i| (a * i).exp_m1()).collect()
}

/// The onset times of impacts in the detail band `level` of `signal` (see the module
/// documentation).
///
/// # Errors
/// As [`crumpling_measure`]; [`CrumplingError::InvalidParameter`] for a configuration
/// whose values are negative or not finite.
pub fn impact_onsets(
    signal: &[f64],
    rate: SampleRate,
    level: usize,
    wavelet: Wavelet,
    cfg: &ImpactOnsetConfig,
) -> Result<Vec<Seconds>, CrumplingError> {
    let valid = |v: f64| v.is_finite() && v >= 0.0;
    if !(valid(cfg.noise_factor)
        && valid(cfg.dynamic_range.0)
        && valid(cfg.smoothing.0)
        && valid(cfg.separation.0))
    {
        return Err(CrumplingError::InvalidParameter(
            "onset parameters must be finite and non-negative",
        ));
    }
    let d = detail(signal, level, wavelet)?;
    let coeff_rate = rate.hz() / (1usize << level) as f64;
    let width = ((cfg.smoothing.0 * coeff_rate).round() as usize).max(1);
    let sep = (cfg.separation.0 * coeff_rate).round() as usize;
    let mut energy = vec![0.0; d.len()];
    let mut acc = 0.0;
    for (i, e) in energy.iter_mut().enumerate() {
        acc += d[i] * d[i];
        if i >= width {
            acc -= d[i - width] * d[i - width];
        }
        *e = acc.max(0.0) / width as f64;
    }
    // The upper median (the nearest rank), as the noise floor.
    let median = crate::numeric::percentile(&energy, 0.5).unwrap_or(0.0);
    let loudest = energy.iter().copied().fold(0.0, f64::max);
    // Energies are squares, hence a tenth of the decibels.
    let threshold =
        (cfg.noise_factor * median).max(loudest * 10f64.powf(-cfg.dynamic_range.0 / 10.0));
    if loudest <= 0.0 {
        return Ok(Vec::new());
    }
    let mut onsets = Vec::new();
    for (k, &e) in energy.iter().enumerate() {
        if e <= threshold {
            continue;
        }
        let lo = k.saturating_sub(sep);
        let hi = (k + sep).min(energy.len() - 1);
        // Strictly above what precedes and at least what follows: a plateau counts once.
        let is_peak =
            energy[lo..k].iter().all(|&x| x < e) && energy[k + 1..=hi].iter().all(|&x| x <= e);
        if is_peak {
            // The smoothed peak trails the onset by the averaging window.
            let start = k.saturating_sub(width - 1);
            onsets.push(Seconds(start as f64 / coeff_rate));
        }
    }
    Ok(onsets)
}

/// The scale `α` for which the mean event rate of `measure` (sampled at `rate`) over the
/// recording equals `onsets` impacts over its duration (see the module documentation).
/// Zero onsets give `α = 0`, a rate of zero everywhere.
///
/// # Errors
/// [`CrumplingError::InvalidParameter`] for an empty measure or one with a negative or
/// non-finite value; [`CrumplingError::NoActivity`] when the measure is zero everywhere
/// but `onsets > 0`.
pub fn estimate_rate_scale(
    measure: &[f64],
    rate: SampleRate,
    onsets: usize,
) -> Result<f64, CrumplingError> {
    if measure.is_empty() || measure.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(CrumplingError::InvalidParameter(
            "measure must be non-empty, finite and non-negative",
        ));
    }
    if onsets == 0 {
        return Ok(0.0);
    }
    let peak = measure.iter().copied().fold(0.0, f64::max);
    if peak <= 0.0 {
        return Err(CrumplingError::NoActivity { onsets });
    }
    let target = onsets as f64;
    let expected = |a: f64| measure.iter().map(|&i| (a * i).exp_m1()).sum::<f64>() / rate.hz();
    let (mut lo, mut hi) = (0.0, 1.0 / peak);
    // The expectation grows at least linearly in a, so doubling brackets the root quickly;
    // an overflow to infinity still brackets it.
    while expected(hi) < target {
        lo = hi;
        hi *= 2.0;
        if !hi.is_finite() {
            return Err(CrumplingError::NoActivity { onsets });
        }
    }
    // The expectation is convex in a: Newton's steps from above the root stay above it
    // and fall toward it monotonically, so they stop, to rounding, where a step no longer
    // moves down (a handful of passes over the measure, where bisection took sixty).
    let mut a = hi;
    for _ in 0..200 {
        let (sum, slope) = measure.iter().fold((0.0, 0.0), |(f, d), &i| {
            let e = (a * i).exp_m1();
            (f + e, d + i * (e + 1.0))
        });
        let excess = sum / rate.hz() - target;
        let next = a - excess * rate.hz() / slope;
        if !(next < a && next >= lo) {
            break;
        }
        a = next;
    }
    Ok(a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;

    const RATE: SampleRate = SampleRate(48_000);
    const PEAK_RATE: f64 = 100.0;

    /// Impacts per second: zero, a rise to the peak and back, zero.
    fn true_rate(t: f64) -> f64 {
        match t {
            t if (0.5..2.0).contains(&t) => PEAK_RATE * (t - 0.5) / 1.5,
            t if (2.0..3.5).contains(&t) => PEAK_RATE * (3.5 - t) / 1.5,
            _ => 0.0,
        }
    }

    /// Four seconds of Poisson impacts (short 7.5-10.5 kHz bursts) over a 150 Hz rumble and
    /// noise at -60 dB; returns the signal and the number of impacts.
    fn impacts(seed: u64) -> (Vec<f64>, usize) {
        let fs = RATE.hz();
        let n = (4.0 * fs) as usize;
        let mut rng = SplitMix64::new(seed);
        let mut x: Vec<f64> = (0..n)
            .map(|i| {
                0.3 * (std::f64::consts::TAU * 150.0 * i as f64 / fs).sin() + 1e-3 * rng.normal()
            })
            .collect();
        let mut count = 0;
        let mut t = 0.0;
        loop {
            // Thinning: candidates at the peak rate, kept in proportion to the true rate.
            t += -(1.0 - rng.uniform()).ln() / PEAK_RATE;
            if t >= 4.0 {
                break;
            }
            if rng.uniform() >= true_rate(t) / PEAK_RATE {
                continue;
            }
            count += 1;
            let (amp, f, phase) = (
                0.5 + 0.5 * rng.uniform(),
                7500.0 + 3000.0 * rng.uniform(),
                rng.uniform() * 6.0,
            );
            let start = (t * fs) as usize;
            for (k, v) in x[start..(start + 150).min(n)].iter_mut().enumerate() {
                let s = k as f64 / fs;
                *v += amp * (-s / 2e-4).exp() * (std::f64::consts::TAU * f * s + phase).sin();
            }
        }
        (x, count)
    }

    fn pearson(a: &[f64], b: &[f64]) -> f64 {
        let n = a.len() as f64;
        let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
        let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
        let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
        let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
        cov / (va * vb).sqrt()
    }

    #[test]
    fn measure_follows_the_rate_and_calibration_counts_the_impacts() {
        for seed in [1, 2, 3] {
            let (x, truth) = impacts(seed);
            let measure = crumpling_measure(&x, RATE, 2, Wavelet::Db4, Seconds(0.025)).unwrap();
            assert_eq!(measure.len(), x.len());
            let fs = RATE.hz();
            let rate: Vec<f64> = (0..x.len()).map(|i| true_rate(i as f64 / fs)).collect();
            let r = pearson(&measure, &rate);
            let peak = measure.iter().copied().fold(0.0, f64::max);
            let quiet = |t0: f64, t1: f64| {
                measure[(t0 * fs) as usize..(t1 * fs) as usize]
                    .iter()
                    .copied()
                    .fold(0.0, f64::max)
                    / peak
            };
            let silent = quiet(0.0, 0.4).max(quiet(3.6, 4.0));

            let onsets =
                impact_onsets(&x, RATE, 2, Wavelet::Db4, &ImpactOnsetConfig::default()).unwrap();
            let a = estimate_rate_scale(&measure, RATE, onsets.len()).unwrap();
            let total: f64 = event_rate(&measure, a).iter().sum::<f64>() / fs;
            let count_err = (total - truth as f64).abs() / truth as f64;
            eprintln!(
                "seed {seed}: r = {r:.3}, silent/peak = {silent:.1e}, {truth} impacts, {} onsets, integral of N = {total:.1} ({:.1}%), a = {a:.3}",
                onsets.len(),
                100.0 * count_err
            );
            assert!(r > 0.8, "correlation {r}");
            assert!(silent < 0.02, "measure in the silent parts: {silent}");
            assert!(count_err < 0.2, "count error {count_err}");
        }
    }

    #[test]
    fn event_rate_is_zero_at_zero_measure_and_calibration_inverts_it() {
        assert_eq!(event_rate(&[0.0, 0.0], 3.0), vec![0.0, 0.0]);
        let measure: Vec<f64> = (0..1000).map(|i| (i % 100) as f64 / 100.0).collect();
        let a = estimate_rate_scale(&measure, SampleRate(1000), 5).unwrap();
        let total: f64 = event_rate(&measure, a).iter().sum::<f64>() / 1000.0;
        assert!((total - 5.0).abs() < 1e-9, "{total}");
        assert_eq!(estimate_rate_scale(&measure, SampleRate(1000), 0), Ok(0.0));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let w = Wavelet::Db4;
        let s = Seconds(0.01);
        assert!(crumpling_measure(&[], RATE, 2, w, s).is_err());
        assert!(crumpling_measure(&[1.0; 3], RATE, 2, w, s).is_err());
        assert!(crumpling_measure(&[f64::NAN; 64], RATE, 2, w, s).is_err());
        assert!(crumpling_measure(&[1.0; 64], RATE, 0, w, s).is_err());
        assert!(crumpling_measure(&[1.0; 64], RATE, 2, w, Seconds(f64::NAN)).is_err());
        let silent = crumpling_measure(&[0.0; 64], RATE, 2, w, s).unwrap();
        assert!(silent.iter().all(|&v| v == 0.0));
        assert_eq!(
            impact_onsets(&[0.0; 64], RATE, 2, w, &ImpactOnsetConfig::default()),
            Ok(Vec::new())
        );
        assert!(estimate_rate_scale(&[], RATE, 3).is_err());
        assert!(estimate_rate_scale(&[f64::NAN], RATE, 3).is_err());
        assert_eq!(
            estimate_rate_scale(&silent, RATE, 3),
            Err(CrumplingError::NoActivity { onsets: 3 })
        );
    }
}
