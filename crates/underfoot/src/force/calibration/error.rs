//! What can be wrong with calibration data, a fit, a session or a calibration file.

use super::MIN_RANK_CORRELATION;
use super::fit::CurveKind;
use crate::document::csv::CsvError;
use crate::document::{DocumentError, FileError};
use crate::numeric::trf::TrfError;

/// What is wrong with calibration data, a fit, or a calibration file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SensorCalibrationError {
    /// A calibration file could not be read or written, is not a sensor calibration of a
    /// version this build reads, or holds a curve that cannot be applied (its
    /// [`reason`](DocumentError::reason) is then a [`CurveError`]).
    #[error(transparent)]
    Document(#[from] DocumentError),
    /// A session file could not be read.
    #[error(transparent)]
    File(#[from] FileError),
    /// A session file the CSV reader cannot split into rows.
    #[error("{origin}: {csv}")]
    Csv {
        /// Where the text came from.
        origin: String,
        /// The reader's error, with its line.
        csv: CsvError,
    },
    /// A curve in memory that cannot be applied.
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
    /// A curve kind that is neither `power` nor `piecewise`.
    #[error("unknown curve kind {found:?}: expected power or piecewise")]
    UnknownKind {
        /// The kind as written.
        found: String,
    },
    /// Rest readings that do not match the sensors.
    #[error("tare: {reason}")]
    Tare {
        /// What is wrong.
        reason: String,
    },
}

/// A curve that cannot be applied: what a calibration file's check
/// ([`Document::validate`](crate::document::Document::validate)) finds. The file's error
/// ([`DocumentError::Invalid`]) names the file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("sensor {sensor:?}: {reason}")]
pub struct CurveError {
    /// The sensor.
    pub sensor: String,
    /// What is wrong.
    pub reason: String,
}

impl CurveError {
    /// The error of a curve in memory, named by `origin`.
    pub(super) fn at(self, origin: &str) -> SensorCalibrationError {
        SensorCalibrationError::InvalidCurve {
            origin: origin.to_owned(),
            sensor: self.sensor,
            reason: self.reason,
        }
    }
}
