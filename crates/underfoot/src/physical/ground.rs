//! An estimated physical model, running: force in, vibration out.
//!
//! [`Ground`] is what the engine plays for `--model physical`, and what the estimation
//! renders, so the two hear the same thing. Its input is the loading rate
//! `v_F = max(dF/dt, 0)` in newtons per second, sample by sample:
//!
//! - an **aggregate** turns it into the event rate `N(t) = α v_F(t)` of its micro-impacts
//!   ([`super::aggregate`]), so it sounds while, and as much as, the foot loads the ground;
//! - a **solid** ignores it and strikes once per heel strike ([`Ground::strike`]), with a
//!   speed proportional to the strike's intensity (its loading rate over the nominal one).
//!
//! A step announced without force (an OSC step, say: [`Ground::step`]) strikes a solid
//! and plays a nominal step's loading through an aggregate, scaled by the intensity.
//! Output is surface velocity times the estimated output gain: a nominal step comes out
//! at the recorded level.
//!
//! Prepared by [`Ground::new`]; [`Ground::assign_from`] loads another prepared model into
//! an existing one without allocating (capacity for [`MAX_MODES`] modes and
//! [`MAX_IMPACTS_IN_FLIGHT`] micro-impacts is reserved up front), so a material can change on the audio
//! thread. Nothing after preparation allocates or panics.

use super::PhysicalError;
use super::aggregate::Aggregate;
use super::model::{GroundKind, MAX_IMPACTS_IN_FLIGHT, MAX_MODES, PhysicalModel};
use crate::force::drive::DriveKind;
use crate::force::gait::nominal_step;
use crate::units::{Newtons, SampleRate};

/// A physical model prepared for a rate; see the module documentation.
///
/// A clone keeps the room for any model that [`new`](Self::new) reserves, so clones can
/// be assigned into without allocating.
#[derive(Debug)]
pub struct Ground {
    kind: GroundKind,
    aggregate: Aggregate,
    events_per_newton: f32,
    gain: f32,
    /// Scratch for the event rate of one block.
    rates: Vec<f32>,
    /// A nominal step's loading rate (N/s) at this rate, for steps announced without
    /// force; the same for every model, so loading another model leaves it be.
    nominal: Vec<f32>,
    cursor: usize,
    burst: f32,
}

impl Clone for Ground {
    fn clone(&self) -> Self {
        let mut aggregate = self.aggregate.clone();
        aggregate.reserve(MAX_MODES, MAX_IMPACTS_IN_FLIGHT);
        Self {
            kind: self.kind,
            aggregate,
            events_per_newton: self.events_per_newton,
            gain: self.gain,
            rates: self.rates.clone(),
            nominal: self.nominal.clone(),
            cursor: self.cursor,
            burst: self.burst,
        }
    }
}

impl Ground {
    /// Prepares `model` at `rate`, for blocks of up to `max_block` samples (longer ones are
    /// processed in pieces).
    ///
    /// # Errors
    /// The model is invalid or does not fit the rate.
    pub fn new(
        model: &PhysicalModel,
        rate: SampleRate,
        seed: u64,
        max_block: usize,
    ) -> Result<Self, PhysicalError> {
        model.validate()?;
        let aggregate = Aggregate::with_capacity(
            &model.modes,
            &model.aggregate_params(),
            rate,
            seed,
            MAX_MODES,
            MAX_IMPACTS_IN_FLIGHT,
        )?;
        let nominal =
            DriveKind::ForceRate.offline(&nominal_step(70.0, 1.8, rate.hz()), rate, Newtons(1.0));
        Ok(Self {
            kind: model.kind,
            aggregate,
            events_per_newton: model.events_per_newton as f32,
            gain: model.output_gain as f32,
            rates: vec![0.0; max_block.max(1)],
            nominal,
            cursor: usize::MAX,
            burst: 0.0,
        })
    }

    /// Loads `other`'s model into this one, keeping this one's scratch, random stream and
    /// silence. Never allocates when `other` was prepared at the same rate (capacity is
    /// reserved by [`new`](Self::new)).
    pub fn assign_from(&mut self, other: &Ground) {
        self.kind = other.kind;
        self.aggregate.assign_from(&other.aggregate);
        self.events_per_newton = other.events_per_newton;
        self.gain = other.gain;
        self.cursor = usize::MAX;
        self.burst = 0.0;
    }

    /// One aggregate or one impact per step.
    #[must_use]
    pub fn kind(&self) -> GroundKind {
        self.kind
    }

    /// Micro-impacts (or strikes) so far.
    #[must_use]
    pub fn events(&self) -> u64 {
        self.aggregate.events()
    }

    /// A heel strike found in the force: a solid strikes, at a speed scaled by
    /// `intensity`; an aggregate is already driven by the force and ignores it.
    pub fn strike(&mut self, intensity: f32) {
        if self.kind == GroundKind::Solid && intensity.is_finite() && intensity > 0.0 {
            self.aggregate.strike(f64::from(intensity));
        }
    }

    /// A step with no force to follow: a solid strikes; an aggregate plays a nominal
    /// step's loading, scaled by `intensity`.
    pub fn step(&mut self, intensity: f32) {
        if !(intensity.is_finite() && intensity > 0.0) {
            return;
        }
        match self.kind {
            GroundKind::Solid => self.aggregate.strike(f64::from(intensity)),
            GroundKind::Aggregate => {
                self.cursor = 0;
                self.burst = intensity;
            }
        }
    }

    /// Silences the surface.
    pub fn reset(&mut self) {
        self.aggregate.reset();
        self.cursor = usize::MAX;
    }

    /// Renders `out.len()` samples (at most `loading.len()`), `loading` being `v_F` in N/s.
    /// Returns 1 if the output went non-finite, in which case the surface was reset and the
    /// block silenced, else 0.
    pub fn process(&mut self, loading: &[f32], out: &mut [f32]) -> u32 {
        let n = out.len().min(loading.len());
        let block = self.rates.len();
        let mut at = 0;
        while at < n {
            let len = block.min(n - at);
            let rates = &mut self.rates[..len];
            match self.kind {
                GroundKind::Aggregate => {
                    for (r, v) in rates.iter_mut().zip(&loading[at..at + len]) {
                        let mut load = v.max(0.0);
                        if let Some(b) = self.nominal.get(self.cursor) {
                            load += self.burst * b;
                            self.cursor += 1;
                        }
                        let x = self.events_per_newton * load;
                        *r = if x.is_finite() { x } else { 0.0 };
                    }
                }
                GroundKind::Solid => rates.fill(0.0),
            }
            let o = &mut out[at..at + len];
            self.aggregate.process(rates, o);
            for y in o.iter_mut() {
                *y *= self.gain;
            }
            at += len;
        }
        if out[..n].iter().all(|y| y.is_finite()) {
            0
        } else {
            self.reset();
            out[..n].fill(0.0);
            1
        }
    }
}
