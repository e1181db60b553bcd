//! `[insole]` and `[[sensor]]`: the sensors an insole frame carries, and how each one's
//! counts become newtons.
//!
//! Each sensor's scale is chosen in the order the [file's documentation](super) gives
//! (its own factor, its curve, the insole's factor); frame slots that no sensor names
//! get a unit factor.

use std::ops::Range;

use toml::Spanned;

use super::raw::{RawInsole, RawSensor};
use super::{ConfigError, MAX_INSOLE_SENSORS, Source, factor_ok};
use crate::force::calibration::{SensorCalibration, SensorCalibrationError};
use crate::force::scale::{CountScale, SensorScale};

/// One insole sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct InsoleSensor {
    /// Its name.
    pub name: String,
    /// Its place in the insole frame.
    pub index: usize,
}

/// The insole as checked: what the servos, channels and simulated board refer to.
pub(super) struct Insole {
    /// Counts per insole frame.
    pub(super) frame_sensors: usize,
    /// The named sensors.
    pub(super) sensors: Vec<InsoleSensor>,
    /// Counts to newtons, one scale per frame index.
    pub(super) scale: CountScale,
}

impl Insole {
    /// The frame index of the sensor called `name`.
    pub(super) fn index_of(&self, name: &str) -> Option<usize> {
        self.sensors
            .iter()
            .find(|s| s.name == name)
            .map(|s| s.index)
    }
}

/// Checks `[insole]` (its span is `[link]`'s when it is absent) and every `[[sensor]]`,
/// loading the calibration file it names with `calibration`.
pub(super) fn resolve(
    insole: Option<Spanned<RawInsole>>,
    raw_sensors: &[Spanned<RawSensor>],
    link_span: &Range<usize>,
    calibration: impl FnOnce(&str) -> Result<SensorCalibration, SensorCalibrationError>,
    at: &Source<'_>,
) -> Result<Insole, ConfigError> {
    let (insole, insole_span) = match insole {
        Some(s) => {
            let span = s.span();
            (s.into_inner(), span)
        }
        None => (RawInsole::default(), link_span.clone()),
    };
    if raw_sensors.is_empty() {
        return Err(at.invalid_anywhere(
            "sensor",
            "no [[sensor]]: the insole needs at least one".into(),
        ));
    }
    let frame_sensors = insole.frame_sensors.unwrap_or(raw_sensors.len());
    if !(1..=MAX_INSOLE_SENSORS).contains(&frame_sensors) {
        return Err(at.invalid(
            "insole.frame_sensors",
            &insole_span,
            format!("{frame_sensors}: need 1 to {MAX_INSOLE_SENSORS}"),
        ));
    }
    let loaded = match &insole.calibration {
        Some(name) => Some(
            calibration(name).map_err(|source| ConfigError::Calibration {
                path: at.path.to_path_buf(),
                source,
            })?,
        ),
        None => None,
    };
    let fallback = insole.newtons_per_count;
    if let Some(f) = fallback
        && !factor_ok(f)
    {
        return Err(at.invalid(
            "insole.newtons_per_count",
            &insole_span,
            format!("{f}: need a positive finite factor"),
        ));
    }
    let mut sensors: Vec<InsoleSensor> = Vec::with_capacity(raw_sensors.len());
    let mut scales: Vec<Option<SensorScale>> = vec![None; frame_sensors];
    for (i, s) in raw_sensors.iter().enumerate() {
        let span = s.span();
        let s = s.get_ref();
        let key = |k: &str| format!("sensor[{i}].{k}");
        if s.name.trim().is_empty() {
            return Err(at.invalid(key("name"), &span, "empty".into()));
        }
        if sensors.iter().any(|o| o.name == s.name) {
            return Err(at.invalid(
                key("name"),
                &span,
                format!("{:?} names a second sensor", s.name),
            ));
        }
        if s.index >= frame_sensors {
            return Err(at.invalid(
                key("index"),
                &span,
                format!("{} but a frame carries {frame_sensors} sensors", s.index),
            ));
        }
        if let Some(o) = sensors.iter().find(|o| o.index == s.index) {
            return Err(at.invalid(
                key("index"),
                &span,
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
                return Err(at.invalid(
                    key("newtons_per_count"),
                    &span,
                    format!("{f}: need a positive finite factor"),
                ));
            }
            (None, Some(c)) => SensorScale::Curve(c.clone()),
            (None, None) if s.curve.is_some() => {
                return Err(at.invalid(
                    key("curve"),
                    &span,
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
                    return Err(at.invalid(
                        key("name"),
                        &span,
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
    Ok(Insole {
        frame_sensors,
        sensors,
        scale,
    })
}
