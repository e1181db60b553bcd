//! Data-logger CSV files: one column of numbers, logged at a known rate.
//!
//! Format accepted: the project's one table dialect ([`crate::document::csv`]):
//! comma-separated, fields trimmed of surrounding whitespace, blank lines and lines
//! starting with `#` ignored, an optional UTF-8 byte-order mark, and line numbers in
//! errors that count every line. Only the first row may be a header.
//!
//! Which column holds the signal ([`CsvSpec::column`]):
//!
//! 1. if the first row is a header (some field is not a number) and a field equals `column`
//!    exactly, the column is that field's position;
//! 2. otherwise, if `column` is a non-negative integer `k`, the column is the `k`-th
//!    (0-based); the first row is skipped as a header when its `k`-th field is not a
//!    number, and is data otherwise (so a first row of numbers is never a header, even when
//!    one of them reads like the column index; and a headerless file may have non-numeric
//!    fields, such as time stamps, in other columns);
//! 3. otherwise the column does not exist, and that is an error at line 1.
//!
//! Every row must have as many fields as the first: a ragged row usually means a logger
//! glitch or a wrong delimiter, and guessing which field is meant would misalign the signal.
//! Numbers are parsed by Rust's `f64` parser, which accepts `nan` and `inf`; those are let
//! through here and rejected with their row index by the common checks in
//! [`read_bytes`](super::read_bytes).

use std::path::Path;

use super::{CsvSpec, MAX_RECORDING_FRAMES, RecordingError};
use crate::document::csv::records;

/// Reads the `spec.column` column of a CSV file held in memory.
pub(crate) fn read_column(
    file: &Path,
    bytes: &[u8],
    spec: &CsvSpec,
) -> Result<Vec<f64>, RecordingError> {
    let csv_err = |line: u64, column: Option<usize>, reason: String| RecordingError::Csv {
        file: file.to_path_buf(),
        line,
        column,
        reason,
    };
    let mut samples = Vec::new();
    // Set from the first row: (column index, number of fields per row).
    let mut layout: Option<(usize, usize)> = None;
    let wanted = spec.column.trim();
    for record in records(bytes) {
        let record = record
            .map_err(|e| csv_err(e.line, None, format!("not readable as CSV ({})", e.message)))?;
        let line = record.line;
        let record = record.as_strs();
        let (column, width) = match layout {
            Some(l) => l,
            None => {
                let width = record.len();
                let is_header = record.iter().any(|f| f.parse::<f64>().is_err());
                if let Some(k) = record
                    .iter()
                    .position(|&f| f == wanted)
                    .filter(|_| is_header)
                {
                    layout = Some((k, width));
                    continue;
                }
                let Ok(k) = wanted.parse::<usize>() else {
                    return Err(csv_err(
                        line,
                        None,
                        format!(
                            "no column named '{wanted}' in the first row [{}], and it is not a \
                             0-based column index",
                            record.join(", ")
                        ),
                    ));
                };
                if k >= width {
                    return Err(csv_err(
                        line,
                        Some(k),
                        format!("no column {k}: the first row has only {width} fields"),
                    ));
                }
                layout = Some((k, width));
                if record[k].parse::<f64>().is_err() {
                    // A header without the requested name: skip it.
                    continue;
                }
                (k, width)
            }
        };
        if record.len() != width {
            return Err(csv_err(
                line,
                None,
                format!(
                    "ragged row: {} fields where the first row has {width}",
                    record.len()
                ),
            ));
        }
        let field = record[column];
        let value = field.parse::<f64>().map_err(|_| {
            csv_err(
                line,
                Some(column),
                format!("column {column}: '{field}' is not a number"),
            )
        })?;
        if samples.len() == MAX_RECORDING_FRAMES {
            return Err(RecordingError::TooLong {
                file: file.to_path_buf(),
                limit: format!("{MAX_RECORDING_FRAMES} rows"),
            });
        }
        samples.push(value);
    }
    Ok(samples)
}
