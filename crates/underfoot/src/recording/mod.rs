//! Recordings: decoding audio files and data-logger CSVs, and finding heel strikes in them.
pub mod strikes;

use crate::units::SampleRate;

/// One recording, mixed to mono, at its own sample rate.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// File name (without directories), as recorded in a model's `sources`.
    pub name: String,
    /// The rate the samples were taken at.
    pub rate: SampleRate,
    /// Mono samples (channels averaged), full scale about 1.
    pub samples: Vec<f64>,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256: String,
}

/// How to read a CSV file: which column holds the signal, and at which rate it was logged.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvSpec {
    /// Column header name, or a 0-based index written as a number.
    pub column: String,
    /// The logging rate.
    pub rate: SampleRate,
}

/// What is wrong with a recording. Every variant names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordingError {
    /// Placeholder until the decoder lands.
    #[error("{path}: not implemented")]
    Todo {
        /// The file.
        path: std::path::PathBuf,
    },
}

/// Reads a recording: WAV, FLAC or Ogg Vorbis by content, or CSV (needs `csv`).
///
/// # Errors
/// A [`RecordingError`] naming the file when it cannot be read, decoded, or is empty,
/// silent, too short or holds non-finite samples.
pub fn read(path: &std::path::Path, csv: Option<&CsvSpec>) -> Result<Recording, RecordingError> {
    let _ = csv;
    Err(RecordingError::Todo {
        path: path.to_path_buf(),
    })
}
