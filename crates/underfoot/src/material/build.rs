//! Fitting a material model from recordings: the whole pipeline in one call.
//!
//! recordings -> [`measure`] -> minimum-phase
//! [`Target`] on a log grid of the band -> [`fit`]
//! with its order search -> [`MaterialModel`], whose `fit` record holds the measured and
//! model magnitudes on 96 log-spaced frequencies of the band and both metrics there, the
//! decay limit the search kept to, and the worst deviation found on a dense grid
//! ([`worst_deviation`](crate::fit::metrics::worst_deviation)).
//!
//! Then, for the filter found: the excitation ([`crate::excitation::estimate()`]: the
//! heel, the train, the recordings' steps measured in time), and the physical model
//! struck by it. Last, the playback level
//! ([`super::level`]) from the nominal step's peak through the filter (or the physical
//! model, if louder).

use std::time::Instant;

use crate::analysis::{AnalysisConfig, AnalysisError, MeasuredResponse, measure};
use crate::excitation::{EstimateConfig as ExcitationConfig, ExcitationModel};
use crate::fit::{FitConfig, FitError, MetricGrid, Metrics, Target, fit};
use crate::material::level::{level_for, nominal_peak};
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
    /// The excitation's estimation from the same recordings (its `analysis` is replaced by
    /// the one above); `None` for one impulse per step.
    pub excitation: Option<ExcitationConfig>,
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
            excitation: Some(ExcitationConfig::default()),
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
    /// The excitation is fitted: the recordings' steps in time, and a render of it.
    Excitation {
        /// The heel impact's share of a step's energy.
        heel: f64,
        /// The recordings' median duration (ms) and micro-event count.
        recorded: (f64, f64),
        /// The calibration render's.
        rendered: (f64, f64),
    },
    /// The excitation could not be fitted; the material plays one impulse per step.
    ExcitationFailed {
        /// Why.
        reason: String,
    },
    /// The playback level was set.
    Level {
        /// The level, dB re the recording.
        level_db: f64,
        /// Whether the material had to be turned down below the common reference to keep
        /// its nominal step 3 dB under the default ceiling.
        turned_down: bool,
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
    /// The excitation's estimation: the recordings' steps in time and the calibration
    /// render's (`None` when it was not run or failed).
    pub excitation: Option<crate::excitation::estimate::Estimate>,
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
    let outcome = fit(&target, &grid, &cfg.fit, &mut |f| {
        progress(&Progress::OrderTried {
            order: f.order,
            max_order,
            lsd_db: f.metrics.lsd_db,
            nrmse: f.metrics.nrmse,
        });
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
        // A long recording's excerpts are one source.
        sources: crate::recording::by_file(recordings)
            .into_iter()
            .map(|file| &recordings[file.start])
            .map(|r| SourceFile {
                file: r.name.clone(),
                sha256: r.sha256.clone(),
            })
            .collect(),
        physical: None,
        excitation: None,
        time: None,
        level_db: 0.0,
    };
    let mut model = model;
    quality::check_fit(model.order, &mut model.fit, &cfg.quality)?;
    // The excitation is fitted for the filter it will be played through; the physical
    // model is struck by it.
    let excitation = cfg.excitation.as_ref().map(|e| {
        let e = ExcitationConfig {
            analysis: a.clone(),
            ..e.clone()
        };
        crate::excitation::estimate(recordings, &measured, &best.sos, &e)
    });
    let played = match &excitation {
        Some(Ok(e)) => e.model.clone(),
        _ => ExcitationModel::heel_only(),
    };
    let physical = cfg.physical.as_ref().map(|cal| {
        let cal = EstimateConfig {
            analysis: a.clone(),
            ..cal.clone()
        };
        estimate_measured(recordings, &measured, &played, &cal).map_err(|e| e.to_string())
    });
    let estimate = match excitation {
        Some(Ok(e)) => {
            progress(&Progress::Excitation {
                heel: e.model.heel,
                recorded: (e.recorded.duration_ms, e.recorded.events),
                rendered: (e.rendered.duration_ms, e.rendered.events),
            });
            model.excitation = Some(e.model.clone());
            model.time = Some(e.recorded.clone());
            Some(e)
        }
        Some(Err(reason)) => {
            progress(&Progress::ExcitationFailed {
                reason: reason.to_string(),
            });
            None
        }
        None => None,
    };
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
    // The level: the nominal step's peak through the filter, or the physical model's if
    // louder (both at the recorded level).
    let iir_peak = nominal_peak(&best.sos, a.rate, &model.excitation_or_heel()).unwrap_or(0.0);
    let physical_peak = model.physical.as_ref().map_or(0.0, |p| p.record.peak);
    let peak = iir_peak.max(physical_peak);
    let level = level_for(peak);
    model.level_db = level.0;
    progress(&Progress::Level {
        level_db: level.0,
        turned_down: level.0 < super::level::REFERENCE.0,
    });
    Ok((
        model,
        BuildReport {
            measured,
            levi: best.levi,
            trials: outcome.trials,
            excitation: estimate,
        },
    ))
}
