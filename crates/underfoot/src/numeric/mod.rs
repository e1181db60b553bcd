//! The crate's numerics: the general tools the stages above share, none of them about
//! footsteps.
//!
//! | module | what |
//! |---|---|
//! | [`trf`] | bounded non-linear least squares (trust-region-reflective) |
//! | [`lstsq`] | the guarded SVD and linear least squares with scaled columns |
//! | [`roots`](mod@roots) | polynomial roots from the companion matrix |
//! | [`bilinear`](mod@bilinear) | the bilinear transform of a second-order analogue section, prewarped |
//! | [`dtft`](mod@dtft) | the DTFT of a finite sequence at one frequency |
//! | [`stats`] | median and nearest-rank percentile |
//!
//! Layer: below [`signal`](crate::signal) and everything else but [`units`](crate::units)
//! and [`math`](crate::math); it knows no filter, recording or material type.

pub mod bilinear;
pub mod dtft;
pub mod lstsq;
pub mod roots;
pub mod stats;
pub mod trf;
pub mod window;

pub use bilinear::{bilinear, prewarp_constant};
pub use dtft::dtft;
pub use lstsq::{NumericalError, solve_scaled, svd};
pub use roots::roots;
pub use stats::{median, normal_quantile, percentile};
