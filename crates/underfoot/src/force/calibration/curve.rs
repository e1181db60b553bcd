//! The curves and applying them at run time: the model of one sensor (a power law or
//! knots), the check that a curve can be applied, and raw readings to newtons with the
//! range clamped and counted (see the parent module, *Range, drift and bad readings at
//! run time*).

use serde::{Deserialize, Serialize};

use super::EXPONENT_BOUNDS;
use super::error::{CurveError, SensorCalibrationError};
use crate::units::Newtons;

/// A fitted curve's shape, in raw reading units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CurveModel {
    /// `F = a·max(r − r0, 0)^b` newtons.
    Power {
        /// Scale, newtons per (reading unit)^b.
        a: f64,
        /// Exponent.
        b: f64,
        /// The reading at no load.
        r0: f64,
    },
    /// Linear interpolation between `(reading, newtons)` knots, both strictly increasing.
    Piecewise {
        /// The knots.
        knots: Vec<[f64; 2]>,
    },
}

/// One sensor's calibration: its name, curve, trusted range and drift correction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SensorCurve {
    /// The sensor's name, e.g. `left.heel`.
    pub name: String,
    /// The curve.
    pub model: CurveModel,
    /// The readings the curve was fitted over, `[low, high]`; readings outside are clamped.
    pub raw_range: [f64; 2],
    /// Reading offset removed before the curve is applied, set by [`SensorCurve::tare`].
    #[serde(default)]
    pub drift: f64,
}

/// What a run of [`SensorCalibration::apply`] met that was not an ordinary reading.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ApplyStats {
    /// Non-finite readings, output as 0 N.
    pub non_finite: usize,
    /// Readings above a curve's range, clamped to its top.
    pub above_range: usize,
    /// Readings below a curve's range, clamped to its bottom.
    pub below_range: usize,
    /// Outputs with no reading or no curve for them, set to 0 N.
    pub missing: usize,
}

impl ApplyStats {
    /// `curve`'s force for `raw` in `f32`, counting what is not an ordinary reading: a
    /// reading outside the curve's range (clamped to it), and a non-finite reading or a
    /// force too large for `f32`, which give 0 N. The one per-sensor step of every way
    /// raw readings become newtons ([`SensorCalibration::apply`], the serial inputs'
    /// per-sensor scaling).
    pub(crate) fn force(&mut self, curve: &SensorCurve, raw: f64) -> f32 {
        match curve.force(raw) {
            // Only a hand-edited file's extreme scale can overflow f32; treat it as a bad
            // reading rather than pass infinity to the synthesis.
            Some((f, side)) if (f.0 as f32).is_finite() => {
                match side {
                    std::cmp::Ordering::Less => self.below_range += 1,
                    std::cmp::Ordering::Greater => self.above_range += 1,
                    std::cmp::Ordering::Equal => {}
                }
                f.0 as f32
            }
            _ => {
                self.non_finite += 1;
                0.0
            }
        }
    }
}

impl std::ops::AddAssign for ApplyStats {
    fn add_assign(&mut self, other: Self) {
        self.non_finite += other.non_finite;
        self.above_range += other.above_range;
        self.below_range += other.below_range;
        self.missing += other.missing;
    }
}

/// Every sensor's curve, in reading order; stored as a [document](crate::document) (see
/// the parent module, *Files*).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorCalibration {
    /// One curve per sensor, in the order readings arrive.
    pub sensors: Vec<SensorCurve>,
}

impl SensorCurve {
    /// The force for a reading, and where it fell: `Less` below the range, `Greater`
    /// above, `Equal` within. A non-finite reading gives `None`.
    #[must_use]
    pub fn force(&self, raw: f64) -> Option<(Newtons, std::cmp::Ordering)> {
        if !raw.is_finite() {
            return None;
        }
        let r = raw - self.drift;
        let [lo, hi] = self.raw_range;
        let side = if r < lo {
            std::cmp::Ordering::Less
        } else if r > hi {
            std::cmp::Ordering::Greater
        } else {
            std::cmp::Ordering::Equal
        };
        // Not f64::clamp: it panics on a reversed range, and a curve built in memory
        // may not have been validated.
        let r = match side {
            std::cmp::Ordering::Less => lo,
            std::cmp::Ordering::Greater => hi,
            std::cmp::Ordering::Equal => r,
        };
        let f = match &self.model {
            CurveModel::Power { a, b, r0 } => power(*a, *b, *r0, r),
            CurveModel::Piecewise { knots } => interpolate(knots, r),
        };
        Some((Newtons(f), side))
    }

    /// Checks that the curve can be applied: finite parameters, a proper range, knots
    /// strictly increasing.
    ///
    /// # Errors
    /// [`SensorCalibrationError::InvalidCurve`] naming `origin` and the sensor.
    pub fn validate(&self, origin: &str) -> Result<(), SensorCalibrationError> {
        self.check().map_err(|e| e.at(origin))
    }

    /// [`SensorCurve::validate`] without an origin: what is wrong, naming the sensor.
    pub(crate) fn check(&self) -> Result<(), CurveError> {
        let bad = |reason: String| CurveError {
            sensor: self.name.clone(),
            reason,
        };
        let [lo, hi] = self.raw_range;
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(bad(format!(
                "raw_range [{lo}, {hi}] is not a finite, non-empty range"
            )));
        }
        if !self.drift.is_finite() {
            return Err(bad(format!("drift {} is not finite", self.drift)));
        }
        match &self.model {
            CurveModel::Power { a, b, r0 } => {
                if !(a.is_finite() && *a > 0.0) {
                    return Err(bad(format!("scale a = {a} must be finite and positive")));
                }
                if !(EXPONENT_BOUNDS.0..=EXPONENT_BOUNDS.1).contains(b) {
                    return Err(bad(format!(
                        "exponent b = {b} is outside [{}, {}]",
                        EXPONENT_BOUNDS.0, EXPONENT_BOUNDS.1
                    )));
                }
                if !r0.is_finite() {
                    return Err(bad(format!("offset r0 = {r0} is not finite")));
                }
            }
            CurveModel::Piecewise { knots } => {
                if knots.len() < 2 {
                    return Err(bad(format!("{} knots, at least 2 needed", knots.len())));
                }
                if knots.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(bad("a knot is not finite".to_owned()));
                }
                if let Some(k) = knots
                    .windows(2)
                    .position(|w| w[1][0] <= w[0][0] || w[1][1] < w[0][1])
                {
                    return Err(bad(format!(
                        "knots {k} and {} are not increasing in reading and force",
                        k + 1
                    )));
                }
            }
        }
        Ok(())
    }
}

/// `a·max(r − r0, 0)^b`.
pub(super) fn power(a: f64, b: f64, r0: f64, r: f64) -> f64 {
    let x = r - r0;
    if x > 0.0 { a * x.powf(b) } else { 0.0 }
}

/// Linear interpolation in increasing knots, clamped at the ends; no allocation.
fn interpolate(knots: &[[f64; 2]], r: f64) -> f64 {
    let (Some(first), Some(last)) = (knots.first(), knots.last()) else {
        return 0.0;
    };
    if r <= first[0] {
        return first[1];
    }
    if r >= last[0] {
        return last[1];
    }
    // The first knot strictly above r. The clamp only matters for unsorted knots (a
    // curve built in memory and never validated), where it keeps the indexing in bounds.
    let i = knots
        .partition_point(|k| k[0] <= r)
        .clamp(1, knots.len() - 1);
    let ([r1, f1], [r2, f2]) = (knots[i - 1], knots[i]);
    f1 + (f2 - f1) * (r - r1) / (r2 - r1)
}

impl SensorCalibration {
    /// Turns one instant's raw readings into newtons, sensor `i`'s reading `raw[i]` into
    /// `out[i]`. Real-time safe: no allocation, no panic.
    ///
    /// Readings outside a curve's range are clamped to it; non-finite readings (and a
    /// force too large for `f32`) give 0 N;
    /// an output with no reading or no curve (the slices are shorter than `out`) gives
    /// 0 N. All are counted in the returned [`ApplyStats`]; extra readings are ignored.
    pub fn apply(&self, raw: &[f32], out: &mut [f32]) -> ApplyStats {
        let mut stats = ApplyStats::default();
        for (i, o) in out.iter_mut().enumerate() {
            let (Some(curve), Some(&r)) = (self.sensors.get(i), raw.get(i)) else {
                *o = 0.0;
                stats.missing += 1;
                continue;
            };
            *o = stats.force(curve, f64::from(r));
        }
        stats
    }

    /// Checks every curve, and that sensor names are unique.
    ///
    /// # Errors
    /// [`SensorCalibrationError::InvalidCurve`] naming `origin` and the sensor.
    pub fn validate(&self, origin: &str) -> Result<(), SensorCalibrationError> {
        self.check().map_err(|e| e.at(origin))
    }

    /// [`SensorCalibration::validate`] without an origin: the check of the file's
    /// document.
    pub(super) fn check(&self) -> Result<(), CurveError> {
        for (i, s) in self.sensors.iter().enumerate() {
            s.check()?;
            if self.sensors[..i].iter().any(|o| o.name == s.name) {
                return Err(CurveError {
                    sensor: s.name.clone(),
                    reason: "a second sensor of this name".to_owned(),
                });
            }
        }
        Ok(())
    }
}
