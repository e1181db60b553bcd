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
//! ```math
//! F(r) = a\,\max(r - r_0,\ 0)^{\,b}, \qquad a > 0,\quad b = 1/k \in [0.2, 5].
//! ```
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
//! [`read_session`]); a fitted calibration is a [document](crate::document) (see
//! [`SensorCalibration::save`]), tagged with its kind [`FILE_KIND`] and version
//! [`FILE_VERSION`]:
//!
//! ```text
//! {"format": "underfoot.sensor-calibration/1",
//!  "sensors": [{"name": "heel", "model": {"power": {"a": 0.012, "b": 1.4, "r0": 200.0}},
//!               "raw_range": [190.0, 3500.0], "drift": 0.0}]}
//! ```
//!
//! Files written before the format tag, which begin
//! `{"kind": "underfoot-sensor-calibration", "version": 1, ...` ([`LEGACY_FILE_KIND`]),
//! still load; saving one writes the tag.
//!
//! # Layout
//!
//! | file | what it holds |
//! |---|---|
//! | `curve.rs` | the models ([`CurveModel`], [`SensorCurve`], [`SensorCalibration`]), their check, and applying them ([`SensorCalibration::apply`], [`ApplyStats`]) |
//! | `tare.rs` | re-zeroing for drift ([`SensorCurve::tare`], [`SensorCalibration::tare`]) |
//! | `fit.rs` | fitting a sensor or a session ([`fit_sensor`], [`SensorCalibration::fit`], [`FitReport`]): the checks on the data, the report |
//! | `power.rs` | the power law's robust fit (IRLS over [`crate::numeric::trf`]) |
//! | `piecewise.rs` | the piecewise model's fit (isotonic regression) |
//! | `session.rs` | the session CSV ([`read_session`], [`session_from_csv_str`]) |
//! | `file.rs` | the calibration file as a [`Document`](crate::document::Document) |
//! | `error.rs` | [`SensorCalibrationError`], and [`CurveError`] for a file's curve |

mod curve;
mod error;
mod file;
mod fit;
mod piecewise;
mod power;
mod session;
mod tare;
#[cfg(test)]
mod tests;

pub use curve::{ApplyStats, CurveModel, SensorCalibration, SensorCurve};
pub use error::{CurveError, SensorCalibrationError};
pub use file::{FILE_KIND, FILE_VERSION, LEGACY_FILE_KIND};
pub use fit::{CurveKind, FitReport, fit_sensor};
pub use session::{SensorSamples, read_session, session_from_csv_str};

use crate::units::Newtons;

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
