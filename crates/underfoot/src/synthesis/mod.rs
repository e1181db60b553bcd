//! Synthesis: a material's filter, played step by step.
//!
//! | module | what it does |
//! |---|---|
//! | [`modal`] | a fitted filter as a sum of modes, and impulse-invariant resampling to the audio rate |
//! | [`voice`] | the real-time voice: modes, per-step numerator perturbation, post filter, normalised drive gains |
pub mod modal;
pub mod voice;

pub use modal::{ModalError, ModalFilter, PoleResidue};
pub use voice::{
    ExcitationChoice, LANE_WIDTH, Lane, PreparedMaterial, SynthModel, Voice, VoiceConfig,
    VoiceError, VoiceLanes,
};
