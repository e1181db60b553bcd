//! Tables: the CSV files the project reads and writes (force tracks, sensor-calibration
//! sessions, data-logger recordings), read one way.
//!
//! The dialect: comma-separated, fields trimmed of surrounding whitespace, double quotes
//! as in RFC 4180 (no field the project writes needs them), blank lines and lines whose
//! first field starts with `#` skipped, an optional UTF-8 byte-order mark ignored, rows
//! of any length (each format checks its own width, so that a ragged row is reported in
//! that format's words). Line numbers count every line of the file, comments and blank
//! lines included, so that an error points at the line an editor shows.
//!
//! ```
//! use underfoot::document::csv::records;
//!
//! let text = "\u{feff}# a comment\ntime_s, left.heel\n\n0.0, 12.5\n";
//! let rows: Vec<_> = records(text.as_bytes()).collect::<Result<_, _>>()?;
//! assert_eq!(rows[0].line, 2);
//! assert_eq!(rows[0].fields, ["time_s", "left.heel"]);
//! assert_eq!(rows[1].line, 4);
//! assert_eq!(rows[1].fields, ["0.0", "12.5"]);
//! # Ok::<(), underfoot::document::csv::CsvError>(())
//! ```

/// One row of a table: its fields, trimmed, and the 1-based line it starts on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvRecord {
    /// The line of the file the row starts on.
    pub line: u64,
    /// The fields, trimmed.
    pub fields: Vec<String>,
}

impl CsvRecord {
    /// The fields as string slices.
    #[must_use]
    pub fn as_strs(&self) -> Vec<&str> {
        self.fields.iter().map(String::as_str).collect()
    }
}

/// A row that is not CSV at all (the reader could not split it).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: not readable as CSV ({message})")]
pub struct CsvError {
    /// The line the reader stopped at.
    pub line: u64,
    /// What the reader objected to.
    pub message: String,
}

/// The rows of a table held in memory, in order, comments and blank lines left out.
pub fn records(bytes: &[u8]) -> impl Iterator<Item = Result<CsvRecord, CsvError>> + '_ {
    let bytes = bytes
        .strip_prefix(b"\xEF\xBB\xBF".as_slice())
        .unwrap_or(bytes);
    let reader = ::csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(::csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(bytes);
    // The reader's own line count leaves out the comment lines it skips, and its byte
    // position of a record is where it began reading: before the line break that ended
    // the previous record and before any comment lines. Step over those, then count the
    // line breaks, once through the file.
    let mut counted = (0usize, 1u64);
    let mut line_at = move |position: Option<&::csv::Position>| {
        let start = position.map_or(0, |p| usize::try_from(p.byte()).unwrap_or(usize::MAX));
        let mut b = start.clamp(counted.0, bytes.len());
        loop {
            while b < bytes.len() && matches!(bytes[b], b'\r' | b'\n') {
                b += 1;
            }
            let line_start = b == 0 || matches!(bytes[b - 1], b'\r' | b'\n');
            if b < bytes.len() && bytes[b] == b'#' && line_start {
                b += bytes[b..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .unwrap_or(bytes.len() - b);
            } else {
                break;
            }
        }
        counted.1 += bytes[counted.0..b].iter().filter(|&&c| c == b'\n').count() as u64;
        counted.0 = b;
        counted.1
    };
    reader
        .into_records()
        .filter_map(move |record| match record {
            Err(e) => Some(Err(CsvError {
                line: line_at(e.position()),
                message: e.to_string(),
            })),
            Ok(record) => {
                // The reader's own comment rule needs `#` in the first column; an indented
                // comment, and a line of blanks (one empty field), are skipped here.
                let first = record.get(0).unwrap_or("");
                if first.starts_with('#') || (record.len() == 1 && first.is_empty()) {
                    return None;
                }
                Some(Ok(CsvRecord {
                    line: line_at(record.position()),
                    fields: record.iter().map(str::to_owned).collect(),
                }))
            }
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(text: &str) -> Vec<(u64, Vec<String>)> {
        records(text.as_bytes())
            .map(|r| r.map(|r| (r.line, r.fields)))
            .collect::<Result<_, _>>()
            .unwrap()
    }

    #[test]
    fn comments_blanks_and_the_bom_are_skipped_and_lines_still_count() {
        let text = "\u{feff}a,b\n\n   \n  # indented comment\n# comment\n 1 , 2 \n3,4,5\r\n6";
        assert_eq!(
            rows(text),
            vec![
                (1, vec!["a".into(), "b".into()]),
                (6, vec!["1".into(), "2".into()]),
                (7, vec!["3".into(), "4".into(), "5".into()]),
                (8, vec!["6".into()]),
            ]
        );
    }

    #[test]
    fn quoted_fields_are_unquoted() {
        assert_eq!(
            rows("\"x, y\",2\n"),
            vec![(1, vec!["x, y".into(), "2".into()])]
        );
    }

    proptest::proptest! {
        /// Without quotes, the table is exactly the lines split at commas, trimmed, with
        /// blank and `#` lines left out, and every line counted.
        #[test]
        fn unquoted_tables_match_a_split_by_hand(
            lines in proptest::collection::vec("[ a-z0-9.,#-]{0,12}", 0..30),
            crlf in proptest::bool::ANY,
        ) {
            let text = lines.join(if crlf { "\r\n" } else { "\n" });
            let by_hand: Vec<(u64, Vec<String>)> = text
                .lines()
                .zip(1u64..)
                .map(|(l, n)| (n, l.trim()))
                .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
                .map(|(n, l)| (n, l.split(',').map(|f| f.trim().to_owned()).collect()))
                .collect();
            proptest::prop_assert_eq!(rows(&text), by_hand);
        }
    }
}
