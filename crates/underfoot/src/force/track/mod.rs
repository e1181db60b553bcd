//! Force tracks: timed sensor readings for every channel, and their CSV file format.
//!
//! # File format
//!
//! A force track is a UTF-8 CSV file: a header row, then one row per reading instant.
//! Two feet with an insole each, heel and toe sensors, read at 500 Hz:
//!
//! ```text
//! # walking, 70 kg; newtons
//! time_s,left.heel,left.toe,right.heel,right.toe
//! 0,0,0,0,0
//! 0.002,0.51,0,0,0
//! 0.004,2.04,0,-0.3,0.1
//! ```
//!
//! * The first column is `time_s`: seconds, finite and strictly increasing from row to
//!   row, at most [`MAX_TRACK_GAP`](crate::limits::MAX_TRACK_GAP) (10 s) apart. The first time need not be zero (a
//!   logger's clock is fine): what plays a track (an offline render, a replay) counts its
//!   times from the first row, so a track at `1700000000` plays as one at `0`.
//! * The file is at most [`MAX_TRACK_BYTES`](crate::limits::MAX_TRACK_BYTES) long.
//! * Every other column is one sensor, named `<channel>.<sensor>`: `left.heel`, or
//!   `tile0.c0` for a tile's corners. Channels are numbered in order of first appearance;
//!   a channel's sensors are contiguous columns, in reading order, at most
//!   [`MAX_SENSORS`](crate::force::MAX_SENSORS) of them, their names unique within the channel.
//! * Channel and sensor names are non-empty and made of letters, digits, `_` and `-`, so
//!   that a column name splits at its one dot and never needs quoting.
//! * A header with a single sensor column and no dot in its name (`time_s,force`) is
//!   the single-column form: one channel named [`LONE_CHANNEL`] (`0`) with one sensor of
//!   that name. [`ForceTrack::to_csv`] writes such a track in the same form.
//! * Values are newtons and must be finite. Small negative values are allowed: an
//!   unloaded sensor drifts below zero, and clipping it here would hide the offset from
//!   the conditioning stage that removes it.
//! * Every row has exactly as many fields as the header: a short row usually means a
//!   logger glitch, and guessing which sensor is missing would misassign the rest.
//! * The file is read as every table of the project is ([`crate::document::csv`]):
//!   fields are separated by commas and trimmed of surrounding whitespace; nothing is
//!   written quoted (no name or number needs it), though a field in double quotes reads
//!   as its contents. Blank lines and lines starting with `#` are skipped; a UTF-8
//!   byte-order mark is ignored. Line numbers in errors count every line of the file,
//!   comments and blank lines included.
//!
//! Reading checks all of this and stops at the first fault, naming the file and line.
//! [`ForceTrack::validate`] applies the same checks to a track built in memory, and
//! [`ForceTrack::save`] runs it before anything reaches a file, so a file written here is
//! always readable here. Numbers are written in the shortest form that parses back to
//! the same value, so a save and a read give back the very same track.
//!
//! # Layout
//!
//! | file | what it holds |
//! |---|---|
//! | `mod.rs` | the track ([`ForceTrack`], [`ForceRow`], [`ChannelSensors`]) and what it measures: duration, channels, sensor rate |
//! | `csv.rs` | reading and writing the file ([`ForceTrack::read`], [`ForceTrack::from_csv_str`], [`ForceTrack::to_csv`], [`ForceTrack::save`]) |
//! | `check.rs` | the format's rules, for a file and for a track in memory ([`ForceTrack::validate`]) |
//! | `error.rs` | [`TrackError`] |

mod check;
mod csv;
mod error;
#[cfg(test)]
mod tests;

pub use error::{BEYOND_F32, NOT_FINITE, TrackError};

use super::SensorReading;
use crate::units::Seconds;

/// The name of the time column, always the first.
pub const TIME_COLUMN: &str = "time_s";

/// The channel name of the single-column form (`time_s,force`).
pub const LONE_CHANNEL: &str = "0";

/// The sensors of one channel, by name (e.g. `heel`, `toe`, or `corner0..corner3`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelSensors {
    /// The channel's name, e.g. `left` or `tile0`.
    pub name: String,
    /// Sensor names, in reading order.
    pub sensors: Vec<String>,
}

/// One row of a track: the time and every channel's reading.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceRow {
    /// Time from the start of the track.
    pub time: Seconds,
    /// One reading per channel, in channel order.
    pub readings: Vec<SensorReading>,
}

/// A force track: rows at increasing times, the same sensors on every row.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceTrack {
    /// The channels and their sensors.
    pub channels: Vec<ChannelSensors>,
    /// The rows, in increasing time.
    pub rows: Vec<ForceRow>,
}

impl ForceTrack {
    /// The time from the first row to the last (zero for fewer than two rows).
    #[must_use]
    pub fn duration(&self) -> Seconds {
        match (self.rows.first(), self.rows.last()) {
            (Some(first), Some(last)) => Seconds(last.time.0 - first.time.0),
            _ => Seconds(0.0),
        }
    }

    /// The number of channels.
    #[must_use]
    pub fn channel_count(&self) -> usize {
        self.channels.len()
    }

    /// The sensor rate in hertz: the inverse of the median interval between rows.
    ///
    /// The median rather than the mean, so that a logger's occasional dropped or doubled
    /// sample does not shift the rate. `None` for fewer than two rows, or if the median
    /// interval is not positive (only possible for a track that fails
    /// [`ForceTrack::validate`]).
    #[must_use]
    pub fn sensor_rate(&self) -> Option<f64> {
        let mut intervals: Vec<f64> = self
            .rows
            .windows(2)
            .map(|w| w[1].time.0 - w[0].time.0)
            .collect();
        if intervals.is_empty() {
            return None;
        }
        let median = crate::numeric::median(&mut intervals);
        (median > 0.0 && median.is_finite()).then(|| 1.0 / median)
    }
}
