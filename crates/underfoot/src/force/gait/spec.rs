//! The gait spec: `key=value` items separated by commas, as the command line and the
//! interface file give a simulated walk.

use super::config::GaitConfig;
use super::error::GaitError;
use crate::units::Seconds;

/// The keys [`GaitConfig::from_spec`] accepts.
pub const SPEC_KEYS: &[&str] = &[
    "steps",
    "cadence",
    "weight",
    "channels",
    "variation",
    "rate",
    "seed",
    "stance",
    "lead_in",
    "tail",
];

/// Every key of the spec with its unit, range and default, as `--help` shows it.
pub const SPEC_HELP: &str = "A walk: comma-separated key=value items, every key optional:
  steps=N      heel strikes per foot (two feet: 2N strikes in all); default 8
  cadence=HZ   steps per second, both feet together, 0.5 to 4; default 1.8, a brisk walk
  weight=KG    body mass in kilograms, 20 to 300; default 70
  channels=N   feet, 1 or 2 (channel 1 is the left foot); default 2
  variation=X  relative step-to-step variation of timing and force, 0 to 0.3; default 0.05
  rate=HZ      sensor readings per second, 50 to 10000; default 500
  seed=N       seed of the variation (the same seed, the same walk); default 1
  stance=X     fraction of a stride a foot is on the ground, 0.55 to 0.75; default 0.62
  lead_in=S    seconds of silence before the first heel strike, 0 to 60; default 0.5
  tail=S       seconds of silence after the last toe-off, 0 to 60; default 1";

impl GaitConfig {
    /// The default configuration changed by `key=value` items separated by commas, e.g.
    /// `steps=12,cadence=1.8,weight=70`; keys are [`SPEC_KEYS`]. An empty spec gives the
    /// defaults. The result is validated.
    ///
    /// # Errors
    /// [`GaitError`] naming the item, key or value at fault, or the setting out of range.
    pub fn from_spec(spec: &str) -> Result<Self, GaitError> {
        let mut config = Self::default();
        let mut seen: Vec<&str> = Vec::new();
        for item in spec.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let Some((key, value)) = item.split_once('=') else {
                return Err(GaitError::Malformed {
                    item: item.to_owned(),
                });
            };
            let (key, value) = (key.trim(), value.trim());
            if seen.contains(&key) {
                return Err(GaitError::DuplicateKey {
                    key: key.to_owned(),
                });
            }
            seen.push(key);
            let bad = |expected| GaitError::BadNumber {
                key: key.to_owned(),
                value: value.to_owned(),
                expected,
            };
            let whole = || value.parse::<u64>().map_err(|_| bad("a whole number"));
            let real = || value.parse::<f64>().map_err(|_| bad("a number"));
            let count =
                || whole().and_then(|n| usize::try_from(n).map_err(|_| bad("a whole number")));
            match key {
                "steps" => config.steps = count()?,
                "cadence" => config.cadence = real()?,
                "weight" => config.weight_kg = real()?,
                "channels" => config.channels = count()?,
                "variation" => config.variation = real()?,
                "rate" => config.sensor_rate = real()?,
                "seed" => config.seed = whole()?,
                "stance" => config.stance_fraction = real()?,
                "lead_in" => config.lead_in = Seconds(real()?),
                "tail" => config.tail = Seconds(real()?),
                _ => {
                    return Err(GaitError::UnknownKey {
                        key: key.to_owned(),
                        value: value.to_owned(),
                    });
                }
            }
        }
        config.validate()?;
        Ok(config)
    }
}
