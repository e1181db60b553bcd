//! How close a model's magnitude is to the measurement.
//!
//! Both metrics compare magnitudes `M_k` (measured) and `S_k` (synthesised) on the same
//! frequencies, by default 96 log-spaced points of the band.
//!
//! **NRMSE** (the IIR paper's equation 3). The IIR paper writes the goodness of fit
//! `C = 1 - ||M - S|| / ||M - mean(M)||` but tabulates the error term (Table I lists values
//! from 0.03 to 35, which only the error term can reach). We report the error term
//!
//! ```math
//! \mathrm{NRMSE} = \frac{\lVert M - S \rVert_2}{\lVert M - \bar M \rVert_2}
//! ```
//!
//! so lower is better, 0 is exact, and 1 is no better than a flat line at the mean.
//!
//! **Log-spectral distance** in decibels, the RMS level error:
//!
//! ```math
//! \mathrm{LSD} = \sqrt{\tfrac{1}{K} \sum_k \left(20 \log_{10} \frac{S_k}{M_k}\right)^2 }
//! ```
//!
//! With a 1 dB intensity JND, an LSD below 1 dB means the average level error is below what
//! a person can tell apart.
//!
//! **Gain-aligned log-spectral distance**, for comparing shapes when the levels are not
//! comparable (a spectrum of other strikes, another conditioning, an unnormalised DFT):
//! the model is first moved by the uniform gain that best matches it in dB, which is the
//! mean level difference
//!
//! ```math
//! \bar d = \tfrac{1}{K} \sum_k 20 \log_{10} \frac{S_k}{M_k} , \qquad
//!   \mathrm{LSD}_{aligned} = \sqrt{\tfrac{1}{K} \sum_k
//!   \left(20 \log_{10} \frac{S_k}{M_k} - \bar d\right)^2 }
//!   = \sqrt{\mathrm{LSD}^2 - \bar d^2} .
//! ```
//!
//! (the mean minimises the RMS, so no other gain does better). A model whose level was
//! set this way (the physical model's output gain, see [`crate::physical::estimate()`])
//! has `\bar d = 0` and both distances agree.
//!
//! These functions are the only definitions of the metrics: `fit`, `compare`, the
//! physical estimation, the reports and the tests all call them, on the grid
//! [`METRIC_POINTS`] log-spaced points of the band (`Band::log_grid`) unless said
//! otherwise, so the same two curves give the same figure wherever it is printed.

use serde::{Deserialize, Serialize};

use crate::signal::Sos;
use crate::units::{Hz, SampleRate};

/// Frequencies of the metric grid (log-spaced over the band) that models are scored on.
pub const METRIC_POINTS: usize = 96;

/// Both fit metrics of one model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Normalised RMS error of the magnitude (lower is better).
    pub nrmse: f64,
    /// RMS log-spectral distance in dB.
    pub lsd_db: f64,
}

/// The NRMSE error term of equation (3).
///
/// # Panics
/// If the slices differ in length.
#[must_use]
pub fn nrmse(measured: &[f64], model: &[f64]) -> f64 {
    assert_eq!(
        measured.len(),
        model.len(),
        "measured and model on the same grid"
    );
    let mean = measured.iter().sum::<f64>() / measured.len().max(1) as f64;
    let err: f64 = measured
        .iter()
        .zip(model)
        .map(|(m, s)| (m - s).powi(2))
        .sum();
    let spread: f64 = measured.iter().map(|m| (m - mean).powi(2)).sum();
    (err / spread).sqrt()
}

/// The RMS log-spectral distance in dB.
///
/// # Panics
/// If the slices differ in length.
#[must_use]
pub fn lsd_db(measured: &[f64], model: &[f64]) -> f64 {
    assert_eq!(
        measured.len(),
        model.len(),
        "measured and model on the same grid"
    );
    let sum: f64 = measured
        .iter()
        .zip(model)
        .map(|(m, s)| (20.0 * (s / m).log10()).powi(2))
        .sum();
    (sum / measured.len().max(1) as f64).sqrt()
}

/// The mean level of `model` over `reference` in dB, `\bar d` of the module
/// documentation: the uniform gain (in dB) that, taken off `model`, best matches it to
/// `reference` in the log-spectral sense.
///
/// # Panics
/// If the slices differ in length.
#[must_use]
pub fn level_offset_db(reference: &[f64], model: &[f64]) -> f64 {
    assert_eq!(
        reference.len(),
        model.len(),
        "reference and model on the same grid"
    );
    let sum: f64 = reference
        .iter()
        .zip(model)
        .map(|(m, s)| 20.0 * (s / m).log10())
        .sum();
    sum / reference.len().max(1) as f64
}

/// The log-spectral distance in dB after the best uniform gain: how far the shapes of
/// `model` and `reference` are apart, whatever their levels (see the module
/// documentation).
///
/// # Panics
/// If the slices differ in length.
#[must_use]
pub fn gain_aligned_lsd_db(reference: &[f64], model: &[f64]) -> f64 {
    assert_eq!(
        reference.len(),
        model.len(),
        "reference and model on the same grid"
    );
    let to_db = |v: &[f64]| -> Vec<f64> { v.iter().map(|x| 20.0 * x.log10()).collect() };
    gain_aligned_level_distance_db(&to_db(reference), &to_db(model))
}

/// [`gain_aligned_lsd_db`] of two curves already in dB: the RMS of their difference once
/// its mean is taken out (0 for empty curves).
///
/// # Panics
/// If the slices differ in length.
#[must_use]
pub fn gain_aligned_level_distance_db(reference_db: &[f64], model_db: &[f64]) -> f64 {
    assert_eq!(
        reference_db.len(),
        model_db.len(),
        "reference and model on the same grid"
    );
    let n = reference_db.len().max(1) as f64;
    let d: Vec<f64> = model_db
        .iter()
        .zip(reference_db)
        .map(|(s, m)| s - m)
        .collect();
    let mean = d.iter().sum::<f64>() / n;
    (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt()
}

/// The grid the metrics are computed on, with the measured magnitude there.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricGrid {
    /// The rate the models run at.
    pub rate: SampleRate,
    /// Frequencies.
    pub freqs: Vec<Hz>,
    /// Measured magnitude at each frequency.
    pub measured: Vec<f64>,
}

impl MetricGrid {
    /// A filter's magnitude on the grid.
    #[must_use]
    pub fn model_magnitude(&self, sos: &Sos) -> Vec<f64> {
        self.freqs
            .iter()
            .map(|&f| sos.response(self.rate.omega(f)).norm())
            .collect()
    }

    /// Both metrics for a filter.
    #[must_use]
    pub fn evaluate(&self, sos: &Sos) -> Metrics {
        self.evaluate_magnitude(&self.model_magnitude(sos))
    }

    /// Both metrics for a model magnitude on this grid.
    #[must_use]
    pub fn evaluate_magnitude(&self, model: &[f64]) -> Metrics {
        Metrics {
            nrmse: nrmse(&self.measured, model),
            lsd_db: lsd_db(&self.measured, model),
        }
    }
}

/// The worst in-band deviation of a filter from a measured magnitude, found on a dense grid.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WorstDeviation {
    /// `max |20 log10(S/M)|` over the dense grid, in dB.
    pub db: f64,
    /// Where it is.
    pub at_hz: f64,
}

/// Points of the dense check per bin of the measured spectrum.
pub const DENSE_PER_BIN: usize = 4;

/// The worst deviation of `sos` (running at `rate`) from a measured magnitude given on FFT
/// bins `0..=N/2` spaced `bin_hz`, over `band`.
///
/// The 96-point metric grid is coarse enough for a narrow model peak to fall between its
/// points. This check evaluates the model at [`DENSE_PER_BIN`] points per bin of the
/// measurement (the measurement interpolated linearly between its bins), so that any peak
/// of a filter whose poles decay within the fit's limit (0.5 s: a -3 dB width of at least
/// `1 / (pi 0.5 s) = 0.64 Hz`, at 0.12 Hz spacing here) is seen within a small fraction of
/// a decibel.
#[must_use]
pub fn worst_deviation(
    sos: &Sos,
    rate: SampleRate,
    magnitude: &[f64],
    bin_hz: f64,
    band: crate::units::Band,
) -> WorstDeviation {
    let step = bin_hz / DENSE_PER_BIN as f64;
    let n = ((band.hi.0 - band.lo.0) / step).floor() as usize;
    let mut worst = WorstDeviation {
        db: 0.0,
        at_hz: band.lo.0,
    };
    for i in 0..=n {
        let f = (band.lo.0 + i as f64 * step).min(band.hi.0);
        let m = crate::fit::target::interpolate_bins(magnitude, bin_hz, f);
        let s = sos.response(rate.omega(Hz(f))).norm();
        let d = (20.0 * (s / m).log10()).abs();
        // A NaN (a zero in the measurement) counts as the worst.
        if d.is_nan() || d > worst.db {
            worst = WorstDeviation { db: d, at_hz: f };
            if !d.is_finite() {
                break;
            }
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_model_scores_zero() {
        let m = [1.0, 2.0, 3.0];
        assert_eq!(nrmse(&m, &m), 0.0);
        assert_eq!(lsd_db(&m, &m), 0.0);
    }

    #[test]
    fn flat_mean_scores_one() {
        let m = [1.0, 2.0, 3.0, 6.0];
        let mean = [3.0; 4];
        assert!((nrmse(&m, &mean) - 1.0).abs() < 1e-15);
    }

    /// A narrow peak between the 96 points is invisible to the LSD grid and not to the
    /// dense check.
    #[test]
    fn dense_check_sees_a_peak_between_grid_points() {
        use crate::signal::Biquad;
        use crate::signal::sos::RootPair;
        use crate::units::Band;
        use num_complex::Complex64;
        let rate = SampleRate(2000);
        let band = Band::new(20.0, 900.0);
        let grid = band.log_grid(METRIC_POINTS);
        // A resonance halfway (in log frequency) between two grid points, 0.5 s decay.
        let f0 = (grid[40].0 * grid[41].0).sqrt();
        let r = crate::fit::decay_radius(rate, crate::units::Seconds(0.5));
        let peak = Complex64::from_polar(r, rate.omega(Hz(f0)));
        let dip = Complex64::from_polar(r * 0.9, rate.omega(Hz(f0)));
        let sos = Sos::new(vec![Biquad::from_roots(
            RootPair::Conjugate(dip),
            RootPair::Conjugate(peak),
            1.0,
        )]);
        // The "measurement" is flat at the filter's level away from the peak.
        let bin_hz = 2000.0 / 8192.0;
        let flat = sos.response(rate.omega(Hz(500.0))).norm();
        let magnitude = vec![flat; 4097];
        let on_grid: Vec<f64> = grid
            .iter()
            .map(|&f| sos.response(rate.omega(f)).norm())
            .collect();
        let worst_on_grid = on_grid
            .iter()
            .map(|s| (20.0 * (s / flat).log10()).abs())
            .fold(0.0, f64::max);
        let dense = worst_deviation(&sos, rate, &magnitude, bin_hz, band);
        // The peak stands about (1 - 0.9 r) / (1 - r) = 100, 40 dB, above the flat level;
        // the nearest grid points sit on its skirts.
        assert!(dense.db > 35.0, "{dense:?}");
        assert!(
            dense.db - worst_on_grid > 10.0,
            "{worst_on_grid} vs {dense:?}"
        );
        assert!((dense.at_hz - f0).abs() < 0.2, "{dense:?} vs {f0}");
    }

    #[test]
    fn uniform_gain_error_is_its_level() {
        let m = [0.1, 1.0, 10.0];
        let s: Vec<f64> = m.iter().map(|v| v * 2.0).collect();
        assert!((lsd_db(&m, &s) - 20.0 * 2f64.log10()).abs() < 1e-12);
    }

    #[test]
    fn gain_alignment_removes_exactly_a_uniform_gain() {
        let m = [0.1, 1.0, 10.0, 3.0];
        let shape = [1.0, 2.0, 0.5, 1.0];
        let s: Vec<f64> = m.iter().zip(&shape).map(|(a, b)| a * b).collect();
        let aligned = gain_aligned_lsd_db(&m, &s);
        for gain in [1e-3, 0.5, 1.0, 7.0, 1e4] {
            let scaled: Vec<f64> = s.iter().map(|v| v * gain).collect();
            assert!((gain_aligned_lsd_db(&m, &scaled) - aligned).abs() < 1e-9);
            let offset = level_offset_db(&m, &scaled);
            let d = 20.0 * f64::log10(gain);
            assert!((offset - level_offset_db(&m, &s) - d).abs() < 1e-9);
            // The identity of the module documentation.
            let plain = lsd_db(&m, &scaled);
            assert!((plain.powi(2) - offset.powi(2) - aligned.powi(2)).abs() < 1e-9);
        }
        // A pure gain has no shape error; a shape error is not removed.
        let doubled: Vec<f64> = m.iter().map(|v| v * 2.0).collect();
        assert!(gain_aligned_lsd_db(&m, &doubled) < 1e-12);
        assert!(aligned > 1.0);
    }

    #[test]
    fn no_other_gain_beats_the_mean_level() {
        let m = [1.0, 4.0, 0.2, 0.9, 2.5];
        let s = [1.3, 2.0, 0.5, 0.7, 2.5];
        let best = gain_aligned_lsd_db(&m, &s);
        for i in -40..=40 {
            let g = 10f64.powf(f64::from(i) / 40.0);
            let scaled: Vec<f64> = s.iter().map(|v| v * g).collect();
            assert!(lsd_db(&m, &scaled) >= best - 1e-12);
        }
    }
}
