//! The files of the compensation workflow: a measured response, an equalizer and a user's
//! limb model (the table of users is [`UserTable`](super::table::UserTable)).
//!
//! Each is a [`Document`] of the one [document layer](crate::document): JSON whose first
//! key is its format tag, `"format": "underfoot.<kind>/1"`, checked on load before
//! anything else, so that handing one command another command's file, or a file from a
//! newer version, gets a message saying so; read with [`document::load`] and written with
//! [`document::save`] (a temporary file renamed over the target, so a failed write never
//! destroys a file that was there).
//!
//! | type | kind | written by |
//! |---|---|---|
//! | [`ResponseFile`] | `frequency-response` | `underfoot calibrate sweep` |
//! | [`EqualizerFile`] | `equalizer` | `underfoot calibrate equalize` |
//! | [`LimbFile`] | `limb-model` | `underfoot calibrate limb` |
//! | [`UserTable`](super::table::UserTable) | `user-table` | `underfoot eq-table add` |
//!
//! Files written before the document layer carried `"kind"` and `"version": 1` keys
//! instead of the tag; they still load ([`Document::LEGACY_KIND`]), and are written back
//! with the tag.
//!
//! [`document::load`]: crate::document::load
//! [`document::save`]: crate::document::save

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::CompensationError;
use super::equalizer::{PassReport, Realisation, SpectralWeights};
use super::limb::LimbModel;
use super::sweep::FrequencyResponse;
use crate::document::Document;
use crate::units::{Band, Hz, SampleRate};

/// A measured frequency response (`underfoot calibrate sweep`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResponseFile {
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
    const VERSION: u32 = 1;
    const LEGACY_KIND: Option<&'static str> = Some("frequency-response");
    const DESCRIPTION: &'static str = "measured response";
    type Invalid = CompensationError;

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
    /// Whether the pass measured the best deviation so far (files written before passes
    /// could be refused have every pass kept).
    #[serde(default = "kept_by_default")]
    pub kept: bool,
}

fn kept_by_default() -> bool {
    true
}

impl From<&PassReport> for PassFigures {
    fn from(p: &PassReport) -> Self {
        Self {
            pass: p.pass,
            deviation_db: p.deviation.0,
            peak_db: p.peak.0,
            kept: p.kept,
        }
    }
}

/// A device equalizer (`underfoot calibrate equalize`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EqualizerFile {
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
            description: description.into(),
            weights,
            realisation,
            passes,
        }
    }
}

impl Document for EqualizerFile {
    const KIND: &'static str = "equalizer";
    const VERSION: u32 = 1;
    const LEGACY_KIND: Option<&'static str> = Some("equalizer");
    const DESCRIPTION: &'static str = "equalizer";
    type Invalid = CompensationError;

    fn validate(&self) -> Result<(), CompensationError> {
        self.weights.validate()?;
        if let Realisation::LowDelay { taps } = self.realisation
            && (taps == 0 || taps > 1 << 16)
        {
            return Err(CompensationError::InvalidParameter {
                name: "realisation.taps",
                value: taps as f64,
                expected: "1 to 65536",
            });
        }
        Ok(())
    }
}

/// A user's fitted limb model (`underfoot calibrate limb`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LimbFile {
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
            description: description.into(),
            model,
            band,
            rms_error_db,
        }
    }
}

impl Document for LimbFile {
    const KIND: &'static str = "limb-model";
    const VERSION: u32 = 1;
    const LEGACY_KIND: Option<&'static str> = Some("limb-model");
    const DESCRIPTION: &'static str = "limb model";
    type Invalid = CompensationError;

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
    use crate::document::{DocumentError, from_json, load, save, to_json};

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
            .replace("frequency-response/1", "frequency-response/7");
        std::fs::write(&path, text).unwrap();
        let err = load::<ResponseFile>(&path).unwrap_err().to_string();
        assert!(err.contains("version 7"), "{err}");
        // Not JSON, missing, truncated.
        std::fs::write(&path, "{\"format\": \"underfoot.freq").unwrap();
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
        // The tag by hand: saving would refuse the short curve before writing it.
        let body = serde_json::to_string(&short).unwrap();
        let text = format!("{{\"format\": \"underfoot.equalizer/1\", {}", &body[1..]);
        std::fs::write(&path, text).unwrap();
        assert!(load::<EqualizerFile>(&path).is_err());
    }

    /// The files written before the document layer, with `"kind"` and `"version"` keys,
    /// still load, as what they held.
    #[test]
    fn files_with_the_old_header_still_load() {
        fn legacy<T: Document>(doc: &T) -> String {
            let tag = format!("\"format\": \"underfoot.{}/1\"", T::KIND);
            let json = to_json(doc, "test").unwrap();
            assert!(json.contains(&tag), "{json}");
            json.replace(
                &tag,
                &format!("\"kind\": \"{}\",\n  \"version\": 1", T::KIND),
            )
        }
        let weights = SpectralWeights::flat(EqualizerConfig::default(), RATE).unwrap();
        let response = ResponseFile::new(&response(), RATE, Band::new(40.0, 1024.0), 3, "old");
        let equalizer =
            EqualizerFile::new(weights, Realisation::LowDelay { taps: 64 }, vec![], "old");
        let limb = LimbFile::new(
            LimbModel::new(
                crate::compensation::limb::LimbParams::TABLE1_MEAN,
                0.005,
                1.0,
            )
            .unwrap(),
            Band::new(40.0, 1024.0),
            0.1,
            "old",
        );
        assert_eq!(
            from_json::<ResponseFile>(&legacy(&response), "old").unwrap(),
            response
        );
        assert_eq!(
            from_json::<EqualizerFile>(&legacy(&equalizer), "old").unwrap(),
            equalizer
        );
        assert_eq!(from_json::<LimbFile>(&legacy(&limb), "old").unwrap(), limb);
        // As the first version wrote it, byte for byte.
        let v1 = "{\n  \"kind\": \"limb-model\",\n  \"version\": 1,\n  \"description\": \"anna\",\n  \
                  \"model\": {\n    \"params\": {\n      \"b3_k3\": 0.0037,\n      \"k2_m2\": 5800000.0,\n      \
                  \"b2_m2\": 2402.0\n    },\n    \"g2\": 0.005,\n    \"level\": 1.0\n  },\n  \
                  \"band\": [\n    40.0,\n    1024.0\n  ],\n  \"rms_error_db\": 0.1\n}\n";
        let old: LimbFile = from_json(v1, "anna.json").unwrap();
        assert_eq!(old.description, "anna");
        assert_eq!(old.model.params.b2_m2, 2402.0);
        // An old header of another kind, or of another version, is refused as before.
        let e = from_json::<ResponseFile>(v1, "anna.json").unwrap_err();
        assert!(matches!(e, DocumentError::WrongKind { .. }), "{e}");
        let e = from_json::<LimbFile>(&v1.replace("\"version\": 1", "\"version\": 2"), "a")
            .unwrap_err();
        assert!(e.to_string().contains("version 2"), "{e}");
    }
}
