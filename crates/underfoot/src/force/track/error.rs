//! What can be wrong with a force track, its file, or its reading.

use super::TIME_COLUMN;
use crate::document::FileError;
use crate::document::csv::CsvError;
use crate::force::MAX_SENSORS;
use crate::limits::MAX_TRACK_GAP;

/// [`TrackError::BadValue`]'s reason for text that is no number, or infinite or NaN.
pub const NOT_FINITE: &str = "is not a finite number";

/// [`TrackError::BadValue`]'s reason for a number a force reading (`f32`) cannot hold.
pub const BEYOND_F32: &str =
    "is beyond the largest force a reading holds (3.4e38); is the column in newtons?";

/// What is wrong with a force track file or track.
///
/// Every variant names where the track came from (`origin`: the file path, or the
/// description given to [`ForceTrack::from_csv_str`](super::ForceTrack::from_csv_str) or
/// [`ForceTrack::validate`](super::ForceTrack::validate)). `line` is the 1-based line of
/// the file; for a track in memory it is the line the row would have in
/// [`ForceTrack::to_csv`](super::ForceTrack::to_csv) (the header is line 1, row `i` is
/// line `i + 2`).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TrackError {
    /// The file could not be read or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// A row the CSV reader cannot split (never from a file this crate writes).
    #[error("{origin}: {csv}")]
    Csv {
        /// Where the text came from.
        origin: String,
        /// The reader's error, with its line.
        csv: CsvError,
    },
    /// Nothing but blank lines and comments.
    #[error("{origin}: empty: expected a header row starting with {TIME_COLUMN}")]
    Empty {
        /// Where the text came from.
        origin: String,
    },
    /// The first row does not start with `time_s`: no header, or the wrong one.
    #[error(
        "{origin}: line {line}: the first column must be {TIME_COLUMN}, found {found:?} \
         (a force track starts with a header row)"
    )]
    NoTimeColumn {
        /// Where the text came from.
        origin: String,
        /// The header's line.
        line: u64,
        /// The first field found.
        found: String,
    },
    /// The header has no column after `time_s`, or the track has no channels.
    #[error("{origin}: line {line}: no sensor columns after {TIME_COLUMN}")]
    NoSensorColumns {
        /// Where the text came from.
        origin: String,
        /// The header's line.
        line: u64,
    },
    /// A column name that is not `<channel>.<sensor>` with valid names, or a duplicate.
    #[error("{origin}: line {line}: column {position} ({column:?}): {reason}")]
    BadColumn {
        /// Where the text came from.
        origin: String,
        /// The header's line.
        line: u64,
        /// 1-based column number (`time_s` is column 1).
        position: usize,
        /// The column's name.
        column: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// A channel's columns are interrupted by another channel's.
    #[error(
        "{origin}: line {line}: column {position} ({column:?}): channel {channel:?} resumes \
         after another channel's columns; a channel's sensors must be contiguous columns \
         (and channel names unique)"
    )]
    NonContiguous {
        /// Where the text came from.
        origin: String,
        /// The header's line.
        line: u64,
        /// 1-based column number of the column that resumes the channel.
        position: usize,
        /// That column's name.
        column: String,
        /// The channel.
        channel: String,
    },
    /// A channel with more sensors than a [`SensorReading`](crate::force::SensorReading) holds.
    #[error(
        "{origin}: line {line}: channel {channel:?} has more than {MAX_SENSORS} sensors \
         (column {position}, {column:?}, is one too many)"
    )]
    TooManySensors {
        /// Where the text came from.
        origin: String,
        /// The header's line.
        line: u64,
        /// The channel.
        channel: String,
        /// 1-based column number of the first sensor too many.
        position: usize,
        /// That column's name.
        column: String,
    },
    /// A row with more or fewer fields than the header.
    #[error("{origin}: line {line}: {found} fields where the header has {expected}")]
    FieldCount {
        /// Where the text came from.
        origin: String,
        /// The row's line.
        line: u64,
        /// The header's number of fields.
        expected: usize,
        /// The row's number of fields.
        found: usize,
    },
    /// A field that is not a number, is infinite or NaN, or is beyond what a reading holds.
    #[error("{origin}: line {line}: column {column}: {text:?} {reason}")]
    BadValue {
        /// Where the text came from.
        origin: String,
        /// The row's line.
        line: u64,
        /// The column's name.
        column: String,
        /// The field as written.
        text: String,
        /// What is wrong with it ([`NOT_FINITE`] or [`BEYOND_F32`]).
        reason: &'static str,
    },
    /// A row whose time is not after the previous row's.
    #[error(
        "{origin}: line {line}: time {time} s is not after the previous row's {previous} s; \
         times must strictly increase"
    )]
    TimeOrder {
        /// Where the text came from.
        origin: String,
        /// The row's line.
        line: u64,
        /// The row's time in seconds.
        time: f64,
        /// The previous row's time in seconds.
        previous: f64,
    },
    /// A row more than [`MAX_TRACK_GAP`] after the previous one (a logger restart, a
    /// typo, or a time in the wrong unit).
    #[error(
        "{origin}: line {line}: time {t} s is {gap} s after the previous row's {p} s; rows \
         may be at most {max} s apart (split the track at the gap)",
        t = seconds(*time),
        p = seconds(*previous),
        gap = seconds(time - previous),
        max = MAX_TRACK_GAP.0
    )]
    TimeGap {
        /// Where the text came from.
        origin: String,
        /// The row's line.
        line: u64,
        /// The row's time in seconds.
        time: f64,
        /// The previous row's time in seconds.
        previous: f64,
    },
    /// A header but no rows.
    #[error("{origin}: a header but no rows")]
    NoRows {
        /// Where the text came from.
        origin: String,
    },
    /// A track in memory whose rows do not fit its channels (never from a file).
    #[error("{origin}: {reason}")]
    Inconsistent {
        /// Where the track came from.
        origin: String,
        /// What does not fit, naming the channel or line.
        reason: String,
    },
}

/// A time for a message: as written when short, in exponent form when a value like 1e300
/// would print three hundred digits.
fn seconds(t: f64) -> String {
    if t.abs() < 1e12 {
        t.to_string()
    } else {
        format!("{t:e}")
    }
}
