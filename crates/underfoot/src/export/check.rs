//! The check of a quantised cascade against the float model.
//!
//! A format passes when, for the quantised cascade:
//!
//! 1. every pole is strictly inside the unit circle and keeps at least half of the float
//!    filter's distance to it (`1 - |p|`), and
//! 2. its response, times the gain, is within [`ExportConfig::tolerance`] (0.5 dB) of the
//!    float (f64) model at [`ExportConfig::grid_points`] log-spaced frequencies over the
//!    band: from the quantised coefficients, and from the DFT of the impulse responses
//!    the fixed-point loop actually computes (until they have decayed by 120 dB), which
//!    adds the data path's rounding to the coefficients'. The impulses are fed at every
//!    one of [`ExportConfig::levels`] (0, -6, ..., -30 dBFS by default; rounded to the
//!    input format, and each response divided by the impulse actually fed), because
//!    rounding noise does not scale with the signal: a loop that is exact at full scale
//!    can be decibels off for a quiet step. `f32` is checked at full scale only (its
//!    rounding scales with the signal).
//!
//! The exporter refuses a library in which any material fails for a format it was asked
//! for, naming the material, the format, the worst frequency and the level of the
//! impulse that failed (or that the coefficients did).

use super::{ExportConfig, ExportError};
use crate::material::MaterialModel;
use crate::numeric::dtft_many;
use crate::signal::Sos;
use crate::units::{Decibels, Hz, SampleRate};

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

/// The band grid and the float reference on it.
pub(super) struct Checker {
    pub(super) rate: SampleRate,
    pub(super) grid: Vec<Hz>,
    reference: Vec<f64>,
    reference_margin: f64,
    tolerance: f64,
    margin_fraction: f64,
}

impl Checker {
    pub(super) fn new(model: &MaterialModel, reference: &Sos, config: &ExportConfig) -> Self {
        let grid = model.band_hz.log_grid(config.grid_points);
        let rate = model.sample_rate;
        let reference_values = grid
            .iter()
            .map(|&f| reference.response(rate.omega(f)).norm())
            .collect();
        Self {
            rate,
            grid,
            reference: reference_values,
            reference_margin: margin(reference),
            tolerance: config.tolerance.0,
            margin_fraction: config.margin_fraction,
        }
    }

    /// Worst deviation (dB) and where, of magnitudes on the grid.
    pub(super) fn worst(&self, magnitudes: impl Iterator<Item = f64>) -> (f64, Hz) {
        magnitudes
            .zip(&self.reference)
            .zip(&self.grid)
            .map(|((m, r), &f)| {
                let d = (20.0 * (m / r).log10()).abs();
                (if d.is_nan() { f64::INFINITY } else { d }, f)
            })
            .fold((0.0, Hz(f64::NAN)), |a, b| if b.0 > a.0 { b } else { a })
    }

    /// The check of one format: `impulses` are its computed impulse responses, each
    /// with its level, divided by the impulse fed.
    pub(super) fn check(
        &self,
        name: &str,
        format: &'static str,
        coefficients: &Sos,
        impulses: &[(Decibels, Vec<f64>)],
    ) -> (FormatCheck, Option<ExportError>) {
        let (coefficients_db, coef_hz) = self.worst(
            self.grid
                .iter()
                .map(|&f| coefficients.response(self.rate.omega(f)).norm()),
        );
        let omegas: Vec<f64> = self.grid.iter().map(|&f| self.rate.omega(f)).collect();
        let levels: Vec<LevelCheck> = impulses
            .iter()
            .map(|(level, ir)| {
                // All the grid's frequencies in one pass over the response: the export's
                // time goes here (a 2,000-material library: 74 s one frequency at a time).
                let (impulse_db, worst_hz) =
                    self.worst(dtft_many(ir, &omegas).into_iter().map(|c| c.norm()));
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
