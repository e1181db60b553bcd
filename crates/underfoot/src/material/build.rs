//! Fitting a material model from recordings: the whole pipeline in one call.
//!
//! recordings -> [`measure`] -> minimum-phase
//! [`Target`] on a log grid of the band -> [`fit`]
//! with its order search -> [`MaterialModel`], whose `fit` record holds the measured and
//! model magnitudes on 96 log-spaced frequencies of the band and both metrics there, the
//! decay limit the search kept to, and the worst deviation found on a dense grid
//! ([`worst_deviation`](crate::fit::metrics::worst_deviation)).

use std::time::Instant;

use crate::analysis::{AnalysisConfig, AnalysisError, MeasuredResponse, measure};
use crate::fit::{FitConfig, FitError, MetricGrid, Metrics, Target, fit};
use crate::material::library::{NameError, validate_name};
use crate::material::quality::{self, QualityConfig, QualityError, RecordingsQuality};
use crate::material::{FilterCoefficients, FitRecord, MaterialModel, SourceFile};
use crate::physical::estimate::estimate_measured;
use crate::physical::{EstimateConfig, GroundKind};
use crate::recording::Recording;

pub use crate::fit::metrics::METRIC_POINTS;

/// Everything that shapes a material fit.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildConfig {
    /// From recordings to a measured response.
    pub analysis: AnalysisConfig,
    /// From the measured response to a filter.
    pub fit: FitConfig,
    /// The physical model's calibration from the same recordings (its `analysis` is
    /// replaced by the one above); `None` to skip it.
    pub physical: Option<EstimateConfig>,
    /// What the build refuses and warns about ([`super::quality`]).
    pub quality: QualityConfig,
}

impl Default for BuildConfig {
    fn default() -> Self {
        Self {
            analysis: AnalysisConfig::default(),
            fit: FitConfig::default(),
            physical: Some(EstimateConfig::default()),
            quality: QualityConfig::default(),
        }
    }
}

/// Progress of a build, for progress bars.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Progress {
    /// The measured response is ready.
    Measured {
        /// Heel strikes found across all recordings.
        strikes: usize,
    },
    /// One order of the search has been fitted.
    OrderTried {
        /// The order.
        order: usize,
        /// The largest order the search may try.
        max_order: usize,
        /// Its log-spectral distance in dB.
        lsd_db: f64,
        /// Its NRMSE.
        nrmse: f64,
    },
    /// The physical model is calibrated.
    Physical {
        /// Solid or aggregate.
        kind: GroundKind,
        /// Its log-spectral distance in dB.
        lsd_db: f64,
    },
    /// The recordings passed the quality gate: what it measured (strike-to-noise ratios,
    /// and whether the recordings disagree, which is a warning, not a refusal).
    Checked(RecordingsQuality),
    /// The physical model could not be calibrated; the material has only its filter.
    PhysicalFailed {
        /// Why.
        reason: String,
    },
}

/// What went wrong fitting a material.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BuildError {
    /// The material name breaks [`validate_name`].
    #[error("invalid material name {name:?}: {reason}")]
    InvalidName {
        /// The name given.
        name: String,
        /// What is wrong with it.
        reason: NameError,
    },
    /// The recordings could not be analysed.
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    /// The response could not be fitted.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// The recordings or the fit failed the quality gate ([`super::quality`]).
    #[error(transparent)]
    Quality(#[from] QualityError),
}

/// Fits a material model to recordings of heel strikes on it.
///
/// # Errors
/// [`BuildError`] when the name is invalid, the recordings hold no usable strike, or no
/// stable fit was found.
pub fn build_material(
    name: &str,
    recordings: &[Recording],
    cfg: &BuildConfig,
    progress: &mut dyn FnMut(&Progress),
) -> Result<MaterialModel, BuildError> {
    build_material_with_report(name, recordings, cfg, progress).map(|(m, _)| m)
}

/// What a build found besides the model: the measurement, and every order tried.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildReport {
    /// The measured response that was fitted.
    pub measured: MeasuredResponse,
    /// The plain Levi fit at the chosen order, for comparison.
    pub levi: Option<Metrics>,
    /// Every order tried: order, metrics, method.
    pub trials: Vec<(usize, Metrics, String)>,
}

/// As [`build_material`], also returning the [`BuildReport`].
///
/// # Errors
/// As [`build_material`].
pub fn build_material_with_report(
    name: &str,
    recordings: &[Recording],
    cfg: &BuildConfig,
    progress: &mut dyn FnMut(&Progress),
) -> Result<(MaterialModel, BuildReport), BuildError> {
    validate_name(name).map_err(|reason| BuildError::InvalidName {
        name: name.to_string(),
        reason,
    })?;
    let started = Instant::now();
    let a = &cfg.analysis;
    if cfg.quality.check_recordings {
        quality::check_rates(recordings, a)?;
        progress(&Progress::Checked(quality::check_recordings(
            recordings,
            a,
            &cfg.quality,
        )?));
    }
    let measured = measure(recordings, a)?;
    progress(&Progress::Measured {
        strikes: measured.strikes.len(),
    });

    let target = Target::minimum_phase(a.rate, a.band, &measured.magnitude, cfg.fit.grid_points)?;
    let freqs = a.band.log_grid(METRIC_POINTS);
    let grid = MetricGrid {
        rate: a.rate,
        measured: measured.on_grid(&freqs),
        freqs,
    };
    let max_order = match cfg.fit.order {
        crate::fit::OrderChoice::Auto { max } => max,
        crate::fit::OrderChoice::Fixed(n) => n,
    };
    // The physical calibration needs only the measurement: it runs beside the IIR fit.
    let calibration = cfg.physical.as_ref().map(|cal| EstimateConfig {
        analysis: a.clone(),
        ..cal.clone()
    });
    let (outcome, physical) = std::thread::scope(|scope| {
        let physical = calibration
            .as_ref()
            .map(|cal| scope.spawn(|| estimate_measured(recordings, &measured, cal)));
        let outcome = fit(&target, &grid, &cfg.fit, &mut |f| {
            progress(&Progress::OrderTried {
                order: f.order,
                max_order,
                lsd_db: f.metrics.lsd_db,
                nrmse: f.metrics.nrmse,
            });
        });
        let physical = physical.map(|h| {
            h.join()
                .map_err(|_| "the physical calibration did not finish".to_string())
                .and_then(|r| r.map_err(|e| e.to_string()))
        });
        (outcome, physical)
    });
    let outcome = outcome?;
    let best = outcome.best;
    let model = MaterialModel {
        name: name.to_string(),
        sample_rate: a.rate,
        band_hz: a.band,
        order: best.sos.order(),
        filter: FilterCoefficients::from_sos(&best.sos),
        fit: FitRecord {
            grid_hz: grid.freqs.iter().map(|f| f.0).collect(),
            model: grid.model_magnitude(&best.sos),
            measured: grid.measured.clone(),
            nrmse: best.metrics.nrmse,
            lsd_db: best.metrics.lsd_db,
            method: best.method.clone(),
            poor_fit: false,
            strikes: measured.strikes.len(),
            fit_seconds: started.elapsed().as_secs_f64(),
            longest_decay: cfg.fit.longest_decay,
            worst: Some(crate::fit::metrics::worst_deviation(
                &best.sos,
                a.rate,
                &measured.magnitude,
                measured.bin_hz,
                a.band,
            )),
        },
        sources: recordings
            .iter()
            .map(|r| SourceFile {
                file: r.name.clone(),
                sha256: r.sha256.clone(),
            })
            .collect(),
        physical: None,
    };
    let mut model = model;
    quality::check_fit(model.order, &mut model.fit, &cfg.quality)?;
    match physical {
        Some(Ok(p)) => {
            progress(&Progress::Physical {
                kind: p.kind,
                lsd_db: p.record.lsd_db,
            });
            model.physical = Some(p);
        }
        Some(Err(reason)) => progress(&Progress::PhysicalFailed { reason }),
        None => {}
    }
    Ok((
        model,
        BuildReport {
            measured,
            levi: best.levi,
            trials: outcome.trials,
        },
    ))
}
