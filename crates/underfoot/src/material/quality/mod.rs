//! The quality gate of a fit: what `fit` refuses, what it warns about, and how well a
//! model generalises to a recording it was not fitted on.
//!
//! A model is only as good as its recordings, and a fit always returns *some* filter. The
//! gate stops the cases where that filter means nothing, before anything is written.
//!
//! # Refusals
//!
//! In this order, each naming the recordings at fault and what to do:
//!
//! 1. **Rate too low** ([`QualityError::RateTooLow`], [`mod@rates`]).
//! 2. **Band above a Nyquist frequency** ([`QualityError::BandAboveNyquist`],
//!    [`QualityError::BandAboveAnalysisNyquist`], [`mod@rates`]).
//! 3. **No strike above the noise** ([`QualityError::NoClearStrike`], [`mod@strikes`]):
//!    the strike-to-noise ratio of each recording.
//!
//! After the fit:
//!
//! 4. **Poor fit** ([`QualityError::PoorFit`], [`mod@poor_fit`]).
//!
//! Beside them, a warning when one recording differs from the others
//! ([`mod@disagreement`]), and a measure of how well the model generalises to a recording
//! it was not fitted on ([`mod@leave_one_out`]).
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the thresholds ([`QualityConfig`]) and the refusals ([`QualityError`]) |
//! | [`rates`](mod@rates) | refusals 1 and 2: rates and band against every Nyquist frequency |
//! | [`strikes`](mod@strikes) | refusal 3: the strike-to-noise ratio, and the recording checks |
//! | [`poor_fit`](mod@poor_fit) | refusal 4: a fit too far from the measurement |
//! | [`disagreement`](mod@disagreement) | the warning: a recording that differs from the others |
//! | [`leave_one_out`](mod@leave_one_out) | generalisation: each recording scored by a model fitted without it |

pub mod disagreement;
pub mod leave_one_out;
pub mod poor_fit;
pub mod rates;
pub mod strikes;

pub use disagreement::{Disagreement, Spread, aligned_lsd_db, disagreement};
pub use leave_one_out::{HeldOut, LeaveOneOut, Refits, leave_one_out, refit_each};
pub use poor_fit::{check_fit, is_poor};
pub use rates::{RateIssue, check_rates, min_rate};
pub use strikes::{RecordingsQuality, StrikeToNoise, check_recordings, strike_to_noise};

use crate::analysis::AnalysisError;
use crate::units::{Band, Decibels, SampleRate, Seconds};

/// No recording below this rate can be analysed, whatever the band (the analysis rate's
/// own floor).
pub const MIN_RATE_HZ: f64 = 100.0;

/// The thresholds of the gate; see the [module docs](self) for why each default.
#[derive(Debug, Clone, PartialEq)]
pub struct QualityConfig {
    /// Run the recording checks (rates, band, strike-to-noise, disagreement) at all.
    pub check_recordings: bool,
    /// A recording's loudest strike must stand this far above its noise floor (15 dB).
    pub min_strike_to_noise: Decibels,
    /// The RMS window of the strike-to-noise envelope (5 ms).
    pub snr_window: Seconds,
    /// The percentile (0 to 1) of the envelope read as the noise floor (0.01).
    pub noise_percentile: f64,
    /// A fit whose log-spectral distance is above this is poor (2 dB).
    pub max_lsd: Decibels,
    /// A fit whose NRMSE is above this is poor (0.5) ...
    pub max_nrmse: f64,
    /// ... when its log-spectral distance is also above this (1 dB).
    pub nrmse_lsd_floor: Decibels,
    /// Keep a poor fit, marked, instead of refusing it.
    pub accept_poor_fit: bool,
    /// Warn when a recording's gain-aligned distance to the others is above this (8 dB).
    pub max_disagreement: Decibels,
}

impl Default for QualityConfig {
    fn default() -> Self {
        Self {
            check_recordings: true,
            min_strike_to_noise: Decibels(15.0),
            snr_window: Seconds(0.005),
            noise_percentile: 0.01,
            max_lsd: Decibels(2.0),
            max_nrmse: 0.5,
            nrmse_lsd_floor: Decibels(1.0),
            accept_poor_fit: false,
            max_disagreement: Decibels(8.0),
        }
    }
}

/// Why the gate refused a fit.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum QualityError {
    /// Recordings at a rate too low to hold any of the band.
    #[error(
        "{}: too low a sample rate to analyse; recordings for the band {band} need at least {min} \
         (an octave above the band's lower edge below their Nyquist frequency): record at a \
         higher rate, or check the rate in the file or the CSV options",
        list_rates(files)
    )]
    RateTooLow {
        /// The recordings, with their rates.
        files: Vec<RateIssue>,
        /// The band asked for.
        band: Band,
        /// The lowest rate accepted.
        min: SampleRate,
    },
    /// The band reaches above the Nyquist frequency of some recordings.
    #[error(
        "the band {band} reaches above the Nyquist frequency of {}: they hold nothing above \
         half their rate, so the fit would be of the resampler, not the ground; use a band \
         such as {suggested}, or recordings at {needed} or more",
        list_rates(files)
    )]
    BandAboveNyquist {
        /// The band asked for.
        band: Band,
        /// The recordings whose Nyquist frequency is at or below the band's top.
        files: Vec<RateIssue>,
        /// A band that fits every recording.
        suggested: Band,
        /// The lowest rate that holds the whole band.
        needed: SampleRate,
    },
    /// The band reaches above the analysis rate's Nyquist frequency.
    #[error(
        "the band {band} reaches above the Nyquist frequency {} of the analysis rate {rate}: \
         use a band such as {suggested}, or an analysis rate of {needed} or more",
        rate.nyquist()
    )]
    BandAboveAnalysisNyquist {
        /// The band asked for.
        band: Band,
        /// The analysis rate.
        rate: SampleRate,
        /// A band that fits.
        suggested: Band,
        /// The lowest analysis rate that holds the band.
        needed: SampleRate,
    },
    /// Recordings in which no strike stands clearly above the noise.
    #[error(
        "no heel strike stands clearly above the noise in {}: the strike-to-noise ratio \
         (loudest 5 ms against the quietest hundredth) must be at least {min}; record closer to \
         the ground or with more gain, or leave these recordings out",
        list_snr(files, *min)
    )]
    NoClearStrike {
        /// The recordings refused.
        files: Vec<StrikeToNoise>,
        /// The threshold.
        min: Decibels,
    },
    /// The best fit is too far from the measurement to mean anything.
    #[error(
        "the best fit (order {order}) is too far from the measured response: LSD {lsd_db:.2} dB, \
         NRMSE {nrmse:.3}, where a usable fit has LSD at most {} and not both NRMSE above {} and \
         LSD above {}; try a higher order, a narrower band, or cleaner recordings, or keep it \
         anyway, marked as a poor fit",
        limits.0, limits.1, limits.2
    )]
    PoorFit {
        /// The order of the best fit.
        order: usize,
        /// Its log-spectral distance in dB.
        lsd_db: f64,
        /// Its NRMSE.
        nrmse: f64,
        /// `max_lsd`, `max_nrmse`, `nrmse_lsd_floor`.
        limits: (Decibels, f64, Decibels),
    },
    /// A recording could not be analysed.
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
}

fn list_rates(files: &[RateIssue]) -> String {
    files
        .iter()
        .map(|f| format!("{} ({})", f.file, f.rate))
        .collect::<Vec<_>>()
        .join(", ")
}

fn list_snr(files: &[StrikeToNoise], min: Decibels) -> String {
    files
        .iter()
        .map(|f| {
            if f.snr.0 < min.0 {
                format!(
                    "{} (its loudest strike is {:.1} dB above its noise, {:.1} dB short)",
                    f.file,
                    f.snr.0,
                    min.0 - f.snr.0
                )
            } else {
                format!(
                    "{} ({:.1} dB above its noise, but the onset detector finds no strike in it)",
                    f.file, f.snr.0
                )
            }
        })
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests;
