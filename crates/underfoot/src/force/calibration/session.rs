//! The calibration session: a CSV table of `sensor,raw,load_n` rows, read through
//! [`crate::document::csv`].

use std::path::Path;

use super::error::SensorCalibrationError;
use crate::document::FileError;
use crate::document::csv::records;
use crate::limits::{MAX_DOCUMENT_BYTES, read_to_string_capped};
use crate::units::Newtons;

/// The header of a session file.
const HEADER: [&str; 3] = ["sensor", "raw", "load_n"];

/// One sensor's samples from a calibration session.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorSamples {
    /// The sensor's name.
    pub name: String,
    /// `(raw reading, known load)` pairs, in file order.
    pub samples: Vec<(f64, Newtons)>,
}

/// Reads a calibration session: a CSV file of `sensor,raw,load_n` rows, see
/// [`session_from_csv_str`].
///
/// # Errors
/// [`SensorCalibrationError::File`], or the first fault found, naming the file and line.
pub fn read_session(path: &Path) -> Result<Vec<SensorSamples>, SensorCalibrationError> {
    let text = read_to_string_capped(path, MAX_DOCUMENT_BYTES).map_err(|source| FileError {
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
/// order of first appearance. The table is read as [`crate::document::csv`] reads every
/// table: blank lines and `#` comments are skipped, a byte-order mark is ignored, and line
/// numbers count every line.
///
/// # Errors
/// [`SensorCalibrationError::Empty`], [`SensorCalibrationError::BadHeader`],
/// [`SensorCalibrationError::FieldCount`] or [`SensorCalibrationError::BadValue`].
pub fn session_from_csv_str(
    text: &str,
    origin: &str,
) -> Result<Vec<SensorSamples>, SensorCalibrationError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut rows = records(text.as_bytes()).map(|row| {
        row.map_err(|csv| SensorCalibrationError::Csv {
            origin: origin.to_owned(),
            csv,
        })
    });
    let Some(header) = rows.next().transpose()? else {
        return Err(SensorCalibrationError::Empty {
            origin: origin.to_owned(),
        });
    };
    if header.fields != HEADER {
        return Err(SensorCalibrationError::BadHeader {
            origin: origin.to_owned(),
            line: header.line,
            found: line_text(text, header.line).to_owned(),
        });
    }
    let mut session: Vec<SensorSamples> = Vec::new();
    for row in rows {
        let row = row?;
        let line = row.line;
        let [name, raw, load] = row.as_strs()[..] else {
            return Err(SensorCalibrationError::FieldCount {
                origin: origin.to_owned(),
                line,
                found: row.fields.len(),
            });
        };
        let bad = |column: &'static str, text: &str, reason: &'static str| {
            SensorCalibrationError::BadValue {
                origin: origin.to_owned(),
                line,
                column,
                text: text.to_owned(),
                reason,
            }
        };
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
        let raw = number("raw", raw)?;
        let load = number("load_n", load)?;
        match session.iter_mut().find(|s| s.name == name) {
            Some(s) => s.samples.push((raw, Newtons(load))),
            None => session.push(SensorSamples {
                name: name.to_owned(),
                samples: vec![(raw, Newtons(load))],
            }),
        }
    }
    if session.is_empty() {
        return Err(SensorCalibrationError::Empty {
            origin: origin.to_owned(),
        });
    }
    Ok(session)
}

/// Line `line` (1-based) of `text` as written, trimmed: a header is quoted in a message
/// as the user wrote it, not as the reader split it.
fn line_text(text: &str, line: u64) -> &str {
    let index = usize::try_from(line.saturating_sub(1)).unwrap_or(usize::MAX);
    text.lines().nth(index).map_or("", str::trim)
}
