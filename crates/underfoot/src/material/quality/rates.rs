//! Refusals 1 and 2: rates and band against every Nyquist frequency.
//!
//! 1. **Rate too low** ([`QualityError::RateTooLow`]). A recording at rate `fs` holds
//!    nothing above `fs / 2`. It must hold at least one octave of the band above the band's
//!    lower edge, and never less than [`MIN_RATE_HZ`] (the analysis rate's own floor):
//!    `fs >= max(100 Hz, 4 lo)`. A 1 Hz WAV fails here.
//! 2. **Band above a Nyquist frequency** ([`QualityError::BandAboveNyquist`],
//!    [`QualityError::BandAboveAnalysisNyquist`]). The band's top must be below the
//!    Nyquist frequency of every recording and of the analysis rate. Above a recording's
//!    Nyquist frequency its resampled spectrum is the resampler's stop band, not the ground,
//!    and a fit there is a fit of the anti-alias filter. The suggested band keeps the lower
//!    edge and puts the top at 0.9 of the lowest Nyquist frequency, the usable part of a
//!    resampler's pass band, rounded down.

use super::{MIN_RATE_HZ, QualityError};
use crate::analysis::AnalysisConfig;
use crate::recording::Recording;
use crate::units::{Band, Hz, SampleRate};

/// One recording whose rate is too low, or whose Nyquist frequency is below the band.
#[derive(Debug, Clone, PartialEq)]
pub struct RateIssue {
    /// The recording's name.
    pub file: String,
    /// Its rate.
    pub rate: SampleRate,
}

/// The lowest whole rate in hertz strictly above `2 f`.
fn rate_for(f: Hz) -> SampleRate {
    SampleRate((2.0 * f.0).floor() as u32 + 1)
}

/// `f` rounded down to a number a person would type: whole tens from 100 Hz, whole hertz
/// below.
fn round_down(f: f64) -> f64 {
    if f >= 100.0 {
        (f / 10.0).floor() * 10.0
    } else {
        f.floor().max(1.0)
    }
}

/// The lowest rate a recording may have for `band`: see the [module docs](self).
#[must_use]
pub fn min_rate(band: Band) -> SampleRate {
    SampleRate(MIN_RATE_HZ.max(4.0 * band.lo.0).ceil() as u32)
}

/// Checks 1 and 2 of the [module docs](self): rates and band against every Nyquist
/// frequency. Cheap; runs before anything is conditioned.
///
/// # Errors
/// [`QualityError::RateTooLow`], [`QualityError::BandAboveAnalysisNyquist`] or
/// [`QualityError::BandAboveNyquist`].
pub fn check_rates(
    recordings: &[Recording],
    analysis: &AnalysisConfig,
) -> Result<(), QualityError> {
    let band = analysis.band;
    let min = min_rate(band);
    let too_low: Vec<RateIssue> = recordings
        .iter()
        .filter(|r| r.rate.0 < min.0)
        .map(|r| RateIssue {
            file: r.name.clone(),
            rate: r.rate,
        })
        .collect();
    if !too_low.is_empty() {
        return Err(QualityError::RateTooLow {
            files: too_low,
            band,
            min,
        });
    }
    let suggest = |nyquist: Hz| Band {
        lo: band.lo,
        hi: Hz(round_down(0.9 * nyquist.0)),
    };
    if band.hi.0 >= analysis.rate.nyquist().0 {
        return Err(QualityError::BandAboveAnalysisNyquist {
            band,
            rate: analysis.rate,
            suggested: suggest(analysis.rate.nyquist()),
            needed: rate_for(band.hi),
        });
    }
    let above: Vec<RateIssue> = recordings
        .iter()
        .filter(|r| band.hi.0 >= r.rate.nyquist().0)
        .map(|r| RateIssue {
            file: r.name.clone(),
            rate: r.rate,
        })
        .collect();
    if let Some(lowest) = above.iter().map(|r| r.rate.0).min() {
        return Err(QualityError::BandAboveNyquist {
            band,
            files: above,
            suggested: suggest(SampleRate(lowest).nyquist()),
            needed: rate_for(band.hi),
        });
    }
    Ok(())
}
