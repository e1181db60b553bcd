//! The files of the compensation workflow: a measured response, an equalizer, a user's
//! limb model, and the table of users ([`table`](mod@super::table)). Each is JSON with a `kind` and a `version`, checked on load before
//! anything else, so that handing one command another command's file, or a file from a
//! newer version, gets a message saying so. Writes go to a temporary file renamed over the
//! target, so a failed write never destroys a file that was there.

use std::path::Path;

use num_complex::Complex64;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::CompensationError;
use super::equalizer::{PassReport, Realisation, SpectralWeights};
use super::limb::LimbModel;
use super::sweep::FrequencyResponse;
use crate::atomic_file::{AtomicWriteError, OutputFile};
use crate::units::{Band, Hz, SampleRate};

/// The version of every compensation file this build reads and writes.
pub const FORMAT_VERSION: u32 = 1;

/// A compensation file type.
pub trait Document: Serialize + DeserializeOwned {
    /// The `kind` tag.
    const KIND: &'static str;
    /// Checks what serde cannot: lengths, finiteness, ranges.
    ///
    /// # Errors
    /// What is wrong.
    fn validate(&self) -> Result<(), CompensationError>;
}

fn file_error(path: &Path, reason: impl Into<String>) -> CompensationError {
    CompensationError::File {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

/// A refused or failed write of `path`, with its cause (which the error's own message
/// does not repeat).
pub(crate) fn write_error(path: &Path, e: &AtomicWriteError) -> CompensationError {
    file_error(path, format!("{e}: {}", e.source))
}

/// Reads a document of type `T`.
///
/// # Errors
/// [`CompensationError::File`] for a missing or unreadable file, bad JSON, another kind
/// of file, another version, or content that fails validation.
pub fn load<T: Document>(path: &Path) -> Result<T, CompensationError> {
    let text = crate::limits::read_to_string_capped(path, crate::limits::MAX_DOCUMENT_BYTES)
        .map_err(|e| file_error(path, e.to_string()))?;
    from_json_str(&text, path)
}

/// Parses and checks a document of type `T` held in memory, as [`load`] does a file;
/// `path` names it in errors.
///
/// # Errors
/// As [`load`], except for reading.
pub fn from_json_str<T: Document>(text: &str, path: &Path) -> Result<T, CompensationError> {
    let value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| file_error(path, format!("not JSON: {e}")))?;
    let kind = value.get("kind").and_then(serde_json::Value::as_str);
    if kind != Some(T::KIND) {
        return Err(file_error(
            path,
            format!(
                "{}, expected one of kind {:?}",
                kind.map_or_else(
                    || "not a compensation file (no \"kind\")".to_string(),
                    |k| format!("a file of kind {k:?}")
                ),
                T::KIND
            ),
        ));
    }
    let version = value.get("version").and_then(serde_json::Value::as_u64);
    if version != Some(u64::from(FORMAT_VERSION)) {
        return Err(file_error(
            path,
            format!(
                "format version {}, this build reads version {FORMAT_VERSION}",
                version.map_or_else(|| "missing".to_string(), |v| v.to_string())
            ),
        ));
    }
    let doc: T =
        serde_json::from_value(value).map_err(|e| file_error(path, format!("malformed: {e}")))?;
    doc.validate()
        .map_err(|e| file_error(path, format!("invalid: {e}")))?;
    Ok(doc)
}

/// Writes a document atomically.
///
/// # Errors
/// [`CompensationError::File`] when it cannot be written (the old file is kept).
pub fn save<T: Document>(path: &Path, doc: &T) -> Result<(), CompensationError> {
    let out = OutputFile::check(path, &[]).map_err(|e| write_error(path, &e))?;
    save_to(&out, doc)
}

/// [`save`] to an output the caller checked against the output policy
/// ([`crate::atomic_file`]) together with its inputs.
///
/// # Errors
/// As [`save`].
pub fn save_to<T: Document>(out: &OutputFile, doc: &T) -> Result<(), CompensationError> {
    let path = out.path();
    doc.validate()?;
    let mut text =
        serde_json::to_string_pretty(doc).map_err(|e| file_error(path, e.to_string()))?;
    text.push('\n');
    out.write(text.as_bytes())
        .map_err(|e| write_error(path, &e))
}

/// A measured frequency response (`underfoot calibrate sweep`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResponseFile {
    /// Always `"frequency-response"`.
    pub kind: String,
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// What was measured, for people (device, load, equalizer, noise).
    pub description: String,
    /// The rate of the measurement.
    pub rate: SampleRate,
    /// The band measured.
    pub band: Band,
    /// Sweeps averaged.
    pub repeats: usize,
    /// The frequencies, ascending, in Hz.
    pub freqs_hz: Vec<f64>,
    /// Magnitude at each, in dB.
    pub magnitude_db: Vec<f64>,
    /// Phase at each, in degrees.
    pub phase_deg: Vec<f64>,
    /// RMS deviation from flat over the band, in dB.
    pub deviation_db: f64,
}

impl ResponseFile {
    /// A file for `response`.
    #[must_use]
    pub fn new(
        response: &FrequencyResponse,
        rate: SampleRate,
        band: Band,
        repeats: usize,
        description: impl Into<String>,
    ) -> Self {
        Self {
            kind: Self::KIND.to_string(),
            version: FORMAT_VERSION,
            description: description.into(),
            rate,
            band,
            repeats,
            freqs_hz: response.freqs.iter().map(|f| f.0).collect(),
            magnitude_db: response.magnitude_db().iter().map(|d| d.0).collect(),
            phase_deg: response.phase_deg(),
            deviation_db: response.deviation_from_flat_db().0,
        }
    }

    /// The response it holds.
    #[must_use]
    pub fn response(&self) -> FrequencyResponse {
        FrequencyResponse {
            freqs: self.freqs_hz.iter().map(|&f| Hz(f)).collect(),
            response: self
                .magnitude_db
                .iter()
                .zip(&self.phase_deg)
                .map(|(&db, &deg)| Complex64::from_polar(10f64.powf(db / 20.0), deg.to_radians()))
                .collect(),
        }
    }
}

impl Document for ResponseFile {
    const KIND: &'static str = "frequency-response";

    fn validate(&self) -> Result<(), CompensationError> {
        let n = self.freqs_hz.len();
        if n < 2 || self.magnitude_db.len() != n || self.phase_deg.len() != n {
            return Err(CompensationError::InvalidParameter {
                name: "freqs_hz/magnitude_db/phase_deg",
                value: n as f64,
                expected: "at least 2 frequencies, with one magnitude and one phase each",
            });
        }
        for (what, values) in [
            ("freqs_hz", &self.freqs_hz),
            ("magnitude_db", &self.magnitude_db),
            ("phase_deg", &self.phase_deg),
        ] {
            if let Some(index) = values.iter().position(|v| !v.is_finite()) {
                return Err(CompensationError::NonFinite { what, index });
            }
        }
        if self.freqs_hz.windows(2).any(|w| w[1] <= w[0]) || self.freqs_hz[0] <= 0.0 {
            return Err(CompensationError::InvalidParameter {
                name: "freqs_hz",
                value: self.freqs_hz[0],
                expected: "positive and strictly ascending",
            });
        }
        if !self.band.fits(self.rate) {
            return Err(CompensationError::InvalidParameter {
                name: "band",
                value: self.band.hi.0,
                expected: "0 < lo < hi < Nyquist",
            });
        }
        Ok(())
    }
}

/// The figures of one equalization pass, as stored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PassFigures {
    /// 1 for the first sweep.
    pub pass: usize,
    /// RMS deviation from flat, dB.
    pub deviation_db: f64,
    /// Peak deviation from flat, dB.
    pub peak_db: f64,
}

impl From<&PassReport> for PassFigures {
    fn from(p: &PassReport) -> Self {
        Self {
            pass: p.pass,
            deviation_db: p.deviation.0,
            peak_db: p.peak.0,
        }
    }
}

/// A device equalizer (`underfoot calibrate equalize`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EqualizerFile {
    /// Always `"equalizer"`.
    pub kind: String,
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// What it equalizes, for people.
    pub description: String,
    /// The weights.
    pub weights: SpectralWeights,
    /// How they were tuned, and must be run.
    pub realisation: Realisation,
    /// The passes that tuned them.
    pub passes: Vec<PassFigures>,
}

impl EqualizerFile {
    /// A file for `weights`.
    #[must_use]
    pub fn new(
        weights: SpectralWeights,
        realisation: Realisation,
        passes: Vec<PassFigures>,
        description: impl Into<String>,
    ) -> Self {
        Self {
            kind: Self::KIND.to_string(),
            version: FORMAT_VERSION,
            description: description.into(),
            weights,
            realisation,
            passes,
        }
    }
}

impl Document for EqualizerFile {
    const KIND: &'static str = "equalizer";

    fn validate(&self) -> Result<(), CompensationError> {
        self.weights.validate()?;
        if let Realisation::LowDelay { taps } = self.realisation {
            if taps == 0 || taps > 1 << 16 {
                return Err(CompensationError::InvalidParameter {
                    name: "realisation.taps",
                    value: taps as f64,
                    expected: "1 to 65536",
                });
            }
        }
        Ok(())
    }
}

/// A user's fitted limb model (`underfoot calibrate limb`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LimbFile {
    /// Always `"limb-model"`.
    pub kind: String,
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// Whose limb, measured how, for people.
    pub description: String,
    /// The fitted model.
    pub model: LimbModel,
    /// The band it was fitted over, and that its compensation covers.
    pub band: Band,
    /// RMS of the fit's residuals, in dB.
    pub rms_error_db: f64,
}

impl LimbFile {
    /// A file for `model`.
    #[must_use]
    pub fn new(
        model: LimbModel,
        band: Band,
        rms_error_db: f64,
        description: impl Into<String>,
    ) -> Self {
        Self {
            kind: Self::KIND.to_string(),
            version: FORMAT_VERSION,
            description: description.into(),
            model,
            band,
            rms_error_db,
        }
    }
}

impl Document for LimbFile {
    const KIND: &'static str = "limb-model";

    fn validate(&self) -> Result<(), CompensationError> {
        self.model.validate()?;
        if !(self.band.lo.0 > 0.0 && self.band.hi.0 > self.band.lo.0 && self.band.hi.0.is_finite())
        {
            return Err(CompensationError::InvalidParameter {
                name: "band",
                value: self.band.lo.0,
                expected: "0 < lo < hi",
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensation::equalizer::EqualizerConfig;

    const RATE: SampleRate = SampleRate(48_000);

    fn response() -> FrequencyResponse {
        FrequencyResponse {
            freqs: vec![Hz(40.0), Hz(100.0), Hz(1000.0)],
            response: vec![
                Complex64::new(1.0, 0.0),
                Complex64::new(0.0, 2.0),
                Complex64::new(-0.5, 0.0),
            ],
        }
    }

    #[test]
    fn files_round_trip_and_refuse_the_wrong_kind_or_version() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.json");
        let file = ResponseFile::new(&response(), RATE, Band::new(40.0, 1024.0), 3, "test");
        save(&path, &file).unwrap();
        let back: ResponseFile = load(&path).unwrap();
        for (a, b) in back.response().response.iter().zip(&response().response) {
            assert!((a - b).norm() < 1e-12);
        }
        // Another kind.
        let err = load::<EqualizerFile>(&path).unwrap_err().to_string();
        assert!(
            err.contains("frequency-response") && err.contains("equalizer"),
            "{err}"
        );
        // Another version.
        let text = std::fs::read_to_string(&path)
            .unwrap()
            .replace("\"version\": 1", "\"version\": 7");
        std::fs::write(&path, text).unwrap();
        let err = load::<ResponseFile>(&path).unwrap_err().to_string();
        assert!(err.contains("version 7"), "{err}");
        // Not JSON, missing, truncated.
        std::fs::write(&path, "{\"kind\": \"freq").unwrap();
        assert!(load::<ResponseFile>(&path).is_err());
        assert!(load::<ResponseFile>(&dir.path().join("none.json")).is_err());
    }

    #[test]
    fn an_invalid_equalizer_is_refused_and_the_old_file_kept() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("eq.json");
        let weights = SpectralWeights::flat(EqualizerConfig::default(), RATE).unwrap();
        let good = EqualizerFile::new(weights.clone(), Realisation::Bank, vec![], "test");
        save(&path, &good).unwrap();
        let mut bad = good.clone();
        bad.weights.gains_db[3] = f64::NAN;
        assert!(save(&path, &bad).is_err());
        assert_eq!(load::<EqualizerFile>(&path).unwrap(), good);
        let mut short = good;
        short.weights.gains_db.pop();
        let text = serde_json::to_string(&short).unwrap();
        std::fs::write(&path, text).unwrap();
        assert!(load::<EqualizerFile>(&path).is_err());
    }
}
