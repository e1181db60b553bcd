//! The response a fit aims at, and how a magnitude-only measurement becomes one.
//!
//! The fitters of equation (2) need a complex response `h_k`, but a measured strike
//! spectrum averaged over several strikes carries magnitude only. We give it the
//! **minimum phase** consistent with that magnitude: the phase of the one causal, stable
//! filter with a stable inverse that has this magnitude. It is the physically natural choice
//! for an impact response (energy arrives first and decays) and, being the Hilbert
//! transform of the log magnitude, it changes as smoothly as the magnitude does.
//!
//! Computed with the real cepstrum on an `N`-point FFT grid: `c = IFFT(ln|H|)`, fold it
//! onto positive quefrencies (`c_0`, `2 c_n` for `0 < n < N/2`, `c_{N/2}`, zero after), and
//! `H_min = exp(FFT(c_folded))`.
//!
//! Outside the band the measurement means nothing (it is what the band-pass left), so the
//! magnitude is held at its band-edge values there before the phase is computed: a flat
//! extension adds no steep slopes whose phase would leak into the band.

use num_complex::Complex64;
use underfoot_fft::RealFftPlanner;

use super::FitError;
use crate::units::{Band, Hz, SampleRate};

/// A sampled complex response to fit, with a weight per frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// The rate the filter will run at.
    pub rate: SampleRate,
    /// Frequencies in radians per sample, increasing.
    pub omega: Vec<f64>,
    /// Complex response at each frequency.
    pub h: Vec<Complex64>,
    /// Non-negative weight of each frequency in least-squares fits.
    pub weight: Vec<f64>,
}

impl Target {
    /// A target from a complex response sampled at `freqs`, uniformly weighted.
    ///
    /// # Errors
    /// [`FitError::BadTarget`] when empty, of mismatched lengths, non-finite, or with a
    /// frequency outside `(0, Nyquist)`.
    pub fn from_response(
        rate: SampleRate,
        freqs: &[Hz],
        h: Vec<Complex64>,
    ) -> Result<Self, FitError> {
        if freqs.is_empty() || freqs.len() != h.len() {
            return Err(FitError::BadTarget(
                "empty, or frequencies and response differ in length",
            ));
        }
        if h.iter().any(|v| !v.re.is_finite() || !v.im.is_finite()) {
            return Err(FitError::BadTarget("non-finite response"));
        }
        if freqs.iter().any(|f| !(f.0 > 0.0 && f.0 < rate.nyquist().0)) {
            return Err(FitError::BadTarget("frequency outside (0, Nyquist)"));
        }
        let omega = freqs.iter().map(|&f| rate.omega(f)).collect();
        let weight = vec![1.0; h.len()];
        Ok(Self {
            rate,
            omega,
            h,
            weight,
        })
    }

    /// A minimum-phase target from a magnitude spectrum on FFT bins `0..=N/2`
    /// (bin `k` at `k * rate / N`), sampled at `points` log-spaced frequencies of `band`.
    ///
    /// # Errors
    /// [`FitError::BadTarget`] when the spectrum is too short, non-finite, not positive in
    /// the band, or the band does not fit the rate.
    pub fn minimum_phase(
        rate: SampleRate,
        band: Band,
        magnitude: &[f64],
        points: usize,
    ) -> Result<Self, FitError> {
        let h = minimum_phase_spectrum(rate, band, magnitude)?;
        let bin_hz = rate.hz() / (2 * (magnitude.len() - 1)) as f64;
        let freqs = band.log_grid(points);
        let response = freqs
            .iter()
            .map(|f| interpolate_bins(&h, bin_hz, f.0))
            .collect();
        Self::from_response(rate, &freqs, response)
    }

    /// Number of frequencies.
    #[must_use]
    pub fn len(&self) -> usize {
        self.omega.len()
    }

    /// Whether there is no frequency.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.omega.is_empty()
    }
}

/// The minimum-phase spectrum (bins `0..=N/2`) with the given magnitude in `band`,
/// held flat outside it.
///
/// # Errors
/// See [`Target::minimum_phase`].
pub fn minimum_phase_spectrum(
    rate: SampleRate,
    band: Band,
    magnitude: &[f64],
) -> Result<Vec<Complex64>, FitError> {
    if magnitude.len() < 8 {
        return Err(FitError::BadTarget("spectrum has fewer than 8 bins"));
    }
    if !band.fits(rate) {
        return Err(FitError::BadTarget("band does not fit the sample rate"));
    }
    let n = 2 * (magnitude.len() - 1);
    let bin_hz = rate.hz() / n as f64;
    let lo_bin = ((band.lo.0 / bin_hz).ceil() as usize).min(magnitude.len() - 1);
    let hi_bin = ((band.hi.0 / bin_hz).floor() as usize).clamp(lo_bin, magnitude.len() - 1);
    let in_band = &magnitude[lo_bin..=hi_bin];
    if in_band.iter().any(|m| !m.is_finite() || *m <= 0.0) {
        return Err(FitError::BadTarget(
            "magnitude not finite and positive in the band",
        ));
    }
    let mut log_mag: Vec<f64> = (0..magnitude.len())
        .map(|k| magnitude[k.clamp(lo_bin, hi_bin)].ln())
        .collect();

    let mut planner = RealFftPlanner::<f64>::new();
    let inverse = planner.plan_fft_inverse(n);
    let forward = planner.plan_fft_forward(n);
    let mut spec: Vec<Complex64> = log_mag.drain(..).map(|v| Complex64::new(v, 0.0)).collect();
    let mut cep = vec![0.0; n];
    inverse
        .process(&mut spec, &mut cep)
        .map_err(|_| FitError::Numerical("cepstrum transform failed"))?;
    let scale = 1.0 / n as f64;
    for (i, c) in cep.iter_mut().enumerate() {
        let fold = match i {
            0 => 1.0,
            i if i < n / 2 => 2.0,
            i if i == n / 2 => 1.0,
            _ => 0.0,
        };
        *c *= fold * scale;
    }
    let mut out = vec![Complex64::new(0.0, 0.0); n / 2 + 1];
    forward
        .process(&mut cep, &mut out)
        .map_err(|_| FitError::Numerical("cepstrum transform failed"))?;
    Ok(out.into_iter().map(Complex64::exp).collect())
}

/// Linear interpolation of a bin-sampled spectrum (bin `k` at `k * bin_hz`) at `f`
/// hertz, clamped to the first and last bins. Zero for an empty spectrum.
#[must_use]
pub fn interpolate_bins<T>(bins: &[T], bin_hz: f64, f: f64) -> T
where
    T: Copy + Default + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
{
    match bins {
        [] => T::default(),
        [only] => *only,
        _ => {
            let x = (f / bin_hz).clamp(0.0, (bins.len() - 1) as f64);
            let i = (x.floor() as usize).min(bins.len() - 2);
            let t = x - i as f64;
            bins[i] * (1.0 - t) + bins[i + 1] * t
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::{Biquad, Sos};

    /// The minimum phase of a minimum-phase filter's magnitude is that filter's phase.
    #[test]
    fn recovers_phase_of_a_minimum_phase_filter() {
        let rate = SampleRate(2000);
        // Zeros and poles inside the unit circle: minimum phase.
        let sos = Sos::new(vec![
            Biquad {
                b: [1.0, -0.5, 0.2],
                a: [1.0, -1.6, 0.8],
            },
            Biquad {
                b: [0.5, 0.3, 0.1],
                a: [1.0, 0.4, 0.5],
            },
        ]);
        let n = 8192;
        let mag: Vec<f64> = (0..=n / 2)
            .map(|k| {
                sos.response(std::f64::consts::TAU * k as f64 / n as f64)
                    .norm()
            })
            .collect();
        // A band covering almost everything, so the flat extension barely matters.
        let band = Band::new(0.5, 999.5);
        let h = minimum_phase_spectrum(rate, band, &mag).unwrap();
        for k in (10..n / 2 - 10).step_by(97) {
            let truth = sos.response(std::f64::consts::TAU * k as f64 / n as f64);
            assert!(
                (h[k] - truth).norm() < 1e-3 * truth.norm(),
                "bin {k}: {} vs {truth}",
                h[k]
            );
        }
    }
}
