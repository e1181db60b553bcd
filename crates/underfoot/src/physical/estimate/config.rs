//! Every setting of the estimation, and their checks.

use super::EstimateError;
use super::crumpling::ImpactOnsetConfig;
use crate::analysis::AnalysisConfig;
use crate::physical::model::{GroundKind, MAX_IMPACTS_IN_FLIGHT, MAX_MODES};
use crate::signal::wavelet::Wavelet;
use crate::units::Seconds;

/// Whether to decide solid or aggregate from the recordings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KindChoice {
    /// From how fast a strike's energy arrives ([`super::onsets`]).
    #[default]
    Auto,
    /// Always this kind.
    Fixed(GroundKind),
}

/// Every setting of the estimation; the defaults are those [`super`] describes.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateConfig {
    /// How recordings become a measured response (the IIR fit's settings).
    pub analysis: AnalysisConfig,
    /// Solid or aggregate.
    pub kind: KindChoice,
    /// A strike that reaches half its energy sooner than this is a solid's.
    pub solid_half_energy: Seconds,
    /// The linear-prediction orders whose poles make the dictionary of candidate modes.
    pub lpc_orders: Vec<usize>,
    /// The most modes the model keeps (at most [`MAX_MODES`]).
    pub max_modes: usize,
    /// Longest decay time a mode keeps.
    pub max_decay: Seconds,
    /// The wavelet of the onset analysis.
    pub wavelet: Wavelet,
    /// The onset count.
    pub onsets: ImpactOnsetConfig,
    /// Width (standard deviation) of the Gaussian window of the crumpling measure.
    pub window: Seconds,
    /// Longest stretch of an isolated impact used for linear prediction.
    pub segment: Seconds,
    /// The hammer's undamped contact time.
    pub contact_time: Seconds,
    /// The strike speed (m/s).
    pub strike_speed: f64,
    /// Coefficient of restitution of the contact.
    pub restitution: f64,
    /// Mass of an aggregate's grain (kg).
    pub grain_mass: f64,
    /// Mass of the heel striking a solid (kg).
    pub heel_mass: f64,
    /// The surface's driving-point mass over the hammer's.
    pub mass_ratio: f64,
    /// Spread of fragment sizes (aggregates).
    pub size_spread: f64,
    /// Micro-impacts ringing at once (aggregates), at most
    /// [`MAX_IMPACTS_IN_FLIGHT`].
    pub impacts_in_flight: usize,
    /// Nominal walker's mass (kg) and cadence (steps/s) for the control mapping.
    pub nominal_weight_kg: f64,
    /// Steps per second of the nominal walker.
    pub nominal_cadence: f64,
    /// Rounds of refitting against the measurement corrected by the render's error.
    pub refine_rounds: usize,
    /// Steps rendered to set the level and score the model.
    pub steps: usize,
    /// The render's seed.
    pub seed: u64,
}

impl Default for EstimateConfig {
    fn default() -> Self {
        Self {
            analysis: AnalysisConfig::default(),
            kind: KindChoice::Auto,
            solid_half_energy: Seconds(0.030),
            lpc_orders: vec![8, 12, 16, 24, 32, 48],
            max_modes: MAX_MODES,
            max_decay: Seconds(0.5),
            wavelet: Wavelet::Db4,
            onsets: ImpactOnsetConfig::default(),
            window: Seconds(0.005),
            segment: Seconds(0.1),
            contact_time: Seconds(0.00025),
            strike_speed: 0.5,
            restitution: 0.7,
            grain_mass: 0.005,
            heel_mass: 0.5,
            mass_ratio: 10.0,
            size_spread: 0.1,
            impacts_in_flight: 4,
            nominal_weight_kg: 70.0,
            nominal_cadence: 1.8,
            steps: 16,
            refine_rounds: 2,
            seed: 0x5EED,
        }
    }
}

/// Refuses a setting out of range.
pub(super) fn check(cfg: &EstimateConfig) -> Result<(), EstimateError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if cfg.lpc_orders.is_empty()
        || cfg
            .lpc_orders
            .iter()
            .any(|&p| !(2..=crate::fit::lpc::MAX_PREDICTOR_ORDER).contains(&p))
    {
        return Err(EstimateError::InvalidSetting(
            "lpc_orders must be a non-empty list of orders from 2 to 128",
        ));
    }
    if cfg.max_modes == 0 || cfg.max_modes > MAX_MODES {
        return Err(EstimateError::InvalidSetting("max_modes must be 1 to 32"));
    }
    if ![
        cfg.solid_half_energy.0,
        cfg.max_decay.0,
        cfg.window.0,
        cfg.segment.0,
        cfg.contact_time.0,
        cfg.strike_speed,
        cfg.grain_mass,
        cfg.heel_mass,
        cfg.mass_ratio,
        cfg.nominal_weight_kg,
        cfg.nominal_cadence,
    ]
    .into_iter()
    .all(positive)
    {
        return Err(EstimateError::InvalidSetting(
            "times, masses, speeds and ratios must be positive and finite",
        ));
    }
    if !(0.0..1.0).contains(&cfg.restitution) {
        return Err(EstimateError::InvalidSetting(
            "restitution must be in [0, 1)",
        ));
    }
    if !(0.0..=1.0).contains(&cfg.size_spread) {
        return Err(EstimateError::InvalidSetting(
            "size_spread must be in [0, 1]",
        ));
    }
    if cfg.impacts_in_flight == 0 || cfg.impacts_in_flight > MAX_IMPACTS_IN_FLIGHT {
        return Err(EstimateError::InvalidSetting(
            "impacts_in_flight must be 1 to 8",
        ));
    }
    if cfg.steps == 0 || cfg.steps > 64 {
        return Err(EstimateError::InvalidSetting("steps must be 1 to 64"));
    }
    Ok(())
}
