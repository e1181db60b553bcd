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
//!   row, at most [`MAX_TRACK_GAP`] (10 s) apart. The first time need not be zero (a
//!   logger's clock is fine): what plays a track (an offline render, a replay) counts its
//!   times from the first row, so a track at `1700000000` plays as one at `0`.
//! * The file is at most [`MAX_TRACK_BYTES`] long.
//! * Every other column is one sensor, named `<channel>.<sensor>`: `left.heel`, or
//!   `tile0.c0` for a tile's corners. Channels are numbered in order of first appearance;
//!   a channel's sensors are contiguous columns, in reading order, at most
//!   [`MAX_SENSORS`] of them, their names unique within the channel.
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
//! * Fields are separated by commas and trimmed of surrounding whitespace; nothing is
//!   quoted (no name or number needs it). Blank lines and lines starting with `#` are
//!   skipped; a UTF-8 byte-order mark is ignored. Line numbers in errors count every
//!   line of the file, comments and blank lines included.
//!
//! Reading checks all of this and stops at the first fault, naming the file and line.
//! [`ForceTrack::validate`] applies the same checks to a track built in memory, and
//! [`ForceTrack::save`] runs it before anything reaches a file, so a file written here is
//! always readable here. Numbers are written in the shortest form that parses back to
//! the same value, so a save and a read give back the very same track.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::{MAX_SENSORS, SensorReading};
use crate::atomic_file::{AtomicWriteError, OutputFile};
use crate::limits::{MAX_TRACK_BYTES, MAX_TRACK_GAP, read_to_string_capped};
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

/// What is wrong with a force track file or track.
///
/// Every variant names where the track came from (`origin`: the file path, or the
/// description given to [`ForceTrack::from_csv_str`] or [`ForceTrack::validate`]).
/// `line` is the 1-based line of the file; for a track in memory it is the line the row
/// would have in [`ForceTrack::to_csv`] (the header is line 1, row `i` is line `i + 2`).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TrackError {
    /// The file could not be read or written.
    #[error("{path}: {action}: {source}", path = path.display())]
    Io {
        /// The file (or, for a save, possibly the temporary file next to it).
        path: PathBuf,
        /// What was being done, e.g. `reading`.
        action: &'static str,
        /// The underlying error.
        #[source]
        source: std::io::Error,
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
    /// A channel with more sensors than a [`SensorReading`] holds.
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
    /// A field that is not a number, or is infinite or NaN.
    #[error("{origin}: line {line}: column {column}: {text:?} is not a finite number")]
    BadValue {
        /// Where the text came from.
        origin: String,
        /// The row's line.
        line: u64,
        /// The column's name.
        column: String,
        /// The field as written.
        text: String,
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

impl From<AtomicWriteError> for TrackError {
    fn from(e: AtomicWriteError) -> Self {
        Self::Io {
            path: e.path,
            action: e.action,
            source: e.source,
        }
    }
}

impl ForceTrack {
    /// Reads and checks a force track file; see the [module docs](self) for the format.
    ///
    /// # Errors
    /// [`TrackError::Io`] if the file cannot be read, is not UTF-8 or is larger than
    /// [`MAX_TRACK_BYTES`] (a device or pipe included), otherwise the
    /// first fault found, naming the file and line.
    pub fn read(path: &Path) -> Result<Self, TrackError> {
        let text =
            read_to_string_capped(path, MAX_TRACK_BYTES).map_err(|source| TrackError::Io {
                path: path.to_path_buf(),
                action: "reading",
                source,
            })?;
        Self::from_csv_str(&text, &path.display().to_string())
    }

    /// Parses and checks a force track held in memory; `origin` names it in errors.
    ///
    /// # Errors
    /// The first fault found, naming `origin` and the line; see [`TrackError`].
    pub fn from_csv_str(text: &str, origin: &str) -> Result<Self, TrackError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        // Split by hand rather than with a CSV reader: nothing in the format needs
        // quoting, and the line numbers in errors must count comments and blank lines.
        let mut records = text
            .lines()
            .zip(1u64..)
            .map(|(l, n)| (n, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
            .map(|(n, l)| (n, l.split(',').map(str::trim).collect::<Vec<&str>>()));

        let Some((header_line, header)) = records.next() else {
            return Err(TrackError::Empty {
                origin: origin.to_owned(),
            });
        };
        if header[0] != TIME_COLUMN {
            return Err(TrackError::NoTimeColumn {
                origin: origin.to_owned(),
                line: header_line,
                found: header[0].to_owned(),
            });
        }
        let channels = channels_from_header(origin, header_line, &header[1..])?;

        let mut rows: Vec<ForceRow> = Vec::new();
        let mut values = [0.0_f32; MAX_SENSORS];
        for (line, record) in records {
            if record.len() != header.len() {
                return Err(TrackError::FieldCount {
                    origin: origin.to_owned(),
                    line,
                    expected: header.len(),
                    found: record.len(),
                });
            }
            let bad_value = |field: usize| TrackError::BadValue {
                origin: origin.to_owned(),
                line,
                column: header[field].to_owned(),
                text: record[field].to_owned(),
            };
            let time: f64 = record[0].parse().map_err(|_| bad_value(0))?;
            let mut field = 1;
            let mut readings = Vec::with_capacity(channels.len());
            for channel in &channels {
                let n = channel.sensors.len();
                for value in &mut values[..n] {
                    *value = record[field].parse().map_err(|_| bad_value(field))?;
                    field += 1;
                }
                // The header allows 1..=MAX_SENSORS sensors, so this always succeeds.
                let reading = SensorReading::new(&values[..n]).ok_or_else(|| {
                    inconsistent(origin, format!("channel {:?} has no sensors", channel.name))
                })?;
                readings.push(reading);
            }
            let row = ForceRow {
                time: Seconds(time),
                readings,
            };
            check_row(origin, &channels, &row, line, rows.last().map(|r| r.time.0))?;
            rows.push(row);
        }
        if rows.is_empty() {
            return Err(TrackError::NoRows {
                origin: origin.to_owned(),
            });
        }
        Ok(Self { channels, rows })
    }

    /// Checks a track against the rules of the file format, as [`ForceTrack::read`] does;
    /// `origin` names the track in errors.
    ///
    /// # Errors
    /// The first fault found; row faults give the line the row would have in
    /// [`ForceTrack::to_csv`].
    pub fn validate(&self, origin: &str) -> Result<(), TrackError> {
        if self.channels.is_empty() {
            return Err(TrackError::NoSensorColumns {
                origin: origin.to_owned(),
                line: 1,
            });
        }
        if let Some(c) = self.channels.iter().find(|c| c.sensors.is_empty()) {
            return Err(inconsistent(
                origin,
                format!("channel {:?} has no sensors", c.name),
            ));
        }
        for (i, c) in self.channels.iter().enumerate() {
            if self.channels[..i].iter().any(|d| d.name == c.name) {
                return Err(inconsistent(
                    origin,
                    format!("two channels are named {:?}", c.name),
                ));
            }
        }
        // The header rules (names, contiguity, sensor count) are checked in one place: by
        // parsing the header this track would be written with.
        let columns = column_names(&self.channels);
        let columns: Vec<&str> = columns.iter().map(String::as_str).collect();
        if channels_from_header(origin, 1, &columns)? != self.channels {
            return Err(inconsistent(
                origin,
                format!(
                    "the channels do not read back from their own header [{}]",
                    columns.join(", ")
                ),
            ));
        }
        if self.rows.is_empty() {
            return Err(TrackError::NoRows {
                origin: origin.to_owned(),
            });
        }
        let mut previous = None;
        for (i, row) in self.rows.iter().enumerate() {
            check_row(origin, &self.channels, row, i as u64 + 2, previous)?;
            previous = Some(row.time.0);
        }
        Ok(())
    }

    /// The track as CSV text in the [file format](self): one header line, one line per
    /// row, each ending in `\n`.
    ///
    /// Numbers are written in the shortest form that parses back to the same `f64` time
    /// or `f32` value, so [`ForceTrack::from_csv_str`] gives back an equal track.
    #[must_use]
    pub fn to_csv(&self) -> String {
        let mut out = String::from(TIME_COLUMN);
        for name in column_names(&self.channels) {
            out.push(',');
            out.push_str(&name);
        }
        out.push('\n');
        for row in &self.rows {
            // Writing to a String cannot fail.
            let _ = write!(out, "{}", row.time.0);
            for value in row.readings.iter().flat_map(SensorReading::as_slice) {
                let _ = write!(out, ",{value}");
            }
            out.push('\n');
        }
        out
    }

    /// Checks the track, then writes it to `path` atomically: a crash or an error part-way
    /// leaves any previous file as it was.
    ///
    /// # Errors
    /// What [`ForceTrack::validate`] finds (naming `path`), or [`TrackError::Io`] naming
    /// the file and the step that failed.
    pub fn save(&self, path: &Path) -> Result<(), TrackError> {
        self.save_to(&OutputFile::check(path, &[])?)
    }

    /// [`ForceTrack::save`] to an output the caller checked against the output policy
    /// ([`crate::atomic_file`]) together with its other outputs and its inputs.
    ///
    /// # Errors
    /// As [`ForceTrack::save`].
    pub fn save_to(&self, out: &OutputFile) -> Result<(), TrackError> {
        self.validate(&out.path().display().to_string())?;
        Ok(out.write(self.to_csv().as_bytes())?)
    }

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
        intervals.sort_by(f64::total_cmp);
        let mid = intervals.len() / 2;
        let median = if intervals.len() % 2 == 1 {
            intervals[mid]
        } else {
            0.5 * (intervals[mid - 1] + intervals[mid])
        };
        (median > 0.0 && median.is_finite()).then(|| 1.0 / median)
    }
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

fn inconsistent(origin: &str, reason: String) -> TrackError {
    TrackError::Inconsistent {
        origin: origin.to_owned(),
        reason,
    }
}

/// The sensor column names (without `time_s`) a track with these channels is written with.
fn column_names(channels: &[ChannelSensors]) -> Vec<String> {
    if let [only] = channels {
        if only.name == LONE_CHANNEL && only.sensors.len() == 1 {
            return only.sensors.clone();
        }
    }
    channels
        .iter()
        .flat_map(|c| c.sensors.iter().map(move |s| format!("{}.{s}", c.name)))
        .collect()
}

/// Why `name` cannot be a channel (`channel == true`) or sensor name, if it cannot.
fn name_fault(name: &str, channel: bool) -> Option<&'static str> {
    let valid = |c: char| c.is_alphanumeric() || c == '_' || c == '-';
    match (name.is_empty(), name.chars().all(valid), channel) {
        (true, _, true) => Some("the channel name (before the dot) is empty"),
        (true, _, false) => Some("the sensor name is empty"),
        (false, false, true) => {
            Some("the channel name has a character other than a letter, digit, '_' or '-'")
        }
        (false, false, false) => {
            Some("the sensor name has a character other than a letter, digit, '_' or '-'")
        }
        (false, true, _) => None,
    }
}

/// The channels named by the sensor columns of a header (the fields after `time_s`).
fn channels_from_header(
    origin: &str,
    line: u64,
    columns: &[&str],
) -> Result<Vec<ChannelSensors>, TrackError> {
    // Column 1 is time_s, so columns[i] is column i + 2.
    let bad = |i: usize, reason: &'static str| TrackError::BadColumn {
        origin: origin.to_owned(),
        line,
        position: i + 2,
        column: columns[i].to_owned(),
        reason,
    };
    match columns {
        [] => {
            return Err(TrackError::NoSensorColumns {
                origin: origin.to_owned(),
                line,
            });
        }
        [lone] if !lone.contains('.') => {
            if *lone == TIME_COLUMN {
                return Err(bad(0, "the time column can only be the first"));
            }
            if let Some(reason) = name_fault(lone, false) {
                return Err(bad(0, reason));
            }
            return Ok(vec![ChannelSensors {
                name: LONE_CHANNEL.to_owned(),
                sensors: vec![(*lone).to_owned()],
            }]);
        }
        _ => {}
    }

    let mut channels: Vec<ChannelSensors> = Vec::new();
    for (i, column) in columns.iter().enumerate() {
        let Some((channel, sensor)) = column.split_once('.') else {
            return Err(bad(
                i,
                "expected <channel>.<sensor>; only a lone force column may leave out the channel",
            ));
        };
        if let Some(reason) = name_fault(channel, true).or_else(|| name_fault(sensor, false)) {
            return Err(bad(i, reason));
        }
        match channels.last_mut() {
            Some(last) if last.name == channel => {
                if last.sensors.iter().any(|s| s == sensor) {
                    return Err(bad(i, "the channel already has a sensor of this name"));
                }
                if last.sensors.len() == MAX_SENSORS {
                    return Err(TrackError::TooManySensors {
                        origin: origin.to_owned(),
                        line,
                        channel: channel.to_owned(),
                        position: i + 2,
                        column: (*column).to_owned(),
                    });
                }
                last.sensors.push(sensor.to_owned());
                continue;
            }
            _ => {}
        }
        if channels.iter().any(|c| c.name == channel) {
            return Err(TrackError::NonContiguous {
                origin: origin.to_owned(),
                line,
                position: i + 2,
                column: (*column).to_owned(),
                channel: channel.to_owned(),
            });
        }
        channels.push(ChannelSensors {
            name: channel.to_owned(),
            sensors: vec![sensor.to_owned()],
        });
    }
    Ok(channels)
}

/// Checks one row against the channels and the previous row's time.
fn check_row(
    origin: &str,
    channels: &[ChannelSensors],
    row: &ForceRow,
    line: u64,
    previous: Option<f64>,
) -> Result<(), TrackError> {
    if row.readings.len() != channels.len() {
        return Err(inconsistent(
            origin,
            format!(
                "line {line}: {} readings for {} channels",
                row.readings.len(),
                channels.len()
            ),
        ));
    }
    for (reading, channel) in row.readings.iter().zip(channels) {
        if reading.len() != channel.sensors.len() {
            return Err(inconsistent(
                origin,
                format!(
                    "line {line}: channel {:?} has {} sensors but a reading of {}",
                    channel.name,
                    channel.sensors.len(),
                    reading.len()
                ),
            ));
        }
    }
    let bad_value = |column: String, text: String| TrackError::BadValue {
        origin: origin.to_owned(),
        line,
        column,
        text,
    };
    let time = row.time.0;
    if !time.is_finite() {
        return Err(bad_value(TIME_COLUMN.to_owned(), time.to_string()));
    }
    let values = row.readings.iter().flat_map(SensorReading::as_slice);
    if let Some((k, v)) = values.enumerate().find(|(_, v)| !v.is_finite()) {
        // Only now, on the error path, is it worth naming the columns.
        let column = column_names(channels).swap_remove(k);
        return Err(bad_value(column, v.to_string()));
    }
    if let Some(previous) = previous {
        if time <= previous {
            return Err(TrackError::TimeOrder {
                origin: origin.to_owned(),
                line,
                time,
                previous,
            });
        }
        if time - previous > MAX_TRACK_GAP.0 {
            return Err(TrackError::TimeGap {
                origin: origin.to_owned(),
                line,
                time,
                previous,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn reading(values: &[f32]) -> SensorReading {
        SensorReading::new(values).unwrap()
    }

    fn feet() -> ForceTrack {
        let channel = |name: &str| ChannelSensors {
            name: name.to_owned(),
            sensors: vec!["heel".to_owned(), "toe".to_owned()],
        };
        ForceTrack {
            channels: vec![channel("left"), channel("right")],
            rows: vec![
                ForceRow {
                    time: Seconds(0.0),
                    readings: vec![reading(&[0.0, 0.0]), reading(&[-0.25, 0.0])],
                },
                ForceRow {
                    time: Seconds(0.002),
                    readings: vec![reading(&[0.1, 1e-7]), reading(&[812.345_6, 3.0])],
                },
                ForceRow {
                    time: Seconds(0.004),
                    readings: vec![reading(&[1.0 / 3.0, 2.5e30]), reading(&[7.0, 0.0])],
                },
            ],
        }
    }

    fn error(text: &str) -> TrackError {
        ForceTrack::from_csv_str(text, "walk.csv").unwrap_err()
    }

    #[test]
    fn round_trip_is_exact() {
        let track = feet();
        let text = track.to_csv();
        assert!(text.starts_with("time_s,left.heel,left.toe,right.heel,right.toe\n"));
        assert_eq!(ForceTrack::from_csv_str(&text, "mem").unwrap(), track);
        track.validate("mem").unwrap();
        assert_eq!(track.channel_count(), 2);
        assert!((track.duration().0 - 0.004).abs() < 1e-15);
        assert!((track.sensor_rate().unwrap() - 500.0).abs() < 1e-9);
    }

    #[test]
    fn reads_the_documented_example_and_lone_columns() {
        let text = "\u{feff}# walking, 70 kg; newtons\n\
                    time_s,left.heel,left.toe,right.heel,right.toe\n\
                    0,0,0,0,0\n\
                    \n\
                    0.002, 0.51 ,0,0,0\n\
                    0.004,2.04,0,-0.3,0.1\n";
        let track = ForceTrack::from_csv_str(text, "doc").unwrap();
        assert_eq!(track.rows.len(), 3);
        assert_eq!(track.channels[1].name, "right");
        assert_eq!(track.rows[2].readings[1].as_slice(), &[-0.3, 0.1]);

        let lone = ForceTrack::from_csv_str("time_s,force\n0,1\n0.01,2.5\n", "lone").unwrap();
        assert_eq!(
            lone.channels,
            vec![ChannelSensors {
                name: "0".to_owned(),
                sensors: vec!["force".to_owned()]
            }]
        );
        assert_eq!(lone.to_csv(), "time_s,force\n0,1\n0.01,2.5\n");
        assert!((lone.sensor_rate().unwrap() - 100.0).abs() < 1e-9);
        // A lone column with a dot is an ordinary channel.
        let tile = ForceTrack::from_csv_str("time_s,tile0.c0\n0,1\n", "t").unwrap();
        assert_eq!(tile.channels[0].name, "tile0");
        assert_eq!(tile.sensor_rate(), None);
        assert_eq!(tile.duration(), Seconds(0.0));
    }

    #[test]
    fn header_faults_are_named() {
        assert!(matches!(error(""), TrackError::Empty { .. }));
        assert!(matches!(
            error("# only a comment\n\n"),
            TrackError::Empty { .. }
        ));
        assert!(matches!(
            error("0,1,2\n0.1,1,2\n"),
            TrackError::NoTimeColumn { line: 1, ref found, .. } if found == "0"
        ));
        assert!(matches!(
            error("# c\ntime_s\n0\n"),
            TrackError::NoSensorColumns { line: 2, .. }
        ));
        assert!(matches!(
            error("time_s,left.heel,toe\n"),
            TrackError::BadColumn { position: 3, ref column, .. } if column == "toe"
        ));
        assert!(matches!(
            error("time_s,left.heel,left.\n"),
            TrackError::BadColumn { position: 3, .. }
        ));
        assert!(matches!(
            error("time_s,le ft.heel\n"),
            TrackError::BadColumn { position: 2, .. }
        ));
        assert!(matches!(
            error("time_s,a.x,a.y,a.x\n"),
            TrackError::BadColumn { position: 4, .. }
        ));
        assert!(matches!(
            error("time_s,time_s\n"),
            TrackError::BadColumn { position: 2, .. }
        ));
        assert!(matches!(
            error("time_s,left.heel,right.heel,left.toe\n0,1,2,3\n"),
            TrackError::NonContiguous { position: 4, ref channel, .. } if channel == "left"
        ));
        let nine: Vec<String> = (0..=MAX_SENSORS).map(|k| format!("tile.c{k}")).collect();
        assert!(matches!(
            error(&format!("time_s,{}\n", nine.join(","))),
            TrackError::TooManySensors { position: 10, ref channel, .. } if channel == "tile"
        ));
        assert!(matches!(
            error("time_s,force\n# no rows\n"),
            TrackError::NoRows { .. }
        ));
    }

    #[test]
    fn row_faults_give_their_line() {
        let head = "# comment\ntime_s,l.heel,l.toe\n0,1,2\n";
        assert!(matches!(
            error(&format!("{head}0.1,1\n")),
            TrackError::FieldCount {
                line: 4,
                expected: 3,
                found: 2,
                ..
            }
        ));
        assert!(matches!(
            error(&format!("{head}0.1,1,2,3\n")),
            TrackError::FieldCount {
                line: 4,
                found: 4,
                ..
            }
        ));
        assert!(matches!(
            error(&format!("{head}\n0.1,1,x\n")),
            TrackError::BadValue { line: 5, ref column, ref text, .. }
                if column == "l.toe" && text == "x"
        ));
        assert!(matches!(
            error(&format!("{head}0.1,NaN,2\n")),
            TrackError::BadValue { line: 4, ref column, .. } if column == "l.heel"
        ));
        // Beyond f32 range parses as infinity, and is caught as such.
        assert!(matches!(
            error(&format!("{head}0.1,1e39,2\n")),
            TrackError::BadValue { line: 4, .. }
        ));
        assert!(matches!(
            error(&format!("{head}inf,1,2\n")),
            TrackError::BadValue { line: 4, ref column, .. } if column == "time_s"
        ));
        assert!(matches!(
            error(&format!("{head}0.1,1,2\n0.1,1,2\n")),
            TrackError::TimeOrder { line: 5, .. }
        ));
        assert!(matches!(
            error(&format!("{head}-0.1,1,2\n")),
            TrackError::TimeOrder { line: 4, .. }
        ));
        // Drifting sensors read slightly negative; that is not an error.
        ForceTrack::from_csv_str(&format!("{head}0.1,-0.4,2\n"), "drift").unwrap();
    }

    #[test]
    fn a_gap_beyond_the_bound_is_refused_with_its_line() {
        let head = "time_s,l.heel,l.toe\n0,1,2\n0.002,1,2\n";
        // A last row at 1e300 s (issue 14): refused, not silently played as 1 s of nothing.
        let e = error(&format!("{head}1e300,1,2\n"));
        assert!(
            matches!(e, TrackError::TimeGap { line: 4, previous, .. } if previous == 0.002),
            "{e:?}"
        );
        assert!(e.to_string().contains("line 4"), "{e}");
        assert!(matches!(
            error(&format!("{head}10.1,1,2\n")),
            TrackError::TimeGap { line: 4, .. }
        ));
        // Exactly the bound is fine; a logger's clock is fine.
        ForceTrack::from_csv_str(&format!("{head}10.002,1,2\n"), "t").unwrap();
        let logger =
            ForceTrack::from_csv_str("time_s,force\n1700000000,1\n1700000000.002,2\n", "logger")
                .unwrap();
        assert!((logger.duration().0 - 0.002).abs() < 1e-6);
        let mut far = feet();
        far.rows[2].time = Seconds(1e300);
        assert!(matches!(
            far.validate("far"),
            Err(TrackError::TimeGap { line: 4, .. })
        ));
    }

    #[cfg(unix)]
    #[test]
    fn an_endless_device_is_refused_as_too_large() {
        let e = ForceTrack::read(Path::new("/dev/zero")).unwrap_err();
        assert!(
            matches!(&e, TrackError::Io { source, .. }
                if source.kind() == std::io::ErrorKind::FileTooLarge),
            "{e:?}"
        );
    }

    #[test]
    fn messages_name_the_file_and_line() {
        let message = error("time_s,force\n0,1\n0.5,oops\n").to_string();
        assert!(
            message.contains("walk.csv") && message.contains("line 3"),
            "{message}"
        );
        assert!(
            message.contains("force") && message.contains("oops"),
            "{message}"
        );
        let missing = ForceTrack::read(Path::new("/nonexistent/walk.csv")).unwrap_err();
        assert!(matches!(missing, TrackError::Io { .. }));
        assert!(missing.to_string().contains("/nonexistent/walk.csv"));
    }

    #[test]
    fn validate_catches_tracks_built_wrongly() {
        let mut track = feet();
        track.rows[2].time = Seconds(0.001);
        assert!(matches!(
            track.validate("mem"),
            Err(TrackError::TimeOrder { line: 4, .. })
        ));
        let mut track = feet();
        track.rows[1].readings.pop();
        assert!(matches!(
            track.validate("mem"),
            Err(TrackError::Inconsistent { .. })
        ));
        let mut track = feet();
        track.rows[1].readings[1] = reading(&[1.0, 2.0, 3.0]);
        assert!(matches!(
            track.validate("mem"),
            Err(TrackError::Inconsistent { .. })
        ));
        let mut track = feet();
        track.rows[0].readings[1] = reading(&[1.0, f32::INFINITY]);
        assert!(matches!(
            track.validate("mem"),
            Err(TrackError::BadValue { line: 2, ref column, .. }) if column == "right.toe"
        ));
        let mut track = feet();
        track.channels[1].name = "left".to_owned();
        assert!(matches!(
            track.validate("mem"),
            Err(TrackError::Inconsistent { .. })
        ));
        let mut track = feet();
        track.channels[0].sensors[1] = "to.e".to_owned();
        assert!(matches!(
            track.validate("mem"),
            Err(TrackError::BadColumn { .. })
        ));
        let mut track = feet();
        track.rows.clear();
        assert!(matches!(
            track.validate("mem"),
            Err(TrackError::NoRows { .. })
        ));
    }

    #[test]
    fn save_is_readable_and_refuses_bad_tracks() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("walk.csv");
        let track = feet();
        track.save(&path).unwrap();
        assert_eq!(ForceTrack::read(&path).unwrap(), track);

        let mut bad = track.clone();
        bad.rows[1].time = Seconds(-1.0);
        let e = bad.save(&path).unwrap_err();
        assert!(e.to_string().contains("walk.csv"), "{e}");
        assert_eq!(ForceTrack::read(&path).unwrap(), track);

        let e = track
            .save(&dir.path().join("missing/walk.csv"))
            .unwrap_err();
        assert!(matches!(e, TrackError::Io { .. }), "{e}");
    }

    fn track_strategy() -> impl Strategy<Value = ForceTrack> {
        let value = prop_oneof![
            prop::num::f32::NORMAL,
            prop::num::f32::SUBNORMAL,
            prop::num::f32::ZERO,
            -2000.0f32..2000.0,
        ];
        prop::collection::vec(1usize..=MAX_SENSORS, 1..4)
            .prop_flat_map(move |sensors| {
                let width: usize = sensors.iter().sum();
                let row = (
                    1e-6f64..1.0,
                    prop::collection::vec(value.clone(), width..=width),
                );
                (
                    Just(sensors),
                    -10.0f64..10.0,
                    prop::collection::vec(row, 1..20),
                )
            })
            .prop_map(|(sensors, start, rows)| {
                let channels: Vec<ChannelSensors> = sensors
                    .iter()
                    .enumerate()
                    .map(|(c, &n)| ChannelSensors {
                        name: format!("ch{c}"),
                        sensors: (0..n).map(|k| format!("s{k}")).collect(),
                    })
                    .collect();
                let mut time = start;
                let rows = rows
                    .into_iter()
                    .map(|(step, values)| {
                        time += step;
                        let mut rest = values.as_slice();
                        let readings = sensors
                            .iter()
                            .map(|&n| {
                                let (now, later) = rest.split_at(n);
                                rest = later;
                                reading(now)
                            })
                            .collect();
                        ForceRow {
                            time: Seconds(time),
                            readings,
                        }
                    })
                    .collect();
                ForceTrack { channels, rows }
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn csv_round_trip(track in track_strategy()) {
            track.validate("generated").unwrap();
            let back = ForceTrack::from_csv_str(&track.to_csv(), "generated").unwrap();
            prop_assert_eq!(back, track);
        }
    }
}
