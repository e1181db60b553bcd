//! What to generate: the settings of a walk, their defaults and their ranges.

use super::error::GaitError;
use super::{CLIP, DEFAULT_STANCE_FRACTION, MAX_ROWS};
use crate::units::Seconds;

/// What to generate. Build with `..Default::default()` or [`GaitConfig::from_spec`].
#[derive(Debug, Clone, PartialEq)]
pub struct GaitConfig {
    /// Heel strikes per channel (spec key `steps`), at least 1.
    pub steps: usize,
    /// Steps per second, both feet together (`cadence`), 0.5 to 4; 1.8 is a brisk walk.
    pub cadence: f64,
    /// Body mass in kilograms (`weight`), 20 to 300.
    pub weight_kg: f64,
    /// Feet, 1 or 2 (`channels`): channel `k` is foot `k`, left first.
    pub channels: usize,
    /// Relative step-to-step variation of timing and peak heights (`variation`), 0 to 0.3.
    pub variation: f64,
    /// Sensor rate in hertz (`rate`), 50 to 10 000.
    pub sensor_rate: f64,
    /// Seed of the variation (`seed`): the same seed gives the same track.
    pub seed: u64,
    /// Nominal stance fraction (`stance`), 0.55 to 0.75.
    pub stance_fraction: f64,
    /// Silence before the first heel strike (`lead_in`, seconds), 0 to 60.
    pub lead_in: Seconds,
    /// Silence after the last toe-off (`tail`, seconds), 0 to 60.
    pub tail: Seconds,
}

impl Default for GaitConfig {
    fn default() -> Self {
        Self {
            steps: 8,
            cadence: 1.8,
            weight_kg: 70.0,
            channels: 2,
            variation: 0.05,
            sensor_rate: 500.0,
            seed: 1,
            stance_fraction: DEFAULT_STANCE_FRACTION,
            lead_in: Seconds(0.5),
            tail: Seconds(1.0),
        }
    }
}

impl GaitConfig {
    /// Checks every setting against its range (see the fields), and that the walk fits
    /// in [`MAX_ROWS`] rows.
    ///
    /// # Errors
    /// [`GaitError::OutOfRange`] naming the first setting at fault, or
    /// [`GaitError::TooLong`].
    pub fn validate(&self) -> Result<(), GaitError> {
        fn within(
            key: &'static str,
            value: f64,
            lo: f64,
            hi: f64,
            allowed: &'static str,
        ) -> Result<(), GaitError> {
            if (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(GaitError::OutOfRange {
                    key,
                    value: value.to_string(),
                    allowed,
                })
            }
        }
        if self.steps == 0 {
            return Err(GaitError::OutOfRange {
                key: "steps",
                value: "0".to_owned(),
                allowed: "at least 1",
            });
        }
        if !(1..=2).contains(&self.channels) {
            return Err(GaitError::OutOfRange {
                key: "channels",
                value: self.channels.to_string(),
                allowed: "1 or 2 (one foot per channel)",
            });
        }
        within("cadence", self.cadence, 0.5, 4.0, "0.5 to 4 steps/s")?;
        within("weight", self.weight_kg, 20.0, 300.0, "20 to 300 kg")?;
        within("variation", self.variation, 0.0, 0.3, "0 to 0.3")?;
        within("rate", self.sensor_rate, 50.0, 10_000.0, "50 to 10000 Hz")?;
        within("stance", self.stance_fraction, 0.55, 0.75, "0.55 to 0.75")?;
        within("lead_in", self.lead_in.0, 0.0, 60.0, "0 to 60 s")?;
        within("tail", self.tail.0, 0.0, 60.0, "0 to 60 s")?;
        // An upper bound on the walk: every interval at its clipped maximum.
        let strikes = (self.strikes_needed() + 1) as f64;
        let longest =
            self.lead_in.0 + strikes * (1.0 + CLIP * self.variation) / self.cadence + self.tail.0;
        let rows = (longest * self.sensor_rate).ceil();
        if rows > MAX_ROWS as f64 {
            return Err(GaitError::TooLong {
                steps: self.steps,
                cadence: self.cadence,
                rate: self.sensor_rate,
                rows: rows as u64,
            });
        }
        Ok(())
    }

    /// Heel strikes of both feet needed: every kept step's cycle must end at a strike.
    pub(super) fn strikes_needed(&self) -> usize {
        2 * self.steps.min(MAX_ROWS) + 2
    }
}
