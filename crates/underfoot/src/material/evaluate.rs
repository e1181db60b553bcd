//! How closely a render reproduces a material: the render is analysed exactly as a
//! recording would be, and compared with the response measured from the material's own
//! recordings.
//!
//! This is evaluation, not playback: it lives with the material model it compares
//! against (and uses [`crate::analysis`] to measure), so the engine that renders knows
//! nothing of analysis, fitting or recordings.

use crate::analysis::steps::{StepConfig, StepSummary, describe_all, describe_struck, summarize};
use crate::analysis::{AnalysisConfig, AnalysisError, measure};
use crate::material::MaterialModel;
use crate::recording::Recording;
use crate::units::{Decibels, Hz, SampleRate, Seconds};

/// How closely a rendered stretch of one channel reproduces a material: the stretch goes
/// through the fitting pipeline's analysis (conditioning, strike detection, the RMS
/// strike spectrum, smoothing) exactly as a recording would, and the result is compared
/// with the response measured from the material's recordings, as the RMS log-spectral
/// distance in decibels over the model's fit grid. `gain` is the output gain the stretch
/// was rendered with; it and the material's playback level (`level_db`) are taken back
/// out, so the comparison is with the recorded level.
///
/// # Errors
/// The analysis fails (no strike found in the stretch, for one).
pub fn segment_lsd(
    samples: &[f32],
    rate: SampleRate,
    model: &MaterialModel,
    gain: Decibels,
) -> Result<f64, AnalysisError> {
    let recording = Recording {
        name: format!("{} (rendered)", model.name),
        rate,
        samples: samples.iter().map(|v| f64::from(*v)).collect(),
        sha256: String::new(),
        excerpt: None,
    };
    let config = AnalysisConfig {
        rate: model.sample_rate,
        band: model.band_hz,
        ..AnalysisConfig::default()
    };
    let measured = measure(&[recording], &config)?;
    let grid: Vec<Hz> = model.fit.grid_hz.iter().map(|f| Hz(*f)).collect();
    // Take the output gain and the playback level back out, then the same distance the fit
    // is scored with.
    let ungain = 1.0 / (gain.to_amplitude() * Decibels(model.level_db).to_amplitude());
    let got: Vec<f64> = measured.on_grid(&grid).iter().map(|m| m * ungain).collect();
    Ok(crate::fit::metrics::lsd_db(&model.fit.measured, &got))
}

/// A rendered stretch of one material measured in time, beside the material's recorded
/// steps ([`MaterialModel::time`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StepComparison {
    /// The rendered steps, measured as the recordings' were
    /// ([`crate::analysis::steps`]).
    pub rendered: StepSummary,
    /// The gain-aligned log-spectral distance between the rendered and the recorded steps'
    /// average band spectra (sixth-octave bands of the model's band), dB.
    pub spectrum_db: f64,
    /// The rendered average spectrum's mean level over the recorded one, dB, with the
    /// output gain and the playback level taken out: 0 when a step plays at its
    /// recorded loudness.
    pub level_db: f64,
}

/// The steps of a rendered stretch `samples` of `model` (struck at `onsets`, seconds into
/// it, each measured from where its sound starts after its strike; or found as a
/// recording's are), measured in time and compared with the recorded ones;
/// `None` for a material without recorded time statistics (a file before format 3).
/// `gain` is the output gain the stretch was rendered with.
///
/// # Errors
/// The step analysis refuses the rate or the band.
pub fn compare_steps(
    samples: &[f32],
    rate: SampleRate,
    onsets: Option<&[Seconds]>,
    model: &MaterialModel,
    gain: Decibels,
) -> Result<Option<StepComparison>, AnalysisError> {
    let Some(recorded) = &model.time else {
        return Ok(None);
    };
    let cfg = StepConfig {
        band: model.band_hz,
        ..StepConfig::default()
    };
    let x: Vec<f64> = samples.iter().map(|v| f64::from(*v)).collect();
    let steps = match onsets {
        Some(strikes) => describe_struck(&x, rate, strikes, &cfg)?,
        None => describe_all(&x, rate, None, &cfg)?,
    };
    let rendered = summarize(&steps, &cfg);
    if rendered.spectrum_db.len() != recorded.spectrum_db.len() || steps.is_empty() {
        return Ok(Some(StepComparison {
            rendered,
            spectrum_db: f64::NAN,
            level_db: f64::NAN,
        }));
    }
    let d: Vec<f64> = rendered
        .spectrum_db
        .iter()
        .zip(&recorded.spectrum_db)
        .map(|(a, b)| a - b)
        .collect();
    let mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
    let spectrum_db =
        (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len().max(1) as f64).sqrt();
    // Power spectra: 10 log10 of the power; the gain and the level are amplitude dB.
    let level_db = mean - gain.0 - model.level_db;
    Ok(Some(StepComparison {
        rendered,
        spectrum_db,
        level_db,
    }))
}
