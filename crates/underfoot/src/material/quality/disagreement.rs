//! The warning: recordings that disagree.
//!
//! With two or more recordings, each is measured alone ([`measure`]) and its level
//! `L_i(f) = 20 log10 M_i(f)` taken on the metric grid of the band. Recording `i` is
//! compared with the mean level of the *others*, `\bar L_{-i}`, by the gain-aligned
//! log-spectral distance
//!
//! ```math
//! d_i = \sqrt{ \tfrac1K \sum_k (\Delta_k - \bar\Delta)^2 }, \quad
//!   \Delta_k = L_i(f_k) - \bar L_{-i}(f_k),
//! ```
//!
//! the RMS of the level difference once its mean (the recording's gain, which depends on
//! the step and the set-up, not the ground) is taken out. Against the others rather than
//! against a mean that includes it, so that one odd recording stands out instead of pulling
//! the mean towards itself. With two recordings `d_1 = d_2` and neither can be singled out.
//! The build warns ([`Disagreement::exceeds`]) when `max_i d_i > max_disagreement` (8 dB by
//! default). Measured, not derived: the shared recordings of one material, different steps
//! on one ground, differ by 2.5 to 7.3 dB (gravel 3.3-3.9, snow 2.5-3.9, sand 5.8, hard 6.0,
//! ice 7.3), so a lower default would warn on most honest recording sets. At 8 dB the
//! warning is for a recording of another ground, another set-up, or one that is mostly
//! something else; lower it to be stricter.

use crate::analysis::{AnalysisConfig, AnalysisError, measure};
use crate::recording::Recording;
use crate::units::{Decibels, Hz};

/// How one recording compares with the others of its material.
#[derive(Debug, Clone, PartialEq)]
pub struct Spread {
    /// The recording's name.
    pub file: String,
    /// Gain-aligned log-spectral distance to the mean level of the other recordings.
    pub lsd: Decibels,
}

/// The per-recording spread of a material's recordings; see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct Disagreement {
    /// One entry per recording, in input order.
    pub recordings: Vec<Spread>,
    /// The threshold it was judged against.
    pub threshold: Decibels,
}

impl Disagreement {
    /// The recording furthest from the others.
    #[must_use]
    pub fn worst(&self) -> Option<&Spread> {
        self.recordings
            .iter()
            .max_by(|a, b| a.lsd.0.total_cmp(&b.lsd.0))
    }

    /// Whether the worst recording is further than the threshold.
    #[must_use]
    pub fn exceeds(&self) -> bool {
        self.worst().is_some_and(|w| w.lsd.0 > self.threshold.0)
    }

    /// A one-line warning naming the odd recording, when [`Self::exceeds`].
    #[must_use]
    pub fn warning(&self) -> Option<String> {
        if !self.exceeds() {
            return None;
        }
        let worst = self.worst()?;
        Some(if self.recordings.len() == 2 {
            format!(
                "the two recordings {} and {} differ by {:.1} dB (gain-aligned LSD over the \
                 band, above {} dB): with two, neither can be singled out; check that both are \
                 of the same ground and set-up, or add a third",
                self.recordings[0].file, self.recordings[1].file, worst.lsd.0, self.threshold.0
            )
        } else {
            let others: Vec<String> = self
                .recordings
                .iter()
                .filter(|r| r.file != worst.file)
                .map(|r| format!("{} {:.1} dB", r.file, r.lsd.0))
                .collect();
            format!(
                "{} is the odd one out: its spectrum differs from the other recordings' by \
                 {:.1} dB (gain-aligned LSD over the band, above {} dB; the others: {}); check \
                 that it is of the same ground and set-up, or leave it out",
                worst.file,
                worst.lsd.0,
                self.threshold.0,
                others.join(", ")
            )
        })
    }
}

/// Each recording's measured level in dB on the metric grid of the band.
fn levels(
    recordings: &[Recording],
    analysis: &AnalysisConfig,
    grid: &[Hz],
) -> Result<Vec<Vec<f64>>, AnalysisError> {
    crate::recording::by_file(recordings)
        .into_iter()
        .map(|file| {
            let m = measure(&recordings[file], analysis)?;
            Ok(m.on_grid(grid)
                .iter()
                .map(|&v| Decibels::from_amplitude(v).0)
                .collect())
        })
        .collect()
}

/// The gain-aligned log-spectral distance between two level curves in dB (the one
/// definition, [`crate::fit::metrics::gain_aligned_level_distance_db`]).
pub use crate::fit::metrics::gain_aligned_level_distance_db as aligned_lsd_db;

/// How far each recording's spectrum is from the others'; see the [module docs](self).
///
/// # Errors
/// [`AnalysisError`] when a recording alone cannot be measured (for instance, no strike
/// in it).
pub fn disagreement(
    recordings: &[Recording],
    analysis: &AnalysisConfig,
    threshold: Decibels,
) -> Result<Disagreement, AnalysisError> {
    let grid = analysis.band.log_grid(crate::fit::metrics::METRIC_POINTS);
    let levels = levels(recordings, analysis, &grid)?;
    let n = levels.len();
    let files = crate::recording::by_file(recordings);
    let spread = files
        .iter()
        .enumerate()
        .map(|(i, file)| {
            let lsd = if n < 2 {
                0.0
            } else {
                let others: Vec<f64> = (0..grid.len())
                    .map(|k| {
                        (0..n)
                            .filter(|&j| j != i)
                            .map(|j| levels[j][k])
                            .sum::<f64>()
                            / (n - 1) as f64
                    })
                    .collect();
                aligned_lsd_db(&levels[i], &others)
            };
            Spread {
                file: recordings[file.start].name.clone(),
                lsd: Decibels(lsd),
            }
        })
        .collect();
    Ok(Disagreement {
        recordings: spread,
        threshold,
    })
}
