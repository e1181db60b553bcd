//! The frequency response of a device from exponential sine sweeps (Farina, 2000).
//!
//! A measurement plays a programme of exponential sine sweeps through the device, records
//! what comes back from the start of playback, divides the recording by the sweep in the
//! frequency domain, and keeps a window of the impulse response around time zero, whose
//! spectrum on a log grid of the band is the response:
//!
//! ```text
//! Sweep::new(config) --excitation()--> Device::play --recording--> Sweep::response
//!                                                                    -> FrequencyResponse
//! ```
//!
//! [`measure`] does the whole round trip for one [`Device`].
//!
//! | file | what |
//! |---|---|
//! | [`excitation`] | the sweep and its programme: [`SweepConfig`], [`Sweep`] |
//! | [`deconvolve`] | regularised spectral division, the window, harmonic distortion, averaging: [`Sweep::response`] |
//! | [`response`](mod@response) | [`FrequencyResponse`] and its deviation from flat |
//! | [`device`] | the [`Device`] trait, [`measure`], and [`MeasuredDevice`], a replay of a measured response |
//!
//! The simulated tile the tests and `--device-under-test simulated` measure is
//! [`crate::sim::SimulatedTile`].

pub mod deconvolve;
pub mod device;
pub mod excitation;
pub mod response;

pub use deconvolve::PRE_WINDOW;
pub use device::{Device, MeasuredDevice, measure};
pub use excitation::{GUARD_OCTAVES, MAX_SWEEP_DURATION, MAX_SWEEP_REPEATS, Sweep, SweepConfig};
pub use response::FrequencyResponse;
pub(crate) use response::interpolate_log;

#[cfg(test)]
mod tests;
