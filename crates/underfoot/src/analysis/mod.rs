//! The measured response of a material: what its heel strikes sound like, on average.
//!
//! Each recording goes through the conditioning chain of the IIR paper's section IV-A, with
//! onsets found automatically rather than by hand:
//!
//! 1. **Denoise** with a Savitzky-Golay smoother at the recording's own rate (the IIR paper's
//!    "17th order" filter at 1 kHz). By default the window is the widest whose response stays
//!    within 0.1 dB of unity up to the top of the band, so the smoother removes what lies
//!    above the band and leaves the band itself alone, whatever the recording's rate.
//! 2. **Resample** to the analysis rate with a band-limited polyphase resampler.
//! 3. **Remove the trend**: a zero-phase Butterworth filter, high-pass at half the band's
//!    lower edge and (when there is room below the Nyquist frequency) low-pass at 1.5 times
//!    its upper edge. The IIR paper put the band-pass edges on the band itself; forward-backward
//!    filtering then takes 6 dB off the band edges, which would be fitted as if it were the
//!    material's. An octave of margin below and half an octave above keep the band clean.
//!    Above the band, the resampler's anti-alias filter already does the low-pass's work
//!    when the band reaches 0.9 times the Nyquist frequency (the default 900 Hz at 2 kHz).
//! 4. **Find the strikes** ([`find_onsets`]) and cut
//!    each from `pre_onset` before its onset for `strike_length`, stopping short of the next
//!    strike, zero-padded to the FFT length (4x the strike length rounded up to a power of
//!    two, so the spectrum is finely interpolated).
//! 5. **Average**: the RMS of the strikes' magnitude spectra,
//!    `M(f) = sqrt(mean_s |X_s(f)|^2)`, an unnormalised DFT so that `M` is the magnitude of a
//!    filter whose impulse response is the strike.
//! 6. **Smooth** in fractional-octave bands (1/6 octave by default, finer than the
//!    vibrotactile frequency JND, so no detail a person could feel is lost).
//!
//! # A recording embedded in silence
//!
//! Steps 1-3 are linear and time-invariant in the interior of a signal, but each has its own
//! edge rule: the smoother fits polynomials to the first and last windows, the resampler's
//! output stops at the recording's ends (cutting its own pre- and post-ringing), and the
//! forward-backward trend filter reflects the signal through its end samples (scipy's odd
//! extension) and starts from the steady state of the first sample. The shared clips start
//! 3-4 ms before the strike, so these rules act on the strike itself: the odd extension
//! mirrors it into a second, inverted strike before the start, and the 10 Hz high-pass
//! turns the join into a slow transient. That invented 20-27 dB of low end (the measured
//! `hard` was -14 dB re its peak at 20 Hz against -41 dB in its raw spectrum), and it
//! changed with how much quiet the clip happened to hold.
//!
//! So every recording `x[0..L)` is conditioned as the signal `x̃` that is `x` on `[0, L)`
//! and zero elsewhere, which is what the chain would see of the same strikes recorded with
//! silence around them. Only finitely many zeros are needed for the result to equal the
//! LTI chain's on `x̃` to within `SETTLE_LEVEL` (1e-9) of the signal:
//!
//! * at the recording's rate, `w + R + 1` zeros, rounded up to a multiple of `M`, at each
//!   end, for a smoother of `w` taps and a resampler reaching `R` input samples
//!   ([`Resampler::reach`]): the smoother's edge fits then see only zeros (and output
//!   zeros), and the resampler outputs all of its ringing. Whole periods `M` of the rate
//!   ratio `L/M` keep the recording's first sample on the analysis grid (at output
//!   sample `pad · L / M`).
//! * at the analysis rate, where it is cheap, `n_s + strike + pre` more zeros at each end,
//!   with `n_s = ⌈ln(1e-9) / ln r⌉` for the trend filter's largest pole radius `r` (0.86 s
//!   for the default 10 Hz high-pass at 2 kHz). The forward pass's ringing has then died
//!   out before the end of the buffer, so the odd extension and the steady-state start of
//!   [`filtfilt`] act on zeros and do nothing; the backward pass's ringing ahead of the
//!   recording is kept. A strike window starting anywhere in the recording runs its full
//!   length into the silence after it, as it would in a longer recording.
//!
//! Strikes are detected on this extended signal too (so the detector sees the same signal
//! however the clip was cut), but only in a recording whose own span has a strike above its
//! own noise: the silence around a recording of noise alone would make that noise look loud.
//! Windows may start before the recording's first sample; a strike's reported onset is
//! clamped to 0 then.
//!
//! **No offset is removed.** A recording is taken as the deviation from rest, as AC-coupled
//! sensors (and the shared recordings, whose means are within 3·10⁻³ of zero, most within
//! 5·10⁻⁵) give it. No estimate of an offset is independent of the cut: the mean of a clip
//! includes the strike's own DC content divided by the clip's length (removing it moved a
//! synthetic strike's response by 0.7 dB when padded), and the median of a clip that is all
//! strike is far from its offset (4.7·10⁻³ on a shared `ice` clip of mean 2·10⁻⁵). A real
//! offset `d` becomes a rectangle of height `d` under the strikes, whose two edges ring
//! through the trend filter; remove it before analysis when it is not small against the
//! strikes' low end.
//!
//! [`raw_response`] is the reference the chain is checked against: the same strikes (same
//! onsets, same windows) of the recordings only resampled, averaged and smoothed alike.

pub mod steps;

use crate::fit::target::interpolate_bins;
use crate::recording::Recording;
use crate::recording::strikes::{OnsetConfig, find_onsets};
use crate::signal::savgol::SavitzkyGolay;
use crate::signal::spectrum::{SpectrumPlan, fractional_octave_smooth};
use crate::signal::{SignalError, Sos, butterworth, filtfilt::filtfilt, resample::Resampler};
use crate::units::{Band, Decibels, Hz, SampleRate, Seconds};

/// How recordings are turned into a measured response.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalysisConfig {
    /// The analysis rate every recording is resampled to (default 2000 Hz).
    pub rate: SampleRate,
    /// The band of interest (default 20-900 Hz).
    pub band: Band,
    /// How much of each strike is taken before its onset (default 10 ms).
    pub pre_onset: Seconds,
    /// Length of each strike's analysis window (default 0.5 s, zero-padded).
    pub strike_length: Seconds,
    /// Smoothing bandwidth as a fraction of an octave: 6 means 1/6 octave.
    pub smoothing_fraction: f64,
    /// Savitzky-Golay denoising.
    pub savgol: SavgolSetting,
    /// Order of the Butterworth band-pass prototype (each pass; run forward and back).
    pub bandpass_order: usize,
    /// Heel-strike detection.
    pub onsets: OnsetConfig,
}

/// How the Savitzky-Golay smoother is set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SavgolSetting {
    /// The widest window of this polynomial order whose response stays within 0.1 dB
    /// of unity over the band.
    Auto {
        /// Polynomial order.
        polyorder: usize,
    },
    /// A fixed window (samples at the recording's rate, odd) and polynomial order.
    Fixed {
        /// Window length in samples.
        window: usize,
        /// Polynomial order.
        polyorder: usize,
    },
    /// No smoothing.
    Off,
}

impl SavgolSetting {
    /// The widest fixed window accepted: far beyond any use, small enough that the
    /// smoother's design stays cheap.
    pub const MAX_WINDOW: usize = 4097;
    /// The highest fixed polynomial order accepted.
    pub const MAX_ORDER: usize = 12;
}

/// `auto` (the widest window of polynomial order 3 within 0.1 dB up to the band's top),
/// `off`, or `WINDOW:ORDER` (an odd window in samples, larger than the polynomial order,
/// within [`SavgolSetting::MAX_WINDOW`] and [`SavgolSetting::MAX_ORDER`]): the command
/// line's `--savgol`, and what the Python package's `savgol=` becomes.
impl core::str::FromStr for SavgolSetting {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "auto" => return Ok(Self::Auto { polyorder: 3 }),
            "off" => return Ok(Self::Off),
            _ => {}
        }
        let bad = || format!("savgol {s:?}: expected auto, off, or WINDOW:ORDER such as 17:3");
        let (w, p) = s.split_once(':').ok_or_else(bad)?;
        let window: usize = w.trim().parse().map_err(|_| bad())?;
        let polyorder: usize = p.trim().parse().map_err(|_| bad())?;
        if window > Self::MAX_WINDOW || polyorder > Self::MAX_ORDER {
            return Err(format!(
                "savgol {s:?}: the window may be at most {} and the order at most {}",
                Self::MAX_WINDOW,
                Self::MAX_ORDER
            ));
        }
        if window.is_multiple_of(2) || polyorder >= window {
            return Err(format!(
                "savgol {s:?}: the window must be odd and larger than the polynomial order"
            ));
        }
        Ok(Self::Fixed { window, polyorder })
    }
}

impl Default for AnalysisConfig {
    fn default() -> Self {
        Self {
            rate: SampleRate(2000),
            band: Band::new(20.0, 900.0),
            pre_onset: Seconds(0.010),
            strike_length: Seconds(0.5),
            smoothing_fraction: 6.0,
            savgol: SavgolSetting::Auto { polyorder: 3 },
            bandpass_order: 4,
            onsets: OnsetConfig::default(),
        }
    }
}

/// What went wrong turning recordings into a measured response.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    /// No recording was given.
    #[error("no recordings to analyse")]
    NoRecordings,
    /// A setting is out of range.
    #[error("invalid analysis setting: {0}")]
    InvalidConfig(String),
    /// A conditioning step failed on one recording.
    #[error("{name}: {source}")]
    Conditioning {
        /// The recording.
        name: String,
        /// What failed.
        source: SignalError,
    },
    /// No heel strike was found in any recording.
    #[error(
        "no heel strike found in {files:?}: are these recordings of footsteps, and louder than their noise?"
    )]
    NoStrikes {
        /// The recordings searched.
        files: Vec<String>,
    },
    /// The averaged spectrum is zero somewhere in the band, so it has no level to fit there.
    #[error(
        "the measured response is zero at {at} inside the band {band}: the strikes hold no energy there"
    )]
    EmptyBand {
        /// Where.
        at: Hz,
        /// The band.
        band: Band,
    },
}

/// Where a strike came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrikeSource {
    /// Index of the recording.
    pub recording: usize,
    /// Onset time in the recording.
    pub onset: Seconds,
}

/// The averaged, smoothed magnitude spectrum of a material's strikes.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredResponse {
    /// The analysis rate.
    pub rate: SampleRate,
    /// The band of interest.
    pub band: Band,
    /// Spacing of the bins in hertz (bin `k` is at `k * bin_hz`).
    pub bin_hz: f64,
    /// Smoothed magnitude, bins `0..=N/2`.
    pub magnitude: Vec<f64>,
    /// The RMS magnitude before smoothing.
    pub raw: Vec<f64>,
    /// Every strike averaged.
    pub strikes: Vec<StrikeSource>,
}

impl MeasuredResponse {
    /// The smoothed magnitude at `f`, interpolated linearly between bins.
    #[must_use]
    pub fn at(&self, f: Hz) -> f64 {
        interpolate_bins(&self.magnitude, self.bin_hz, f.0)
    }

    /// The smoothed magnitude at each frequency of `grid`.
    #[must_use]
    pub fn on_grid(&self, grid: &[Hz]) -> Vec<f64> {
        grid.iter().map(|&f| self.at(f)).collect()
    }
}

/// The lowest analysis rate.
pub const MIN_ANALYSIS_RATE: u32 = 100;
/// The highest analysis rate: 192 kHz, the highest rate a recording is expected at.
pub const MAX_ANALYSIS_RATE: u32 = 192_000;

impl AnalysisConfig {
    fn validate(&self) -> Result<(), AnalysisError> {
        let bad = |m: String| Err(AnalysisError::InvalidConfig(m));
        if !self.band.fits(self.rate) {
            return bad(format!(
                "band {} must lie inside (0, {}) at rate {}",
                self.band,
                self.rate.nyquist(),
                self.rate
            ));
        }
        if !(self.strike_length.0 > 0.0 && self.strike_length.0 <= 60.0) {
            return bad(format!(
                "strike length {} must be in (0, 60] s",
                self.strike_length
            ));
        }
        if !(self.pre_onset.0 >= 0.0 && self.pre_onset.0 < self.strike_length.0) {
            return bad(format!(
                "pre-onset {} must be in [0, strike length)",
                self.pre_onset
            ));
        }
        if !(self.smoothing_fraction.is_finite() && self.smoothing_fraction > 0.0) {
            return bad(format!(
                "smoothing fraction 1/{} must be positive",
                self.smoothing_fraction
            ));
        }
        if self.bandpass_order == 0 || self.bandpass_order > 20 {
            return bad(format!(
                "band-pass order {} must be in 1..=20",
                self.bandpass_order
            ));
        }
        if !(MIN_ANALYSIS_RATE..=MAX_ANALYSIS_RATE).contains(&self.rate.0) {
            // Above the cap a resampled recording would be a multi-gigabyte allocation
            // (`--rate 4000000000` was a 34 GB one).
            return bad(format!(
                "analysis rate {} must be {MIN_ANALYSIS_RATE} to {MAX_ANALYSIS_RATE} Hz",
                self.rate
            ));
        }
        Ok(())
    }

    /// Checks the settings and designs the trend filter: the set-up every entry point shares.
    fn prepare(&self) -> Result<Sos, AnalysisError> {
        self.validate()?;
        self.trend_filter()
            .map_err(|source| AnalysisError::InvalidConfig(source.to_string()))
    }

    /// The zero-phase trend filter of step 3.
    fn trend_filter(&self) -> Result<Sos, SignalError> {
        // An octave below the band, but never below the lowest edge a band may have: a
        // band from 0.1 Hz passes the checks, and its trend filter must design too.
        let lo = Hz((self.band.lo.0 / 2.0).max(Band::MIN_EDGE));
        let hi = self.band.hi.0 * 1.5;
        if hi < 0.9 * self.rate.nyquist().0 {
            butterworth::bandpass(self.bandpass_order, Band { lo, hi: Hz(hi) }, self.rate)
        } else {
            butterworth::highpass(self.bandpass_order, lo, self.rate)
        }
    }
}

/// Below this fraction of its level, the trend filter's ringing counts as died out.
const SETTLE_LEVEL: f64 = 1e-9;

/// The trend filter's ringing is followed for at most this long (a filter with a pole on
/// the unit circle never settles; the band's checks keep that from happening).
const MAX_SETTLE: Seconds = Seconds(60.0);

/// Which steps of the chain a recording goes through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Chain {
    /// Steps 1-3: smoother, resampler, trend filter.
    Conditioned,
    /// The resampler alone: the reference of [`raw_response`].
    Raw,
}

/// One recording on its zero extension at the analysis rate: the recording's first sample
/// is at `x[lead]` and it spans `span` samples; everything else is what the chain made of
/// the silence around it.
struct Extended {
    x: Vec<f64>,
    lead: usize,
    span: usize,
}

impl Extended {
    /// The part of `x` the recording itself spans.
    fn recording(&self) -> &[f64] {
        &self.x[self.lead..self.lead + self.span]
    }
}

/// The samples of one recording after steps 1-3, at the analysis rate, over the span of
/// the recording (sample `n` at time `n / rate` from its start).
///
/// They are the samples of the linear, time-invariant chain run on the recording embedded
/// in silence (see the module docs), so they do not depend on how the recording was cut.
///
/// # Errors
/// [`AnalysisError::Conditioning`] when a step cannot run on this recording (empty).
pub fn condition(rec: &Recording, cfg: &AnalysisConfig) -> Result<Vec<f64>, AnalysisError> {
    let trend = cfg.prepare()?;
    let ext = extend(rec, cfg, &trend, Chain::Conditioned)?;
    Ok(ext.recording().to_vec())
}

/// Samples for the trend filter's ringing to fall to [`SETTLE_LEVEL`]:
/// `ceil(ln(level) / ln(r))` for the largest pole radius `r`.
pub(crate) fn settle_samples(trend: &Sos, rate: SampleRate) -> usize {
    let cap = rate.samples_in(MAX_SETTLE);
    let r = trend.poles().iter().map(|p| p.norm()).fold(0.0, f64::max);
    if r.is_nan() || r >= 1.0 {
        return cap;
    }
    if r <= 0.0 {
        return 1;
    }
    let n = (SETTLE_LEVEL.ln() / r.ln()).ceil();
    if n.is_finite() {
        (n as usize).clamp(1, cap)
    } else {
        cap
    }
}

/// Steps 1-3 (or the resampler alone) on the recording extended with zeros, far enough
/// that every filter starts and ends in silence; both chains lay the result out alike.
fn extend(
    rec: &Recording,
    cfg: &AnalysisConfig,
    trend: &Sos,
    chain: Chain,
) -> Result<Extended, AnalysisError> {
    let wrap = |source| AnalysisError::Conditioning {
        name: rec.name.clone(),
        source,
    };
    if rec.samples.is_empty() {
        return Err(wrap(SignalError::TooShort {
            len: 0,
            needed: 1,
            what: "conditioning",
        }));
    }
    let smoother = match cfg.savgol {
        SavgolSetting::Auto { polyorder } => {
            SavitzkyGolay::widest_within(rec.rate, cfg.band.hi, Decibels(0.1), polyorder, 257)
        }
        SavgolSetting::Fixed { window, polyorder } => {
            Some(SavitzkyGolay::new(window, polyorder).map_err(wrap)?)
        }
        SavgolSetting::Off => None,
    };
    let resampler = Resampler::shared(rec.rate, cfg.rate).map_err(wrap)?;
    let (up, down) = resampler.ratio();

    // At the recording's rate, zeros enough for the smoother's edge fits to see only zeros
    // and for the resampler to output all of its ringing, rounded up to whole periods of
    // the rate ratio so that the recording's first sample stays on the analysis grid.
    let fir = smoother.as_ref().map_or(0, SavitzkyGolay::window) + resampler.reach() + 1;
    let (up, down) = (up as usize, down as usize);
    let pad_in = fir.div_ceil(down) * down;
    let mut input = Vec::with_capacity(2 * pad_in + rec.samples.len());
    input.resize(pad_in, 0.0);
    input.extend_from_slice(&rec.samples);
    input.resize(input.len() + pad_in, 0.0);
    // `input` is consumed here so that no more than two copies of the recording at its
    // own rate are alive at once (the recording's and this one).
    let smoothed = match (&smoother, chain) {
        (Some(sg), Chain::Conditioned) => {
            let input = input;
            sg.apply(&input).map_err(wrap)?
        }
        _ => input,
    };
    let resampled = resampler.process(&smoothed);
    drop(smoothed);

    // At the analysis rate, what the FIR steps leave is exactly zero, so the rest of the
    // silence is added there, where it is cheap: long enough for the trend filter's
    // ringing to die out at both ends, plus a whole strike window, so that a window
    // starting anywhere in the recording runs its full length.
    let tail = settle_samples(trend, cfg.rate)
        + cfg.rate.samples_in(cfg.strike_length).max(8)
        + cfg.rate.samples_in(cfg.pre_onset);
    let mut x = vec![0.0; tail];
    x.extend_from_slice(&resampled);
    x.resize(x.len() + tail, 0.0);
    if chain == Chain::Conditioned {
        x = filtfilt(trend, &x).map_err(wrap)?;
    }
    Ok(Extended {
        x,
        lead: tail + pad_in * up / down,
        span: resampler.output_len(rec.samples.len()),
    })
}

/// The measured response of the strikes in `recordings`.
///
/// # Errors
/// [`AnalysisError`] when the settings are invalid, a recording cannot be conditioned, no
/// strike is found anywhere, or the average has no energy somewhere in the band.
pub fn measure(
    recordings: &[Recording],
    cfg: &AnalysisConfig,
) -> Result<MeasuredResponse, AnalysisError> {
    analyse(recordings, cfg, Chain::Conditioned)
}

/// Each recorded file's own measured response on `grid`, in the order of `recordings`
/// (a long file's excerpts are measured together, as one file): what a figure draws
/// behind the mean that [`measure`] gives over all of them. A file in which no strike is
/// found, or whose strikes hold no energy somewhere in the band, has no curve of its own
/// and is left out.
#[must_use]
pub fn measure_each_file(
    recordings: &[Recording],
    cfg: &AnalysisConfig,
    grid: &[Hz],
) -> Vec<Vec<f64>> {
    crate::recording::by_file(recordings)
        .into_iter()
        .filter_map(|file| measure(&recordings[file], cfg).ok())
        .map(|m| m.on_grid(grid))
        .collect()
}

/// The reference the conditioning is checked against: the magnitude spectrum of the same
/// strikes as [`measure`] finds (same onsets, same windows), averaged and smoothed the same
/// way, but of the recordings only resampled to the analysis rate, with no smoother and no
/// trend filter.
///
/// # Errors
/// As [`measure`].
pub fn raw_response(
    recordings: &[Recording],
    cfg: &AnalysisConfig,
) -> Result<MeasuredResponse, AnalysisError> {
    analyse(recordings, cfg, Chain::Raw)
}

fn analyse(
    recordings: &[Recording],
    cfg: &AnalysisConfig,
    chain: Chain,
) -> Result<MeasuredResponse, AnalysisError> {
    let trend = cfg.prepare()?;
    if recordings.is_empty() {
        return Err(AnalysisError::NoRecordings);
    }
    let strike_len = cfg.rate.samples_in(cfg.strike_length).max(8);
    let pre = cfg.rate.samples_in(cfg.pre_onset);
    let n_fft = (4 * strike_len).next_power_of_two();
    let mut plan = SpectrumPlan::new(n_fft);
    let mut mag = vec![0.0; n_fft / 2 + 1];
    let mut power = vec![0.0; n_fft / 2 + 1];
    let mut strikes = Vec::new();
    for (index, rec) in recordings.iter().enumerate() {
        let conditioned = extend(rec, cfg, &trend, Chain::Conditioned)?;
        // Strikes are looked for in the recording embedded in its silence, so that the
        // detector sees the same signal however tightly the recording was cut; but a
        // recording whose own samples hold nothing standing above their noise (noise
        // alone, which the silence would make look loud) has none.
        let onsets = if find_onsets(conditioned.recording(), cfg.rate, &cfg.onsets).is_empty() {
            Vec::new()
        } else {
            find_onsets(&conditioned.x, cfg.rate, &cfg.onsets)
        };
        let source = match chain {
            Chain::Conditioned => conditioned,
            Chain::Raw => extend(rec, cfg, &trend, Chain::Raw)?,
        };
        let x = &source.x;
        for (i, &onset) in onsets.iter().enumerate() {
            // The window may reach into the silence before and after the recording.
            let start = onset.saturating_sub(pre);
            let next = onsets
                .get(i + 1)
                .map_or(x.len(), |&n| n.saturating_sub(pre).max(start + 1));
            let end = (start + strike_len).min(next).min(x.len());
            if end <= start {
                continue;
            }
            plan.magnitude(&x[start..end], &mut mag).map_err(|source| {
                AnalysisError::Conditioning {
                    name: rec.name.clone(),
                    source,
                }
            })?;
            for (p, m) in power.iter_mut().zip(&mag) {
                *p += m * m;
            }
            strikes.push(StrikeSource {
                recording: index,
                onset: cfg.rate.duration_of(onset.saturating_sub(source.lead)),
            });
        }
    }
    if strikes.is_empty() {
        return Err(AnalysisError::NoStrikes {
            files: recordings.iter().map(|r| r.name.clone()).collect(),
        });
    }
    let n = strikes.len() as f64;
    let raw: Vec<f64> = power.iter().map(|p| (p / n).sqrt()).collect();
    let bin_hz = cfg.rate.hz() / n_fft as f64;
    let magnitude = fractional_octave_smooth(&raw, bin_hz, cfg.smoothing_fraction);
    let response = MeasuredResponse {
        rate: cfg.rate,
        band: cfg.band,
        bin_hz,
        magnitude,
        raw,
        strikes,
    };
    let lo_bin = (cfg.band.lo.0 / bin_hz).floor() as usize;
    let hi_bin = ((cfg.band.hi.0 / bin_hz).ceil() as usize).min(response.magnitude.len() - 1);
    if let Some(k) = (lo_bin..=hi_bin)
        .find(|&k| !(response.magnitude[k] > 0.0 && response.magnitude[k].is_finite()))
    {
        return Err(AnalysisError::EmptyBand {
            at: Hz(k as f64 * bin_hz),
            band: cfg.band,
        });
    }
    Ok(response)
}
