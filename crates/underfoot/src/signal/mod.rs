//! Signal conditioning: the building blocks that turn a raw recording into a clean strike.
//!
//! Each block is independent and tested against its closed-form definition.
//!
//! Without the `std` feature only [`noise`] and [`fixed`] remain: what firmware needs.
#[cfg(feature = "std")]
pub mod butterworth;
#[cfg(feature = "std")]
pub mod delay;
#[cfg(feature = "std")]
pub mod filtfilt;
pub mod fixed;
pub mod noise;
#[cfg(feature = "std")]
pub mod resample;
#[cfg(feature = "std")]
pub mod savgol;
#[cfg(feature = "std")]
pub mod sos;
#[cfg(feature = "std")]
pub mod spectrum;
#[cfg(feature = "std")]
pub mod wavelet;
#[cfg(feature = "std")]
pub mod zpk;

#[cfg(feature = "std")]
pub use sos::{Biquad, Sos};

/// What can be wrong with the parameters or input of a conditioning block.
#[cfg(feature = "std")]
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SignalError {
    /// A filter band does not fit the sample rate.
    #[error(
        "band {band} does not fit sample rate {rate} (need {} Hz <= lo < hi < {})",
        crate::units::Band::MIN_EDGE,
        rate.nyquist()
    )]
    BandOutOfRange {
        /// The band asked for.
        band: crate::units::Band,
        /// The rate it was asked at.
        rate: crate::units::SampleRate,
    },
    /// A cutoff frequency does not fit the sample rate.
    #[error("cutoff {cutoff} does not fit sample rate {rate} (need 0 < f < Nyquist)")]
    CutoffOutOfRange {
        /// The cutoff asked for.
        cutoff: crate::units::Hz,
        /// The rate it was asked at.
        rate: crate::units::SampleRate,
    },
    /// A parameter is out of its valid range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// The input is too short for the operation.
    #[error("input of {len} samples is too short: {what} needs at least {needed}")]
    TooShort {
        /// Samples given.
        len: usize,
        /// Samples needed.
        needed: usize,
        /// The operation.
        what: &'static str,
    },
    /// The input is longer than the operation can take.
    #[error("input of {len} samples is too long: {what} takes at most {max}")]
    TooLong {
        /// Samples given.
        len: usize,
        /// Samples allowed.
        max: usize,
        /// The operation.
        what: &'static str,
    },
    /// An output buffer has the wrong length.
    #[error("output buffer of {len} values has the wrong length: {what} writes {expected}")]
    WrongLength {
        /// Length given.
        len: usize,
        /// Length needed.
        expected: usize,
        /// The operation.
        what: &'static str,
    },
}
