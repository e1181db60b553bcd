//! The rules of the file format, checked in one place for a file read and a track built
//! in memory: the header's channels and sensors, and each row against them and the row
//! before (see the parent module, *File format*).

use super::error::{NOT_FINITE, TrackError};
use super::{ChannelSensors, ForceRow, ForceTrack, LONE_CHANNEL, TIME_COLUMN};
use crate::force::{MAX_SENSORS, SensorReading};
use crate::limits::MAX_TRACK_GAP;

impl ForceTrack {
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
}

pub(super) fn inconsistent(origin: &str, reason: String) -> TrackError {
    TrackError::Inconsistent {
        origin: origin.to_owned(),
        reason,
    }
}

/// The sensor column names (without `time_s`) a track with these channels is written with.
pub(super) fn column_names(channels: &[ChannelSensors]) -> Vec<String> {
    if let [only] = channels
        && only.name == LONE_CHANNEL
        && only.sensors.len() == 1
    {
        return only.sensors.clone();
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
pub(super) fn channels_from_header(
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
pub(super) fn check_row(
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
        reason: NOT_FINITE,
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
