//! The equalizer of the unloaded device: spectral weights found by successive sweeps,
//! applied by the filter bank or by its low-delay minimum-phase realisation.
//!
//! A sweep through the equalized device gives its response; the weights, a gain in dB on
//! each bin of a uniform bank, are cut where the response stands above its mean and
//! boosted where it falls below (equations (4)-(5) of the compensation paper), within bounds; the next
//! sweep measures the result. The weights run as the compensation paper's filter bank or as a
//! minimum-phase FIR with no bulk delay.
//!
//! | file | what |
//! |---|---|
//! | [`weights`] | the weights, their settings, and the update of equations (4)-(5): [`SpectralWeights`], [`EqualizerConfig`] |
//! | [`filter`] | the weights as a running filter, bank or low-delay: [`Realisation`], [`EqualizerFilter`] |
//! | [`tune`] | the passes of sweeps that tune the weights on a device: [`equalize`], [`flatness`] |
//! | [`static_inverse`] | the earlier static inverse FIR, kept for comparison: [`StaticInverse`] |

pub mod filter;
pub mod static_inverse;
pub mod tune;
pub mod weights;

pub use filter::{EqualizerFilter, Realisation};
pub use static_inverse::{Inverted, StaticInverse};
pub use tune::{
    Capped, Equalization, Equalized, MAX_AUTO_TAPS, MAX_REALISATION_ERROR, PassReport, auto_taps,
    equalize, flatness,
};
pub use weights::{EqualizerConfig, SpectralWeights};
