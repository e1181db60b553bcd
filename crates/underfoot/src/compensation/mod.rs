//! Compensation: making the device transparent for the user standing on it.
//!
//! The tile, its suspension, the actuator, the shoe and the leg all colour the vibration
//! on its way to the skin (Otis et al., *limb compensation*). This stage measures that
//! colouring and undoes it:
//!
//! - [`filterbank`]: a uniform FFT analysis-synthesis filter bank (weighted overlap-add),
//!   whose sub-band gains are the equalizer's spectral weights;
//! - [`sweep`]: the frequency response of a device from exponential sine sweeps, and the
//!   [`Device`](sweep::Device) it is measured on;
//! - [`equalizer`]: the spectral weights of the unloaded device, found by successive
//!   sweeps (equations (4)-(5)), realised by the bank or as a low-delay minimum-phase
//!   filter ([`fir`]), and the older static inverse FIR for comparison;
//! - [`adapt`]: the weights kept right while a person stands and walks on the tile, from
//!   the drive and the accelerometer (Welch H1 estimate of the loaded device);
//! - [`limb`]: the rheological model of the lower limb (equations (1)-(3)), its bounded
//!   fit to a loaded-over-unloaded sweep, and its inverse `Z_c` as a compensation filter;
//! - [`table`]: the table of users: each user's equalizer curve, interpolated for a new
//!   user's limb parameters;
//! - [`files`]: the measured responses, equalizers and limb models the workflow writes,
//!   [documents](crate::document) like the table of users;
//! - [`chain`]: the equalizer and limb filter as the engine runs them on each channel,
//!   before the limiter.
//!
//! The simulated tile and user that stand in for the hardware and a person, in the tests
//! and on the command line (`--device-under-test simulated`), are in [`crate::sim`].
//!
//! # Example
//!
//! Measure a device with a sweep and flatten it: here the simulated tile (a device of
//! known response, with its own measurement noise) and two corrected passes of the
//! equalizer, realised as the low-delay filter the engine runs.
//!
//! ```
//! use underfoot::compensation::equalizer::{EqualizerConfig, Realisation, equalize};
//! use underfoot::compensation::sweep::{Sweep, SweepConfig, measure};
//! use underfoot::sim::{SimulatedTile, TileConfig};
//! use underfoot::units::SampleRate;
//!
//! let rate = SampleRate(48_000);
//! let sweep = Sweep::new(SweepConfig::new(rate))?;
//! let mut tile = SimulatedTile::new(&TileConfig::default(), rate)?;
//!
//! // The bare tile: its deviation from flat over the band, in dB RMS.
//! let bare = measure(&mut tile, &sweep)?;
//! assert!(bare.deviation_from_flat_db().0 > 2.0);
//!
//! // Pass 1 measures it, pass 2 measures it through the weights pass 1 corrected.
//! // (`false`: the filter keeps the length given; `calibrate equalize --taps auto` lets it
//! // grow where the weights need it.)
//! let config = EqualizerConfig::default();
//! let eq = equalize(&mut tile, &sweep, config, Realisation::default(), 2, false)?;
//! assert!(eq.passes[1].deviation.0 < 0.5 * eq.passes[0].deviation.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Set-up allocates; the per-sample paths never do. Errors are [`CompensationError`];
//! reading and writing the files is the [document layer](crate::document)'s, with its
//! [`DocumentError`](crate::document::DocumentError) (whose validation reason is a
//! [`CompensationError`]).

pub mod adapt;
pub mod chain;
pub mod equalizer;
pub mod files;
pub mod filterbank;
pub mod fir;
pub mod limb;
pub mod sweep;
pub mod table;

use crate::numeric::trf::TrfError;

/// What is wrong with a compensation setting or measurement.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CompensationError {
    /// A parameter is out of its range.
    #[error("{name} = {value} is out of range: {expected}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The range it must lie in.
        expected: &'static str,
    },
    /// A recording is too short for what was asked of it.
    #[error("{what}: {len} samples, at least {needed} needed")]
    TooShort {
        /// What was too short.
        what: &'static str,
        /// Its length.
        len: usize,
        /// The length needed.
        needed: usize,
    },
    /// A measurement device cannot play or record.
    #[error("device: {reason}")]
    Device {
        /// What went wrong.
        reason: String,
    },
    /// A signal holds a value that is not finite.
    #[error("{what}: sample {index} is not finite")]
    NonFinite {
        /// Which signal.
        what: &'static str,
        /// Where.
        index: usize,
    },
    /// Two inputs that must match in length do not.
    #[error("{what}: {len} entries, {expected} expected")]
    Mismatch {
        /// What does not match.
        what: &'static str,
        /// Its length.
        len: usize,
        /// The length expected.
        expected: usize,
    },
    /// Something that must hold at least one entry is empty.
    #[error("{what} is empty")]
    Empty {
        /// What is empty.
        what: &'static str,
    },
    /// The bounded least-squares fit could not be run.
    #[error("fit failed: {0}")]
    FitFailed(#[source] TrfError),
    /// A filter that must be stable is not.
    #[error("unstable: {what}")]
    Unstable {
        /// Which filter, and why.
        what: &'static str,
    },
}

impl CompensationError {
    /// [`CompensationError::InvalidParameter`]: `name` is `value`, outside `expected`.
    pub(crate) fn invalid(name: &'static str, value: f64, expected: &'static str) -> Self {
        Self::InvalidParameter {
            name,
            value,
            expected,
        }
    }
}
