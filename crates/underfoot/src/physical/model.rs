//! An estimated physical model of a ground material, as stored in a library file.

use serde::{Deserialize, Serialize};

use super::resonator::LONGEST_DECAY;
use super::{AggregateParams, ImpactParams, PhysicalError, SurfaceMode};
use crate::units::Hz;

/// The most modes a stored model may have.
pub const MAX_MODES: usize = 32;

/// The most micro-impacts a stored aggregate may ring at once.
pub const MAX_IMPACTS_IN_FLIGHT: usize = 8;

/// How the ground answers a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GroundKind {
    /// One impact per step: concrete, wood, metal.
    Solid,
    /// Many micro-impacts while the foot loads the ground: gravel, sand, snow.
    Aggregate,
}

impl GroundKind {
    /// Its name in files and reports.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            GroundKind::Solid => "solid",
            GroundKind::Aggregate => "aggregate",
        }
    }
}

/// A physical model estimated from recordings ([`mod@super::estimate`]): the surface's
/// modes and the hammer that strikes it. What strikes it, and when, is the material's
/// excitation ([`crate::excitation`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhysicalModel {
    /// One impact per step, or a stream of micro-impacts.
    pub kind: GroundKind,
    /// The surface at the point struck (frequencies in Hz, decay times in s, gains in
    /// m/(N·s)).
    pub modes: Vec<SurfaceMode>,
    /// The hammer; its `velocity` is the RMS speed of a strike (m/s).
    pub hammer: ImpactParams,
    /// Fragment sizes are log-uniform in `[1/(1+s), 1+s]` (aggregates).
    pub size_spread: f64,
    /// How many micro-impacts can ring at once (aggregates). Stored as `voices`, its name
    /// in library files.
    #[serde(rename = "voices")]
    pub impacts_in_flight: usize,
    /// Output units per m/s of surface velocity: the recorded level.
    pub output_gain: f64,
    /// How the estimation went.
    pub record: PhysicalRecord,
}

/// What the estimation measured and how well the model matches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhysicalRecord {
    /// Impact onsets per strike, counted in the wavelet detail band.
    pub onsets_per_strike: f64,
    /// Median time from a strike's onset to half its energy, in ms (what decides the
    /// kind when it is automatic).
    pub half_energy_ms: f64,
    /// The scale `a` of the event-rate profile `N(t) = e^{a I(t)} - 1`.
    pub rate_scale: f64,
    /// Recordings the poles came from: isolated micro-impacts (`true`) or whole strikes.
    pub isolated_impacts: bool,
    /// The model's magnitude on the material's fit grid, rendered and analysed as a
    /// recording is.
    pub model: Vec<f64>,
    /// NRMSE of `model` against the measurement.
    pub nrmse: f64,
    /// Log-spectral distance of `model` against the measurement, in dB.
    pub lsd_db: f64,
    /// The largest sample of that render at the model's output gain: a nominal step's
    /// peak at the recorded level, which sets the material's playback level when it is
    /// louder than the filter's ([`crate::material::level`]). 0 in files before format 3.
    #[serde(default)]
    pub peak: f64,
}

impl PhysicalModel {
    /// The micro-impact settings of this model (a solid uses them for its one strike).
    #[must_use]
    pub fn aggregate_params(&self) -> AggregateParams {
        AggregateParams {
            impact: self.hammer,
            size_spread: self.size_spread,
            impacts_in_flight: self.impacts_in_flight,
        }
    }

    /// Checks everything a file could get wrong.
    ///
    /// # Errors
    /// [`PhysicalError`] naming the first bad value.
    pub fn validate(&self) -> Result<(), PhysicalError> {
        if self.modes.is_empty() {
            return Err(PhysicalError::NoModes);
        }
        let invalid = |name, value: f64, expected| PhysicalError::InvalidParameter {
            name,
            value,
            expected,
        };
        if self.modes.len() > MAX_MODES {
            return Err(invalid(
                "modes",
                self.modes.len() as f64,
                "at most 32 modes",
            ));
        }
        // The rate is not known yet: only a finite frequency is required here; the bank
        // checks it against the Nyquist frequency when it is prepared.
        for (index, m) in self.modes.iter().enumerate() {
            m.check(index, Hz(f64::INFINITY))?;
            // Refused rather than clamped, as a filter pole beyond its model's limit is: the
            // file would not describe what plays (only the format-1 upgrade of IIR filters
            // clamps, because that reproduces what their voice played).
            if m.decay.0 > LONGEST_DECAY.0 {
                return Err(PhysicalError::DecayTooLong {
                    index,
                    decay: m.decay,
                    limit: LONGEST_DECAY,
                });
            }
        }
        let h = &self.hammer;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(h.mass) {
            return Err(invalid("hammer mass", h.mass, "positive (kg)"));
        }
        if !positive(h.stiffness) {
            return Err(invalid("hammer stiffness", h.stiffness, "positive"));
        }
        if !(h.alpha.is_finite() && h.alpha >= 1.0) {
            return Err(invalid("hammer alpha", h.alpha, "at least 1"));
        }
        if !(h.damping.is_finite() && h.damping >= 0.0) {
            return Err(invalid("hammer damping", h.damping, "non-negative"));
        }
        if !positive(h.velocity) {
            return Err(invalid("hammer velocity", h.velocity, "positive (m/s)"));
        }
        if !(self.size_spread.is_finite() && (0.0..=1.0).contains(&self.size_spread)) {
            return Err(invalid("size_spread", self.size_spread, "in [0, 1]"));
        }
        if self.impacts_in_flight == 0 || self.impacts_in_flight > MAX_IMPACTS_IN_FLIGHT {
            // Named as in the file.
            return Err(invalid("voices", self.impacts_in_flight as f64, "1 to 8"));
        }
        if !positive(self.output_gain) {
            return Err(invalid(
                "output_gain",
                self.output_gain,
                "positive and finite",
            ));
        }
        Ok(())
    }
}
