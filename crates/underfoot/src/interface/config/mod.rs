//! The interface configuration file, `prosthetic.toml`: which insole sensors there are and
//! how their counts become newtons, which servos they drive and how, which vibration
//! channels they drive, and where the interface is connected.
//!
//! ```toml
//! [link]
//! port = "/dev/ttyACM0"     # or "simulated"
//! baud = 115200
//! servo_rate_hz = 50        # servo frames per second, 1 to 500
//! insole_timeout_s = 0.2    # no insole frame for this long: servos go to rest
//!
//! [insole]
//! newtons_per_count = 0.5   # for sensors without a curve
//! calibration = "sensors.json"   # optional; from `underfoot calibrate sensors`
//! frame_sensors = 3         # optional; counts per insole frame (default: the sensors)
//!
//! [[sensor]]
//! name = "heel"
//! index = 0                 # its place in the insole frame
//! # curve = "left.heel"     # its curve in the calibration file (default: its name)
//! # newtons_per_count = 0.4 # its own factor instead of a curve
//!
//! [[servo]]
//! id = 0                    # its place in the servo frame
//! sensors = ["heel"]
//! weights = [1.0]           # optional, default 1 each
//! range_us = [1000, 2000]
//! rest_us = 1100
//! full_us = 1900            # below rest_us for a reversed servo
//! threshold_n = 20          # the servo rests below this force
//! full_force_n = 500        # and reaches full_us at this one
//! dead_band_us = 8
//! rate_us_per_s = 2000
//!
//! [[channel]]               # one vibration channel (piezo disc) of the engine each
//! name = "disc-heel"
//! sensors = ["heel"]
//!
//! [simulated]               # used when port = "simulated"
//! gait = "steps=10,cadence=1.6"  # a `gait:` spec; one foot
//! newtons_per_count = 0.5   # the simulated ADC
//! slew_us_per_s = 3000      # how fast the simulated servos move
//! ```
//!
//! A sensor's scale is, in order of preference: its own `newtons_per_count`, its curve in
//! the calibration file (named by `curve`, or by its own name), `[insole]
//! newtons_per_count`. A `curve` that the file lacks is an error, never a silent fallback.
//!
//! Every error names the file, the key (`servo[1].range_us`) and, where known, the line.
//!
//! | file | what it does |
//! |---|---|
//! | `raw.rs` | the file's shape, as serde reads it: tables, keys, defaults |
//! | [`link`] | `[link]` and `[simulated]`: where the interface is ([`Link`]), servo rate, insole timeout |
//! | [`sensors`] | `[insole]` and `[[sensor]]`: the frame's sensors ([`InsoleSensor`]) and each one's scale |
//! | `servos.rs` | `[[servo]]`: each servo's inputs, range and calibration |
//! | [`channels`] | `[[channel]]`: the vibration channels ([`VibrationChannel`]) |

use std::ops::Range;
use std::path::{Path, PathBuf};

use crate::document::FileError;
use crate::force::calibration::{SensorCalibration, SensorCalibrationError};
use crate::force::scale::CountScale;
use crate::interface::servo::ServoConfig;
use crate::units::{Hz, Seconds};

pub mod channels;
pub mod link;
mod raw;
pub mod sensors;
mod servos;

#[cfg(test)]
mod tests;

pub use channels::VibrationChannel;
pub use link::{Link, SimulatedConfig};
pub use sensors::InsoleSensor;

/// The most insole sensors per frame (the serial protocol's limit).
pub const MAX_INSOLE_SENSORS: usize = 64;

/// The most servos (the servo frame's limit).
pub const MAX_SERVOS: usize = 16;

/// What is wrong with an interface configuration.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read.
    #[error(transparent)]
    File(#[from] FileError),
    /// Not TOML, or a key of the wrong type or unknown.
    #[error("{path}{at}: {message}", path = path.display(), at = at_line(*line))]
    Syntax {
        /// The file.
        path: PathBuf,
        /// The line, if known.
        line: Option<usize>,
        /// The parser's message.
        message: String,
    },
    /// A value out of range or inconsistent with another.
    #[error("{path}{at}: {key}: {reason}", path = path.display(), at = at_line(*line))]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key, e.g. `servo[1].range_us`.
        key: String,
        /// The line of the table holding the key, if known.
        line: Option<usize>,
        /// What is wrong.
        reason: String,
    },
    /// The sensor calibration file named by `[insole] calibration` is unusable.
    #[error("{path}: insole.calibration: {source}", path = path.display())]
    Calibration {
        /// The configuration file.
        path: PathBuf,
        /// The calibration's error (it names its own file).
        source: SensorCalibrationError,
    },
}

fn at_line(line: Option<usize>) -> String {
    line.map_or(String::new(), |l| format!(":{l}"))
}

/// A validated interface configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceConfig {
    /// Where the interface is.
    pub link: Link,
    /// Servo frames per second.
    pub servo_rate: Hz,
    /// No insole frame for this long: servos go to rest.
    pub insole_timeout: Seconds,
    /// Counts per insole frame.
    pub frame_sensors: usize,
    /// The named sensors.
    pub sensors: Vec<InsoleSensor>,
    /// Counts to newtons, one scale per frame index.
    pub scale: CountScale,
    /// The servos; their inputs are frame indices.
    pub servos: Vec<ServoConfig>,
    /// The vibration channels, engine channel `k` being `channels[k]`.
    pub channels: Vec<VibrationChannel>,
}

impl InterfaceConfig {
    /// Reads and checks a configuration file; a calibration file it names is read
    /// relative to it.
    ///
    /// # Errors
    /// [`ConfigError`] naming the file, key and line at fault.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = crate::limits::read_to_string_capped(path, crate::limits::MAX_DOCUMENT_BYTES)
            .map_err(|source| FileError {
                path: path.to_path_buf(),
                action: "reading",
                source,
            })?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::parse(&text, path, |name| {
            SensorCalibration::load(&base.join(name))
        })
    }

    /// Parses and checks configuration text. `path` names it in errors; `calibration`
    /// loads the file named by `[insole] calibration`.
    ///
    /// # Errors
    /// [`ConfigError`] naming the key and line at fault.
    pub fn parse(
        text: &str,
        path: &Path,
        calibration: impl FnOnce(&str) -> Result<SensorCalibration, SensorCalibrationError>,
    ) -> Result<Self, ConfigError> {
        let raw: raw::RawFile = toml::from_str(text).map_err(|e| ConfigError::Syntax {
            path: path.to_path_buf(),
            line: e.span().map(|s| line_of(text, s.start)),
            message: e.message().trim().to_owned(),
        })?;
        let at = Source { text, path };
        // Checked in the file's order of concerns, so that the first error reported is
        // the same whatever else is wrong.
        let link_span = raw.link.span();
        let link = raw.link.into_inner();
        let (servo_rate, insole_timeout) = link::check(&link, &link_span, &at)?;
        let insole = sensors::resolve(raw.insole, &raw.sensor, &link_span, calibration, &at)?;
        let servos = servos::resolve(&raw.servo, &insole, &at)?;
        let channels = channels::resolve(&raw.channel, &insole, &at)?;
        let link = link::resolve(link, raw.simulated.as_ref(), link_span, &insole, &at)?;
        Ok(Self {
            link,
            servo_rate,
            insole_timeout,
            frame_sensors: insole.frame_sensors,
            sensors: insole.sensors,
            scale: insole.scale,
            servos,
            channels,
        })
    }
}

/// The text being checked and its file, to name the place at fault.
struct Source<'a> {
    text: &'a str,
    path: &'a Path,
}

impl Source<'_> {
    /// `key` is wrong; `span` is the table that holds it.
    fn invalid(&self, key: impl Into<String>, span: &Range<usize>, reason: String) -> ConfigError {
        ConfigError::Invalid {
            path: self.path.to_path_buf(),
            key: key.into(),
            line: Some(line_of(self.text, span.start)),
            reason,
        }
    }

    /// `key` is wrong as a whole (a table missing, too many of them): no one line.
    fn invalid_anywhere(&self, key: &str, reason: String) -> ConfigError {
        ConfigError::Invalid {
            path: self.path.to_path_buf(),
            key: key.into(),
            line: None,
            reason,
        }
    }
}

/// The line (1-based) of byte offset `at` in `text`.
fn line_of(text: &str, at: usize) -> usize {
    text.as_bytes()
        .iter()
        .take(at)
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// A counts-to-newtons factor that can be used.
fn factor_ok(f: f32) -> bool {
    f.is_finite() && f > 0.0
}
