//! `[[servo]]`: each servo's sensors and their weights, its pulse range, dead band, rate
//! limit and calibration, checked by the servo's own rules ([`ServoConfig::validate`]).

use toml::Spanned;

use super::raw::RawServo;
use super::sensors::Insole;
use super::{ConfigError, MAX_SERVOS, Source};
use crate::interface::servo::{PulseWidth, ServoCalibration, ServoConfig, ServoError};
use crate::units::Newtons;

/// Checks every `[[servo]]`; their inputs become `insole`'s frame indices.
pub(super) fn resolve(
    raw: &[Spanned<RawServo>],
    insole: &Insole,
    at: &Source<'_>,
) -> Result<Vec<ServoConfig>, ConfigError> {
    if raw.len() > MAX_SERVOS {
        return Err(at.invalid_anywhere(
            "servo",
            format!("{} servos, at most {MAX_SERVOS}", raw.len()),
        ));
    }
    let mut servos = Vec::with_capacity(raw.len());
    for (i, s) in raw.iter().enumerate() {
        let span = s.span();
        let s = s.get_ref();
        let key = |k: &str| format!("servo[{i}].{k}");
        if usize::from(s.id) >= MAX_SERVOS {
            return Err(at.invalid(
                key("id"),
                &span,
                format!("{}: need 0 to {}", s.id, MAX_SERVOS - 1),
            ));
        }
        let weights = match &s.weights {
            Some(w) if w.len() != s.sensors.len() => {
                return Err(at.invalid(
                    key("weights"),
                    &span,
                    format!("{} weights for {} sensors", w.len(), s.sensors.len()),
                ));
            }
            Some(w) => w.clone(),
            None => vec![1.0; s.sensors.len()],
        };
        let mut inputs = Vec::with_capacity(s.sensors.len());
        for (name, w) in s.sensors.iter().zip(weights) {
            let Some(index) = insole.index_of(name) else {
                return Err(at.invalid(
                    key("sensors"),
                    &span,
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
        if let Err(ServoError::Invalid { key: k, reason, .. }) =
            config.validate(insole.frame_sensors)
        {
            return Err(at.invalid(key(k), &span, reason));
        }
        if servos.iter().any(|o: &ServoConfig| o.id == s.id) {
            return Err(at.invalid(key("id"), &span, format!("{} is another servo's", s.id)));
        }
        servos.push(config);
    }
    Ok(servos)
}
