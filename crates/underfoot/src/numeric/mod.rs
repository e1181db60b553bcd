//! The crate's numerics: the general tools the stages above share, none of them about
//! footsteps.
//!
//! | file | what |
//! |---|---|
//! | [`bilinear`] | the bilinear transform of a second-order analogue section, prewarped |
//! | [`dtft`] | the DTFT of a finite sequence at one frequency |
//! | [`stats`] | median and nearest-rank percentile |
//!
//! Layer: below [`signal`](crate::signal) and everything else but [`units`](crate::units)
//! and [`math`](crate::math); it knows no filter, recording or material type.

pub mod bilinear;
pub mod dtft;
pub mod stats;

pub use bilinear::{bilinear, prewarp_constant};
pub use dtft::dtft;
pub use stats::{median, percentile};
