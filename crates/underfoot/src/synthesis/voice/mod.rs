//! The event-based voice of the IIR paper's Fig. 3: one material filter per channel, driven
//! by force, with new numerator coefficients at every step.
//!
//! The voice has two halves: a [`PreparedMaterial`] is a library model made ready for one
//! audio rate, off the audio thread (modal form resampled, decays limited, residues
//! re-solved, a post filter, one normalised gain per drive); a [`Voice`] copies its
//! coefficients into fixed-size arrays and runs them on the audio thread, with new
//! numerators at every step (the IIR paper's equation 4).
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the sizes of a voice, and the post filter's section |
//! | [`config`](mod@config) | the settings ([`VoiceConfig`], [`SynthModel`]) and the errors ([`VoiceError`]) |
//! | [`prepared`](mod@prepared) | the material at the audio rate: modal form, residues, post filter, drive gains |
//! | [`play`](mod@play) | the voice itself: the modal filter in `f32`, the perturbation, the audio loop |
//! | [`lanes`](mod@lanes) | up to eight voices run together, one per SIMD lane, to the same bits |

pub mod config;
pub mod lanes;
pub mod play;
pub mod prepared;

pub use config::{ExcitationChoice, SynthModel, VoiceConfig, VoiceError};
pub use lanes::{LANE_WIDTH, Lane, VoiceLanes};
pub use play::Voice;
pub use prepared::PreparedMaterial;

/// The most modes a voice runs (a model of order up to 32).
pub const MAX_MODES: usize = 32;
/// The most second-order sections in the post filter.
pub const MAX_POST_SECTIONS: usize = 8;
const LANES: usize = 4;

/// A transposed direct-form II biquad in `f32`, for the post filter.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Section {
    b: [f32; 3],
    a: [f32; 2],
    s: [f32; 2],
}

impl Section {
    /// Passes its input through: what the unused sections hold.
    const IDENTITY: Self = Self {
        b: [1.0, 0.0, 0.0],
        a: [0.0, 0.0],
        s: [0.0, 0.0],
    };

    #[inline]
    fn tick(&mut self, x: f32) -> f32 {
        let y = self.b[0] * x + self.s[0];
        self.s[0] = self.b[1] * x - self.a[0] * y + self.s[1];
        self.s[1] = self.b[2] * x - self.a[1] * y;
        y
    }
}

#[cfg(test)]
mod tests;
