//! What can be wrong with a recording file.

use crate::document::FileError;
use crate::units::Seconds;
use std::path::PathBuf;

/// What is wrong with a recording. Every variant names the file it is about, so that a
/// batch run over a folder says which file to look at.
///
/// `file` is the path given to [`read`](super::read), or the name given to
/// [`read_bytes`](super::read_bytes).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordingError {
    /// The file could not be opened or read (not found, no permission, ...): the file
    /// error names it, and says why as its source.
    #[error(transparent)]
    File(#[from] FileError),

    /// The file, or what it decodes to, is longer than the documented limit
    /// ([`crate::limits`]).
    #[error("{}: too long: more than {limit} (split the recording)", file.display())]
    TooLong {
        /// The file.
        file: PathBuf,
        /// The limit, in words.
        limit: String,
    },

    /// The file decoded to no samples at all.
    #[error("{}: holds no samples", file.display())]
    Empty {
        /// The file.
        file: PathBuf,
    },

    /// The recording is shorter than [`MIN_DURATION`](super::MIN_DURATION).
    #[error(
        "{}: only {samples} samples ({:.4} s at {rate} Hz), shorter than the minimum of {} s",
        file.display(),
        duration.0,
        min.0
    )]
    TooShort {
        /// The file.
        file: PathBuf,
        /// Number of (mono) samples found.
        samples: usize,
        /// Their sample rate in hertz.
        rate: u32,
        /// Their duration.
        duration: Seconds,
        /// The minimum accepted duration.
        min: Seconds,
    },

    /// No sample differs from the first by more than `1e-9 * max(1, |first|)`: digital
    /// silence or a constant (e.g. a disconnected sensor).
    #[error("{}: silent: every sample equals the first ({first})", file.display())]
    Silent {
        /// The file.
        file: PathBuf,
        /// The value every sample has.
        first: f64,
    },

    /// A sample is NaN or infinite.
    #[error("{}: sample {index} is not a finite number ({value})", file.display())]
    NonFinite {
        /// The file.
        file: PathBuf,
        /// 0-based index of the first offending (mono) sample; for a CSV, of the data row.
        index: usize,
        /// The offending value.
        value: f64,
    },

    /// A sample beyond [`MAX_SAMPLE`](super::MAX_SAMPLE) in magnitude: no sensor reads
    /// that, and its energy would overflow the analysis.
    #[error(
        "{}: sample {index} is {value:e}, beyond the ±{:e} a recording may hold \
         (raw counts or a wrong column?)",
        file.display(),
        super::MAX_SAMPLE
    )]
    OutOfRange {
        /// The file.
        file: PathBuf,
        /// 0-based index of the first offending (mono) sample; for a CSV, of the data row.
        index: usize,
        /// The offending value.
        value: f64,
    },

    /// Not a recognisable audio format, an undecodable packet, or truncated data.
    #[error("{}: corrupt or unsupported audio: {reason}", file.display())]
    Corrupt {
        /// The file.
        file: PathBuf,
        /// What the decoder found wrong.
        reason: String,
    },

    /// The sample rate is zero, missing, or changes within the file.
    #[error("{}: invalid sample rate: {reason}", file.display())]
    InvalidRate {
        /// The file.
        file: PathBuf,
        /// What is wrong with it.
        reason: String,
    },

    /// A CSV file could not be parsed.
    #[error("{}: line {line}: {reason}", file.display())]
    Csv {
        /// The file.
        file: PathBuf,
        /// 1-based line number of the offending record.
        line: u64,
        /// 0-based column of the offending field, when one field is at fault.
        column: Option<usize>,
        /// What is wrong (unparsable number, missing column, ragged row, ...).
        reason: String,
    },

    /// A `.csv` file was given without a [`CsvSpec`](super::CsvSpec) saying which column
    /// holds the signal and at which rate it was logged.
    #[error("{}: a CSV file needs a column and a sample rate (CsvSpec)", file.display())]
    CsvNeedsSpec {
        /// The file.
        file: PathBuf,
    },
}

impl RecordingError {
    /// The file (path or name) the error is about.
    #[must_use]
    pub fn file(&self) -> &std::path::Path {
        match self {
            Self::File(e) => &e.path,
            Self::TooLong { file, .. }
            | Self::Empty { file }
            | Self::TooShort { file, .. }
            | Self::Silent { file, .. }
            | Self::NonFinite { file, .. }
            | Self::OutOfRange { file, .. }
            | Self::Corrupt { file, .. }
            | Self::InvalidRate { file, .. }
            | Self::Csv { file, .. }
            | Self::CsvNeedsSpec { file } => file,
        }
    }
}
