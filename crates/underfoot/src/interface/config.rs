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

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::servo::{PulseWidth, ServoCalibration, ServoConfig, ServoError};
use crate::force::MAX_SENSORS;
use crate::force::calibration::{SensorCalibration, SensorCalibrationError};
use crate::force::gait::GaitConfig;
use crate::force::scale::{CountScale, SensorScale};
use crate::units::{Hz, Newtons, Seconds};

/// The most insole sensors per frame (the serial protocol's limit).
pub const MAX_INSOLE_SENSORS: usize = 64;

/// The most servos (the servo frame's limit).
pub const MAX_SERVOS: usize = 16;

/// What is wrong with an interface configuration.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}", path = path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
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

/// Where the interface is.
#[derive(Debug, Clone, PartialEq)]
pub enum Link {
    /// A serial port.
    Serial {
        /// The port: `/dev/ttyACM0`, `COM3`.
        port: String,
        /// Line speed.
        baud: u32,
    },
    /// The simulated foot (see `io::prosthetic`).
    Simulated(SimulatedConfig),
}

/// The simulated foot's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatedConfig {
    /// The walk, one foot.
    pub gait: GaitConfig,
    /// Newtons per count of the simulated ADC.
    pub newtons_per_count: f32,
    /// How fast the simulated servos move, µs per second.
    pub slew: f64,
    /// Frame indices of the heel, midfoot and toe sensors.
    pub heel_midfoot_toe: [usize; 3],
}

/// One insole sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct InsoleSensor {
    /// Its name.
    pub name: String,
    /// Its place in the insole frame.
    pub index: usize,
}

/// One vibration channel of the engine and the sensors whose force drives it.
#[derive(Debug, Clone, PartialEq)]
pub struct VibrationChannel {
    /// Its name.
    pub name: String,
    /// Frame indices of its sensors (1 to `MAX_SENSORS`).
    pub sensors: Vec<usize>,
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

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    link: Spanned<RawLink>,
    #[serde(default)]
    insole: Option<Spanned<RawInsole>>,
    #[serde(default)]
    sensor: Vec<Spanned<RawSensor>>,
    #[serde(default)]
    servo: Vec<Spanned<RawServo>>,
    #[serde(default)]
    channel: Vec<Spanned<RawChannel>>,
    #[serde(default)]
    simulated: Option<Spanned<RawSimulated>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLink {
    port: String,
    #[serde(default = "default_baud")]
    baud: u32,
    #[serde(default = "default_servo_rate")]
    servo_rate_hz: f64,
    #[serde(default = "default_timeout")]
    insole_timeout_s: f64,
}

fn default_baud() -> u32 {
    115_200
}
fn default_servo_rate() -> f64 {
    50.0
}
fn default_timeout() -> f64 {
    0.2
}

#[derive(Debug, Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawInsole {
    newtons_per_count: Option<f32>,
    calibration: Option<String>,
    frame_sensors: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSensor {
    name: String,
    index: usize,
    curve: Option<String>,
    newtons_per_count: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawServo {
    id: u8,
    sensors: Vec<String>,
    weights: Option<Vec<f64>>,
    range_us: [u16; 2],
    rest_us: u16,
    full_us: u16,
    threshold_n: f64,
    full_force_n: f64,
    dead_band_us: f64,
    rate_us_per_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChannel {
    name: String,
    sensors: Vec<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSimulated {
    #[serde(default)]
    gait: String,
    #[serde(default = "default_sim_npc")]
    newtons_per_count: f32,
    #[serde(default = "default_sim_slew")]
    slew_us_per_s: f64,
}

fn default_sim_npc() -> f32 {
    0.5
}
fn default_sim_slew() -> f64 {
    3000.0
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

impl InterfaceConfig {
    /// Reads and checks a configuration file; a calibration file it names is read
    /// relative to it.
    ///
    /// # Errors
    /// [`ConfigError`] naming the file, key and line at fault.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = crate::limits::read_to_string_capped(path, crate::limits::MAX_DOCUMENT_BYTES)
            .map_err(|source| ConfigError::Io {
                path: path.to_path_buf(),
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
        let raw: RawFile = toml::from_str(text).map_err(|e| ConfigError::Syntax {
            path: path.to_path_buf(),
            line: e.span().map(|s| line_of(text, s.start)),
            message: e.message().trim().to_owned(),
        })?;
        let invalid =
            |key: String, span: std::ops::Range<usize>, reason: String| ConfigError::Invalid {
                path: path.to_path_buf(),
                key,
                line: Some(line_of(text, span.start)),
                reason,
            };

        // Link.
        let link_span = raw.link.span();
        let link = raw.link.into_inner();
        let servo_rate = link.servo_rate_hz;
        if !(servo_rate.is_finite() && (1.0..=500.0).contains(&servo_rate)) {
            return Err(invalid(
                "link.servo_rate_hz".into(),
                link_span,
                format!("{servo_rate}: need 1 to 500"),
            ));
        }
        let timeout = link.insole_timeout_s;
        if !(timeout.is_finite() && (0.01..=10.0).contains(&timeout)) {
            return Err(invalid(
                "link.insole_timeout_s".into(),
                link_span,
                format!("{timeout}: need 0.01 to 10 seconds"),
            ));
        }
        if link.baud == 0 {
            return Err(invalid("link.baud".into(), link_span, "0 baud".into()));
        }
        if link.port.trim().is_empty() {
            return Err(invalid(
                "link.port".into(),
                link_span,
                "empty: a serial port, or \"simulated\"".into(),
            ));
        }

        // Sensors.
        let (insole, insole_span) = match raw.insole {
            Some(s) => {
                let span = s.span();
                (s.into_inner(), span)
            }
            None => (RawInsole::default(), link_span.clone()),
        };
        if raw.sensor.is_empty() {
            return Err(ConfigError::Invalid {
                path: path.to_path_buf(),
                key: "sensor".into(),
                line: None,
                reason: "no [[sensor]]: the insole needs at least one".into(),
            });
        }
        let frame_sensors = insole.frame_sensors.unwrap_or(raw.sensor.len());
        if !(1..=MAX_INSOLE_SENSORS).contains(&frame_sensors) {
            return Err(invalid(
                "insole.frame_sensors".into(),
                insole_span,
                format!("{frame_sensors}: need 1 to {MAX_INSOLE_SENSORS}"),
            ));
        }
        let loaded = match &insole.calibration {
            Some(name) => Some(
                calibration(name).map_err(|source| ConfigError::Calibration {
                    path: path.to_path_buf(),
                    source,
                })?,
            ),
            None => None,
        };
        let fallback = insole.newtons_per_count;
        let factor_ok = |f: f32| f.is_finite() && f > 0.0;
        if let Some(f) = fallback
            && !factor_ok(f)
        {
            return Err(invalid(
                "insole.newtons_per_count".into(),
                insole_span,
                format!("{f}: need a positive finite factor"),
            ));
        }
        let mut sensors: Vec<InsoleSensor> = Vec::with_capacity(raw.sensor.len());
        let mut scales: Vec<Option<SensorScale>> = vec![None; frame_sensors];
        for (i, s) in raw.sensor.iter().enumerate() {
            let span = s.span();
            let s = s.get_ref();
            let key = |k: &str| format!("sensor[{i}].{k}");
            if s.name.trim().is_empty() {
                return Err(invalid(key("name"), span, "empty".into()));
            }
            if sensors.iter().any(|o| o.name == s.name) {
                return Err(invalid(
                    key("name"),
                    span,
                    format!("{:?} names a second sensor", s.name),
                ));
            }
            if s.index >= frame_sensors {
                return Err(invalid(
                    key("index"),
                    span,
                    format!("{} but a frame carries {frame_sensors} sensors", s.index),
                ));
            }
            if let Some(o) = sensors.iter().find(|o| o.index == s.index) {
                return Err(invalid(
                    key("index"),
                    span,
                    format!("{} is sensor {:?}'s already", s.index, o.name),
                ));
            }
            let curve_name = s.curve.as_deref().unwrap_or(&s.name);
            let curve = loaded
                .as_ref()
                .and_then(|c| c.sensors.iter().find(|c| c.name == curve_name));
            let scale = match (s.newtons_per_count, curve) {
                (Some(f), _) if factor_ok(f) => SensorScale::Linear {
                    newtons_per_count: f,
                },
                (Some(f), _) => {
                    return Err(invalid(
                        key("newtons_per_count"),
                        span,
                        format!("{f}: need a positive finite factor"),
                    ));
                }
                (None, Some(c)) => SensorScale::Curve(c.clone()),
                (None, None) if s.curve.is_some() => {
                    return Err(invalid(
                        key("curve"),
                        span,
                        format!(
                            "{curve_name:?} is not in {}",
                            insole
                                .calibration
                                .as_deref()
                                .unwrap_or("any file: insole.calibration is not set")
                        ),
                    ));
                }
                (None, None) => match fallback {
                    Some(f) => SensorScale::Linear {
                        newtons_per_count: f,
                    },
                    None => {
                        return Err(invalid(
                            key("name"),
                            span,
                            format!(
                                "no scale for {:?}: give insole.newtons_per_count, the \
                                 sensor's own, or a curve of that name in insole.calibration",
                                s.name
                            ),
                        ));
                    }
                },
            };
            scales[s.index] = Some(scale);
            sensors.push(InsoleSensor {
                name: s.name.clone(),
                index: s.index,
            });
        }
        // Frame slots no sensor names are carried but unused: give them a unit factor
        // rather than refuse the frame, so a board may send spare channels.
        let scale = CountScale::PerSensor(
            scales
                .into_iter()
                .map(|s| {
                    s.unwrap_or(SensorScale::Linear {
                        newtons_per_count: 1.0,
                    })
                })
                .collect(),
        );
        let index_of = |name: &str| sensors.iter().find(|s| s.name == name).map(|s| s.index);

        // Servos.
        if raw.servo.len() > MAX_SERVOS {
            return Err(ConfigError::Invalid {
                path: path.to_path_buf(),
                key: "servo".into(),
                line: None,
                reason: format!("{} servos, at most {MAX_SERVOS}", raw.servo.len()),
            });
        }
        let mut servos = Vec::with_capacity(raw.servo.len());
        for (i, s) in raw.servo.iter().enumerate() {
            let span = s.span();
            let s = s.get_ref();
            let key = |k: &str| format!("servo[{i}].{k}");
            if usize::from(s.id) >= MAX_SERVOS {
                return Err(invalid(
                    key("id"),
                    span,
                    format!("{}: need 0 to {}", s.id, MAX_SERVOS - 1),
                ));
            }
            let weights = match &s.weights {
                Some(w) if w.len() != s.sensors.len() => {
                    return Err(invalid(
                        key("weights"),
                        span,
                        format!("{} weights for {} sensors", w.len(), s.sensors.len()),
                    ));
                }
                Some(w) => w.clone(),
                None => vec![1.0; s.sensors.len()],
            };
            let mut inputs = Vec::with_capacity(s.sensors.len());
            for (name, w) in s.sensors.iter().zip(weights) {
                let Some(index) = index_of(name) else {
                    return Err(invalid(
                        key("sensors"),
                        span,
                        format!("no [[sensor]] named {name:?}"),
                    ));
                };
                inputs.push((index, w));
            }
            let config = ServoConfig {
                id: s.id,
                inputs,
                min: PulseWidth(s.range_us[0]),
                max: PulseWidth(s.range_us[1]),
                dead_band: s.dead_band_us,
                rate: s.rate_us_per_s,
                calibration: ServoCalibration {
                    rest: PulseWidth(s.rest_us),
                    full: PulseWidth(s.full_us),
                    threshold: Newtons(s.threshold_n),
                    full_force: Newtons(s.full_force_n),
                },
            };
            if let Err(ServoError::Invalid { key: k, reason, .. }) = config.validate(frame_sensors)
            {
                return Err(invalid(key(k), span, reason));
            }
            if servos.iter().any(|o: &ServoConfig| o.id == s.id) {
                return Err(invalid(
                    key("id"),
                    span,
                    format!("{} is another servo's", s.id),
                ));
            }
            servos.push(config);
        }

        // Vibration channels.
        if raw.channel.is_empty() {
            return Err(ConfigError::Invalid {
                path: path.to_path_buf(),
                key: "channel".into(),
                line: None,
                reason: "no [[channel]]: the vibration needs at least one".into(),
            });
        }
        let mut channels: Vec<VibrationChannel> = Vec::with_capacity(raw.channel.len());
        for (i, c) in raw.channel.iter().enumerate() {
            let span = c.span();
            let c = c.get_ref();
            let key = |k: &str| format!("channel[{i}].{k}");
            if !(1..=MAX_SENSORS).contains(&c.sensors.len()) {
                return Err(invalid(
                    key("sensors"),
                    span,
                    format!("{} sensors: need 1 to {MAX_SENSORS}", c.sensors.len()),
                ));
            }
            let mut idx = Vec::with_capacity(c.sensors.len());
            for name in &c.sensors {
                let Some(index) = index_of(name) else {
                    return Err(invalid(
                        key("sensors"),
                        span,
                        format!("no [[sensor]] named {name:?}"),
                    ));
                };
                idx.push(index);
            }
            channels.push(VibrationChannel {
                name: c.name.clone(),
                sensors: idx,
            });
        }

        // Where.
        let link = if link.port == "simulated" {
            let (sim, span) = match &raw.simulated {
                Some(s) => (s.get_ref(), s.span()),
                None => {
                    return Err(invalid(
                        "simulated".into(),
                        link_span,
                        "port = \"simulated\" needs a [simulated] table".into(),
                    ));
                }
            };
            let mut gait = GaitConfig::from_spec(&sim.gait)
                .map_err(|e| invalid("simulated.gait".into(), span.clone(), e.to_string()))?;
            // One prosthetic foot.
            gait.channels = 1;
            gait.validate()
                .map_err(|e| invalid("simulated.gait".into(), span.clone(), e.to_string()))?;
            if !factor_ok(sim.newtons_per_count) {
                return Err(invalid(
                    "simulated.newtons_per_count".into(),
                    span,
                    format!("{}: need a positive finite factor", sim.newtons_per_count),
                ));
            }
            if !(sim.slew_us_per_s.is_finite() && sim.slew_us_per_s > 0.0) {
                return Err(invalid(
                    "simulated.slew_us_per_s".into(),
                    span,
                    format!("{}: need a positive finite rate", sim.slew_us_per_s),
                ));
            }
            let mut roles = [0; 3];
            for (r, name) in roles.iter_mut().zip(["heel", "midfoot", "toe"]) {
                *r = index_of(name).ok_or_else(|| {
                    invalid(
                        "simulated".into(),
                        span.clone(),
                        format!("the simulated foot needs a [[sensor]] named {name:?}"),
                    )
                })?;
            }
            Link::Simulated(SimulatedConfig {
                gait,
                newtons_per_count: sim.newtons_per_count,
                slew: sim.slew_us_per_s,
                heel_midfoot_toe: roles,
            })
        } else {
            Link::Serial {
                port: link.port,
                baud: link.baud,
            }
        };

        Ok(Self {
            link,
            servo_rate: Hz(servo_rate),
            insole_timeout: Seconds(timeout),
            frame_sensors,
            sensors,
            scale,
            servos,
            channels,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[link]
port = "simulated"
servo_rate_hz = 100

[insole]
newtons_per_count = 0.5

[[sensor]]
name = "heel"
index = 0
[[sensor]]
name = "midfoot"
index = 1
newtons_per_count = 0.25
[[sensor]]
name = "toe"
index = 2

[[servo]]
id = 0
sensors = ["heel", "midfoot"]
weights = [1.0, 0.5]
range_us = [1000, 2000]
rest_us = 1100
full_us = 1900
threshold_n = 20
full_force_n = 500
dead_band_us = 8
rate_us_per_s = 2000

[[channel]]
name = "disc"
sensors = ["heel", "toe"]

[simulated]
gait = "steps=4"
"#;

    fn parse(text: &str) -> Result<InterfaceConfig, ConfigError> {
        InterfaceConfig::parse(text, Path::new("p.toml"), |name| {
            Err(SensorCalibrationError::Tare {
                reason: format!("no file {name} in this test"),
            })
        })
    }

    fn invalid(text: &str) -> (String, Option<usize>, String) {
        match parse(text) {
            Err(ConfigError::Invalid {
                key, line, reason, ..
            }) => (key, line, reason),
            other => panic!("expected Invalid, got {other:?}"),
        }
    }

    #[test]
    fn a_good_file_parses_into_frame_indices() {
        let c = parse(GOOD).unwrap();
        assert_eq!(c.frame_sensors, 3);
        assert_eq!(c.servo_rate, Hz(100.0));
        assert_eq!(c.insole_timeout, Seconds(0.2));
        assert_eq!(c.servos[0].inputs, vec![(0, 1.0), (1, 0.5)]);
        assert_eq!(c.channels[0].sensors, vec![0, 2]);
        let mut out = [0.0; 3];
        c.scale.apply(&[10, 10, 10], &mut out);
        assert_eq!(out, [5.0, 2.5, 5.0]);
        let Link::Simulated(sim) = &c.link else {
            panic!("simulated")
        };
        assert_eq!(sim.gait.channels, 1);
        assert_eq!(sim.gait.steps, 4);
        assert_eq!(sim.heel_midfoot_toe, [0, 1, 2]);
    }

    #[test]
    fn errors_name_key_and_line() {
        let (key, line, _) =
            invalid(&GOOD.replace("range_us = [1000, 2000]", "range_us = [2000, 1000]"));
        assert_eq!(key, "servo[0].range_us");
        let servo_line = GOOD.lines().position(|l| l == "[[servo]]").unwrap() + 1;
        assert_eq!(line, Some(servo_line));
        let (key, _, reason) =
            invalid(&GOOD.replace("\"heel\", \"midfoot\"]", "\"heel\", \"arch\"]"));
        assert_eq!(key, "servo[0].sensors");
        assert!(reason.contains("arch"), "{reason}");
        let (key, _, _) = invalid(&GOOD.replace("index = 2", "index = 1"));
        assert_eq!(key, "sensor[2].index");
        let (key, _, _) = invalid(&GOOD.replace("index = 2", "index = 7"));
        assert_eq!(key, "sensor[2].index");
        let (key, _, _) = invalid(&GOOD.replace("servo_rate_hz = 100", "servo_rate_hz = 0"));
        assert_eq!(key, "link.servo_rate_hz");
        let (key, _, _) = invalid(&GOOD.replace("gait = \"steps=4\"", "gait = \"steps=x\""));
        assert_eq!(key, "simulated.gait");
        let (key, _, _) = invalid(&GOOD.replace("newtons_per_count = 0.25", "curve = \"mid\""));
        assert_eq!(key, "sensor[1].curve");
        let (key, _, _) = invalid(&GOOD.replace("[insole]\nnewtons_per_count = 0.5", ""));
        assert_eq!(key, "sensor[0].name");
        let (key, _, _) = invalid(&GOOD.replace("dead_band_us = 8", "dead_band_us = -8"));
        assert_eq!(key, "servo[0].dead_band_us");
        let (key, _, _) = invalid(
            &GOOD
                .replace("name = \"midfoot\"", "name = \"ball\"")
                .replace("\"heel\", \"midfoot\"]", "\"heel\", \"ball\"]"),
        );
        assert_eq!(key, "simulated");
        // Syntax: an unknown key and a wrong type, with their lines.
        for (from, to) in [
            ("rate_us_per_s = 2000", "rate_us_per_sec = 2000"),
            ("rest_us = 1100", "rest_us = \"1100\""),
            ("rest_us = 1100", "rest_us = 70000"),
        ] {
            match parse(&GOOD.replace(from, to)) {
                Err(ConfigError::Syntax { line, message, .. }) => {
                    let want = GOOD.lines().position(|l| l == from).unwrap() + 1;
                    assert_eq!(line, Some(want), "{message}");
                }
                other => panic!("{to}: {other:?}"),
            }
        }
        match parse(&GOOD.replace(
            "[insole]\nnewtons_per_count = 0.5",
            "[insole]\ncalibration = \"s.json\"",
        )) {
            Err(e @ ConfigError::Calibration { .. }) => {
                assert!(e.to_string().contains("s.json"), "{e}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_example_file_parses() {
        let text = include_str!("../../../../examples/prosthetic.toml");
        let sim = parse(text).unwrap();
        assert!(matches!(sim.link, Link::Simulated(_)));
        assert_eq!(
            (sim.sensors.len(), sim.servos.len(), sim.channels.len()),
            (3, 3, 4)
        );
        // The reversed toe servo.
        assert!(sim.servos[2].calibration.full < sim.servos[2].calibration.rest);
        // The same file for a real board: only the port changes.
        let board = text.replacen("port = \"simulated\"", "port = \"/dev/ttyACM0\"", 1);
        let serial = parse(&board).unwrap();
        assert!(
            matches!(serial.link, Link::Serial { ref port, baud: 115_200 } if port == "/dev/ttyACM0")
        );
        assert_eq!(sim.servos, serial.servos);
    }

    #[test]
    fn serial_link_and_calibration_file() {
        use crate::force::calibration::{CurveModel, SensorCurve};
        let text = GOOD
            .replace(
                "port = \"simulated\"",
                "port = \"/dev/ttyACM0\"\nbaud = 57600",
            )
            .replace(
                "[insole]\nnewtons_per_count = 0.5",
                "[insole]\nnewtons_per_count = 0.5\ncalibration = \"cal/s.json\"",
            );
        let c = InterfaceConfig::parse(&text, Path::new("p.toml"), |name| {
            assert_eq!(name, "cal/s.json");
            Ok(SensorCalibration {
                sensors: vec![SensorCurve {
                    name: "toe".into(),
                    model: CurveModel::Power {
                        a: 2.0,
                        b: 1.0,
                        r0: 10.0,
                    },
                    raw_range: [0.0, 1000.0],
                    drift: 0.0,
                }],
            })
        })
        .unwrap();
        assert_eq!(
            c.link,
            Link::Serial {
                port: "/dev/ttyACM0".into(),
                baud: 57600
            }
        );
        let mut out = [0.0; 3];
        c.scale.apply(&[10, 10, 20], &mut out);
        // Heel by the fallback factor, midfoot by its own, toe by its curve.
        assert_eq!(out, [5.0, 2.5, 20.0]);
    }
}
