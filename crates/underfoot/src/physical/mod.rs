//! Physical models: a hammer striking a resonating surface.
//!
//! The other synthesis path ([`crate::synthesis`]) plays back what was measured. This
//! one computes it from physics, as in the aggregate model of a vibrotactile floor tile:
//! an impact (a lumped mass meeting a nonlinear contact spring and damper) drives a bank of
//! damped modes (the surface), and the vibration is the surface's motion at the contact
//! point.
//!
//! | module | what |
//! |---|---|
//! | [`resonator`] | the surface, a [`ResonatorBank`] of [`SurfaceMode`]s discretised by impulse invariance, also available as second-order sections for interchange |
//! | [`impact`] | the Hunt-Crossley contact between a hammer and a rigid or resonating surface, integrated by an energy-consistent implicit step |
//! | [`aggregate`] | gravel, snow or sand as a stream of micro-impacts of random energy and fragment size, Poisson at a rate `N(t)` the caller drives or struck by an excitation's impulses, on a pool of impacts in flight |
//! | [`estimate`](mod@estimate) | all of the above estimated from recordings, with no hand tuning |
//! | [`model`] | the estimated [`PhysicalModel`] as stored in a library file |
//! | [`ground`] | an estimated model running, a step's excitation in and vibration out ([`Ground`]) |
//!
//! All are prepared once (where they may allocate and validate) and then run without
//! allocating or panicking.
//!
//! # Example
//!
//! The built-in gravel's physical model, estimated from its recordings, struck by its
//! excitation ([`crate::excitation`]): a step announced without force, whose clock runs at
//! the nominal pace, its micro-impulses each a grain striking the surface's modes.
//!
//! ```
//! use underfoot::excitation::{Generator, Tables};
//! use underfoot::material::builtin::builtin;
//! use underfoot::physical::{Ground, GroundKind};
//! use underfoot::units::SampleRate;
//!
//! let library = builtin();
//! let gravel = library.get("gravel")?;
//! let model = gravel.physical.as_ref().expect("gravel has a physical model");
//! assert_eq!(model.kind, GroundKind::Aggregate);
//!
//! let rate = SampleRate(48_000);
//! let tables = Tables::new(&gravel.excitation_or_heel(), rate)?;
//! let mut ground = Ground::new(model, rate, 1, tables.mean_impulse_energy())?;
//! let mut generator = Generator::new(7);
//! generator.step(&tables, 1.0);
//! let mut excitation = vec![0.0f32; 24_000];
//! generator.process(&tables, &vec![1.0; 24_000], &mut excitation);
//! let mut out = vec![0.0f32; excitation.len()];
//! assert_eq!(ground.process(&excitation, &mut out), 0); // 0: nothing went non-finite
//! assert!(ground.events() > 10);
//! assert!(out.iter().any(|y| *y != 0.0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod aggregate;
pub mod estimate;
pub mod ground;
pub mod impact;
pub mod model;
pub mod resonator;

pub use aggregate::{Aggregate, AggregateParams};
pub use estimate::{EstimateConfig, EstimateError, KindChoice, estimate};
pub use ground::Ground;
pub use impact::{Impact, ImpactParams, Surface};
pub use model::{GroundKind, PhysicalModel, PhysicalRecord};
pub use resonator::{ResonatorBank, SurfaceMode};

use crate::units::{Hz, SampleRate, Seconds};

/// What is wrong with the parameters of a physical model.
///
/// Every payload is a number or a `&'static str`, so the error can be built on the audio
/// thread (by [`Impact::strike`]) without allocating.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PhysicalError {
    /// The sample rate is zero.
    #[error("the sample rate must be positive")]
    ZeroRate,
    /// A resonator bank was asked for without any mode.
    #[error("a resonator bank needs at least one mode")]
    NoModes,
    /// A mode's frequency is not strictly between 0 and the Nyquist frequency.
    #[error("mode {index}: frequency {frequency} is not in (0, {nyquist})")]
    FrequencyOutOfRange {
        /// Which mode.
        index: usize,
        /// Its frequency.
        frequency: Hz,
        /// The Nyquist frequency of the rate asked for.
        nyquist: Hz,
    },
    /// A mode's decay time is not positive and finite.
    #[error("mode {index}: decay time {decay} must be positive and finite")]
    BadDecay {
        /// Which mode.
        index: usize,
        /// Its decay time.
        decay: Seconds,
    },
    /// A stored mode rings longer than the cap every physical model is played with
    /// ([`resonator::LONGEST_DECAY`]).
    #[error(
        "mode {index}: decay time {decay} is longer than the {limit} any mode may ring \
         (refit the material)"
    )]
    DecayTooLong {
        /// Which mode.
        index: usize,
        /// Its decay time.
        decay: Seconds,
        /// The cap.
        limit: Seconds,
    },
    /// A mode's gain is not finite.
    #[error("mode {index}: gain {gain} must be finite")]
    BadGain {
        /// Which mode.
        index: usize,
        /// Its gain.
        gain: f64,
    },
    /// A scalar parameter is out of its range.
    #[error("{name} = {value} is out of range: {expected}")]
    InvalidParameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The range it must lie in.
        expected: &'static str,
    },
    /// The surface was prepared for another sample rate than the impact.
    #[error("the surface runs at {surface}, the impact at {impact}")]
    RateMismatch {
        /// The surface's rate.
        surface: SampleRate,
        /// The impact's rate.
        impact: SampleRate,
    },
    /// The bank could not be factored into second-order sections.
    #[error("cannot factor the resonator bank into sections: {0}")]
    Factorisation(&'static str),
}
