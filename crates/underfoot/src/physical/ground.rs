//! An estimated physical model, running: a step's excitation in, vibration out.
//!
//! [`Ground`] is what the engine plays for `--model physical`, and what the estimation
//! renders, so the two hear the same thing. Its input is the step's excitation
//! ([`crate::excitation`]), the same signal the IIR voice filters: a heel impulse and a
//! train of micro-impulses on a clock the foot drives. Each non-zero sample `x` strikes
//! the surface ([`Aggregate::process_impulses`]) with energy `x² / ē` times the hammer's
//! mean, `ē` the mean energy of one of the material's impulses: an impulse of mean energy
//! strikes at the hammer's RMS speed. Impulses within 2 ms of the last strike merge into
//! the next: a dense train (thousands a second) would take the few impacts in flight
//! from each other before their surfaces could ring. A solid (one heavy hammer) answers the
//! heel with one impact and a train, where it has one, with light ones; an aggregate (a
//! grain) answers every impulse with a grain of random size. The sign of an impulse, which
//! keeps the IIR voice's train white, means nothing to a hammer: a strike is a strike.
//!
//! Output is surface velocity times the estimated output gain: a nominal step comes out at
//! the recorded level.
//!
//! Prepared by [`Ground::new`]; [`Ground::assign_from`] loads another prepared model into
//! an existing one without allocating (capacity for [`MAX_MODES`] modes and
//! [`MAX_IMPACTS_IN_FLIGHT`] micro-impacts is reserved up front), so a material can change
//! on the audio thread. Nothing after preparation allocates or panics.

use super::PhysicalError;
use super::aggregate::Aggregate;
use super::model::{GroundKind, MAX_IMPACTS_IN_FLIGHT, MAX_MODES, PhysicalModel};
use crate::units::SampleRate;

/// A physical model prepared for a rate; see the module documentation.
///
/// A clone keeps the room for any model that [`new`](Self::new) reserves, so clones can
/// be assigned into without allocating.
#[derive(Debug)]
pub struct Ground {
    kind: GroundKind,
    aggregate: Aggregate,
    gain: f32,
    /// `ē`: the mean energy of one impulse of the material's excitation.
    mean_energy: f64,
}

impl Clone for Ground {
    fn clone(&self) -> Self {
        let mut aggregate = self.aggregate.clone();
        aggregate.reserve(MAX_MODES, MAX_IMPACTS_IN_FLIGHT);
        Self {
            kind: self.kind,
            aggregate,
            gain: self.gain,
            mean_energy: self.mean_energy,
        }
    }
}

impl Ground {
    /// Prepares `model` at `rate` for an excitation whose impulses have the mean energy
    /// `mean_energy` ([`crate::excitation::Tables::mean_impulse_energy`]).
    ///
    /// # Errors
    /// The model is invalid or does not fit the rate, or `mean_energy` is not positive.
    pub fn new(
        model: &PhysicalModel,
        rate: SampleRate,
        seed: u64,
        mean_energy: f64,
    ) -> Result<Self, PhysicalError> {
        model.validate()?;
        if !(mean_energy.is_finite() && mean_energy > 0.0) {
            return Err(PhysicalError::InvalidParameter {
                name: "mean impulse energy",
                value: mean_energy,
                expected: "positive and finite",
            });
        }
        let aggregate = Aggregate::with_capacity(
            &model.modes,
            &model.aggregate_params(),
            rate,
            seed,
            MAX_MODES,
            MAX_IMPACTS_IN_FLIGHT,
        )?;
        Ok(Self {
            kind: model.kind,
            aggregate,
            gain: model.output_gain as f32,
            mean_energy,
        })
    }

    /// Loads `other`'s model into this one, keeping this one's random stream and
    /// silence. Never allocates when `other` was prepared at the same rate (capacity is
    /// reserved by [`new`](Self::new)).
    pub fn assign_from(&mut self, other: &Ground) {
        self.kind = other.kind;
        self.aggregate.assign_from(&other.aggregate);
        self.gain = other.gain;
        self.mean_energy = other.mean_energy;
    }

    /// One impact or a stream of grains per step.
    #[must_use]
    pub fn kind(&self) -> GroundKind {
        self.kind
    }

    /// Strikes so far.
    #[must_use]
    pub fn events(&self) -> u64 {
        self.aggregate.events()
    }

    /// Silences the surface.
    pub fn reset(&mut self) {
        self.aggregate.reset();
    }

    /// Renders `out.len()` samples (at most `excitation.len()`), each non-zero sample of
    /// `excitation` a strike. Returns 1 if the output went non-finite, in which case the
    /// surface was reset and the block silenced, else 0.
    pub fn process(&mut self, excitation: &[f32], out: &mut [f32]) -> u32 {
        let n = out.len().min(excitation.len());
        let out = &mut out[..n];
        self.aggregate
            .process_impulses(&excitation[..n], self.mean_energy, out);
        for y in out.iter_mut() {
            *y *= self.gain;
        }
        if out.iter().all(|y| y.is_finite()) {
            0
        } else {
            self.reset();
            out.fill(0.0);
            1
        }
    }
}
