//! The settings a render or a session plays with, in one place: what the command line's
//! synthesis flags and the Python package's keyword arguments both fill in, so that the
//! two prepare the same bank and build the same engine from the same values.
//!
//! [`PlaySettings::check`] bounds every value (a gain beyond +60 dB overflows a float and
//! silences every sample; an audio rate below 8 kHz cannot hold the band), then
//! [`PlaySettings::prepare`] prepares the materials played and
//! [`PlaySettings::engine_config`] fills in the engine's settings, the step detector
//! included. Compensation (an equalizer, a limb model) is added to the returned
//! [`EngineConfig`] by the caller, which reads its files.

use super::{EngineConfig, EngineError, MaterialBank};
use crate::force::drive::DriveKind;
use crate::force::gait::nominal_step;
use crate::material::{Library, LibraryError};
use crate::synthesis::{ExcitationChoice, SynthModel, VoiceConfig};
use crate::units::{Decibels, Hz, Newtons, SampleRate};

/// The cadence of the nominal step the force drives are normalised with, in steps per
/// second (a comfortable walk).
const NOMINAL_CADENCE: f64 = 1.8;

/// How materials are played: the model, its drive and excitation, the levels, and the
/// step detector's threshold. The defaults are the command line's.
#[derive(Debug, Clone, PartialEq)]
pub struct PlaySettings {
    /// The audio rate.
    pub rate: SampleRate,
    /// What drives a material's filter.
    pub drive: DriveKind,
    /// Which of a material's models plays.
    pub model: SynthModel,
    /// What drives each step.
    pub excitation: ExcitationChoice,
    /// Output gain before the limiter, on top of each material's playback level.
    pub gain: Decibels,
    /// The limiter's ceiling, re full scale (at most 0).
    pub ceiling: Decibels,
    /// Standard deviation of the per-step numerator perturbation; `None` for each
    /// material's own.
    pub perturbation: Option<f32>,
    /// Seed of every random stream.
    pub seed: u64,
    /// Order of the low-pass that removes fitting artefacts (0: none).
    pub lowpass_order: usize,
    /// Body mass the force drives are normalised for, kg.
    pub weight_kg: f64,
    /// The total force a heel strike rises through.
    pub step_threshold: Newtons,
    /// About how often force readings arrive.
    pub sensor_rate: Hz,
}

impl Default for PlaySettings {
    fn default() -> Self {
        let engine = EngineConfig::default();
        Self {
            rate: engine.rate,
            drive: engine.drive,
            model: SynthModel::default(),
            excitation: ExcitationChoice::default(),
            gain: engine.gain,
            ceiling: engine.ceiling,
            perturbation: engine.perturbation,
            seed: engine.seed,
            lowpass_order: VoiceConfig::default().lowpass_order,
            weight_kg: 70.0,
            step_threshold: crate::force::steps::DEFAULT_THRESHOLD,
            sensor_rate: engine.sensor_rate,
        }
    }
}

/// The highest low-pass order accepted: far beyond any use (the default is 4), low
/// enough that its design stays well conditioned.
pub const MAX_LOWPASS_ORDER: usize = 16;

impl PlaySettings {
    /// Checks every value against its range.
    ///
    /// # Errors
    /// [`EngineError::InvalidConfig`], naming the setting, its value and its range.
    pub fn check(&self) -> Result<(), EngineError> {
        let refuse = |what: String| Err(EngineError::InvalidConfig(what));
        let within = |v: f64, lo: f64, hi: f64| v.is_finite() && (lo..=hi).contains(&v);
        if !(8_000..=384_000).contains(&self.rate.0) {
            return refuse(format!("audio rate {}: need 8000 to 384000 Hz", self.rate));
        }
        if !within(self.weight_kg, 20.0, 300.0) {
            return refuse(format!("weight {} kg: need 20 to 300", self.weight_kg));
        }
        if !within(self.sensor_rate.0, 1.0, 10_000.0) {
            return refuse(format!(
                "sensor rate {} Hz: need 1 to 10000",
                self.sensor_rate.0
            ));
        }
        if !within(self.gain.0, -120.0, 60.0) {
            return refuse(format!("gain {} dB: need -120 to 60", self.gain.0));
        }
        if !within(self.ceiling.0, -120.0, 0.0) {
            return refuse(format!(
                "ceiling {} dB: need -120 to 0 (re full scale)",
                self.ceiling.0
            ));
        }
        if !within(self.step_threshold.0, 1.0, 5000.0) {
            return refuse(format!(
                "step threshold {} N: need 1 to 5000",
                self.step_threshold.0
            ));
        }
        if let Some(sigma) = self.perturbation
            && !within(f64::from(sigma), 0.0, 0.5)
        {
            return refuse(format!("perturbation {sigma}: need 0 to 0.5"));
        }
        if self.lowpass_order > MAX_LOWPASS_ORDER {
            return refuse(format!(
                "low-pass order {}: need 0 to {MAX_LOWPASS_ORDER}",
                self.lowpass_order
            ));
        }
        Ok(())
    }

    /// How each material is prepared for playback.
    #[must_use]
    pub fn voice(&self) -> VoiceConfig {
        VoiceConfig {
            lowpass_order: self.lowpass_order,
            model: self.model,
            excitation: self.excitation,
            ..VoiceConfig::default()
        }
    }

    /// The nominal step (total force at the audio rate) the force drives are normalised
    /// with.
    #[must_use]
    pub fn nominal_step(&self) -> Vec<f64> {
        nominal_step(self.weight_kg, NOMINAL_CADENCE, self.rate.hz())
    }

    /// Prepares the materials of `library` for playback: all of them, or those `only`
    /// names (preparing one takes some 30 ms, so a command that plays a few of a large
    /// library prepares those few).
    ///
    /// # Errors
    /// [`PlayError::Library`] for a name the library does not hold, and
    /// [`PlayError::Engine`] for settings out of range or a material that cannot be
    /// played.
    pub fn prepare(
        &self,
        library: &Library,
        only: Option<&[&str]>,
    ) -> Result<MaterialBank, PlayError> {
        self.check()?;
        let played = match only {
            None => None,
            Some(names) => {
                let mut played = Library::new();
                for name in names {
                    played.upsert(library.get(name)?.clone());
                }
                Some(played)
            }
        };
        Ok(MaterialBank::prepare(
            played.as_ref().unwrap_or(library),
            self.rate,
            &self.voice(),
            &self.nominal_step(),
            Newtons::weight_of(self.weight_kg),
        )
        .map_err(EngineError::from)?)
    }

    /// The engine's settings for `channels` channels (no compensation).
    ///
    /// # Errors
    /// [`EngineError::InvalidConfig`] as [`PlaySettings::check`].
    pub fn engine_config(&self, channels: usize) -> Result<EngineConfig, EngineError> {
        self.check()?;
        let mut config = EngineConfig {
            rate: self.rate,
            channels,
            drive: self.drive,
            perturbation: self.perturbation,
            seed: self.seed,
            nominal_weight: Newtons::weight_of(self.weight_kg),
            sensor_rate: self.sensor_rate,
            gain: self.gain,
            ceiling: self.ceiling,
            ..EngineConfig::default()
        };
        config.detector.set_threshold(self.step_threshold);
        // The loading rate a nominal step rises through the threshold with, as the
        // sensors see it: what a step's intensity is measured against.
        let sensor_rate = SampleRate(self.sensor_rate.0.round() as u32);
        config.detector.nominal_loading_rate = config.detector.loading_rate_of(
            &nominal_step(self.weight_kg, NOMINAL_CADENCE, self.sensor_rate.0),
            sensor_rate,
        );
        Ok(config)
    }
}

/// Why materials cannot be prepared for playing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PlayError {
    /// A material name the library does not hold.
    #[error(transparent)]
    Library(#[from] LibraryError),
    /// A setting out of range, or a material that cannot be played.
    #[error(transparent)]
    Engine(#[from] EngineError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_setting_out_of_range_is_refused_by_name() {
        let cases: [(&str, PlaySettings); 8] = [
            (
                "audio rate",
                PlaySettings {
                    rate: SampleRate(4000),
                    ..Default::default()
                },
            ),
            (
                "weight",
                PlaySettings {
                    weight_kg: f64::NAN,
                    ..Default::default()
                },
            ),
            (
                "sensor rate",
                PlaySettings {
                    sensor_rate: Hz(0.0),
                    ..Default::default()
                },
            ),
            (
                "gain",
                PlaySettings {
                    gain: Decibels(61.0),
                    ..Default::default()
                },
            ),
            (
                "ceiling",
                PlaySettings {
                    ceiling: Decibels(1.0),
                    ..Default::default()
                },
            ),
            (
                "step threshold",
                PlaySettings {
                    step_threshold: Newtons(0.5),
                    ..Default::default()
                },
            ),
            (
                "perturbation",
                PlaySettings {
                    perturbation: Some(0.6),
                    ..Default::default()
                },
            ),
            (
                "low-pass order",
                PlaySettings {
                    lowpass_order: 99,
                    ..Default::default()
                },
            ),
        ];
        for (what, settings) in cases {
            let e = settings.check().expect_err(what).to_string();
            assert!(e.contains(what), "{what}: {e}");
            assert!(settings.engine_config(1).is_err(), "{what}");
        }
        PlaySettings::default().check().unwrap();
    }

    #[test]
    fn only_the_named_materials_are_prepared_and_an_unknown_name_is_refused() {
        let library = crate::material::builtin::builtin();
        let settings = PlaySettings::default();
        let bank = settings.prepare(library, Some(&["gravel"])).unwrap();
        assert_eq!(bank.slot("gravel").unwrap(), 0);
        assert!(bank.slot("sand").is_err());
        let e = settings.prepare(library, Some(&["lava"])).unwrap_err();
        assert!(matches!(e, PlayError::Library(_)), "{e}");
        assert!(e.to_string().contains("lava"), "{e}");
    }
}
