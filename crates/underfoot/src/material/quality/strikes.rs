//! Refusal 3: no strike above the noise.
//!
//! 3. **No strike above the noise** ([`QualityError::NoClearStrike`]). On each recording's
//!    conditioned signal `x` (at the analysis rate, trend removed, see
//!    [`condition`]), the moving RMS over every whole window of
//!    `W = snr_window` samples (5 ms by default, the onset detector's envelope),
//!    `e[n] = sqrt( (1/W) sum_{m=n}^{n+W-1} x[m]^2 )`, gives the
//!    **strike-to-noise ratio**
//!
//! ```math
//! \mathrm{SNR} = 20 \log_{10} \frac{\max_n e(n)}{P_{1}(e)} \ \mathrm{dB},
//! ```
//!
//!    the loudest 5 ms against the noise floor, read from the quietest part of the signal
//!    (the 1st percentile of the envelope, nearest rank: the quietest hundredth, which a
//!    single-step clip of strike and fade-out still has, and which ignores a few stray
//!    near-zero windows). The recording is refused when `SNR < min_strike_to_noise`
//!    (15 dB by default), or when it passes but the onset detector
//!    ([`find_onsets`](crate::recording::strikes::find_onsets)) finds no strike in it
//!    (with several recordings; one recording alone gets the analysis' own error), since it
//!    would silently add nothing to the average.
//!
//!    The threshold is measured, not derived. Noise alone (uniform white noise at the shared
//!    recordings' peak level and rates, 1 s or 60 s long, or the ±1 LSB of an empty 16-bit
//!    file) scores 6.7 to 12.6 dB, Gaussian noise up to 13 dB: the 1st percentile of a 10-sample RMS reads low, and its maximum over a
//!    minute high. The 22 shared recordings score 16.4 dB (gravel, a crunching texture whose
//!    0.3 s clips hold no quiet at all) to 68 dB (water); all but the gravel and one snow
//!    clip score above 21 dB. 15 dB sits between, closer to the noise since the weakest real
//!    recordings are close to it too; the onset detector's own 12 dB noise margin (on the
//!    10th percentile) is the second line that noise does not pass.

use super::{Disagreement, QualityConfig, QualityError, disagreement};
use crate::analysis::{AnalysisConfig, condition};
use crate::recording::Recording;
use crate::units::{Decibels, SampleRate};

/// The strike-to-noise ratio of one recording.
#[derive(Debug, Clone, PartialEq)]
pub struct StrikeToNoise {
    /// The recording's name.
    pub file: String,
    /// Loudest envelope over the noise floor; `-inf` for a recording that is all zeros
    /// after conditioning.
    pub snr: Decibels,
    /// Heel strikes the onset detector finds in it.
    pub strikes: usize,
}

/// What the recording checks found; passed to the build's progress callback.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordingsQuality {
    /// Each recording's strike-to-noise ratio, in input order.
    pub strike_to_noise: Vec<StrikeToNoise>,
    /// How the recordings agree; `None` with a single recording.
    pub disagreement: Option<Disagreement>,
}

/// The strike-to-noise ratio of a signal: see the [module docs](self).
///
/// `-inf` dB for a signal with no energy at all, `+inf` for one whose quietest hundredth is
/// exactly zero while something else is not.
#[must_use]
pub fn strike_to_noise(x: &[f64], rate: SampleRate, cfg: &QualityConfig) -> Decibels {
    if x.is_empty() {
        return Decibels(f64::NEG_INFINITY);
    }
    let w = rate.samples_in(cfg.snr_window).clamp(1, x.len());
    let mut env = Vec::with_capacity(x.len() + 1 - w);
    let mut acc: f64 = x[..w].iter().map(|v| v * v).sum();
    env.push(acc);
    for n in w..x.len() {
        acc += x[n] * x[n] - x[n - w] * x[n - w];
        env.push(acc);
    }
    // A running sum's rounding can dip just below zero.
    let mut env: Vec<f64> = env.iter().map(|e| (e.max(0.0) / w as f64).sqrt()).collect();
    let peak = env.iter().copied().fold(0.0, f64::max);
    env.sort_by(f64::total_cmp);
    let p = cfg.noise_percentile.clamp(0.0, 1.0);
    let floor = env[((p * (env.len() - 1) as f64).round() as usize).min(env.len() - 1)];
    if peak <= 0.0 {
        return Decibels(f64::NEG_INFINITY);
    }
    if floor <= 0.0 {
        return Decibels(f64::INFINITY);
    }
    Decibels::from_amplitude(peak / floor)
}

/// Check 3 and the disagreement warning of the [module docs](self), after [`check_rates`](super::check_rates).
///
/// # Errors
/// [`QualityError::NoClearStrike`] naming every recording that fails, or
/// [`QualityError::Analysis`] when a recording cannot be conditioned.
pub fn check_recordings(
    recordings: &[Recording],
    analysis: &AnalysisConfig,
    cfg: &QualityConfig,
) -> Result<RecordingsQuality, QualityError> {
    // A long recording's excerpts are one file: its ratio is its loudest excerpt's
    // (each measured against the noise around it), its strikes are theirs together.
    let files = crate::recording::by_file(recordings);
    let mut strike_to_noise_all = Vec::with_capacity(files.len());
    for file in &files {
        let mut snr = Decibels(f64::NEG_INFINITY);
        let mut strikes = 0;
        for rec in &recordings[file.clone()] {
            let x = condition(rec, analysis)?;
            let here = strike_to_noise(&x, analysis.rate, cfg);
            if here.0.is_nan() || here.0 > snr.0 {
                snr = here;
            }
            strikes +=
                crate::recording::strikes::find_onsets(&x, analysis.rate, &analysis.onsets).len();
        }
        strike_to_noise_all.push(StrikeToNoise {
            file: recordings[file.start].name.clone(),
            snr,
            strikes,
        });
    }
    // With one recording, no strike is the analysis' own error; with several, a recording
    // without one would silently add nothing.
    let several = files.len() > 1;
    let failed: Vec<StrikeToNoise> = strike_to_noise_all
        .iter()
        .filter(|s| {
            s.snr.0.is_nan() || s.snr.0 < cfg.min_strike_to_noise.0 || (several && s.strikes == 0)
        })
        .cloned()
        .collect();
    if !failed.is_empty() {
        return Err(QualityError::NoClearStrike {
            files: failed,
            min: cfg.min_strike_to_noise,
        });
    }
    let disagreement = if several {
        Some(disagreement(recordings, analysis, cfg.max_disagreement)?)
    } else {
        None
    };
    Ok(RecordingsQuality {
        strike_to_noise: strike_to_noise_all,
        disagreement,
    })
}
