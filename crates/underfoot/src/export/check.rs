//! The check of a quantised cascade against the float model.
//!
//! A format passes when, for the quantised cascade:
//!
//! 1. every pole is strictly inside the unit circle and keeps at least half of the float
//!    filter's distance to it (`1 - |p|`), and
//! 2. its response, times the gain, is within [`ExportConfig::tolerance`] (0.5 dB) of the
//!    float (f64) model at every frequency of the check's grid over the band: from the
//!    quantised coefficients, and from the DFT of the impulse responses the fixed-point
//!    loop actually computes (until they have decayed by 120 dB), which adds the data
//!    path's rounding to the coefficients'. The impulses are fed at every
//!    one of [`ExportConfig::levels`] (0, -6, ..., -30 dBFS by default; rounded to the
//!    input format, and each response divided by the impulse actually fed), because
//!    rounding noise does not scale with the signal: a loop that is exact at full scale
//!    can be decibels off for a quiet step. `f32` is checked at full scale only (its
//!    rounding scales with the signal).
//!
//! # The grid
//! The grid is every bin of an `M`-point DFT that falls in the band, `f_k = k f_s / M`,
//! with `M` the smallest power of two that holds the whole impulse response (at least
//! [`MIN_DFT`]) and puts at least [`MIN_BAND_BINS`] bins in the band (at most
//! [`MAX_DFT`]). At those frequencies the DTFT of an `n <= M` sample response is exactly
//! its zero-padded DFT, so one real FFT per response gives all of them exactly. Before,
//! a Goertzel recursion per frequency at 256 log-spaced frequencies was a third of a
//! 2,000-material export's time; the FFTs are a few percent. The grid is denser than those
//! 256 points everywhere above 33 Hz (at 2 kHz, 4096 bins are 0.49 Hz apart, 1,800 of them
//! between 20 and 900 Hz) and at most 1.6 times sparser below; a resonance the voice may
//! play (at most a 0.5 s decay, 0.64 Hz between its -3 dB points) always has a bin within
//! its -3 dB width.
//!
//! The exporter refuses a library in which any material fails for a format it was asked
//! for, naming the material, the format, the worst frequency and the level of the
//! impulse that failed (or that the coefficients did).

use super::{ExportConfig, ExportError};
use crate::material::MaterialModel;
use crate::signal::Sos;
use crate::signal::spectrum::SpectrumPlan;
use crate::units::{Decibels, Hz, SampleRate};
use num_complex::Complex64;

/// How close one format comes to the float model.
#[derive(Debug, Clone, PartialEq)]
pub struct FormatCheck {
    /// Worst deviation over the band of the quantised coefficients' response, in dB.
    pub coefficients_db: f64,
    /// Worst deviation over the band of the DFT of the computed impulse response, in
    /// dB, over every level checked.
    pub impulse_db: f64,
    /// Where the larger of the two is.
    pub worst_hz: Hz,
    /// The impulse level of the worst impulse deviation.
    pub worst_level: Decibels,
    /// Per level checked, in the order of [`ExportConfig::levels`].
    pub levels: Vec<LevelCheck>,
    /// `1 - |p|` of the pole nearest the unit circle.
    pub pole_margin: f64,
}

/// The computed impulse response at one level against the float model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelCheck {
    /// The impulse's level, in dBFS.
    pub level: Decibels,
    /// Worst deviation over the band, in dB.
    pub impulse_db: f64,
    /// Where it is.
    pub worst_hz: Hz,
}

impl FormatCheck {
    /// The larger of the two deviations.
    #[must_use]
    pub fn worst_db(&self) -> f64 {
        self.coefficients_db.max(self.impulse_db)
    }
}

/// `1 - |p|` of the pole nearest the unit circle.
pub(super) fn margin(sos: &Sos) -> f64 {
    1.0 - sos.poles().iter().map(|p| p.norm()).fold(0.0, f64::max)
}

/// The fewest DFT points of the grid.
pub const MIN_DFT: usize = 4096;

/// The fewest grid frequencies in the band, when [`MAX_DFT`] allows.
pub const MIN_BAND_BINS: usize = 256;

/// The most DFT points of the grid (a band a few hertz wide stops here).
pub const MAX_DFT: usize = 1 << 20;

/// The DFT size for impulse responses of `n` samples over `band` at `rate`: see
/// [the grid](self#the-grid).
fn dft_size(n: usize, band_width: Hz, rate: SampleRate) -> usize {
    let mut m = n.max(MIN_DFT).next_power_of_two().min(MAX_DFT);
    while m < MAX_DFT && band_width.0 * (m as f64) < MIN_BAND_BINS as f64 * rate.hz() {
        m *= 2;
    }
    m
}

/// The band grid and the float reference on it.
pub(super) struct Checker {
    pub(super) grid: Vec<Hz>,
    /// The DFT bin of each grid frequency.
    bins: std::ops::Range<usize>,
    /// `e^{-jω}` at each grid frequency.
    z1: Vec<Complex64>,
    plan: SpectrumPlan,
    magnitudes: Vec<f64>,
    reference: Vec<f64>,
    reference_margin: f64,
    tolerance: f64,
    margin_fraction: f64,
}

impl Checker {
    /// The check of impulse responses of at most `n` samples.
    pub(super) fn new(
        model: &MaterialModel,
        reference: &Sos,
        config: &ExportConfig,
        n: usize,
    ) -> Self {
        let rate = model.sample_rate;
        let band = model.band_hz;
        let m = dft_size(n.max(1), Hz(band.hi.0 - band.lo.0), rate);
        let spacing = rate.hz() / m as f64;
        let first = (band.lo.0 / spacing).ceil() as usize;
        let last = ((band.hi.0 / spacing).floor() as usize).min(m / 2);
        let bins = first..(last + 1).max(first);
        let grid: Vec<Hz> = bins.clone().map(|k| Hz(k as f64 * spacing)).collect();
        let z1: Vec<Complex64> = grid
            .iter()
            .map(|&f| Complex64::from_polar(1.0, -rate.omega(f)))
            .collect();
        let reference_values = z1
            .iter()
            .map(|&z| reference.response_at(z).norm())
            .collect();
        Self {
            grid,
            bins,
            z1,
            plan: SpectrumPlan::new(m),
            magnitudes: vec![0.0; m / 2 + 1],
            reference: reference_values,
            reference_margin: margin(reference),
            tolerance: config.tolerance.0,
            margin_fraction: config.margin_fraction,
        }
    }

    /// Worst deviation (dB) and where, of magnitudes on the grid.
    pub(super) fn worst(&self, magnitudes: impl Iterator<Item = f64>) -> (f64, Hz) {
        Self::worst_of(&self.reference, &self.grid, magnitudes)
    }

    fn worst_of(
        reference: &[f64],
        grid: &[Hz],
        magnitudes: impl Iterator<Item = f64>,
    ) -> (f64, Hz) {
        magnitudes
            .zip(reference)
            .zip(grid)
            .map(|((m, r), &f)| {
                let d = (20.0 * (m / r).log10()).abs();
                (if d.is_nan() { f64::INFINITY } else { d }, f)
            })
            .fold((0.0, Hz(f64::NAN)), |a, b| if b.0 > a.0 { b } else { a })
    }

    /// Worst deviation (dB) and where, of an impulse response of at most the `n` samples
    /// the checker was made for (longer is a bug, reported as an infinite deviation).
    pub(super) fn impulse_worst(&mut self, ir: &[f64]) -> (f64, Hz) {
        if self.plan.magnitude(ir, &mut self.magnitudes).is_err() {
            return (f64::INFINITY, Hz(f64::NAN));
        }
        let magnitudes = &self.magnitudes[self.bins.clone()];
        Self::worst_of(&self.reference, &self.grid, magnitudes.iter().copied())
    }

    /// The check of one format: `impulses` are its computed impulse responses, each
    /// with its level, divided by the impulse fed.
    pub(super) fn check(
        &mut self,
        name: &str,
        format: &'static str,
        coefficients: &Sos,
        impulses: &[(Decibels, Vec<f64>)],
    ) -> (FormatCheck, Option<ExportError>) {
        let (coefficients_db, coef_hz) =
            self.worst(self.z1.iter().map(|&z| coefficients.response_at(z).norm()));
        let levels: Vec<LevelCheck> = impulses
            .iter()
            .map(|(level, ir)| {
                let (impulse_db, worst_hz) = self.impulse_worst(ir);
                LevelCheck {
                    level: *level,
                    impulse_db,
                    worst_hz,
                }
            })
            .collect();
        // The worst level; a NaN deviation (already mapped to infinity) wins.
        let worst_level = levels.iter().fold(None::<&LevelCheck>, |w, l| match w {
            Some(w) if w.impulse_db >= l.impulse_db => Some(w),
            _ => Some(l),
        });
        let (impulse_db, ir_hz, level) = worst_level
            .map_or((f64::NAN, Hz(f64::NAN), Decibels(0.0)), |l| {
                (l.impulse_db, l.worst_hz, l.level)
            });
        let impulse_worse = impulse_db > coefficients_db;
        let worst_hz = if impulse_worse { ir_hz } else { coef_hz };
        let check = FormatCheck {
            coefficients_db,
            impulse_db,
            worst_hz,
            worst_level: level,
            levels,
            pole_margin: margin(coefficients),
        };
        let fail = |reason: String, at_level: bool| ExportError::CheckFailed {
            name: name.to_string(),
            format,
            reason,
            worst_db: check.worst_db(),
            worst_hz: worst_hz.0,
            level: at_level.then_some(level),
            tolerance_db: self.tolerance,
        };
        if !(check.pole_margin > 0.0
            && check.pole_margin >= self.margin_fraction * self.reference_margin)
        {
            let e = fail(
                format!(
                    "a pole moved to {:.6} from the unit circle (the float filter's is {:.6})",
                    check.pole_margin, self.reference_margin
                ),
                false,
            );
            return (check, Some(e));
        }
        if check.worst_db().is_nan() || check.worst_db() > self.tolerance {
            let e = fail(
                "its response is too far from the float filter's".into(),
                impulse_worse,
            );
            return (check, Some(e));
        }
        (check, None)
    }
}
