//! The static alternative: one least-squares inverse FIR, for comparison.
//!
//! The earlier design (the compensation paper's reference \[1\]) fitted a short FIR once to the
//! unloaded response. [`StaticInverse::fit`] fits an FIR `c` of a given order so that
//! `C(f) H(f) ≈ g e^{-j 2π f d / fs}` over the band in the least-squares sense (with a
//! modelling delay `d` of half the order and a small ridge), the classic least-squares
//! inverse filter. At the compensation paper's order 14 and 48 kHz it has no resolution in the band
//! at all, which is the compensation paper's point; it is kept for the comparison.

use num_complex::Complex64;

use super::weights::centred_db;
use crate::compensation::CompensationError;
use crate::compensation::fir::Fir;
use crate::compensation::sweep::{Device, FrequencyResponse};
use crate::units::{Decibels, SampleRate};

/// The earlier static compensation: one least-squares inverse FIR fitted to the unloaded
/// response; see the [module documentation](self).
#[derive(Debug, Clone, PartialEq)]
pub struct StaticInverse {
    /// The FIR's coefficients (order + 1 of them).
    pub taps: Vec<f64>,
    /// The modelling delay in samples.
    pub delay: usize,
}

impl StaticInverse {
    /// Fits an inverse FIR of `order` to `measured` at `rate`.
    ///
    /// # Errors
    /// As [`SpectralWeights::update`](super::SpectralWeights::update) for the response,
    /// [`CompensationError::InvalidParameter`] for an order of 0 or above 4096, or a
    /// singular fit.
    pub fn fit(
        measured: &FrequencyResponse,
        order: usize,
        rate: SampleRate,
    ) -> Result<Self, CompensationError> {
        centred_db(measured)?;
        if order == 0 || order > 4096 {
            return Err(CompensationError::InvalidParameter {
                name: "order",
                value: order as f64,
                expected: "1 to 4096",
            });
        }
        let n = order + 1;
        let delay = order / 2;
        // The target's level is the mean magnitude, so the inverse is level-neutral.
        let db: Vec<f64> = measured.magnitude_db().iter().map(|d| d.0).collect();
        let level = Decibels(db.iter().sum::<f64>() / db.len() as f64).to_amplitude();
        // Normal equations of min Σ_i |Σ_n c_n e^{-jω_i n} H_i - level e^{-jω_i d}|^2 + λ|c|^2.
        let mut ata = vec![0.0; n * n];
        let mut atb = vec![0.0; n];
        let mut row = vec![Complex64::new(0.0, 0.0); n];
        for (f, h) in measured.freqs.iter().zip(&measured.response) {
            let w = rate.omega(*f);
            for (m, r) in row.iter_mut().enumerate() {
                *r = Complex64::from_polar(1.0, -w * m as f64) * h;
            }
            let target = Complex64::from_polar(level, -w * delay as f64);
            for i in 0..n {
                for j in i..n {
                    ata[i * n + j] += (row[i].conj() * row[j]).re;
                }
                atb[i] += (row[i].conj() * target).re;
            }
        }
        let trace = (0..n).map(|i| ata[i * n + i]).sum::<f64>() / n as f64;
        for i in 0..n {
            ata[i * n + i] += 1e-6 * trace.max(f64::MIN_POSITIVE);
            for j in 0..i {
                ata[i * n + j] = ata[j * n + i];
            }
        }
        let taps = solve_spd(&mut ata, &mut atb, n).ok_or(CompensationError::InvalidParameter {
            name: "order",
            value: order as f64,
            expected: "an order the response can determine (the fit is singular)",
        })?;
        Ok(Self { taps, delay })
    }

    /// The streaming filter.
    ///
    /// # Errors
    /// As [`Fir::new`].
    pub fn filter(&self) -> Result<Fir, CompensationError> {
        Fir::new(&self.taps)
    }
}

/// Solves the symmetric positive-definite system `a x = b` by Cholesky, in place.
fn solve_spd(a: &mut [f64], b: &mut [f64], n: usize) -> Option<Vec<f64>> {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d.is_nan() || d <= 0.0 {
            return None;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i * n + k] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    b.iter().all(|v| v.is_finite()).then(|| b.to_vec())
}

/// A device heard through a static inverse FIR, its modelling delay removed.
pub struct Inverted<'a, D: Device + ?Sized> {
    /// The inverse filter.
    pub inverse: &'a StaticInverse,
    /// The device behind it.
    pub device: &'a mut D,
}

impl<D: Device + ?Sized> Device for Inverted<'_, D> {
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        let d = self.inverse.delay;
        let mut drive = vec![0.0; excitation.len() + d];
        for (n, y) in drive.iter_mut().enumerate() {
            *y = self
                .inverse
                .taps
                .iter()
                .enumerate()
                .filter(|&(m, _)| m <= n && n - m < excitation.len())
                .map(|(m, c)| c * excitation[n - m])
                .sum();
        }
        self.device.play(&drive[d..])
    }
}
