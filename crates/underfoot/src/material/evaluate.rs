//! How closely a render reproduces a material: the render is analysed exactly as a
//! recording would be, and compared with the response measured from the material's own
//! recordings.
//!
//! This is evaluation, not playback: it lives with the material model it compares
//! against (and uses [`crate::analysis`] to measure), so the engine that renders knows
//! nothing of analysis, fitting or recordings.

use crate::analysis::{AnalysisConfig, AnalysisError, measure};
use crate::material::MaterialModel;
use crate::recording::Recording;
use crate::units::{Decibels, Hz, SampleRate};

/// How closely a rendered stretch of one channel reproduces a material: the stretch goes
/// through the fitting pipeline's analysis (conditioning, strike detection, the RMS
/// strike spectrum, smoothing) exactly as a recording would, and the result is compared
/// with the response measured from the material's recordings, as the RMS log-spectral
/// distance in decibels over the model's fit grid. `gain` is the output gain the stretch
/// was rendered with, taken back out so the comparison is with the recorded level.
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
    };
    let config = AnalysisConfig {
        rate: model.sample_rate,
        band: model.band_hz,
        ..AnalysisConfig::default()
    };
    let measured = measure(&[recording], &config)?;
    let grid: Vec<Hz> = model.fit.grid_hz.iter().map(|f| Hz(*f)).collect();
    // Take the output gain back out, then the same distance the fit is scored with.
    let ungain = 1.0 / gain.to_amplitude();
    let got: Vec<f64> = measured.on_grid(&grid).iter().map(|m| m * ungain).collect();
    Ok(crate::fit::metrics::lsd_db(&model.fit.measured, &got))
}
