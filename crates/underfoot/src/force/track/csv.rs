//! The track as a CSV file: reading it through [`crate::document::csv`], and writing it
//! in the shortest form that reads back the same (see the parent module, *File format*).

use std::fmt::Write as _;
use std::path::Path;

use super::check::{channels_from_header, check_row, column_names, inconsistent};
use super::error::{BEYOND_F32, NOT_FINITE, TrackError};
use super::{ForceRow, ForceTrack, TIME_COLUMN};
use crate::atomic_file::OutputFile;
use crate::document::FileError;
use crate::document::csv::records;
use crate::force::{MAX_SENSORS, SensorReading};
use crate::limits::{MAX_TRACK_BYTES, read_to_string_capped};
use crate::units::Seconds;

impl ForceTrack {
    /// Reads and checks a force track file; see the [module docs](super) for the format.
    ///
    /// # Errors
    /// [`TrackError::File`] if the file cannot be read, is not UTF-8 or is larger than
    /// [`MAX_TRACK_BYTES`] (a device or pipe included), otherwise the
    /// first fault found, naming the file and line.
    pub fn read(path: &Path) -> Result<Self, TrackError> {
        let text = read_to_string_capped(path, MAX_TRACK_BYTES).map_err(|source| FileError {
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
        let mut records = records(text.as_bytes()).map(|record| {
            record.map_err(|csv| TrackError::Csv {
                origin: origin.to_owned(),
                csv,
            })
        });
        let Some(header) = records.next().transpose()? else {
            return Err(TrackError::Empty {
                origin: origin.to_owned(),
            });
        };
        let header_line = header.line;
        let header = header.as_strs();
        // A row always has a field, if only an empty one.
        let [first, columns @ ..] = &header[..] else {
            return Err(TrackError::Empty {
                origin: origin.to_owned(),
            });
        };
        if *first != TIME_COLUMN {
            return Err(TrackError::NoTimeColumn {
                origin: origin.to_owned(),
                line: header_line,
                found: (*first).to_owned(),
            });
        }
        let channels = channels_from_header(origin, header_line, columns)?;

        let mut rows: Vec<ForceRow> = Vec::new();
        let mut values = [0.0_f32; MAX_SENSORS];
        for record in records {
            let record = record?;
            let line = record.line;
            let record = &record.fields;
            if record.len() != header.len() {
                return Err(TrackError::FieldCount {
                    origin: origin.to_owned(),
                    line,
                    expected: header.len(),
                    found: record.len(),
                });
            }
            let bad_value = |field: usize, reason| TrackError::BadValue {
                origin: origin.to_owned(),
                line,
                column: header[field].to_owned(),
                text: record[field].to_owned(),
                reason,
            };
            let time: f64 = record[0].parse().map_err(|_| bad_value(0, NOT_FINITE))?;
            let mut field = 1;
            let mut readings = Vec::with_capacity(channels.len());
            for channel in &channels {
                let n = channel.sensors.len();
                for value in &mut values[..n] {
                    let text = &record[field];
                    *value = text.parse().map_err(|_| bad_value(field, NOT_FINITE))?;
                    // Checked here, where the text is at hand: `1e300` overflows `f32` to
                    // infinity, which the row check would report as "inf".
                    if value.is_infinite() && text.parse::<f64>().is_ok_and(f64::is_finite) {
                        return Err(bad_value(field, BEYOND_F32));
                    }
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

    /// The track as CSV text in the [file format](super): one header line, one line per
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
    /// What [`ForceTrack::validate`] finds (naming `path`), or [`TrackError::File`] naming
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
}
