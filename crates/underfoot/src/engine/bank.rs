//! The materials an engine can play, prepared for its rate before it starts.

use crate::material::Library;
use crate::synthesis::{PreparedMaterial, VoiceConfig, VoiceError};
use crate::units::{Newtons, SampleRate};

use super::EngineError;

/// The materials an engine can play, prepared for its rate. Built off the audio thread.
#[derive(Debug, Clone, Default)]
pub struct MaterialBank {
    pub(super) materials: Vec<PreparedMaterial>,
}

impl MaterialBank {
    /// Prepares every material of `library` for `rate`, normalising the force drives with
    /// `nominal_step` (total force of one nominal step at `rate`, see
    /// [`gait::nominal_step`](crate::force::gait::nominal_step)) for a walker of `weight`.
    ///
    /// # Errors
    /// The first material that cannot be played.
    pub fn prepare(
        library: &Library,
        rate: SampleRate,
        voice: &VoiceConfig,
        nominal_step: &[f64],
        weight: Newtons,
    ) -> Result<Self, VoiceError> {
        let materials = library
            .materials
            .iter()
            .map(|m| {
                let mut p = PreparedMaterial::prepare(m, rate, voice)?;
                p.normalise_drives(nominal_step, weight);
                Ok(p)
            })
            .collect::<Result<Vec<_>, VoiceError>>()?;
        Ok(Self { materials })
    }

    /// A bank of already prepared materials.
    #[must_use]
    pub fn from_prepared(materials: Vec<PreparedMaterial>) -> Self {
        Self { materials }
    }

    /// The materials' names, in slot order.
    #[must_use]
    pub fn names(&self) -> Vec<String> {
        self.materials.iter().map(|m| m.name.clone()).collect()
    }

    /// The slot of a material.
    ///
    /// # Errors
    /// [`EngineError::UnknownMaterial`] listing the names there are.
    pub fn slot(&self, name: &str) -> Result<u16, EngineError> {
        self.materials
            .iter()
            .position(|m| m.name == name)
            .map(|i| i as u16)
            .ok_or_else(|| EngineError::UnknownMaterial {
                name: name.to_string(),
                available: self.names().join(", "),
            })
    }

    /// The prepared materials.
    #[must_use]
    pub fn materials(&self) -> &[PreparedMaterial] {
        &self.materials
    }
}
