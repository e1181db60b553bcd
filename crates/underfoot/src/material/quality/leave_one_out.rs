//! Generalisation: leave one recording out.
//!
//! [`leave_one_out`] fits the model on all recordings but one (the same configuration,
//! without the physical calibration and without the gate, which the whole set has passed)
//! and scores it against the measured response of the one left out, by the same
//! gain-aligned distance, on the model's metric grid. Each recording is left out in turn.
//! Beside it, the in-sample figure: the model fitted on all recordings, against the same
//! recording alone. Each entry keeps the model fitted on the others and the left-out
//! recording's steps measured in time, so that a caller with an engine can render the one
//! and compare it with the other. When the left-out distance is close to the in-sample one, the
//! recordings were enough; when it is much larger, the model has learnt the particular
//! steps rather than the ground, and more recordings are needed. With one recording there
//! is nothing to leave out, and the function says so by returning `None`. The refits need
//! nothing of the model fitted on all recordings ([`refit_each`]; [`Refits::score`] then
//! scores them), so `fit` runs them beside that model's fit.

use super::QualityConfig;
use super::disagreement::aligned_lsd_db;
use crate::analysis::steps::{StepConfig, StepSummary, describe_all, summarize};
use crate::analysis::{MeasuredResponse, measure};
use crate::material::MaterialModel;
use crate::material::build::{BuildConfig, BuildError, build_material};
use crate::recording::Recording;
use crate::units::{Decibels, Hz};

/// One recording left out.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOut {
    /// The recording left out.
    pub file: String,
    /// Its strikes.
    pub strikes: usize,
    /// Order of the model fitted on the others.
    pub order: usize,
    /// Gain-aligned LSD of the model fitted on the others against this recording.
    pub lsd: Decibels,
    /// Gain-aligned LSD of the model fitted on all recordings against this recording.
    pub in_sample_lsd: Decibels,
    /// The held-out recording's level relative to the left-out model's (the gain taken out).
    pub gain: Decibels,
    /// The model fitted on the others (filter, excitation, level), to render and compare
    /// with this recording in time.
    pub model: MaterialModel,
    /// This recording's steps measured in time ([`crate::analysis::steps`]); `None` when
    /// the step analysis finds none.
    pub recorded: Option<StepSummary>,
}

/// The leave-one-recording-out distances of a material; see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct LeaveOneOut {
    /// One entry per recording, in input order.
    pub held_out: Vec<HeldOut>,
}

impl LeaveOneOut {
    /// The mean left-out distance.
    #[must_use]
    pub fn mean_lsd(&self) -> Decibels {
        mean(self.held_out.iter().map(|h| h.lsd.0))
    }

    /// The mean in-sample distance, for comparison.
    #[must_use]
    pub fn mean_in_sample_lsd(&self) -> Decibels {
        mean(self.held_out.iter().map(|h| h.in_sample_lsd.0))
    }
}

fn mean(v: impl ExactSizeIterator<Item = f64>) -> Decibels {
    let n = v.len().max(1) as f64;
    Decibels(v.sum::<f64>() / n)
}

/// Fits on all recordings but one, for each in turn, and scores each model on the one left
/// out; `full` is the model fitted on all of them (for the in-sample figure). `None` with
/// fewer than two recordings. [`refit_each`] then [`Refits::score`]: the refits do not need
/// `full`, so a caller may run them while `full` is being fitted.
///
/// # Errors
/// [`BuildError`] when a fit on a subset, or the measurement of a recording alone, fails.
pub fn leave_one_out(
    recordings: &[Recording],
    cfg: &BuildConfig,
    full: &MaterialModel,
) -> Result<Option<LeaveOneOut>, BuildError> {
    Ok(refit_each(recordings, cfg, &full.name)?.map(|r| r.score(full)))
}

/// The models of [`leave_one_out`] fitted on all recordings but one, and what each left-out
/// recording gives alone, before the model fitted on all of them is known.
#[derive(Debug, Clone, PartialEq)]
pub struct Refits {
    /// Per recording left out: its measured response, and the entry without its scores.
    held_out: Vec<(MeasuredResponse, HeldOut)>,
}

/// The first half of [`leave_one_out`]: for each recording (a long recording's excerpts
/// together), the material `name` fitted on the others, the one left out measured and its
/// steps described. `None` with fewer than two recordings.
///
/// # Errors
/// As [`leave_one_out`].
pub fn refit_each(
    recordings: &[Recording],
    cfg: &BuildConfig,
    name: &str,
) -> Result<Option<Refits>, BuildError> {
    // A long recording's excerpts are held out together: they are one file.
    let files = crate::recording::by_file(recordings);
    if files.len() < 2 {
        return Ok(None);
    }
    let sub_cfg = BuildConfig {
        physical: None,
        quality: QualityConfig {
            check_recordings: false,
            accept_poor_fit: true,
            ..cfg.quality.clone()
        },
        ..cfg.clone()
    };
    let mut held_out = Vec::with_capacity(files.len());
    for file in &files {
        let left: &[Recording] = &recordings[file.clone()];
        let others: Vec<Recording> = recordings[..file.start]
            .iter()
            .chain(&recordings[file.end..])
            .cloned()
            .collect();
        let model = build_material(name, &others, &sub_cfg, &mut |_| {})?;
        let measured = measure(left, &cfg.analysis)?;
        let steps_cfg = StepConfig {
            band: cfg.analysis.band,
            ..StepConfig::default()
        };
        let mut steps = Vec::new();
        for rec in left {
            steps.extend(describe_all(&rec.samples, rec.rate, None, &steps_cfg)?);
        }
        let entry = HeldOut {
            file: left[0].name.clone(),
            strikes: measured.strikes.len(),
            order: model.order,
            lsd: Decibels(f64::NAN),
            in_sample_lsd: Decibels(f64::NAN),
            gain: Decibels(f64::NAN),
            recorded: (!steps.is_empty()).then(|| summarize(&steps, &steps_cfg)),
            model,
        };
        held_out.push((measured, entry));
    }
    Ok(Some(Refits { held_out }))
}

impl Refits {
    /// The second half of [`leave_one_out`]: each refit and `full` scored on the recording
    /// left out, on `full`'s metric grid.
    #[must_use]
    pub fn score(self, full: &MaterialModel) -> LeaveOneOut {
        let db = |v: &[f64]| -> Vec<f64> {
            v.iter()
                .map(|&m| Decibels::from_amplitude(m).0)
                .collect::<Vec<_>>()
        };
        let grid: Vec<Hz> = full.fit.grid_hz.iter().map(|&f| Hz(f)).collect();
        let full_db = db(&full.fit.model);
        let held_out = self
            .held_out
            .into_iter()
            .map(|(measured, entry)| {
                let measured_db = db(&measured.on_grid(&grid));
                let model_db = db(&entry.model.fit.model);
                let gain = measured_db
                    .iter()
                    .zip(&model_db)
                    .map(|(m, s)| m - s)
                    .sum::<f64>()
                    / measured_db.len().max(1) as f64;
                HeldOut {
                    lsd: Decibels(aligned_lsd_db(&model_db, &measured_db)),
                    in_sample_lsd: Decibels(aligned_lsd_db(&full_db, &measured_db)),
                    gain: Decibels(gain),
                    ..entry
                }
            })
            .collect();
        LeaveOneOut { held_out }
    }
}
