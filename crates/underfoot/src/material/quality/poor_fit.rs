//! Refusal 4, after the fit: a poor fit.
//!
//! 4. **Poor fit** ([`QualityError::PoorFit`]): the winning model's metrics (see
//!    [`crate::fit::metrics`]) are above a bound. A fit is poor when
//!    `LSD > max_lsd` (2 dB by default: twice the 1 dB intensity JND, four times the
//!    order search's 0.5 dB target, and more than twice the worst built-in material), or
//!    when `NRMSE > max_nrmse` (0.5) *and* `LSD > nrmse_lsd_floor` (1 dB). The NRMSE
//!    divides by the spread of the measured magnitude about its mean, so a nearly flat
//!    response makes it large for errors no one can feel; it only counts when the level
//!    error is also above the JND. 0.5 means the model misses half of the measured shape;
//!    the built-in materials are at 0.04 to 0.19. The "NRMSE 1.84" is refused by
//!    both. With [`QualityConfig::accept_poor_fit`] the model is kept, with
//!    [`FitRecord::poor_fit`] set.

use super::{QualityConfig, QualityError};
use crate::material::FitRecord;

/// Whether a fit's metrics are poor by the bounds of `cfg`; see the [module docs](self).
#[must_use]
pub fn is_poor(lsd_db: f64, nrmse: f64, cfg: &QualityConfig) -> bool {
    // A NaN LSD is poor: a comparison with NaN is false, so test for "good" and negate. A
    // NaN NRMSE (a perfectly flat measurement) counts only through the LSD.
    let good_lsd = lsd_db <= cfg.max_lsd.0;
    let good_shape = nrmse <= cfg.max_nrmse || lsd_db <= cfg.nrmse_lsd_floor.0;
    !(good_lsd && good_shape)
}

/// Check 4 of the [module docs](self): refuses a poor fit, or marks it when
/// [`QualityConfig::accept_poor_fit`].
///
/// # Errors
/// [`QualityError::PoorFit`] when the fit is poor and not accepted.
pub fn check_fit(
    order: usize,
    fit: &mut FitRecord,
    cfg: &QualityConfig,
) -> Result<(), QualityError> {
    if !is_poor(fit.lsd_db, fit.nrmse, cfg) {
        return Ok(());
    }
    if cfg.accept_poor_fit {
        fit.poor_fit = true;
        return Ok(());
    }
    Err(QualityError::PoorFit {
        order,
        lsd_db: fit.lsd_db,
        nrmse: fit.nrmse,
        limits: (cfg.max_lsd, cfg.max_nrmse, cfg.nrmse_lsd_floor),
    })
}
