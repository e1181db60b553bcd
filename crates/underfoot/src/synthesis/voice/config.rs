//! How a model is prepared for playback ([`VoiceConfig`]), which of a material's models
//! plays ([`SynthModel`]), and why a model cannot be played ([`VoiceError`]).

use super::MAX_MODES;
use crate::synthesis::modal::ModalError;
use crate::units::{Hz, Seconds};

/// How a model is prepared for playback.
#[derive(Debug, Clone, PartialEq)]
pub struct VoiceConfig {
    /// Order of the low-pass that removes fitting artefacts; 0 for none (default 4).
    pub lowpass_order: usize,
    /// Its cutoff; `None` for the top of the model's band (the default).
    pub lowpass_cutoff: Option<Hz>,
    /// Cutoff of the second-order high-pass; `None` for half the bottom of the band,
    /// `Some(Hz(0.0))` for none.
    pub highpass_cutoff: Option<Hz>,
    /// No mode rings longer than this (time to decay by `e`; default 0.5 s, i.e. a
    /// 60 dB decay in 3.5 s).
    pub longest_decay: Seconds,
    /// Frequencies (log-spaced over the band) the residues are re-solved on (default 256).
    pub fit_points: usize,
    /// Pull of the residue solve towards the impulse-invariant residues (default 1e-4).
    pub regularisation: f64,
    /// Rounds of the magnitude-only residue solve (default 10).
    pub magnitude_iterations: usize,
    /// Which model plays: the fitted filter (default) or the calibrated physical model.
    pub model: SynthModel,
    /// What drives a step: the material's fitted excitation (default) or one impulse.
    pub excitation: ExcitationChoice,
}

/// What drives each step of a material.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ExcitationChoice {
    /// The excitation fitted from the material's recordings: the heel impact and its train
    /// of micro-impacts ([`crate::excitation`]); one impulse for a material fitted before
    /// the excitation existed.
    #[default]
    Fitted,
    /// One impulse per step, whatever the material: the IIR paper's drive.
    Heel,
}

/// Which of a material's models the engine plays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SynthModel {
    /// The fitted IIR filter, perturbed at every step ([`Voice`](super::Voice)).
    #[default]
    Iir,
    /// The physical model calibrated from the same recordings
    /// ([`crate::physical::Ground`]): one Hunt-Crossley impact per step on a solid, a
    /// Poisson stream of micro-impacts driven by the loading rate on an aggregate.
    Physical,
}

impl core::str::FromStr for ExcitationChoice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fitted" => Ok(Self::Fitted),
            "heel" => Ok(Self::Heel),
            _ => Err(format!("{s:?}: expected fitted or heel")),
        }
    }
}

impl core::str::FromStr for SynthModel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "iir" => Ok(Self::Iir),
            "physical" => Ok(Self::Physical),
            _ => Err(format!("{s:?}: expected iir or physical")),
        }
    }
}

impl Default for VoiceConfig {
    fn default() -> Self {
        Self {
            lowpass_order: 4,
            lowpass_cutoff: None,
            highpass_cutoff: None,
            longest_decay: Seconds(0.5),
            fit_points: 256,
            regularisation: 0.0,
            magnitude_iterations: 40,
            model: SynthModel::Iir,
            excitation: ExcitationChoice::Fitted,
        }
    }
}

/// Why a model cannot be played.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum VoiceError {
    /// The model's filter has malformed sections.
    #[error("material {name:?}: the filter has malformed sections")]
    MalformedFilter {
        /// The material.
        name: String,
    },
    /// The filter has no modal form.
    #[error("material {name:?}: {source}")]
    Modal {
        /// The material.
        name: String,
        /// Why.
        source: ModalError,
    },
    /// The filter has more modes than a voice runs.
    #[error("material {name:?} has {modes} modes; a voice runs at most {MAX_MODES}")]
    TooManyModes {
        /// The material.
        name: String,
        /// How many.
        modes: usize,
    },
    /// The physical model was asked for and the material has none.
    #[error("material {name:?} has no physical model (refit it with `underfoot fit`)")]
    NoPhysicalModel {
        /// The material.
        name: String,
    },
    /// The material's physical model cannot run at this rate.
    #[error("material {name:?}: physical model: {source}")]
    Physical {
        /// The material.
        name: String,
        /// Why.
        source: crate::physical::PhysicalError,
    },
    /// A setting of the [`VoiceConfig`] is out of range.
    #[error("voice setting {name} = {value} is out of range: {expected}")]
    InvalidConfig {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The range it must lie in.
        expected: &'static str,
    },
    /// The material's excitation cannot play at this rate.
    #[error("material {name:?}: excitation: {source}")]
    Excitation {
        /// The material.
        name: String,
        /// Why.
        source: crate::excitation::ExcitationError,
    },
    /// A post-filter setting does not fit the rate.
    #[error("material {name:?}: post filter: {reason}")]
    PostFilter {
        /// The material.
        name: String,
        /// Why.
        reason: String,
    },
}
