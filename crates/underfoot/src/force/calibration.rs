//! Force-sensor calibration: from readings taken under known loads to a curve per sensor
//! that turns a raw reading (ADC counts or volts) into newtons at run time.
//!
//! # Why a power law
//!
//! A force-sensing resistor (FSR) is a polymer film whose contact area grows with the
//! force pressing it, so its *conductance* `G = 1/R` rises roughly as a power of force,
//! `G ∝ F^k` with `k` near 1 (FSR data sheets plot `log R` against `log F` as a
//! nearly straight line over the working range). Read through a transimpedance amplifier (the
//! circuit Interlink recommends) the raw reading is proportional to conductance plus an
//! offset, so force is a power of the reading above that offset:
//!
//! $$ F(r) = a\,\max(r - r_0,\ 0)^{\,b}, \qquad a > 0,\quad b = 1/k \in [0.2, 5]. $$
//!
//! `r0` is the reading at no load (the amplifier's offset), `b` the curvature. This is
//! [`CurveKind::Power`]. Below `r0` the force is zero, which is what an unloaded sensor
//! feels. Read through a plain voltage divider the reading is not proportional to
//! conductance over a wide swing; the power law is then only approximate, and the
//! piecewise model below is the better choice.
//!
//! ## Fitting the power law
//!
//! The fit minimises the squared force error `Σ wᵢ (F(rᵢ) − Lᵢ)²` over `a`, `b`, `r0`
//! with the bounded trust-region solver of [`crate::numeric::trf`]. Force space rather than
//! log space, because the lab scale's error is additive in newtons (the tile paper reports
//! ±10 N) and the unloaded readings, whose logarithm does not exist, are the ones that pin
//! `r0`. Readings and loads are scaled to `[0, 1]` for the solver, so the problem is as
//! well conditioned for 12-bit counts as for volts. Starting points come from a log-log line
//! for a few trial offsets; the best is kept. The weights `wᵢ` are Huber weights
//! re-estimated three times (iteratively reweighted least squares, the threshold at 1.345
//! times a median-absolute-deviation scale), so a few mis-recorded loads (a hand on the
//! scale) bend the curve little.
//!
//! # The piecewise alternative
//!
//! [`CurveKind::Piecewise`] makes no assumption about the shape: the samples, sorted by
//! reading, are averaged in about `2√n` groups (at most 64), and the group means are made
//! increasing by pool-adjacent-violators (isotonic regression), which merges neighbouring
//! groups whose mean loads are out of order. The curve interpolates linearly between the
//! knots that remain, whose readings and loads are both strictly increasing, so the curve
//! is monotone by construction. It needs dense data (at least
//! [`MIN_POINTS_PIECEWISE`] samples); with sparse data the power law is the safer choice.
//!
//! # Range, drift and bad readings at run time
//!
//! A curve is trusted only over the readings it was fitted on, `raw_range`. A reading
//! above the range is clamped to its top (the force saturates at the largest calibrated
//! load rather than following an extrapolated power law), a reading below it to its
//! bottom; [`SensorCalibration::apply`] counts both. A non-finite reading gives 0 N and is
//! counted.
//!
//! FSRs drift: the unloaded reading creeps with temperature and wear. [`SensorCurve::tare`]
//! re-zeros a curve from readings taken at rest by shifting it along the reading axis, so
//! that the median rest reading maps to the force the curve gave at rest when it was
//! fitted. A shift keeps the curve's shape; it corrects offset drift, not a change of
//! sensitivity, which needs a new calibration.
//!
//! # Files
//!
//! A calibration session is a CSV file of `sensor,raw,load_n` rows (see
//! [`read_session`]); a fitted calibration is a versioned JSON file (see
//! [`SensorCalibration::save`]):
//!
//! ```text
//! {"kind": "underfoot-sensor-calibration", "version": 1,
//!  "sensors": [{"name": "heel", "model": {"power": {"a": 0.012, "b": 1.4, "r0": 200.0}},
//!               "raw_range": [190.0, 3500.0], "drift": 0.0}]}
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::atomic_file::{AtomicWriteError, OutputFile};
use crate::numeric::trf::{FnResiduals, TrfError, TrfOptions, least_squares_bounded};
use crate::units::Newtons;

/// The `kind` tag of a calibration file.
pub const FILE_KIND: &str = "underfoot-sensor-calibration";

/// The calibration file version this code writes and reads.
pub const FILE_VERSION: u64 = 1;

/// The fewest samples a power-law fit accepts (three parameters and some to spare).
pub const MIN_POINTS_POWER: usize = 5;

/// The fewest samples the piecewise model accepts: it has no shape to lean on.
pub const MIN_POINTS_PIECEWISE: usize = 12;

/// The fewest distinct loads: two loads fit any curve through them, three begin to show
/// its shape.
pub const MIN_LOAD_LEVELS: usize = 3;

/// The narrowest load range accepted: below this the curve is mostly scale error.
pub const MIN_LOAD_SPAN: Newtons = Newtons(1.0);

/// The least Spearman rank correlation between readings and loads: below it the readings
/// do not order the loads (a sensor wired so that its reading falls with force, a swapped
/// column, or a sensor that was not loaded).
pub const MIN_RANK_CORRELATION: f64 = 0.8;

/// The bounds of the power-law exponent `b`.
pub const EXPONENT_BOUNDS: (f64, f64) = (0.2, 5.0);

/// The most knots a piecewise curve gets.
pub const MAX_KNOTS: usize = 64;

/// Which curve to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CurveKind {
    /// `F = a·(r − r0)^b`: the FSR's conductance law; few samples suffice.
    Power,
    /// Monotone piecewise-linear through isotonic group means; needs dense data.
    Piecewise,
}

impl CurveKind {
    /// The fewest samples this kind accepts.
    #[must_use]
    pub fn min_points(self) -> usize {
        match self {
            Self::Power => MIN_POINTS_POWER,
            Self::Piecewise => MIN_POINTS_PIECEWISE,
        }
    }
}

impl std::fmt::Display for CurveKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Power => "power",
            Self::Piecewise => "piecewise",
        })
    }
}

impl std::str::FromStr for CurveKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "power" => Ok(Self::Power),
            "piecewise" => Ok(Self::Piecewise),
            other => Err(format!(
                "unknown curve kind {other:?}: expected power or piecewise"
            )),
        }
    }
}

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

/// How well a curve fits its samples.
#[derive(Debug, Clone, PartialEq)]
pub struct FitReport {
    /// The sensor.
    pub sensor: String,
    /// The curve kind fitted.
    pub kind: CurveKind,
    /// Samples used.
    pub points: usize,
    /// Root-mean-square of curve minus load over the samples.
    pub rms_error: Newtons,
    /// Largest absolute curve-minus-load over the samples.
    pub max_error: Newtons,
    /// The smallest and largest load.
    pub load_range: (Newtons, Newtons),
    /// Samples the robust fit gave less than half weight (likely mis-recorded loads);
    /// always 0 for the piecewise model.
    pub downweighted: usize,
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

/// Every sensor's curve, in reading order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SensorCalibration {
    /// One curve per sensor, in the order readings arrive.
    pub sensors: Vec<SensorCurve>,
}

/// One sensor's samples from a calibration session.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorSamples {
    /// The sensor's name.
    pub name: String,
    /// `(raw reading, known load)` pairs, in file order.
    pub samples: Vec<(f64, Newtons)>,
}

/// What is wrong with calibration data, a fit, or a calibration file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibrationError {
    /// A file could not be read or written.
    #[error("{path}: {action}: {source}", path = path.display())]
    Io {
        /// The file (or, for a save, the temporary file next to it).
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A calibration file that is not JSON of the right shape.
    #[error("{origin}: not a valid sensor calibration at line {line}, column {column}: {message}")]
    Json {
        /// Where the text came from.
        origin: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What the parser objected to.
        message: String,
    },
    /// The `kind` tag is missing or is not [`FILE_KIND`].
    #[error(
        "{origin}: kind is {found:?}, expected {FILE_KIND:?} (is this a sensor calibration file?)"
    )]
    WrongKind {
        /// Where the text came from.
        origin: String,
        /// The tag found, if any.
        found: Option<String>,
    },
    /// The `version` is missing or not one this code reads.
    #[error(
        "{origin}: version {found:?} is not supported; this version of underfoot reads version {FILE_VERSION}"
    )]
    WrongVersion {
        /// Where the text came from.
        origin: String,
        /// The version found, as written.
        found: Option<String>,
    },
    /// A curve in a file or in memory that cannot be applied.
    #[error("{origin}: sensor {sensor:?}: {reason}")]
    InvalidCurve {
        /// Where the calibration came from.
        origin: String,
        /// The sensor.
        sensor: String,
        /// What is wrong.
        reason: String,
    },
    /// A session file whose header is not `sensor,raw,load_n`.
    #[error("{origin}: line {line}: the header must be sensor,raw,load_n, found {found:?}")]
    BadHeader {
        /// Where the text came from.
        origin: String,
        /// The header's line.
        line: u64,
        /// The header as written.
        found: String,
    },
    /// A session file with no header or no rows.
    #[error("{origin}: no calibration rows (expected a sensor,raw,load_n header and rows)")]
    Empty {
        /// Where the text came from.
        origin: String,
    },
    /// A session row with the wrong number of fields.
    #[error("{origin}: line {line}: {found} fields where sensor,raw,load_n has 3")]
    FieldCount {
        /// Where the text came from.
        origin: String,
        /// The row's line.
        line: u64,
        /// Fields found.
        found: usize,
    },
    /// A session field that is not a finite number, or a bad sensor name.
    #[error("{origin}: line {line}: {column}: {text:?} {reason}")]
    BadValue {
        /// Where the text came from.
        origin: String,
        /// The row's line.
        line: u64,
        /// The column: `sensor`, `raw` or `load_n`.
        column: &'static str,
        /// The field as written.
        text: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// Too few samples for the curve kind.
    #[error("sensor {sensor:?}: {found} samples, a {kind} curve needs at least {needed}")]
    TooFewPoints {
        /// The sensor.
        sensor: String,
        /// The curve kind.
        kind: CurveKind,
        /// Samples given.
        found: usize,
        /// Samples needed.
        needed: usize,
    },
    /// A sample with a non-finite reading or load.
    #[error("sensor {sensor:?}: sample {index} (raw {raw}, load {load} N) is not finite")]
    NonFinite {
        /// The sensor.
        sensor: String,
        /// 0-based index of the sample.
        index: usize,
        /// Its reading.
        raw: f64,
        /// Its load in newtons.
        load: f64,
    },
    /// Readings that do not rise with load.
    #[error(
        "sensor {sensor:?}: readings do not rise with load (rank correlation {rank_correlation:.2}, \
         at least {MIN_RANK_CORRELATION} needed); is the reading inverted, or the sensor not loaded?"
    )]
    NonMonotone {
        /// The sensor.
        sensor: String,
        /// Spearman's rank correlation between readings and loads.
        rank_correlation: f64,
    },
    /// Too few distinct loads, too small a load span, or readings that do not vary.
    #[error("sensor {sensor:?}: {reason}")]
    NarrowRange {
        /// The sensor.
        sensor: String,
        /// Which range, and what it was.
        reason: String,
    },
    /// The solver failed.
    #[error("sensor {sensor:?}: the power-law fit failed: {source}")]
    Fit {
        /// The sensor.
        sensor: String,
        /// The solver's error.
        #[source]
        source: TrfError,
    },
    /// Rest readings that do not match the sensors.
    #[error("tare: {reason}")]
    Tare {
        /// What is wrong.
        reason: String,
    },
}

impl From<AtomicWriteError> for CalibrationError {
    fn from(e: AtomicWriteError) -> Self {
        Self::Io {
            path: e.path,
            action: e.action,
            source: e.source,
        }
    }
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

    /// The reading at which this curve, without drift, gives its rest force: `r0` for
    /// the power law, the bottom of the range for the piecewise model.
    fn rest_reading(&self) -> f64 {
        match &self.model {
            CurveModel::Power { r0, .. } => r0.max(self.raw_range[0]),
            CurveModel::Piecewise { .. } => self.raw_range[0],
        }
    }

    /// Re-zeros the curve from readings taken with the sensor unloaded: the median of
    /// `readings_at_rest` becomes the reading the curve treats as its rest reading. Returns
    /// the drift now removed, in reading units.
    ///
    /// # Errors
    /// [`CalibrationError::Tare`] if there are no finite readings.
    pub fn tare(&mut self, readings_at_rest: &[f64]) -> Result<f64, CalibrationError> {
        let mut finite: Vec<f64> = readings_at_rest
            .iter()
            .copied()
            .filter(|r| r.is_finite())
            .collect();
        if finite.is_empty() {
            return Err(CalibrationError::Tare {
                reason: format!("sensor {:?}: no finite rest readings", self.name),
            });
        }
        self.drift = crate::numeric::median(&mut finite) - self.rest_reading();
        Ok(self.drift)
    }

    /// Checks that the curve can be applied: finite parameters, a proper range, knots
    /// strictly increasing.
    ///
    /// # Errors
    /// [`CalibrationError::InvalidCurve`] naming `origin` and the sensor.
    pub fn validate(&self, origin: &str) -> Result<(), CalibrationError> {
        let bad = |reason: String| CalibrationError::InvalidCurve {
            origin: origin.to_owned(),
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

fn power(a: f64, b: f64, r0: f64, r: f64) -> f64 {
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

/// Spearman's rank correlation, ties given their average rank.
fn rank_correlation(x: &[f64], y: &[f64]) -> f64 {
    fn ranks(v: &[f64]) -> Vec<f64> {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        let mut r = vec![0.0; v.len()];
        let mut s = 0;
        while s < idx.len() {
            let mut e = s + 1;
            while e < idx.len() && v[idx[e]] == v[idx[s]] {
                e += 1;
            }
            let avg = (s + e - 1) as f64 / 2.0;
            for &k in &idx[s..e] {
                r[k] = avg;
            }
            s = e;
        }
        r
    }
    let (rx, ry) = (ranks(x), ranks(y));
    let n = x.len() as f64;
    let (mx, my) = (rx.iter().sum::<f64>() / n, ry.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in rx.iter().zip(&ry) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    if sxx == 0.0 || syy == 0.0 {
        0.0
    } else {
        sxy / (sxx * syy).sqrt()
    }
}

/// Fits one sensor's curve to `(raw reading, known load)` samples; `name` names the sensor
/// in the curve and in errors.
///
/// # Errors
/// [`CalibrationError::TooFewPoints`], [`CalibrationError::NonFinite`],
/// [`CalibrationError::NarrowRange`] (fewer than [`MIN_LOAD_LEVELS`] distinct loads, a
/// span under [`MIN_LOAD_SPAN`], or constant readings), [`CalibrationError::NonMonotone`]
/// (rank correlation under [`MIN_RANK_CORRELATION`]), or [`CalibrationError::Fit`].
pub fn fit_sensor(
    name: &str,
    samples: &[(f64, Newtons)],
    kind: CurveKind,
) -> Result<(SensorCurve, FitReport), CalibrationError> {
    if let Some((index, &(raw, load))) = samples
        .iter()
        .enumerate()
        .find(|(_, (r, l))| !(r.is_finite() && l.0.is_finite()))
    {
        return Err(CalibrationError::NonFinite {
            sensor: name.to_owned(),
            index,
            raw,
            load: load.0,
        });
    }
    if samples.len() < kind.min_points() {
        return Err(CalibrationError::TooFewPoints {
            sensor: name.to_owned(),
            kind,
            found: samples.len(),
            needed: kind.min_points(),
        });
    }
    let raw: Vec<f64> = samples.iter().map(|s| s.0).collect();
    let load: Vec<f64> = samples.iter().map(|s| s.1.0).collect();
    let narrow = |reason: String| CalibrationError::NarrowRange {
        sensor: name.to_owned(),
        reason,
    };
    let (r_lo, r_hi) = min_max(&raw);
    let (l_lo, l_hi) = min_max(&load);
    if r_hi <= r_lo {
        return Err(narrow(format!(
            "every reading is {r_lo}: the sensor did not respond"
        )));
    }
    if l_hi - l_lo < MIN_LOAD_SPAN.0 {
        return Err(narrow(format!(
            "loads span {l_lo} to {l_hi} N, less than {} N",
            MIN_LOAD_SPAN.0
        )));
    }
    let mut levels = load.clone();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    if levels.len() < MIN_LOAD_LEVELS {
        return Err(narrow(format!(
            "{} distinct loads, at least {MIN_LOAD_LEVELS} needed",
            levels.len()
        )));
    }
    let rho = rank_correlation(&raw, &load);
    if rho < MIN_RANK_CORRELATION {
        return Err(CalibrationError::NonMonotone {
            sensor: name.to_owned(),
            rank_correlation: rho,
        });
    }

    let (model, raw_range, downweighted) = match kind {
        CurveKind::Power => {
            let (model, downweighted) = fit_power(name, &raw, &load, r_lo, r_hi)?;
            (model, [r_lo, r_hi], downweighted)
        }
        CurveKind::Piecewise => {
            let knots = fit_piecewise(&raw, &load);
            let range = [knots[0][0], knots[knots.len() - 1][0]];
            if range[1] <= range[0] {
                return Err(narrow("the readings collapse to a single knot".to_owned()));
            }
            (CurveModel::Piecewise { knots }, range, 0)
        }
    };
    let curve = SensorCurve {
        name: name.to_owned(),
        model,
        raw_range,
        drift: 0.0,
    };
    let (mut sum2, mut max) = (0.0_f64, 0.0_f64);
    for (&r, &l) in raw.iter().zip(&load) {
        let f = curve.force(r).map_or(0.0, |(f, _)| f.0);
        sum2 += (f - l) * (f - l);
        max = max.max((f - l).abs());
    }
    let report = FitReport {
        sensor: name.to_owned(),
        kind,
        points: samples.len(),
        rms_error: Newtons((sum2 / samples.len() as f64).sqrt()),
        max_error: Newtons(max),
        load_range: (Newtons(l_lo), Newtons(l_hi)),
        downweighted,
    };
    Ok((curve, report))
}

fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        })
}

/// The power law by Huber-weighted bounded least squares in scaled units; returns the
/// model in reading units and the number of samples left with under half weight.
fn fit_power(
    name: &str,
    raw: &[f64],
    load: &[f64],
    r_lo: f64,
    r_hi: f64,
) -> Result<(CurveModel, usize), CalibrationError> {
    let span = r_hi - r_lo;
    let scale = load.iter().fold(0.0_f64, |m, l| m.max(l.abs()));
    let x: Vec<f64> = raw.iter().map(|r| (r - r_lo) / span).collect();
    let y: Vec<f64> = load.iter().map(|l| l / scale).collect();
    let m = x.len();
    let (b_lo, b_hi) = EXPONENT_BOUNDS;
    // The offset may lie below every reading (a sensor never seen unloaded), but not
    // above the top one, where the curve would be zero everywhere.
    let lower = [1e-9, b_lo, -1.0];
    let upper = [1e9, b_hi, 0.999];
    let opts = TrfOptions::default();
    let mut w = vec![1.0_f64; m];
    let mut best: Option<[f64; 3]> = None;
    for _round in 0..4 {
        let problem = FnResiduals {
            m,
            f: |p: &[f64], r: &mut [f64]| {
                for i in 0..m {
                    let d = x[i] - p[2];
                    let f = if d > 0.0 { p[0] * d.powf(p[1]) } else { 0.0 };
                    r[i] = w[i].sqrt() * (f - y[i]);
                }
            },
        };
        let starts: Vec<[f64; 3]> = match best {
            Some(p) => vec![p],
            None => start_points(&x, &y),
        };
        let mut round_best: Option<(f64, [f64; 3])> = None;
        let mut last_error = None;
        for s in starts {
            let s = [
                s[0].clamp(lower[0], upper[0]),
                s[1].clamp(lower[1], upper[1]),
                s[2].clamp(lower[2], upper[2]),
            ];
            match least_squares_bounded(&problem, &s, &lower, &upper, &opts) {
                Ok(sol) if round_best.is_none_or(|(c, _)| sol.cost < c) => {
                    round_best = Some((sol.cost, [sol.x[0], sol.x[1], sol.x[2]]));
                }
                Ok(_) => {}
                Err(e) => last_error = Some(e),
            }
        }
        let Some((_, p)) = round_best else {
            return Err(CalibrationError::Fit {
                sensor: name.to_owned(),
                source: last_error.unwrap_or(TrfError::Numerical("no start point converged")),
            });
        };
        best = Some(p);
        // Huber weights from the unweighted residuals, scaled by their MAD.
        let mut res: Vec<f64> = (0..m)
            .map(|i| {
                let d = x[i] - p[2];
                let f = if d > 0.0 { p[0] * d.powf(p[1]) } else { 0.0 };
                (f - y[i]).abs()
            })
            .collect();
        let abs = res.clone();
        let sigma = (1.4826 * crate::numeric::median(&mut res)).max(1e-9);
        let k = 1.345 * sigma;
        for (wi, a) in w.iter_mut().zip(&abs) {
            *wi = if *a <= k { 1.0 } else { k / a };
        }
    }
    let p = best.unwrap_or([1.0, 1.0, 0.0]);
    let downweighted = w.iter().filter(|&&wi| wi < 0.5).count();
    let (a, b, x0) = (p[0], p[1], p[2]);
    Ok((
        CurveModel::Power {
            a: scale * a / span.powf(b),
            b,
            r0: r_lo + x0 * span,
        },
        downweighted,
    ))
}

/// Start points for the power law: a log-log line for a few trial offsets at or below
/// the lowest reading.
fn start_points(x: &[f64], y: &[f64]) -> Vec<[f64; 3]> {
    [-0.2, -0.05, -0.01, 0.0]
        .iter()
        .map(|&x0| {
            let pts: Vec<(f64, f64)> = x
                .iter()
                .zip(y)
                .filter(|&(&xi, &yi)| xi - x0 > 1e-3 && yi > 0.02)
                .map(|(&xi, &yi)| ((xi - x0).ln(), yi.ln()))
                .collect();
            let n = pts.len() as f64;
            if pts.len() < 2 {
                return [1.0, 1.0, x0];
            }
            let (mx, my) = pts
                .iter()
                .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
            let (sxy, sxx) = pts.iter().fold((0.0, 0.0), |(a, b), p| {
                (a + (p.0 - mx) * (p.1 - my), b + (p.0 - mx) * (p.0 - mx))
            });
            let slope = if sxx > 0.0 { sxy / sxx } else { 1.0 };
            let slope = if slope.is_finite() { slope } else { 1.0 };
            let intercept = my - slope * mx;
            [intercept.exp(), slope, x0]
        })
        .collect()
}

/// Group means in reading order, made increasing by pool-adjacent-violators.
fn fit_piecewise(raw: &[f64], load: &[f64]) -> Vec<[f64; 2]> {
    let mut idx: Vec<usize> = (0..raw.len()).collect();
    idx.sort_by(|&i, &j| raw[i].total_cmp(&raw[j]).then(load[i].total_cmp(&load[j])));
    let n = idx.len();
    let groups = ((2.0 * (n as f64).sqrt()).round() as usize).clamp(2, MAX_KNOTS.min(n / 3).max(2));
    // (sum of readings, sum of loads, count) per block.
    let mut blocks: Vec<(f64, f64, f64)> = Vec::with_capacity(groups);
    let mut start = 0;
    for g in 0..groups {
        let end = (g + 1) * n / groups;
        if end <= start {
            continue;
        }
        let (mut sr, mut sl) = (0.0, 0.0);
        for &k in &idx[start..end] {
            sr += raw[k];
            sl += load[k];
        }
        let c = (end - start) as f64;
        // Equal readings in neighbouring groups would give two knots at one reading.
        match blocks.last_mut() {
            Some(last) if last.0 / last.2 >= sr / c => {
                last.0 += sr;
                last.1 += sl;
                last.2 += c;
            }
            _ => blocks.push((sr, sl, c)),
        }
        start = end;
    }
    let mut pooled: Vec<(f64, f64, f64)> = Vec::with_capacity(blocks.len());
    for b in blocks {
        pooled.push(b);
        while pooled.len() >= 2 {
            let (p, q) = (pooled[pooled.len() - 2], pooled[pooled.len() - 1]);
            if p.1 / p.2 >= q.1 / q.2 {
                pooled.pop();
                let last = pooled.len() - 1;
                pooled[last] = (p.0 + q.0, p.1 + q.1, p.2 + q.2);
            } else {
                break;
            }
        }
    }
    let mut knots: Vec<[f64; 2]> = pooled.iter().map(|b| [b.0 / b.2, b.1 / b.2]).collect();
    // Group means sit inside the data, half a group from either end; stopping the curve
    // there would clamp the extremes (the rest reading and the heaviest load) to a
    // group's average. Extend the end segments' slopes to the extreme readings instead,
    // never below the lightest load.
    let (r_lo, r_hi) = min_max(raw);
    let (l_lo, _) = min_max(load);
    if let [first, second, ..] = knots[..] {
        if r_lo < first[0] {
            let slope = (second[1] - first[1]) / (second[0] - first[0]);
            knots.insert(
                0,
                [
                    r_lo,
                    (first[1] - slope * (first[0] - r_lo)).max(l_lo.min(first[1])),
                ],
            );
        }
    }
    if let [.., before, last] = knots[..] {
        if r_hi > last[0] {
            let slope = (last[1] - before[1]) / (last[0] - before[0]);
            knots.push([r_hi, last[1] + slope * (r_hi - last[0])]);
        }
    }
    // Clamping at the lightest load can tie the first two knots' forces; keep the knot
    // sequence strictly increasing in reading and non-decreasing in force.
    knots
}

impl SensorCalibration {
    /// Fits every sensor of a session.
    ///
    /// # Errors
    /// The first sensor's error, see [`fit_sensor`].
    pub fn fit(
        session: &[SensorSamples],
        kind: CurveKind,
    ) -> Result<(Self, Vec<FitReport>), CalibrationError> {
        let mut sensors = Vec::with_capacity(session.len());
        let mut reports = Vec::with_capacity(session.len());
        for s in session {
            let (curve, report) = fit_sensor(&s.name, &s.samples, kind)?;
            sensors.push(curve);
            reports.push(report);
        }
        Ok((Self { sensors }, reports))
    }

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

    /// Re-zeros every sensor from readings taken at rest: `readings_at_rest` holds whole
    /// rows of one reading per sensor, interleaved (`s0, s1, .., s0, s1, ..`). Returns the
    /// drift removed per sensor.
    ///
    /// # Errors
    /// [`CalibrationError::Tare`] if the length is not a non-zero multiple of the sensor
    /// count, or a sensor has no finite rest reading.
    pub fn tare(&mut self, readings_at_rest: &[f32]) -> Result<Vec<f64>, CalibrationError> {
        let n = self.sensors.len();
        if n == 0 || readings_at_rest.is_empty() || readings_at_rest.len() % n != 0 {
            return Err(CalibrationError::Tare {
                reason: format!(
                    "{} rest readings are not whole rows of {n} sensors",
                    readings_at_rest.len()
                ),
            });
        }
        let mut drifts = Vec::with_capacity(n);
        for (s, curve) in self.sensors.iter_mut().enumerate() {
            let column: Vec<f64> = readings_at_rest
                .iter()
                .skip(s)
                .step_by(n)
                .map(|&r| f64::from(r))
                .collect();
            drifts.push(curve.tare(&column)?);
        }
        Ok(drifts)
    }

    /// Checks every curve, and that sensor names are unique.
    ///
    /// # Errors
    /// [`CalibrationError::InvalidCurve`] naming `origin` and the sensor.
    pub fn validate(&self, origin: &str) -> Result<(), CalibrationError> {
        for (i, s) in self.sensors.iter().enumerate() {
            s.validate(origin)?;
            if self.sensors[..i].iter().any(|o| o.name == s.name) {
                return Err(CalibrationError::InvalidCurve {
                    origin: origin.to_owned(),
                    sensor: s.name.clone(),
                    reason: "a second sensor of this name".to_owned(),
                });
            }
        }
        Ok(())
    }

    /// The calibration as file text (JSON with `kind` and `version`).
    #[must_use]
    pub fn to_json(&self) -> String {
        let file = FileRef {
            kind: FILE_KIND,
            version: FILE_VERSION,
            sensors: &self.sensors,
        };
        // Serialising plain structs of numbers and strings cannot fail.
        let mut text = serde_json::to_string_pretty(&file).unwrap_or_default();
        text.push('\n');
        text
    }

    /// Parses and checks calibration file text; `origin` names it in errors.
    ///
    /// # Errors
    /// [`CalibrationError::Json`], [`CalibrationError::WrongKind`],
    /// [`CalibrationError::WrongVersion`] or [`CalibrationError::InvalidCurve`].
    pub fn from_json_str(text: &str, origin: &str) -> Result<Self, CalibrationError> {
        let json = |e: serde_json::Error| CalibrationError::Json {
            origin: origin.to_owned(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        };
        // Kind and version first, so that a future file is refused for its version rather
        // than for whatever field it added.
        let value: serde_json::Value = serde_json::from_str(text).map_err(json)?;
        let kind = value.get("kind").and_then(|k| k.as_str());
        if kind != Some(FILE_KIND) {
            return Err(CalibrationError::WrongKind {
                origin: origin.to_owned(),
                found: value.get("kind").map(ToString::to_string),
            });
        }
        match value.get("version") {
            Some(v) if v.as_u64() == Some(FILE_VERSION) => {}
            other => {
                return Err(CalibrationError::WrongVersion {
                    origin: origin.to_owned(),
                    found: other.map(ToString::to_string),
                });
            }
        }
        let file: FileOwned = serde_json::from_str(text).map_err(json)?;
        let calibration = Self {
            sensors: file.sensors,
        };
        calibration.validate(origin)?;
        Ok(calibration)
    }

    /// Reads and checks a calibration file.
    ///
    /// # Errors
    /// [`CalibrationError::Io`], or what [`SensorCalibration::from_json_str`] finds.
    pub fn load(path: &Path) -> Result<Self, CalibrationError> {
        let text = crate::limits::read_to_string_capped(path, crate::limits::MAX_DOCUMENT_BYTES)
            .map_err(|source| CalibrationError::Io {
                path: path.to_path_buf(),
                action: "reading",
                source,
            })?;
        Self::from_json_str(&text, &path.display().to_string())
    }

    /// Checks the calibration, then writes it atomically: a failure leaves any previous
    /// file as it was.
    ///
    /// # Errors
    /// What [`SensorCalibration::validate`] finds, or [`CalibrationError::Io`].
    pub fn save(&self, path: &Path) -> Result<(), CalibrationError> {
        self.save_to(&OutputFile::check(path, &[])?)
    }

    /// [`SensorCalibration::save`] to an output the caller checked against the output
    /// policy ([`crate::atomic_file`]) together with its inputs.
    ///
    /// # Errors
    /// As [`SensorCalibration::save`].
    pub fn save_to(&self, out: &OutputFile) -> Result<(), CalibrationError> {
        self.validate(&out.path().display().to_string())?;
        Ok(out.write(self.to_json().as_bytes())?)
    }
}

#[derive(Serialize)]
struct FileRef<'a> {
    kind: &'static str,
    version: u64,
    sensors: &'a [SensorCurve],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileOwned {
    #[allow(dead_code)]
    kind: String,
    #[allow(dead_code)]
    version: u64,
    sensors: Vec<SensorCurve>,
}

/// Reads a calibration session: a CSV file of `sensor,raw,load_n` rows, see
/// [`session_from_csv_str`].
///
/// # Errors
/// [`CalibrationError::Io`], or the first fault found, naming the file and line.
pub fn read_session(path: &Path) -> Result<Vec<SensorSamples>, CalibrationError> {
    let text = crate::limits::read_to_string_capped(path, crate::limits::MAX_DOCUMENT_BYTES)
        .map_err(|source| CalibrationError::Io {
            path: path.to_path_buf(),
            action: "reading",
            source,
        })?;
    session_from_csv_str(&text, &path.display().to_string())
}

/// Parses a calibration session held in memory; `origin` names it in errors.
///
/// The format: a header `sensor,raw,load_n`, then one row per reading: the sensor's
/// name (letters, digits, `_`, `-` and `.`, e.g. `left.heel`), its raw reading, and the
/// known load in newtons, both finite. Sensors may be interleaved; they are returned in
/// order of first appearance. Blank lines and `#` comments are skipped, a byte-order mark
/// is ignored, and line numbers count every line.
///
/// # Errors
/// [`CalibrationError::Empty`], [`CalibrationError::BadHeader`],
/// [`CalibrationError::FieldCount`] or [`CalibrationError::BadValue`].
pub fn session_from_csv_str(
    text: &str,
    origin: &str,
) -> Result<Vec<SensorSamples>, CalibrationError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut records = text
        .lines()
        .zip(1u64..)
        .map(|(l, n)| (n, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
    let Some((header_line, header)) = records.next() else {
        return Err(CalibrationError::Empty {
            origin: origin.to_owned(),
        });
    };
    let fields: Vec<&str> = header.split(',').map(str::trim).collect();
    if fields != ["sensor", "raw", "load_n"] {
        return Err(CalibrationError::BadHeader {
            origin: origin.to_owned(),
            line: header_line,
            found: header.to_owned(),
        });
    }
    let mut session: Vec<SensorSamples> = Vec::new();
    for (line, record) in records {
        let f: Vec<&str> = record.split(',').map(str::trim).collect();
        if f.len() != 3 {
            return Err(CalibrationError::FieldCount {
                origin: origin.to_owned(),
                line,
                found: f.len(),
            });
        }
        let bad =
            |column: &'static str, text: &str, reason: &'static str| CalibrationError::BadValue {
                origin: origin.to_owned(),
                line,
                column,
                text: text.to_owned(),
                reason,
            };
        let name = f[0];
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
        {
            return Err(bad(
                "sensor",
                name,
                "is not a sensor name (letters, digits, _, - and .)",
            ));
        }
        let number = |column: &'static str, text: &str| {
            text.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(column, text, "is not a finite number"))
        };
        let raw = number("raw", f[1])?;
        let load = number("load_n", f[2])?;
        match session.iter_mut().find(|s| s.name == name) {
            Some(s) => s.samples.push((raw, Newtons(load))),
            None => session.push(SensorSamples {
                name: name.to_owned(),
                samples: vec![(raw, Newtons(load))],
            }),
        }
    }
    if session.is_empty() {
        return Err(CalibrationError::Empty {
            origin: origin.to_owned(),
        });
    }
    Ok(session)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A seeded normal generator (splitmix64 and Box-Muller), so the tests are repeatable
    /// without a random-number crate.
    struct Noise(u64);

    impl Noise {
        fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^= z >> 31;
            ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
        }
    }

    const A: f64 = 0.0119;
    const B: f64 = 1.4;
    const R0: f64 = 200.0;

    fn truth(r: f64) -> f64 {
        power(A, B, R0, r)
    }

    /// A lab-scale session: loads 0 to 1000 N, a 12-bit reading from the true curve, the
    /// scale's error normal with `sigma` newtons.
    fn session(n: usize, sigma: f64, seed: u64) -> Vec<(f64, Newtons)> {
        let mut noise = Noise(seed);
        (0..n)
            .map(|i| {
                let load = 1000.0 * i as f64 / (n - 1) as f64;
                let raw = R0 + (load / A).powf(1.0 / B);
                (raw.round(), Newtons(load + sigma * noise.normal()))
            })
            .collect()
    }

    fn check_recovery(curve: &SensorCurve, samples: &[(f64, Newtons)]) -> f64 {
        let (lo, hi) = min_max(&samples.iter().map(|s| s.0).collect::<Vec<_>>());
        let mut worst = 0.0_f64;
        for k in 0..=200 {
            let r = lo + (hi - lo) * f64::from(k) / 200.0;
            let (f, _) = curve.force(r).unwrap();
            worst = worst.max((f.0 - truth(r)).abs());
        }
        worst
    }

    #[test]
    fn power_law_recovers_a_known_curve() {
        for seed in 1..=5 {
            let samples = session(120, 3.0, seed);
            let (curve, report) = fit_sensor("heel", &samples, CurveKind::Power).unwrap();
            let CurveModel::Power { a, b, r0 } = curve.model else {
                panic!("not a power law");
            };
            assert!((b - B).abs() / B < 0.03, "seed {seed}: b {b}");
            // r0 is weakly determined when b > 1 (the curve leaves zero tangentially), so
            // it is judged against the span of readings.
            assert!((r0 - R0).abs() / 3300.0 < 0.02, "seed {seed}: r0 {r0}");
            assert!((a - A).abs() / A < 0.15, "seed {seed}: a {a}");
            let worst = check_recovery(&curve, &samples);
            eprintln!(
                "seed {seed}: a {:+.2}%, b {:+.2}%, r0 {r0:.1} (true {R0}), worst {worst:.2} N, \
                 rms {:.2} N, max {:.2} N",
                100.0 * (a / A - 1.0),
                100.0 * (b / B - 1.0),
                report.rms_error.0,
                report.max_error.0
            );
            assert!(worst < 10.0, "seed {seed}: worst {worst} N");
            assert!(report.rms_error.0 < 4.0, "{report:?}");
            assert_eq!(report.points, 120);
        }
    }

    #[test]
    fn piecewise_recovers_a_known_curve() {
        let samples = session(400, 3.0, 7);
        let (curve, report) = fit_sensor("toe", &samples, CurveKind::Piecewise).unwrap();
        curve.validate("test").unwrap();
        let worst = check_recovery(&curve, &samples);
        eprintln!("piecewise: worst {worst:.2} N, {report:?}");
        assert!(worst < 10.0, "worst {worst} N");
        assert!(report.rms_error.0 < 6.0, "{report:?}");
    }

    #[test]
    fn robust_fit_shrugs_off_a_few_bad_loads() {
        let mut samples = session(120, 3.0, 11);
        for k in [10, 50, 90] {
            samples[k].1 = Newtons(samples[k].1.0 + 300.0);
        }
        let (curve, report) = fit_sensor("heel", &samples, CurveKind::Power).unwrap();
        assert!(report.downweighted >= 3, "{report:?}");
        assert!(check_recovery(&curve, &samples) < 15.0);
    }

    #[test]
    fn bad_data_is_refused_by_name() {
        let good = session(40, 1.0, 3);
        let e = fit_sensor("heel", &good[..3], CurveKind::Power).unwrap_err();
        assert!(
            matches!(e, CalibrationError::TooFewPoints { found: 3, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("heel"));
        let e = fit_sensor("heel", &good[..10], CurveKind::Piecewise).unwrap_err();
        assert!(
            matches!(e, CalibrationError::TooFewPoints { needed: 12, .. }),
            "{e}"
        );

        let mut nan = good.clone();
        nan[4].0 = f64::NAN;
        assert!(matches!(
            fit_sensor("heel", &nan, CurveKind::Power),
            Err(CalibrationError::NonFinite { index: 4, .. })
        ));

        let inverted: Vec<_> = good.iter().map(|&(r, l)| (-r, l)).collect();
        let e = fit_sensor("toe", &inverted, CurveKind::Power).unwrap_err();
        assert!(matches!(e, CalibrationError::NonMonotone { .. }), "{e}");
        assert!(e.to_string().contains("toe"));

        let two_loads: Vec<_> = (0..10)
            .map(|i| (f64::from(i), Newtons(if i < 5 { 0.0 } else { 50.0 })))
            .collect();
        assert!(matches!(
            fit_sensor("x", &two_loads, CurveKind::Power),
            Err(CalibrationError::NarrowRange { .. })
        ));
        let tiny: Vec<_> = (0..10)
            .map(|i| (f64::from(i), Newtons(0.01 * f64::from(i))))
            .collect();
        assert!(matches!(
            fit_sensor("x", &tiny, CurveKind::Power),
            Err(CalibrationError::NarrowRange { .. })
        ));
        let flat: Vec<_> = (0..10).map(|i| (5.0, Newtons(f64::from(i)))).collect();
        assert!(matches!(
            fit_sensor("x", &flat, CurveKind::Power),
            Err(CalibrationError::NarrowRange { .. })
        ));
    }

    #[test]
    fn apply_clamps_and_counts() {
        let samples = session(60, 2.0, 5);
        let (curve, _) = fit_sensor("heel", &samples, CurveKind::Power).unwrap();
        let cal = SensorCalibration {
            sensors: vec![curve.clone(), curve],
        };
        let top = cal.sensors[0].force(cal.sensors[0].raw_range[1]).unwrap().0;
        let mut out = [9.0_f32; 3];
        let stats = cal.apply(&[1e9, f32::NAN], &mut out);
        assert!((f64::from(out[0]) - top.0).abs() < 1e-3 * top.0);
        assert_eq!(out[1], 0.0);
        assert_eq!(out[2], 0.0);
        assert_eq!(
            stats,
            ApplyStats {
                non_finite: 1,
                above_range: 1,
                below_range: 0,
                missing: 1
            }
        );
        let stats = cal.apply(&[-1e9, 0.0, 7.0], &mut out[..2]);
        assert_eq!(stats.below_range, 2);

        let huge = SensorCalibration {
            sensors: vec![SensorCurve {
                name: "edited".to_owned(),
                model: CurveModel::Power {
                    a: 1e300,
                    b: 1.0,
                    r0: 0.0,
                },
                raw_range: [0.0, 10.0],
                drift: 0.0,
            }],
        };
        huge.validate("edited.json").unwrap();
        let stats = huge.apply(&[5.0], &mut out[..1]);
        assert_eq!((out[0], stats.non_finite), (0.0, 1));
        assert!(out[0] >= 0.0 && out[0] < 1.0);
    }

    #[test]
    fn tare_removes_an_offset() {
        let samples = session(80, 2.0, 9);
        for kind in [CurveKind::Power, CurveKind::Piecewise] {
            let (curve, _) = fit_sensor("heel", &samples, kind).unwrap();
            let mut cal = SensorCalibration {
                sensors: vec![curve],
            };
            let probe = R0 + (500.0 / A).powf(1.0 / B);
            let before = cal.sensors[0].force(probe).unwrap().0.0;
            let rest_before = cal.sensors[0].force(R0).unwrap().0.0;
            // The sensor drifted up by 150 counts.
            let drift = 150.0;
            let rest: Vec<f32> = (0..20)
                .map(|i| (R0 + drift) as f32 + (i % 3) as f32 - 1.0)
                .collect();
            let removed = cal.tare(&rest).unwrap()[0];
            let after = cal.sensors[0].force(probe + drift).unwrap().0.0;
            let at_rest = cal.sensors[0].force(R0 + drift).unwrap().0.0;
            assert!((after - before).abs() < 10.0, "{kind}: {before} -> {after}");
            assert!(
                (at_rest - rest_before).abs() < 5.0,
                "{kind}: rest {at_rest}"
            );
            assert!((removed - drift).abs() < 30.0, "{kind}: removed {removed}");
        }
        let mut cal = SensorCalibration::default();
        assert!(cal.tare(&[1.0]).is_err());
    }

    #[test]
    fn file_round_trip_and_refusals() {
        let session = vec![
            SensorSamples {
                name: "left.heel".to_owned(),
                samples: session(60, 2.0, 1),
            },
            SensorSamples {
                name: "left.toe".to_owned(),
                samples: session(60, 2.0, 2),
            },
        ];
        let (mut cal, reports) = SensorCalibration::fit(&session, CurveKind::Power).unwrap();
        assert_eq!(reports.len(), 2);
        cal.sensors[1] = fit_sensor("left.toe", &session[1].samples, CurveKind::Piecewise)
            .unwrap()
            .0;
        cal.sensors[0].drift = 12.5;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sensors.json");
        cal.save(&path).unwrap();
        assert_eq!(SensorCalibration::load(&path).unwrap(), cal);

        let text = cal.to_json();
        let v2 = text.replace("\"version\": 1", "\"version\": 2");
        let e = SensorCalibration::from_json_str(&v2, "v2.json").unwrap_err();
        assert!(matches!(e, CalibrationError::WrongVersion { .. }), "{e}");
        assert!(e.to_string().contains("v2.json"));
        let other = text.replace(FILE_KIND, "underfoot-library");
        assert!(matches!(
            SensorCalibration::from_json_str(&other, "x"),
            Err(CalibrationError::WrongKind { .. })
        ));
        assert!(matches!(
            SensorCalibration::from_json_str("{", "x"),
            Err(CalibrationError::Json { .. })
        ));
        let mut bad = cal.clone();
        bad.sensors[0].model = CurveModel::Power {
            a: 1.0,
            b: 9.0,
            r0: 0.0,
        };
        let e = bad.save(&path).unwrap_err();
        assert!(matches!(e, CalibrationError::InvalidCurve { .. }), "{e}");
        assert!(matches!(
            SensorCalibration::from_json_str(&bad.to_json(), "x"),
            Err(CalibrationError::InvalidCurve { .. })
        ));
        // The refused save left the good file alone.
        assert_eq!(SensorCalibration::load(&path).unwrap(), cal);
    }

    #[test]
    fn session_csv_reads_and_refuses() {
        let text = "\u{feff}# scale session\nsensor,raw,load_n\nheel,200,0\n\ntoe, 210 ,0\nheel,900,250.5\n";
        let s = session_from_csv_str(text, "cal.csv").unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].name, "heel");
        assert_eq!(
            s[0].samples,
            vec![(200.0, Newtons(0.0)), (900.0, Newtons(250.5))]
        );
        assert_eq!(s[1].samples, vec![(210.0, Newtons(0.0))]);

        let err = |t: &str| session_from_csv_str(t, "cal.csv").unwrap_err();
        assert!(matches!(err(""), CalibrationError::Empty { .. }));
        assert!(matches!(
            err("sensor,raw,load_n\n"),
            CalibrationError::Empty { .. }
        ));
        assert!(matches!(
            err("# c\nsensor,raw\n"),
            CalibrationError::BadHeader { line: 2, .. }
        ));
        assert!(matches!(
            err("sensor,raw,load_n\nheel,1\n"),
            CalibrationError::FieldCount {
                line: 2,
                found: 2,
                ..
            }
        ));
        let e = err("sensor,raw,load_n\nheel,1,0\nheel,x,5\n");
        assert!(
            matches!(
                e,
                CalibrationError::BadValue {
                    line: 3,
                    column: "raw",
                    ..
                }
            ),
            "{e}"
        );
        let message = e.to_string();
        assert!(
            message.contains("cal.csv") && message.contains("line 3"),
            "{message}"
        );
        assert!(matches!(
            err("sensor,raw,load_n\nheel,1,inf\n"),
            CalibrationError::BadValue {
                column: "load_n",
                ..
            }
        ));
        assert!(matches!(
            err("sensor,raw,load_n\nhe el,1,2\n"),
            CalibrationError::BadValue {
                column: "sensor",
                ..
            }
        ));
        assert!(matches!(
            read_session(Path::new("/nonexistent/cal.csv")),
            Err(CalibrationError::Io { .. })
        ));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn fitting_and_applying_never_panic(
            points in prop::collection::vec((-1e6f64..1e6, -1e4f64..1e4), 0..60),
            piecewise in any::<bool>(),
            probes in prop::collection::vec(any::<f32>(), 0..8),
        ) {
            // Half the cases trend upwards, so that they reach the solver rather than
            // stop at the monotonicity check.
            let trend = if piecewise == (points.len() % 2 == 0) { 0.01 } else { 0.0 };
            let samples: Vec<(f64, Newtons)> = points
                .iter()
                .map(|&(r, l)| (r, Newtons(l * (1.0 - 99.0 * trend) + trend * r)))
                .collect();
            let kind = if piecewise { CurveKind::Piecewise } else { CurveKind::Power };
            if let Ok((curve, report)) = fit_sensor("any", &samples, kind) {
                prop_assert!(report.rms_error.0.is_finite());
                let cal = SensorCalibration { sensors: vec![curve.clone(), curve] };
                let mut out = [0.0_f32; 4];
                cal.apply(&probes, &mut out);
                prop_assert!(out.iter().all(|v| v.is_finite()));
            }
        }

        #[test]
        fn unvalidated_curves_never_panic(
            knots in prop::collection::vec(prop::array::uniform2(any::<f64>()), 0..6),
            range in prop::array::uniform2(any::<f64>()),
            probes in prop::collection::vec(any::<f32>(), 0..8),
        ) {
            let cal = SensorCalibration {
                sensors: vec![SensorCurve {
                    name: "raw".to_owned(),
                    model: CurveModel::Piecewise { knots },
                    raw_range: range,
                    drift: 0.0,
                }],
            };
            let mut out = [0.0_f32; 2];
            cal.apply(&probes, &mut out);
            prop_assert!(out.iter().all(|v| v.is_finite()));
        }

        #[test]
        fn piecewise_is_monotone_for_any_input(
            points in prop::collection::vec((0.0f64..4096.0, -20.0f64..1000.0), 12..200),
            probes in prop::collection::vec(-1e6f64..1e6, 1..50),
        ) {
            // Give the data an upward trend so that it passes the monotonicity check;
            // the noise on top is arbitrary.
            let samples: Vec<(f64, Newtons)> = points
                .iter()
                .map(|&(r, l)| (r, Newtons(l * 0.2 + r * 0.5)))
                .collect();
            let Ok((curve, _)) = fit_sensor("p", &samples, CurveKind::Piecewise) else {
                return Ok(());
            };
            curve.validate("p").unwrap();
            let mut probes = probes;
            probes.sort_by(f64::total_cmp);
            let mut previous = f64::NEG_INFINITY;
            for r in probes {
                let f = curve.force(r).unwrap().0.0;
                prop_assert!(f.is_finite());
                prop_assert!(f >= previous, "{} after {}", f, previous);
                previous = f;
            }
        }
    }
}
