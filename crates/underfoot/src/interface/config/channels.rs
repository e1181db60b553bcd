//! `[[channel]]`: the engine's vibration channels (piezo discs), each driven by the force
//! of the sensors it names.

use toml::Spanned;

use super::raw::RawChannel;
use super::sensors::Insole;
use super::{ConfigError, Source};
use crate::force::MAX_SENSORS;

/// One vibration channel of the engine and the sensors whose force drives it.
#[derive(Debug, Clone, PartialEq)]
pub struct VibrationChannel {
    /// Its name.
    pub name: String,
    /// Frame indices of its sensors (1 to `MAX_SENSORS`).
    pub sensors: Vec<usize>,
}

/// Checks every `[[channel]]`; their sensors become `insole`'s frame indices.
pub(super) fn resolve(
    raw: &[Spanned<RawChannel>],
    insole: &Insole,
    at: &Source<'_>,
) -> Result<Vec<VibrationChannel>, ConfigError> {
    if raw.is_empty() {
        return Err(at.invalid_anywhere(
            "channel",
            "no [[channel]]: the vibration needs at least one".into(),
        ));
    }
    let mut channels: Vec<VibrationChannel> = Vec::with_capacity(raw.len());
    for (i, c) in raw.iter().enumerate() {
        let span = c.span();
        let c = c.get_ref();
        let key = |k: &str| format!("channel[{i}].{k}");
        if !(1..=MAX_SENSORS).contains(&c.sensors.len()) {
            return Err(at.invalid(
                key("sensors"),
                &span,
                format!("{} sensors: need 1 to {MAX_SENSORS}", c.sensors.len()),
            ));
        }
        let mut idx = Vec::with_capacity(c.sensors.len());
        for name in &c.sensors {
            let Some(index) = insole.index_of(name) else {
                return Err(at.invalid(
                    key("sensors"),
                    &span,
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
    Ok(channels)
}
