//! Step 4 of the estimation: the control mapping `N(t) = α v_F(t)`.
//!
//! The recordings carry no force, so `α` is fixed by counting: a nominal step (the gait
//! model's, 70 kg at 1.8 steps/s) must produce `K` events on average,
//! `α = K / \int v_F dt`, where `\int v_F dt` is the force the step loads on (the sum of
//! its rises). With a force track recorded alongside, [`fit_rate_mapping`] fits `α` to the
//! event-rate profile by least squares, as the tile paper's Fig. 4 suggests (`N(t)`
//! follows `v_F(t)`).

use super::{EstimateConfig, EstimateError, RENDER_RATE};
use crate::force::gait::nominal_step;
use crate::physical::model::GroundKind;

/// `α`, the events per newton of loading, for `onsets_per_strike` impact onsets per
/// strike (at least one counts); zero for a solid, which strikes once per step.
pub(super) fn events_per_newton(
    kind: GroundKind,
    onsets_per_strike: f64,
    cfg: &EstimateConfig,
) -> f64 {
    let rise = loading_rise(cfg);
    match kind {
        GroundKind::Aggregate if rise > 0.0 => onsets_per_strike.max(1.0) / rise,
        _ => 0.0,
    }
}

/// The force a nominal step loads on: the sum of its rises, in newtons.
fn loading_rise(cfg: &EstimateConfig) -> f64 {
    let step = nominal_step(cfg.nominal_weight_kg, cfg.nominal_cadence, RENDER_RATE.hz());
    step.windows(2).map(|w| (w[1] - w[0]).max(0.0)).sum()
}

/// Fits the control mapping `N(t) ≈ α v_F(t)` by least squares through the origin, from an
/// event-rate profile and the loading rate sampled at the same instants (both per second).
/// Negative loading rates are taken as zero (the model only answers loading).
///
/// # Errors
/// [`EstimateError::InvalidSetting`] for profiles of different lengths, a non-finite
/// value, or a loading rate that is zero throughout.
pub fn fit_rate_mapping(event_rate: &[f64], loading_rate: &[f64]) -> Result<f64, EstimateError> {
    if event_rate.len() != loading_rate.len() {
        return Err(EstimateError::InvalidSetting(
            "event rate and loading rate must have the same length",
        ));
    }
    if event_rate
        .iter()
        .chain(loading_rate)
        .any(|v| !v.is_finite())
    {
        return Err(EstimateError::InvalidSetting(
            "event rate and loading rate must be finite",
        ));
    }
    let (mut num, mut den) = (0.0, 0.0);
    for (n, v) in event_rate.iter().zip(loading_rate) {
        let v = v.max(0.0);
        num += n * v;
        den += v * v;
    }
    if den <= 0.0 {
        return Err(EstimateError::InvalidSetting(
            "the loading rate is zero throughout",
        ));
    }
    Ok((num / den).max(0.0))
}
