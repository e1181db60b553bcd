//! Estimating the physical model's parameters from recordings, with no hand tuning.
//!
//! The IIR paper's physical model was tuned by ear, "an iterative process for each type of
//! ground" (section V-B); the tile paper sketches how to identify it from data instead
//! (section 2.2). This module does the whole identification from the same recordings the
//! IIR fit uses ([`estimate()`]):
//!
//! 1. **The measurement.** The strikes are conditioned and averaged exactly as for the IIR
//!    fit ([`crate::analysis::measure`]): the target is the same measured response `M(f)`.
//! 2. **Solid or aggregate** ([`KindChoice::Auto`], [`onsets`]). A solid answers a step
//!    with one impact, whose energy arrives at once; an aggregate with a stream of
//!    micro-impacts spread over the loading: below a median of `solid_half_energy`
//!    (30 ms) from 5% to 50% of a strike's energy, the ground is a solid.
//! 3. **Impact onsets and the event rate** ([`onsets`], [`crumpling`]). The Daubechies
//!    detail band whose top is nearest 12 kHz isolates impact onsets; they are counted in each strike
//!    window (`K` per strike), and the scale `a` of the event rate `N(t) = e^{a I(t)} - 1`
//!    of the crumpling measure `I(t)` is fitted so that the expected number of events
//!    equals the count (recorded as `rate_scale`): the tile paper's analysis, kept in the
//!    record. What strikes the model is not this rate but the material's excitation
//!    ([`crate::excitation`]), the same heel impulse and train of micro-impulses the IIR
//!    voice plays, fitted from the same recordings: its rate follows the force too
//!    (`N(t) = α(τ) |v_F(t)|`), with a gain that depends on the step's progress.
//! 4. **The excitation**, given: the renders of step 8 play nominal steps of it.
//! 5. **Modes by linear prediction** ([`modes`]). The poles of the predictors of several
//!    orders, from the isolated impacts (or the strike windows), make a dictionary of
//!    candidate modes.
//! 6. **The hammer** ([`hammer`]). A Hunt-Crossley contact of the contact time asked for;
//!    a grain (5 g) for an aggregate, a heel (0.5 kg) for a solid.
//! 7. **Modal gains** ([`gains`]). Signed gains of the dictionary's modes, by ridge
//!    least squares with the hammer's pulse, against the measured magnitude relative to
//!    itself; at most `max_modes` (32) modes are kept.
//! 8. **Physical scale, level, and the render's own error.** The gains are scaled so that
//!    the surface's driving-point mass, `1 / \sum_k 2π f_k |g_k|`, is `mass_ratio` (10)
//!    times the hammer's: the ground is much heavier than what strikes it, so the contact
//!    stays close to the rigid one the gains were fitted with. Then `steps` (16) nominal
//!    steps are rendered ([`render`]), analysed exactly as the recordings were, and the
//!    output gain is set so that the mean level in dB over the band equals the
//!    measurement's. What the render still misses, `M(f) / R(f)`, multiplies the goal of
//!    the gain fit, and steps 7 and 8 run again (`refine_rounds`, 2 by default: on the
//!    shared recordings the third round comes out best for hard, sand, snow and water,
//!    the second for the others, the first never; each costs a render); the round closest to the measurement is kept, and its render at that gain
//!    gives the recorded NRMSE and log-spectral distance ([`score_render`] computes the
//!    same figure again).
//!
//! **Cost.** The renders are most of it (a nominal step is a second at 48 kHz through
//! 32 modes and four impacts in flight; each render's two halves run on two threads); the
//! measurement is the IIR fit's, passed in by [`estimate_measured`], and
//! [`crate::material::build`] runs the estimation after the IIR fit and the excitation's,
//! whose model strikes it. `underfoot-bench`'s `benches/calibration.rs` and
//! `scripts/time-fit` measure it.
//!
//! On the shared recordings the estimated models come within 0.8-2.1 dB (log-spectral
//! distance) of the measurement in the render they were fitted on, and 0.8-2.4 dB in a
//! render with another seed (`tests/physical.rs`).
//!
//! # Files
//!
//! | module | what |
//! |---|---|
//! | `mod.rs` | the steps in order: [`estimate()`], [`estimate_measured`], [`EstimateError`] |
//! | [`config`] | every setting ([`EstimateConfig`]) and its range |
//! | [`onsets`] | steps 2 and 3: impact onsets per strike, the energy's arrival, solid or aggregate |
//! | [`crumpling`] | the tile paper's crumpling measure, impact onsets and event rate |
//! | [`modes`] | step 5: the dictionary of candidate modes by linear prediction |
//! | [`hammer`] | step 6: the hammer ([`hammer_for`]) and the spectrum of its pulse |
//! | [`gains`] | step 7: the modal gains |
//! | [`render`] | step 8's renders: nominal steps through a model, analysed and scored ([`score_render`]) |

pub mod config;
pub mod crumpling;
pub mod gains;
pub mod hammer;
pub mod modes;
pub mod onsets;
pub mod render;

pub use config::{EstimateConfig, KindChoice};
pub use hammer::hammer_for;
pub use render::{RENDER_RATE, analyse_render, held_out_seed, render_steps, score_render};

use crumpling::CrumplingError;
use gains::GainFit;
use hammer::contact_spectrum;
use render::render_measure;

use super::PhysicalError;
use super::model::{GroundKind, PhysicalModel, PhysicalRecord};
use crate::analysis::{AnalysisError, MeasuredResponse, measure};
use crate::excitation::ExcitationModel;
use crate::fit::lpc::LpcError;
use crate::fit::metrics::{METRIC_POINTS, level_offset_db, lsd_db, nrmse};
use crate::fit::target::Target;
use crate::recording::Recording;

/// What went wrong in an estimation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EstimateError {
    /// The recordings could not be analysed.
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    /// The onset or event-rate analysis failed.
    #[error("event-rate analysis of {name}: {source}")]
    Crumpling {
        /// The recording.
        name: String,
        /// What failed.
        source: CrumplingError,
    },
    /// Linear prediction failed.
    #[error("linear prediction: {0}")]
    Lpc(#[from] LpcError),
    /// No pole of the predictor is a mode in the band.
    #[error("linear prediction of order {order} found no mode in the band {lo}-{hi} Hz")]
    NoModes {
        /// The order.
        order: usize,
        /// The band's lower edge (Hz).
        lo: f64,
        /// Its upper edge (Hz).
        hi: f64,
    },
    /// The gains could not be fitted.
    #[error("the modal gains could not be fitted: {0}")]
    Gains(&'static str),
    /// A setting is out of range.
    #[error("invalid estimation setting: {0}")]
    InvalidSetting(&'static str),
    /// The model could not be built.
    #[error(transparent)]
    Physical(#[from] PhysicalError),
    /// The excitation the model is rendered with is invalid.
    #[error(transparent)]
    Excitation(#[from] crate::excitation::ExcitationError),
}

/// Estimates a physical model from recordings of footsteps on one material, struck by
/// `excitation` (the material's, [`crate::excitation::estimate()`]).
///
/// # Errors
/// [`EstimateError`] when the recordings hold no usable strike, no mode is found, or a
/// setting is out of range.
pub fn estimate(
    recordings: &[Recording],
    excitation: &ExcitationModel,
    cfg: &EstimateConfig,
) -> Result<PhysicalModel, EstimateError> {
    config::check(cfg)?;
    let measured = measure(recordings, &cfg.analysis)?;
    estimate_measured(recordings, &measured, excitation, cfg)
}

/// As [`estimate()`], from the measured response of `recordings` already computed with
/// `cfg.analysis` (the IIR fit's, in [`crate::material::build`]), so the recordings are
/// not measured twice.
///
/// # Errors
/// As [`estimate()`]; [`EstimateError::InvalidSetting`] when `measured` was taken at
/// another rate or band than `cfg.analysis`, or holds strikes of recordings not given.
pub fn estimate_measured(
    recordings: &[Recording],
    measured: &MeasuredResponse,
    excitation: &ExcitationModel,
    cfg: &EstimateConfig,
) -> Result<PhysicalModel, EstimateError> {
    excitation.validate()?;
    config::check(cfg)?;
    let a = &cfg.analysis;
    if measured.rate != a.rate || measured.band != a.band {
        return Err(EstimateError::InvalidSetting(
            "the measured response was taken at another rate or band than the estimation's",
        ));
    }
    if measured
        .strikes
        .iter()
        .any(|s| s.recording >= recordings.len())
    {
        return Err(EstimateError::InvalidSetting(
            "the measured response holds strikes of recordings not given",
        ));
    }
    let fit_freqs = a.band.log_grid(2 * METRIC_POINTS);
    let metric_freqs = a.band.log_grid(METRIC_POINTS);
    let target = measured.on_grid(&metric_freqs);

    // Per strike: its energy's arrival and its impact onsets, at the recording's rate.
    let events = onsets::analyse(recordings, measured, cfg)?;
    let kind = onsets::ground_kind(cfg.kind, events.half_energy_ms, cfg.solid_half_energy);

    // Poles from the isolated impacts, or the strikes.
    let (segments, isolated_impacts) =
        modes::segments(recordings, kind, &events.onsets_by_recording, measured, cfg)?;
    let poles = modes::lpc_dictionary(&segments, a.rate, &cfg.lpc_orders, a, cfg.max_decay)?;

    // The hammer, and the spectrum of its force on a rigid surface.
    let mass = match kind {
        GroundKind::Solid => cfg.heel_mass,
        GroundKind::Aggregate => cfg.grain_mass,
    };
    let hammer = hammer_for(
        mass,
        cfg.contact_time,
        cfg.strike_speed,
        cfg.restitution,
        1.5,
    );
    let pulse = contact_spectrum(hammer, RENDER_RATE, &fit_freqs)?;

    // Gains against the measured magnitude, then the physical scale and the level; then
    // again against the measurement corrected by what the render missed.
    let fit_target = measured.on_grid(&fit_freqs);
    let phase0 = Target::minimum_phase(a.rate, a.band, &measured.magnitude, fit_freqs.len())
        .map_err(|_| EstimateError::Gains("no minimum-phase target for the measurement"))?;
    let initial: Vec<f64> = phase0.h.iter().map(|h| h.arg()).collect();
    let record = PhysicalRecord {
        onsets_per_strike: events.onsets_per_strike,
        half_energy_ms: events.half_energy_ms,
        rate_scale: events.rate_scale,
        isolated_impacts,
        model: Vec::new(),
        nrmse: f64::NAN,
        lsd_db: f64::NAN,
        peak: 0.0,
    };
    let fit = GainFit {
        dictionary: &poles,
        freqs: &fit_freqs,
        pulse: &pulse,
        initial_phase: &initial,
        max_modes: cfg.max_modes,
    };
    let mut goal = fit_target.clone();
    let mut best: Option<PhysicalModel> = None;
    for _ in 0..=cfg.refine_rounds {
        let mut modes = fit.modes(&goal)?;
        let mobility: f64 = modes
            .iter()
            .map(|m| std::f64::consts::TAU * m.frequency.0 * m.gain.abs())
            .sum();
        let scale = 1.0 / (cfg.mass_ratio * mass * mobility);
        for m in &mut modes {
            m.gain *= scale;
        }
        let mut model = PhysicalModel {
            kind,
            modes,
            hammer,
            size_spread: if kind == GroundKind::Aggregate {
                cfg.size_spread
            } else {
                0.0
            },
            impacts_in_flight: cfg.impacts_in_flight,
            output_gain: 1.0 / scale,
            record: record.clone(),
        };
        model.validate()?;
        // Level: render, analyse as a recording, match the mean level in dB.
        let (got, peak) = render_measure(&model, excitation, cfg, cfg.seed)?;
        let scored = got.on_grid(&metric_freqs);
        let correction = 10f64.powf(-level_offset_db(&target, &scored) / 20.0);
        model.output_gain *= correction;
        model.record.peak = peak * correction;
        let scored: Vec<f64> = scored.iter().map(|g| g * correction).collect();
        model.record.nrmse = nrmse(&target, &scored);
        model.record.lsd_db = lsd_db(&target, &scored);
        model.record.model = scored;
        for ((g, t), r) in goal
            .iter_mut()
            .zip(&fit_target)
            .zip(got.on_grid(&fit_freqs))
        {
            *g *= t / (r * correction);
        }
        if best
            .as_ref()
            .is_none_or(|b| model.record.lsd_db < b.record.lsd_db)
        {
            best = Some(model);
        }
    }
    best.ok_or(EstimateError::Gains("no round of the estimation finished"))
}
