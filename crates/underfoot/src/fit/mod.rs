//! TODO(lead): IIR fitting.

use crate::units::Decibels;

/// How the filter order is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OrderChoice {
    /// The lowest order (up to `max`) whose fit reaches the targets.
    Auto {
        /// Upper bound of the search.
        max: usize,
    },
    /// Exactly this order.
    Fixed(usize),
}

/// Parameters of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitConfig {
    /// Order choice (default: automatic up to 16).
    pub order: OrderChoice,
    /// Automatic order search stops at the first order whose log-spectral distance is at most this.
    pub target_lsd: Decibels,
    /// ... and whose NRMSE is at most this.
    pub target_nrmse: f64,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self { order: OrderChoice::Auto { max: 16 }, target_lsd: Decibels(0.5), target_nrmse: 0.1 }
    }
}

/// What went wrong in a fit.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FitError {
    /// Placeholder.
    #[error("todo")]
    Todo,
}
