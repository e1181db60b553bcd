//! Recordings: decoding audio files and data-logger CSVs, and finding heel strikes in them.
//!
//! [`read`] turns a file into a [`Recording`]: mono `f64` samples at the file's own rate,
//! with the file's name and SHA-256 so that a fitted model can say what it was learnt from.
//!
//! * WAV, FLAC and Ogg Vorbis are decoded by symphonia, the container chosen by probing the
//!   content (the extension is only a hint); see [Decoding](self#decoding) below.
//! * A file whose extension is `.csv` (any case) is read as a data-logger CSV, which needs a
//!   [`CsvSpec`]: the column holding the signal and the logging rate. The spec is ignored
//!   for audio files, so one spec can be passed for a whole folder.
//!
//! # Decoding
//! Multi-channel audio is averaged to mono with equal weights. Integer PCM is scaled so
//! that full scale is `[-1, 1)` (divided by `2^(bits-1)`); float PCM is kept as stored.
//! Decoding is all-or-nothing: a damaged packet, a demuxer error, or fewer frames than
//! the header promises is [`RecordingError::Corrupt`], never half a recording.
//!
//! # Checks
//! Every recording, whatever its format, must then pass, in this order:
//!
//! 1. at least one sample ([`RecordingError::Empty`]);
//! 2. every sample finite ([`RecordingError::NonFinite`], with the first bad index) and
//!    within [`MAX_SAMPLE`] ([`RecordingError::OutOfRange`]): a CSV sample of `1e308` is
//!    finite, but its square is not, and the strike analysis would then report a strike
//!    "-inf dB above its noise";
//! 3. at least [`MIN_DURATION`] long ([`RecordingError::TooShort`]): shorter than a
//!    strike's analysis window is useless and usually a mistake;
//! 4. not silent ([`RecordingError::Silent`]): some sample differs from the first by more
//!    than `SILENCE_TOLERANCE * max(1, |x[0]|)`. Relative to `max(1, |x[0]|)` rather than
//!    to `|x[0]|` alone so that exact digital silence (all zeros), a DC offset (a CSV of a
//!    sensor stuck at 512) and a float file of constant 0.25 are all caught by one rule,
//!    while a real recording, whose noise floor is far above `1e-9` full scale, passes.
//!
//! # Size
//! A file is read only up to [`MAX_RECORDING_BYTES`] and decodes to at most
//! [`MAX_RECORDING_FRAMES`] frames (30 minutes at 48 kHz); beyond either it is refused as
//! [`RecordingError::TooLong`] before memory grows further, so a device node (`/dev/zero`)
//! or a pipe that never ends is refused too.
//!
//! A long recording (a walk of minutes) is read by [`read_for_analysis`] as excerpts
//! around its strikes, never held whole: see [`excerpts`].
//!
//! Heel strikes are found in [`strikes`].
mod csv;
mod decode;
mod error;
pub mod excerpts;
pub mod strikes;

pub use error::RecordingError;
pub use excerpts::{Excerpt, by_file, read_for_analysis};

use crate::document::FileError;
use crate::limits::read_capped;
pub use crate::limits::{MAX_RECORDING_BYTES, MAX_RECORDING_FRAMES};
use crate::units::{SampleRate, Seconds};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// Recordings shorter than this are rejected as [`RecordingError::TooShort`].
pub const MIN_DURATION: Seconds = Seconds(0.05);

/// Relative tolerance of the silence check: see the [module docs](self#checks).
pub const SILENCE_TOLERANCE: f64 = 1e-9;

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
    /// Where in its file this excerpt of a long recording is (see [`excerpts`]); `None`
    /// for a whole recording.
    pub excerpt: Option<Excerpt>,
}

impl Recording {
    /// The length of the recording.
    #[must_use]
    pub fn duration(&self) -> Seconds {
        self.rate.duration_of(self.samples.len())
    }
}

/// How to read a CSV file: which column holds the signal, and at which rate it was logged.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CsvSpec {
    /// Column header name, or a 0-based index written as a number (used when the first
    /// row has no field of that name, or the file has no header).
    pub column: String,
    /// The logging rate.
    pub rate: SampleRate,
}

/// Reads a recording: WAV, FLAC or Ogg Vorbis by content, or CSV (needs `csv`).
///
/// `name` in the result is the file name without directories.
///
/// # Errors
/// A [`RecordingError`] naming the file when it cannot be read, decoded, or is empty,
/// silent, too short or holds non-finite samples; see the [module docs](self#checks).
pub fn read(path: &Path, csv: Option<&CsvSpec>) -> Result<Recording, RecordingError> {
    let bytes = read_capped(path, MAX_RECORDING_BYTES).map_err(|source| {
        if source.kind() == std::io::ErrorKind::FileTooLarge {
            RecordingError::TooLong {
                file: path.to_path_buf(),
                limit: format!("{} MiB", MAX_RECORDING_BYTES >> 20),
            }
        } else {
            RecordingError::File(FileError {
                path: path.to_path_buf(),
                action: "reading",
                source,
            })
        }
    })?;
    decode_and_check(path, file_name(path), &bytes, csv)
}

/// A recording from samples already in memory (a caller's array, not a file), checked
/// as [`read`] checks a file's (see the [module docs](self#checks)); `name` stands for
/// the file in errors and in a model's `sources`, and the digest is of the samples'
/// little-endian bytes. The samples are taken whole: [`read_for_analysis`]'s excerpts are
/// for files too long to hold.
///
/// # Errors
/// [`RecordingError::InvalidRate`] for a rate of zero, [`RecordingError::TooLong`] past
/// [`MAX_RECORDING_FRAMES`], and the checks of
/// [`read`].
pub fn from_samples(
    name: &str,
    rate: SampleRate,
    samples: Vec<f64>,
) -> Result<Recording, RecordingError> {
    let file = Path::new(name);
    if rate.0 == 0 {
        return Err(RecordingError::InvalidRate {
            file: file.to_path_buf(),
            reason: "the rate given is 0 Hz".into(),
        });
    }
    if samples.len() > MAX_RECORDING_FRAMES {
        return Err(RecordingError::TooLong {
            file: file.to_path_buf(),
            limit: format!("{} samples", MAX_RECORDING_FRAMES),
        });
    }
    check(file, rate, &samples)?;
    let mut digest = Sha256::new();
    for v in &samples {
        digest.update(v.to_le_bytes());
    }
    Ok(Recording {
        name: name.to_owned(),
        rate,
        samples,
        sha256: hex(&digest.finalize()),
        excerpt: None,
    })
}

/// Reads a recording held in memory, as [`read`] does a file named `name`.
///
/// The extension of `name` decides whether it is a CSV, and hints the audio format.
///
/// # Errors
/// As [`read`], with `name` as the file in every error.
pub fn read_bytes(
    name: &str,
    bytes: &[u8],
    csv: Option<&CsvSpec>,
) -> Result<Recording, RecordingError> {
    let file = PathBuf::from(name);
    decode_and_check(&file, file_name(&file), bytes, csv)
}

/// Whether `path` names a data-logger CSV: its extension is `.csv`, in any case.
fn is_csv(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
}

/// A recording's name: its file name without directories (the whole path when it has
/// none, such as `..`).
fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.to_string_lossy().into_owned(),
        |n| n.to_string_lossy().into_owned(),
    )
}

fn decode_and_check(
    file: &Path,
    name: String,
    bytes: &[u8],
    csv: Option<&CsvSpec>,
) -> Result<Recording, RecordingError> {
    let (rate, samples) = if is_csv(file) {
        let spec = csv.ok_or_else(|| RecordingError::CsvNeedsSpec {
            file: file.to_path_buf(),
        })?;
        if spec.rate.0 == 0 {
            return Err(RecordingError::InvalidRate {
                file: file.to_path_buf(),
                reason: "the CSV spec gives 0 Hz".into(),
            });
        }
        (spec.rate, csv::read_column(file, bytes, spec)?)
    } else {
        decode::decode_audio(file, bytes)?
    };
    check(file, rate, &samples)?;
    Ok(Recording {
        name,
        rate,
        samples,
        sha256: sha256_hex(bytes),
        excerpt: None,
    })
}

/// The largest sample magnitude a recording may hold: far above any sensor's full scale
/// in its own units (audio is ±1, an accelerometer a few thousand m/s², a 24-bit ADC's raw
/// counts 8.4e6), and far below where squares summed over the longest recording overflow
/// (`1e24` × 8.6e7 samples).
pub const MAX_SAMPLE: f64 = 1e12;

/// The checks every recording must pass; see the [module docs](self#checks).
fn check(file: &Path, rate: SampleRate, x: &[f64]) -> Result<(), RecordingError> {
    let file = || file.to_path_buf();
    let Some(&first) = x.first() else {
        return Err(RecordingError::Empty { file: file() });
    };
    if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(RecordingError::NonFinite {
            file: file(),
            index,
            value,
        });
    }
    if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| v.abs() > MAX_SAMPLE) {
        return Err(RecordingError::OutOfRange {
            file: file(),
            index,
            value,
        });
    }
    let duration = rate.duration_of(x.len());
    if duration.0 < MIN_DURATION.0 {
        return Err(RecordingError::TooShort {
            file: file(),
            samples: x.len(),
            rate: rate.0,
            duration,
            min: MIN_DURATION,
        });
    }
    let tol = SILENCE_TOLERANCE * first.abs().max(1.0);
    if x.iter().all(|v| (v - first).abs() <= tol) {
        return Err(RecordingError::Silent {
            file: file(),
            first,
        });
    }
    Ok(())
}

fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// A digest as lower-case hex.
fn hex(digest: &[u8]) -> String {
    use std::fmt::Write;
    digest.iter().fold(String::with_capacity(64), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_in_memory_are_checked_as_a_file_is_and_named_in_errors() {
        let rate = SampleRate(1000);
        let tone: Vec<f64> = (0..200).map(|n| (n as f64 * 0.3).sin()).collect();
        let r = from_samples("array 0", rate, tone.clone()).unwrap();
        assert_eq!((r.name.as_str(), r.samples.len()), ("array 0", 200));
        assert_eq!(r.sha256.len(), 64);
        assert_ne!(
            r.sha256,
            from_samples("b", rate, tone[1..].to_vec()).unwrap().sha256
        );
        let mut nan = tone.clone();
        nan[7] = f64::NAN;
        for (samples, rate, expect) in [
            (nan, rate, "sample 7"),
            (vec![], rate, "no samples"),
            (vec![0.5; 200], rate, "silent"),
            (tone[..10].to_vec(), rate, "short"),
            (tone.clone(), SampleRate(0), "0 Hz"),
        ] {
            let e = from_samples("array 0", rate, samples)
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("array 0: ") && e.contains(expect), "{e}");
        }
    }

    #[test]
    fn sha256_of_known_strings() {
        // FIPS 180-2 test vectors.
        assert_eq!(
            sha256_hex(b""),
            "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
        );
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn silence_rule_is_relative_to_max_one_first() {
        let f = Path::new("x.csv");
        let r = SampleRate(1000);
        let mut x = vec![512.0; 100];
        x[50] += 1e-7; // within 1e-9 * 512
        assert!(matches!(
            check(f, r, &x),
            Err(RecordingError::Silent { .. })
        ));
        x[50] = 512.0 + 1e-6; // beyond 1e-9 * 512 = 5.12e-7
        assert!(check(f, r, &x).is_ok());
        let mut z = vec![0.0; 100];
        z[3] = 5e-10;
        assert!(matches!(
            check(f, r, &z),
            Err(RecordingError::Silent { .. })
        ));
        z[3] = 2e-9;
        assert!(check(f, r, &z).is_ok());
    }

    /// A 16-bit mono WAV header whose data chunk claims `data_len` bytes, then `body`.
    fn wav_claiming(data_len: u32, body: &[u8]) -> Vec<u8> {
        let mut w = Vec::new();
        w.extend_from_slice(b"RIFF");
        w.extend_from_slice(&data_len.saturating_add(36).to_le_bytes());
        w.extend_from_slice(b"WAVEfmt ");
        w.extend_from_slice(&16u32.to_le_bytes());
        w.extend_from_slice(&1u16.to_le_bytes()); // PCM
        w.extend_from_slice(&1u16.to_le_bytes()); // mono
        w.extend_from_slice(&48_000u32.to_le_bytes());
        w.extend_from_slice(&96_000u32.to_le_bytes());
        w.extend_from_slice(&2u16.to_le_bytes());
        w.extend_from_slice(&16u16.to_le_bytes());
        w.extend_from_slice(b"data");
        w.extend_from_slice(&data_len.to_le_bytes());
        w.extend_from_slice(body);
        w
    }

    #[test]
    fn a_header_promising_more_than_the_cap_is_refused_before_decoding() {
        let body: Vec<u8> = (0..4800u32)
            .flat_map(|i| ((i % 200) as i16).to_le_bytes())
            .collect();
        let fine = wav_claiming(body.len() as u32, &body);
        assert_eq!(
            read_bytes("ok.wav", &fine, None).unwrap().samples.len(),
            4800
        );
        let e = read_bytes("huge.wav", &wav_claiming(u32::MAX - 64, &body), None).unwrap_err();
        assert!(matches!(e, RecordingError::TooLong { .. }), "{e:?}");
        assert!(e.to_string().contains("huge.wav"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn an_endless_device_is_refused_not_read_forever() {
        // Issue 14: `fit /dev/zero` grew until the kernel killed it.
        let e = read(Path::new("/dev/zero"), None).unwrap_err();
        assert!(matches!(e, RecordingError::TooLong { .. }), "{e:?}");
    }

    #[test]
    fn too_short_boundary_is_min_duration() {
        let f = Path::new("x.csv");
        let r = SampleRate(1000);
        let x: Vec<f64> = (0..50).map(|i| f64::from(i % 2)).collect();
        assert!(check(f, r, &x).is_ok(), "exactly 50 ms is long enough");
        assert!(matches!(
            check(f, r, &x[..49]),
            Err(RecordingError::TooShort { samples: 49, .. })
        ));
    }

    #[test]
    fn a_sample_too_large_to_analyse_is_refused_with_its_value() {
        let f = Path::new("x.csv");
        let mut x: Vec<f64> = (0..1000).map(|i| f64::from(i % 7) * 0.1).collect();
        x[17] = 1e308;
        let e = check(f, SampleRate(1000), &x).unwrap_err();
        assert!(
            matches!(e, RecordingError::OutOfRange { index: 17, value, .. } if value == 1e308),
            "{e:?}"
        );
        assert!(e.to_string().contains("sample 17 is 1e308"), "{e}");
        x[17] = -MAX_SAMPLE;
        assert!(check(f, SampleRate(1000), &x).is_ok());
    }

    #[test]
    fn first_non_finite_index_is_reported() {
        let f = Path::new("x.csv");
        let mut x: Vec<f64> = (0..100).map(|i| f64::from(i).sin()).collect();
        x[70] = f64::NEG_INFINITY;
        x[42] = f64::NAN;
        assert!(matches!(
            check(f, SampleRate(1000), &x),
            Err(RecordingError::NonFinite { index: 42, .. })
        ));
    }
}
