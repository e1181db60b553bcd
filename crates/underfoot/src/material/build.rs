//! TODO(lead): fitting a material model from recordings.

use crate::analysis::{AnalysisConfig, AnalysisError};
use crate::fit::{FitConfig, FitError};
use crate::material::MaterialModel;
use crate::recording::Recording;

/// Everything that shapes a material fit.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BuildConfig {
    /// From recordings to a measured response.
    pub analysis: AnalysisConfig,
    /// From the measured response to a filter.
    pub fit: FitConfig,
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
}

/// What went wrong fitting a material.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BuildError {
    /// The material name is empty or not printable.
    #[error("invalid material name {0:?}: use letters, digits, '-', '_' or '.'")]
    InvalidName(String),
    /// The recordings could not be analysed.
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    /// The response could not be fitted.
    #[error(transparent)]
    Fit(#[from] FitError),
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
    let _ = (recordings, cfg, progress);
    Err(BuildError::InvalidName(name.to_string()))
}
