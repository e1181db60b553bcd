//! A step measured in time: the same descriptors for a recording and for a render.
//!
//! The measured response ([`super::measure`]) says how a material's strikes sound on
//! average, in frequency. What a foot feels is also *when*: on gravel a step is a burst
//! of dozens of micro-impacts over a few hundred milliseconds, on concrete one thump. This
//! module measures that, identically on recordings and on rendered output, so the two can
//! be compared and the excitation ([`crate::excitation`]) fitted to the recordings.
//!
//! # The signal
//!
//! A signal is band-limited to the analysis band (20-900 Hz by default) by a Butterworth
//! band-pass run forward and backward (zero phase, order `2 × filter_order` in all) on the
//! signal embedded in silence: zeros are added at both ends until the filter's ringing has
//! died out ([`band_limit`]), so a clip cut tightly around a step is filtered as the same
//! step recorded with quiet around it. A step is the stretch from `before` (50 ms) ahead
//! of its onset to `after` (600 ms) past it, cut short where the next step's stretch
//! begins and zero-padded to full length.
//!
//! # The descriptors ([`Step`])
//!
//! With `x[n]` the band-limited step and `E[n] = Σ_{m ≤ n} x[m]²` its cumulative energy:
//!
//! - **duration** `D90`: from the sample where `E` reaches 5% of the step's energy to the
//!   one where it reaches 95%;
//! - **micro-events**: the peaks of the RMS envelope `e[n]` over `envelope` (1.5 ms,
//!   centred), in dB, that are within `event_range` (25 dB) of its maximum, at least
//!   `event_separation` (3 ms) from a higher peak, and at least `event_prominence` (6 dB)
//!   prominent. A peak's prominence is its height over the higher of the two lowest points
//!   between it and a higher envelope value (or the window's edge) on either side: how far
//!   it stands out of its surroundings. The filters run in that order (range, separation,
//!   prominence), as `scipy.signal.find_peaks` runs its `height`, `distance` and
//!   `prominence`. Each event keeps its time from the onset and its level relative to
//!   the loudest;
//! - **crest factor**: the largest `|x|` over the RMS of `x` in the `crest_span` (350 ms)
//!   from `before` ahead of the onset, `|x|` between samples too (its true peak, by
//!   windowed-sinc interpolation around the largest samples): a step measured at 4 kHz
//!   and at 48 kHz then has the same crest factor, where the largest sample at 4 kHz can
//!   miss a 900 Hz peak by 2.4 dB;
//! - **decay envelope**: the energy in consecutive `decay_bin` (10 ms) bins from the
//!   onset, in dB re the loudest bin;
//! - **band spectrum**: the power `|X(f)|²` of the whole zero-padded stretch, averaged over
//!   `1/spectrum_fraction`-octave bands (1/6 octave) centred from the band's bottom edge
//!   plus half a band up, while the band's top edge stays inside the analysis band. `X` is
//!   the DFT divided by the rate, the continuous-time transform it approximates, so that a
//!   step at 22.05 kHz and its render at 48 kHz have the same spectrum.
//!
//! # Between steps ([`StepSummary`])
//!
//! Medians over the steps of duration, event count, crest factor and event rate; the
//! decay envelope (the median of the steps') and the micro-events' rate in each of its
//! bins (their mean); the spread between steps, the mean over every pair of steps of the gain-aligned
//! log-spectral distance between their band spectra (in dB, the RMS over bands of the
//! difference with its mean removed: a louder step is not a different one); and the
//! average band spectrum, which [`spectrum_distance`] compares between two sets of steps
//! the same way.
//!
//! # Onsets
//!
//! A recording's steps start where [`super::measure`] found its strikes. A render's are
//! found by [`find_steps`]: the first sample where the 5 ms RMS envelope comes within
//! `onset_range` (40 dB) of the signal's loudest, after at least `onset_gap` (300 ms)
//! below it; or, where the walk's heel strikes are known, where the envelope rises
//! through that threshold after each strike ([`onsets_near`]): the engine starts a step
//! when the force crosses its detector's threshold, 10-20 ms after the foot lands.

use serde::{Deserialize, Serialize};

use super::AnalysisError;
use crate::fit::metrics::gain_aligned_level_distance_db;
use crate::numeric::window::{Edges, centred_rms};
use crate::signal::{Sos, butterworth};
use crate::units::{Band, Decibels, SampleRate, Seconds};

/// How steps are measured; the defaults are those the module documentation gives.
#[derive(Debug, Clone, PartialEq)]
pub struct StepConfig {
    /// The band the signal is limited to.
    pub band: Band,
    /// Order of the Butterworth band-pass prototype (each pass).
    pub filter_order: usize,
    /// How much of a step is taken before its onset.
    pub before: Seconds,
    /// How much after it.
    pub after: Seconds,
    /// Length of the RMS window whose peaks are micro-events.
    pub envelope: Seconds,
    /// Micro-events are within this of the loudest envelope value.
    pub event_range: Decibels,
    /// ... stand out this much from their surroundings ...
    pub event_prominence: Decibels,
    /// ... and are at least this far from a higher one.
    pub event_separation: Seconds,
    /// The span the crest factor is taken over, from `before` ahead of the onset.
    pub crest_span: Seconds,
    /// Width of a bin of the decay envelope.
    pub decay_bin: Seconds,
    /// Bands of the spectrum per octave.
    pub spectrum_fraction: f64,
    /// A step starts within this of the loudest envelope value ([`find_steps`]).
    pub onset_range: Decibels,
    /// ... after at least this long below it.
    pub onset_gap: Seconds,
}

impl Default for StepConfig {
    fn default() -> Self {
        Self {
            band: Band::new(20.0, 900.0),
            filter_order: 4,
            before: Seconds(0.05),
            after: Seconds(0.6),
            envelope: Seconds(0.0015),
            event_range: Decibels(25.0),
            event_prominence: Decibels(6.0),
            event_separation: Seconds(0.003),
            crest_span: Seconds(0.35),
            decay_bin: Seconds(0.01),
            spectrum_fraction: 6.0,
            onset_range: Decibels(40.0),
            onset_gap: Seconds(0.3),
        }
    }
}

/// One micro-event of a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MicroEvent {
    /// From the step's onset.
    pub time: Seconds,
    /// Its envelope peak re the step's loudest (at most 0).
    pub level: Decibels,
}

/// The descriptors of one step (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Its onset in the signal it was cut from.
    pub onset: Seconds,
    /// Its energy (sum of squares of the band-limited stretch).
    pub energy: f64,
    /// The time between 5% and 95% of its energy.
    pub duration: Seconds,
    /// Its micro-events, in time order.
    pub events: Vec<MicroEvent>,
    /// Peak over RMS in the crest span.
    pub crest: Decibels,
    /// Energy per decay bin from the onset, dB re the loudest bin.
    pub decay_db: Vec<f64>,
    /// Power per fractional-octave band (see [`band_centres`]).
    pub bands: Vec<f64>,
}

impl Step {
    /// Micro-events per second of the step's duration.
    #[must_use]
    pub fn event_rate(&self) -> f64 {
        self.events.len() as f64 / self.duration.0.max(1e-3)
    }

    /// The times between consecutive micro-events.
    pub fn intervals(&self) -> impl Iterator<Item = Seconds> + '_ {
        self.events
            .windows(2)
            .map(|w| Seconds(w[1].time.0 - w[0].time.0))
    }
}

/// What a set of steps has in common, and how much its steps differ; what a library
/// stores of its recordings (`time` in a material).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepSummary {
    /// How many steps.
    pub steps: usize,
    /// Median duration (`D90`), ms.
    pub duration_ms: f64,
    /// Median micro-event count.
    pub events: f64,
    /// Median micro-events per second of a step's duration.
    pub event_rate_hz: f64,
    /// Median time between consecutive micro-events, ms (0 with fewer than two).
    pub interval_ms: f64,
    /// Quartiles (25, 50, 75%) of the micro-events' levels re their step's loudest, dB.
    pub event_level_db: [f64; 3],
    /// Median crest factor, dB.
    pub crest_db: f64,
    /// Mean gain-aligned log-spectral distance between two steps, dB; `None` for a single
    /// step.
    pub spread_db: Option<f64>,
    /// Median decay envelope: energy per 10 ms from the onset, dB re the loudest bin.
    pub decay_db: Vec<f64>,
    /// The micro-events' rate over the step: per bin of the decay envelope (10 ms from the
    /// onset), the mean over the steps of the events whose peak falls in it, per second.
    #[serde(default)]
    pub event_rate_hz_by_bin: Vec<f64>,
    /// The band centres of `spectrum_db`, Hz.
    pub bands_hz: Vec<f64>,
    /// Average band spectrum (mean power over the steps), dB.
    pub spectrum_db: Vec<f64>,
}

/// The centres of the fractional-octave bands of a step's spectrum.
#[must_use]
pub fn band_centres(cfg: &StepConfig) -> Vec<f64> {
    let half = 2f64.powf(0.5 / cfg.spectrum_fraction);
    let step = half * half;
    let mut centres = Vec::new();
    let mut c = cfg.band.lo.0 * half;
    while c * half <= cfg.band.hi.0 * (1.0 + 1e-9) && centres.len() < 1000 {
        centres.push(c);
        c *= step;
    }
    centres
}

fn check(cfg: &StepConfig, rate: SampleRate) -> Result<(), AnalysisError> {
    let bad = |m: String| Err(AnalysisError::InvalidConfig(m));
    if !cfg.band.fits(rate) {
        return bad(format!(
            "step band {} must lie inside (0, {}) at rate {rate}",
            cfg.band,
            rate.nyquist()
        ));
    }
    let times = [
        cfg.before.0,
        cfg.after.0,
        cfg.envelope.0,
        cfg.event_separation.0,
        cfg.crest_span.0,
        cfg.decay_bin.0,
        cfg.onset_gap.0,
    ];
    if !times
        .iter()
        .all(|t| t.is_finite() && *t >= 0.0 && *t <= 60.0)
        || cfg.after.0 <= 0.0
        || cfg.decay_bin.0 <= 0.0
    {
        return bad("step times must be in [0, 60] s, `after` and the decay bin positive".into());
    }
    if cfg.filter_order == 0 || cfg.filter_order > 20 {
        return bad(format!(
            "step filter order {} must be in 1..=20",
            cfg.filter_order
        ));
    }
    if !(cfg.spectrum_fraction.is_finite() && (1.0..=48.0).contains(&cfg.spectrum_fraction)) {
        return bad(format!(
            "bands per octave {} must be in 1..=48",
            cfg.spectrum_fraction
        ));
    }
    Ok(())
}

/// `samples` band-limited to `cfg.band`, zero-phase, as if recorded with silence around
/// them (see the module documentation).
///
/// # Errors
/// [`AnalysisError::InvalidConfig`] for a band that does not fit `rate` or another bad
/// setting.
pub fn band_limit(
    samples: &[f64],
    rate: SampleRate,
    cfg: &StepConfig,
) -> Result<Vec<f64>, AnalysisError> {
    check(cfg, rate)?;
    let sos = butterworth::bandpass(cfg.filter_order, cfg.band, rate)
        .map_err(|e| AnalysisError::InvalidConfig(e.to_string()))?;
    Ok(zero_phase_in_silence(&sos, samples, rate))
}

/// `x` filtered forward and backward by `sos`, from rest, with zeros around it until the
/// filter's ringing has died out: the zero-phase filtering of `x` embedded in silence.
pub(crate) fn zero_phase_in_silence(sos: &Sos, x: &[f64], rate: SampleRate) -> Vec<f64> {
    let pad = super::settle_samples(sos, rate);
    let mut y = vec![0.0; x.len() + 2 * pad];
    y[pad..pad + x.len()].copy_from_slice(x);
    sos.filter_in_place(&mut y);
    y.reverse();
    sos.filter_in_place(&mut y);
    y.reverse();
    y.truncate(pad + x.len());
    y.drain(..pad);
    y
}

/// The onsets (sample indices) of the steps in a band-limited `signal` (see the module
/// documentation, *Onsets*).
#[must_use]
pub fn find_steps(signal: &[f64], rate: SampleRate, cfg: &StepConfig) -> Vec<usize> {
    let env = centred_rms(signal, rate.samples_in(Seconds(0.005)), Edges::Zeros);
    let loudest = env.iter().copied().fold(0.0, f64::max);
    if loudest <= 0.0 {
        return Vec::new();
    }
    let threshold = loudest * Decibels(-cfg.onset_range.0).to_amplitude();
    let gap = rate.samples_in(cfg.onset_gap);
    let mut onsets = Vec::new();
    let mut last: Option<usize> = None;
    for (i, _) in env.iter().enumerate().filter(|(_, e)| **e > threshold) {
        if last.is_none_or(|l| i - l > gap) {
            onsets.push(i);
        }
        last = Some(i);
    }
    onsets
}

/// The descriptors of the step at `onset` (a sample index) of a band-limited `signal`,
/// whose stretch stops at `limit` (the next step's start) if that comes first.
#[must_use]
pub fn describe(
    signal: &[f64],
    rate: SampleRate,
    onset: usize,
    limit: usize,
    cfg: &StepConfig,
) -> Step {
    describe_with(signal, rate, onset, limit, cfg, true)
}

/// As [`describe`]; without the band spectrum (left empty) unless `spectrum`: most of the
/// cost of a step, and what a search over durations and counts does not need.
pub(crate) fn describe_with(
    signal: &[f64],
    rate: SampleRate,
    onset: usize,
    limit: usize,
    cfg: &StepConfig,
    spectrum: bool,
) -> Step {
    let before = rate.samples_in(cfg.before);
    let len = before + rate.samples_in(cfg.after);
    let start = onset as isize - before as isize;
    let mut x = vec![0.0; len];
    for (i, v) in x.iter_mut().enumerate() {
        let n = start + i as isize;
        if n >= 0 && (n as usize) < signal.len().min(limit.max(onset + 1)) {
            *v = signal[n as usize];
        }
    }
    let energy: f64 = x.iter().map(|v| v * v).sum();
    Step {
        onset: rate.duration_of(onset),
        energy,
        duration: energy_duration(&x, rate),
        events: micro_events(&x, rate, before, cfg),
        crest: crest(&x[..rate.samples_in(cfg.crest_span).clamp(1, len)]),
        decay_db: decay(&x[before.min(len)..], rate.samples_in(cfg.decay_bin).max(1)),
        bands: if spectrum {
            band_powers(&x, rate, &band_centres(cfg), cfg.spectrum_fraction)
        } else {
            Vec::new()
        },
    }
}

/// The onsets of the steps of a band-limited `signal` struck at `strikes` (sample
/// indices, ascending), found as [`find_steps`] finds a recording's: each where the 5 ms
/// RMS envelope rises through the threshold, the first such rise from `before` ahead of
/// its strike up to `onset_gap` after it (and not past a neighbouring strike); the
/// strike itself where there is no rise there (a tail still ringing, or no sound).
///
/// A strike is where the foot lands; a render's step starts where the engine's detector
/// sees the force cross its threshold, some milliseconds later, and the band-limiting's
/// zero-phase filter rings a little ahead of that as it does ahead of a recorded step.
/// Measured from where the signal rises, a render's steps line up with a recording's.
#[must_use]
pub fn onsets_near(
    signal: &[f64],
    rate: SampleRate,
    strikes: &[usize],
    cfg: &StepConfig,
) -> Vec<usize> {
    let env = centred_rms(signal, rate.samples_in(Seconds(0.005)), Edges::Zeros);
    let loudest = env.iter().copied().fold(0.0, f64::max);
    let threshold = loudest * Decibels(-cfg.onset_range.0).to_amplitude();
    let before = rate.samples_in(cfg.before);
    let gap = rate.samples_in(cfg.onset_gap);
    strikes
        .iter()
        .enumerate()
        .map(|(i, &s)| {
            let previous = if i == 0 { 0 } else { strikes[i - 1] + 1 };
            let start = s.saturating_sub(before).max(previous).max(1);
            let end = strikes
                .get(i + 1)
                .map_or(usize::MAX, |&n| n)
                .min(s.saturating_add(gap))
                .min(env.len());
            (start..end)
                .find(|&n| env[n - 1] <= threshold && env[n] > threshold)
                .unwrap_or(s)
        })
        .collect()
}

/// As [`describe_all`] with the steps' strikes given (seconds into `samples`, ascending),
/// each step measured from its onset near its strike ([`onsets_near`]).
///
/// # Errors
/// As [`band_limit`].
pub fn describe_struck(
    samples: &[f64],
    rate: SampleRate,
    strikes: &[Seconds],
    cfg: &StepConfig,
) -> Result<Vec<Step>, AnalysisError> {
    let y = band_limit(samples, rate, cfg)?;
    let strikes: Vec<usize> = strikes.iter().map(|t| rate.samples_in(*t)).collect();
    Ok(describe_onsets(
        &y,
        rate,
        &onsets_near(&y, rate, &strikes, cfg),
        cfg,
        true,
    ))
}

/// Every step of `samples` (not band-limited): at `onsets` (seconds into `samples`) when
/// given, else where [`find_steps`] finds them. Each stretch stops where the next starts.
///
/// # Errors
/// As [`band_limit`].
pub fn describe_all(
    samples: &[f64],
    rate: SampleRate,
    onsets: Option<&[Seconds]>,
    cfg: &StepConfig,
) -> Result<Vec<Step>, AnalysisError> {
    describe_all_with(samples, rate, onsets, cfg, true)
}

/// As [`describe_all`], with the band spectra only if `spectrum` ([`describe_with`]).
pub(crate) fn describe_all_with(
    samples: &[f64],
    rate: SampleRate,
    onsets: Option<&[Seconds]>,
    cfg: &StepConfig,
    spectrum: bool,
) -> Result<Vec<Step>, AnalysisError> {
    let y = band_limit(samples, rate, cfg)?;
    let onsets: Vec<usize> = match onsets {
        Some(t) => t.iter().map(|t| rate.samples_in(*t)).collect(),
        None => find_steps(&y, rate, cfg),
    };
    Ok(describe_onsets(&y, rate, &onsets, cfg, spectrum))
}

/// The steps of a band-limited `y` at `onsets` (sample indices), each cut where the next
/// one's stretch begins.
fn describe_onsets(
    y: &[f64],
    rate: SampleRate,
    onsets: &[usize],
    cfg: &StepConfig,
    spectrum: bool,
) -> Vec<Step> {
    let before = rate.samples_in(cfg.before);
    onsets
        .iter()
        .enumerate()
        .map(|(i, &o)| {
            let limit = onsets
                .get(i + 1)
                .map_or(usize::MAX, |next| next.saturating_sub(before));
            describe_with(y, rate, o, limit, cfg, spectrum)
        })
        .collect()
}

fn energy_duration(x: &[f64], rate: SampleRate) -> Seconds {
    let total: f64 = x.iter().map(|v| v * v).sum();
    if total <= 0.0 {
        return Seconds(0.0);
    }
    let mut acc = 0.0;
    let (mut first, mut last) = (None, None);
    for (i, v) in x.iter().enumerate() {
        acc += v * v;
        if first.is_none() && acc >= 0.05 * total {
            first = Some(i);
        }
        if acc >= 0.95 * total {
            last = Some(i);
            break;
        }
    }
    match (first, last) {
        (Some(a), Some(b)) => rate.duration_of(b - a),
        _ => Seconds(0.0),
    }
}

fn micro_events(x: &[f64], rate: SampleRate, onset: usize, cfg: &StepConfig) -> Vec<MicroEvent> {
    let env = centred_rms(x, rate.samples_in(cfg.envelope), Edges::Zeros);
    let loudest = env.iter().copied().fold(0.0, f64::max);
    if loudest <= 0.0 {
        return Vec::new();
    }
    let db: Vec<f64> = env
        .iter()
        .map(|e| 20.0 * (e / loudest).max(1e-15).log10())
        .collect();
    let peaks = find_peaks(
        &db,
        -cfg.event_range.0,
        rate.samples_in(cfg.event_separation).max(1),
        cfg.event_prominence.0,
    );
    peaks
        .into_iter()
        .map(|p| MicroEvent {
            time: Seconds((p as f64 - onset as f64) / rate.hz()),
            level: Decibels(db[p]),
        })
        .collect()
}

/// The local maxima of `y` (the middle of a flat top) at least `height`, then thinned to
/// one per `distance` samples (the higher kept), then those at least `prominence`
/// prominent: `scipy.signal.find_peaks` with those three arguments.
fn find_peaks(y: &[f64], height: f64, distance: usize, prominence: f64) -> Vec<usize> {
    let n = y.len();
    let mut peaks = Vec::new();
    let mut i = 1;
    while i + 1 < n {
        if y[i - 1] < y[i] {
            let mut ahead = i + 1;
            while ahead + 1 < n && y[ahead] == y[i] {
                ahead += 1;
            }
            if y[ahead] < y[i] {
                peaks.push((i + ahead - 1) / 2);
                i = ahead;
            }
        }
        i += 1;
    }
    peaks.retain(|&p| y[p] >= height);
    // Distance: from the highest down, each peak removes its lower neighbours within
    // `distance` (of two equal peaks the earlier goes first).
    let mut keep = vec![true; peaks.len()];
    let mut order: Vec<usize> = (0..peaks.len()).collect();
    order.sort_by(|&a, &b| y[peaks[b]].total_cmp(&y[peaks[a]]).then(a.cmp(&b)));
    for &k in &order {
        if !keep[k] {
            continue;
        }
        let mut j = k;
        while j > 0 && peaks[k] - peaks[j - 1] < distance {
            j -= 1;
            keep[j] = false;
        }
        let mut j = k + 1;
        while j < peaks.len() && peaks[j] - peaks[k] < distance {
            keep[j] = false;
            j += 1;
        }
    }
    let peaks: Vec<usize> = peaks
        .into_iter()
        .zip(keep)
        .filter_map(|(p, k)| k.then_some(p))
        .collect();
    peaks
        .into_iter()
        .filter(|&p| {
            let side_min = |range: &mut dyn Iterator<Item = usize>| {
                let mut low = y[p];
                for j in range {
                    if y[j] > y[p] {
                        break;
                    }
                    low = low.min(y[j]);
                }
                low
            };
            let left = side_min(&mut (0..p).rev());
            let right = side_min(&mut (p + 1..n));
            y[p] - left.max(right) >= prominence
        })
        .collect()
}

fn crest(x: &[f64]) -> Decibels {
    let peak = true_peak(x);
    let rms = (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt();
    if rms > 0.0 {
        Decibels::from_amplitude(peak / rms)
    } else {
        Decibels(0.0)
    }
}

/// Half the length of the interpolation kernel of [`true_peak`], in samples.
const PEAK_TAPS: usize = 16;

/// The largest `|x(t)|` of the band-limited signal whose samples are `x`, between samples
/// too: `x(t) = Σ_n x[n] sinc(t - n) w(t - n)`, `w` a Hann window over `±PEAK_TAPS`,
/// evaluated at eighths of a sample within one sample of each local maximum of `|x|`
/// within 3 dB of the largest sample. Between two samples a band-limited signal can
/// peak above both by up to `1/cos(π f_max / f_s)`: 2.4 dB at 4 kHz for a 900 Hz band,
/// 0.01 dB at 48 kHz; where the true peak is within a sample of the largest samples.
fn true_peak(x: &[f64]) -> f64 {
    let largest = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if largest <= 0.0 || largest.is_nan() || x.len() < 3 {
        return largest;
    }
    // The kernel at the offsets `k / 8` (k in -7..=7) from a sample: the same 15 rows of
    // taps for every local maximum, so they are computed once.
    let weights = peak_weights();
    let at = |i: usize, k: i32| -> f64 {
        // The point `t = i + k/8`; its taps run over `n` from `floor(t) - PEAK_TAPS + 1`.
        let base = i as isize + if k < 0 { -1 } else { 0 };
        let row = &weights[(k + 7) as usize];
        let mut acc = 0.0;
        for (j, (sinc, w)) in row.iter().enumerate() {
            let n = base - PEAK_TAPS as isize + 1 + j as isize;
            if n < 0 || n as usize >= x.len() {
                continue;
            }
            acc += x[n as usize] * sinc * w;
        }
        acc
    };
    let mut peak = largest;
    for i in 1..x.len() - 1 {
        let v = x[i].abs();
        if v >= 0.7 * largest && v >= x[i - 1].abs() && v >= x[i + 1].abs() {
            for k in -7..=7 {
                peak = peak.max(at(i, k).abs());
            }
        }
    }
    peak
}

/// The interpolation kernel of [`true_peak`], `sinc(d)` and `w(d)` (a Hann window over
/// `±PEAK_TAPS`), at the point `t = i + k/8` (row `k + 7`, `k` in -7..=7) for the
/// `2 PEAK_TAPS` samples `n` from `floor(t) - PEAK_TAPS + 1` on (`d = t - n`; 0 where
/// `|d|` reaches `PEAK_TAPS`).
fn peak_weights() -> &'static [[(f64, f64); 2 * PEAK_TAPS]; 15] {
    static WEIGHTS: std::sync::OnceLock<[[(f64, f64); 2 * PEAK_TAPS]; 15]> =
        std::sync::OnceLock::new();
    WEIGHTS.get_or_init(|| {
        let half = PEAK_TAPS as f64;
        let mut rows = [[(0.0, 0.0); 2 * PEAK_TAPS]; 15];
        for (r, row) in rows.iter_mut().enumerate() {
            let k = r as i32 - 7;
            // `t - floor(t)`, exact: eighths are exact in binary.
            let frac = f64::from(k.rem_euclid(8)) / 8.0;
            for (j, w) in row.iter_mut().enumerate() {
                let d = frac + half - 1.0 - j as f64;
                if d.abs() >= half {
                    continue;
                }
                let sinc = if d == 0.0 {
                    1.0
                } else {
                    (std::f64::consts::PI * d).sin() / (std::f64::consts::PI * d)
                };
                *w = (sinc, 0.5 + 0.5 * (std::f64::consts::PI * d / half).cos());
            }
        }
        rows
    })
}

fn decay(x: &[f64], bin: usize) -> Vec<f64> {
    let energies: Vec<f64> = x
        .chunks(bin)
        .map(|c| c.iter().map(|v| v * v).sum())
        .collect();
    let loudest = energies.iter().copied().fold(0.0, f64::max);
    energies
        .iter()
        .map(|e| {
            if loudest > 0.0 {
                10.0 * (e / loudest).max(1e-15).log10()
            } else {
                -150.0
            }
        })
        .collect()
}

fn band_powers(x: &[f64], rate: SampleRate, centres: &[f64], fraction: f64) -> Vec<f64> {
    let n_fft = (4 * x.len().max(2)).next_power_of_two();
    let mut plan = crate::signal::spectrum::SpectrumPlan::new(n_fft);
    let mut mag = vec![0.0; n_fft / 2 + 1];
    // The window is no longer than the FFT, so the plan cannot refuse it.
    if plan.magnitude(x, &mut mag).is_err() {
        return vec![0.0; centres.len()];
    }
    let bin_hz = rate.hz() / n_fft as f64;
    for m in &mut mag {
        *m /= rate.hz();
    }
    let half = 2f64.powf(0.5 / fraction);
    centres
        .iter()
        .map(|c| {
            let lo = (c / half / bin_hz).ceil() as usize;
            let hi = ((c * half / bin_hz).ceil() as usize).min(mag.len());
            if hi <= lo {
                let k = ((c / bin_hz).round() as usize).min(mag.len() - 1);
                return mag[k] * mag[k];
            }
            mag[lo..hi].iter().map(|m| m * m).sum::<f64>() / (hi - lo) as f64
        })
        .collect()
}

/// Gain-aligned log-spectral distance between two band spectra (powers), dB.
fn aligned_distance(a: &[f64], b: &[f64]) -> f64 {
    let db = |p: &[f64]| -> Vec<f64> { p.iter().map(|v| 10.0 * v.max(1e-300).log10()).collect() };
    gain_aligned_level_distance_db(&db(b), &db(a))
}

/// The mean over every pair of `steps` of the gain-aligned distance between their band
/// spectra, dB; `None` for fewer than two steps.
#[must_use]
pub fn spread(steps: &[Step]) -> Option<f64> {
    let mut sum = 0.0;
    let mut pairs = 0usize;
    for (i, a) in steps.iter().enumerate() {
        for b in &steps[i + 1..] {
            sum += aligned_distance(&a.bands, &b.bands);
            pairs += 1;
        }
    }
    (pairs > 0).then(|| sum / pairs as f64)
}

/// The mean band power of `steps`.
fn mean_bands(steps: &[Step]) -> Vec<f64> {
    let n = steps.first().map_or(0, |s| s.bands.len());
    let mut mean = vec![0.0; n];
    for s in steps {
        for (m, b) in mean.iter_mut().zip(&s.bands) {
            *m += b / steps.len() as f64;
        }
    }
    mean
}

/// The gain-aligned log-spectral distance between the average band spectra of two sets of
/// steps, dB.
#[must_use]
pub fn spectrum_distance(a: &[Step], b: &[Step]) -> f64 {
    aligned_distance(&mean_bands(a), &mean_bands(b))
}

/// The median of `values` (0 for none).
fn median_of(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        0.0
    } else {
        crate::numeric::median(&mut values)
    }
}

/// What `steps` have in common (see [`StepSummary`]); `cfg` gives the band centres.
#[must_use]
pub fn summarize(steps: &[Step], cfg: &StepConfig) -> StepSummary {
    let levels: Vec<f64> = steps
        .iter()
        .flat_map(|s| s.events.iter().map(|e| e.level.0))
        .collect();
    let quartile = |p: f64| crate::numeric::percentile(&levels, p).unwrap_or(0.0);
    let bins = steps.iter().map(|s| s.decay_db.len()).max().unwrap_or(0);
    let decay_db = (0..bins)
        .map(|k| {
            median_of(
                steps
                    .iter()
                    .map(|s| s.decay_db.get(k).copied().unwrap_or(-150.0))
                    .collect(),
            )
        })
        .collect();
    let bin = cfg.decay_bin.0.max(1e-4);
    let mut event_rate_hz_by_bin = vec![0.0; bins];
    for s in steps {
        for e in &s.events {
            let b = (e.time.0 / bin).floor();
            if b >= 0.0 && (b as usize) < bins {
                event_rate_hz_by_bin[b as usize] += 1.0 / (bin * steps.len() as f64);
            }
        }
    }
    StepSummary {
        steps: steps.len(),
        event_rate_hz_by_bin,
        duration_ms: 1e3 * median_of(steps.iter().map(|s| s.duration.0).collect()),
        events: median_of(steps.iter().map(|s| s.events.len() as f64).collect()),
        event_rate_hz: median_of(steps.iter().map(Step::event_rate).collect()),
        interval_ms: 1e3
            * median_of(
                steps
                    .iter()
                    .flat_map(|s| s.intervals().map(|t| t.0))
                    .collect(),
            ),
        event_level_db: [quartile(0.25), quartile(0.5), quartile(0.75)],
        crest_db: median_of(steps.iter().map(|s| s.crest.0).collect()),
        spread_db: spread(steps),
        decay_db,
        bands_hz: band_centres(cfg),
        spectrum_db: mean_bands(steps)
            .iter()
            .map(|p| 10.0 * p.max(1e-300).log10())
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;

    fn rate() -> SampleRate {
        SampleRate(8000)
    }

    #[test]
    fn the_peak_between_samples_is_found() {
        // A 900 Hz pulse at 4 kHz centred half-way between two samples: the largest
        // sample is 2.4 dB under the pulse's peak (1), the true peak within 0.05 dB.
        let fs = 4000.0;
        let pulse = |t: f64| {
            let d = t - 200.5 / fs;
            (-(d * 1e3).powi(2) / 2.0).exp() * (2.0 * std::f64::consts::PI * 900.0 * d).cos()
        };
        let x: Vec<f64> = (0..400).map(|n| pulse(f64::from(n) / fs)).collect();
        let largest = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let fine = 1.0;
        assert!(20.0 * (fine / largest).log10() > 0.5, "{largest} vs {fine}");
        let got = true_peak(&x);
        assert!(
            (20.0 * (got / fine).log10()).abs() < 0.05,
            "{got} vs {fine} (largest sample {largest})"
        );
        assert_eq!(true_peak(&[0.0; 8]), 0.0);
        assert_eq!(true_peak(&[1.0]), 1.0);
    }

    #[test]
    fn peaks_follow_scipy_rules() {
        // Two peaks 2 samples apart: the lower goes with distance 3.
        let y = [0.0, 5.0, 1.0, 4.0, 0.0, 0.0, 3.0, 2.9, 3.0, 0.0];
        assert_eq!(find_peaks(&y, -1.0, 1, 0.0), vec![1, 3, 6, 8]);
        assert_eq!(find_peaks(&y, -1.0, 3, 0.0), vec![1, 6]);
        // Prominence: 8's 3.0 stands 3 over the lowest point before the 4.0 at 3 (the dip
        // to 2.9 does not bound it: 6 is no higher); 3's 4.0 stands 3 over its left dip.
        assert_eq!(find_peaks(&y, -1.0, 1, 0.5), vec![1, 3, 6, 8]);
        assert_eq!(find_peaks(&y, -1.0, 1, 3.5), vec![1]);
        // A flat top's middle.
        assert_eq!(
            find_peaks(&[0.0, 2.0, 2.0, 2.0, 0.0], -1.0, 1, 0.0),
            vec![2]
        );
        assert_eq!(find_peaks(&y, 3.5, 1, 0.0), vec![1, 3]);
    }

    #[test]
    fn onsets_follow_strikes_to_where_the_sound_starts() {
        // Two bursts 15 ms after their strikes; a third strike on a tail still ringing
        // and a fourth that makes no sound keep their strike times.
        let r = rate();
        let mut y = vec![0.0; 5 * 8000];
        let burst = |y: &mut Vec<f64>, at: usize, len: usize| {
            for (n, v) in y[at..at + len].iter_mut().enumerate() {
                *v = (2.0 * std::f64::consts::PI * 200.0 * n as f64 / 8000.0).sin();
            }
        };
        burst(&mut y, 8000 + 120, 400);
        burst(&mut y, 16_000 + 120, 400);
        burst(&mut y, 24_000 - 2000, 2400);
        let strikes = [8000, 16_000, 24_000, 32_000];
        let on = onsets_near(&y, r, &strikes, &StepConfig::default());
        // The 5 ms envelope is centred: it rises about 20 samples ahead of the burst.
        assert!((100..=120).contains(&(on[0] - 8000)), "{on:?}");
        assert_eq!(on[1] - on[0], 8000, "{on:?}");
        assert_eq!(&on[2..], &[24_000, 32_000], "{on:?}");
        let cfg = StepConfig::default();
        let yb = band_limit(&y, r, &cfg).unwrap();
        let steps = describe_struck(&y, r, &[Seconds(1.0), Seconds(2.0)], &cfg).unwrap();
        // Measured on the band-limited signal, whose zero-phase filter rings ahead of the
        // burst (here 19 ms): where that rises, as a recording's onset is found.
        let ahead = onsets_near(&yb, r, &strikes[..2], &cfg);
        assert!(ahead[0] > 8000 - 400 && ahead[0] < on[0], "{ahead:?}");
        assert_eq!(ahead[1] - ahead[0], 8000, "{ahead:?}");
        assert!((steps[0].onset.0 - ahead[0] as f64 / 8000.0).abs() < 1e-12);
    }

    #[test]
    fn a_click_train_is_counted_and_timed() {
        // Ten 400 Hz bursts of 2 ms, 20 ms apart, equal level: ten events, D90 about the
        // train's length.
        let fs = rate();
        let mut x = vec![0.0; fs.samples_in(Seconds(1.0))];
        let onset = fs.samples_in(Seconds(0.2));
        for k in 0..10 {
            let at = onset + k * fs.samples_in(Seconds(0.02));
            for n in 0..16 {
                x[at + n] = (std::f64::consts::TAU * 400.0 * n as f64 / 8000.0).sin();
            }
        }
        let cfg = StepConfig::default();
        let steps = describe_all(&x, fs, None, &cfg).unwrap();
        assert_eq!(steps.len(), 1);
        let s = &steps[0];
        // The onset is where the 5 ms envelope of the zero-phase band-limited signal
        // comes within 40 dB of the loudest: its pre-ringing gets there a little early.
        assert!((0.18..=0.2).contains(&s.onset.0), "{:?}", s.onset);
        assert_eq!(s.events.len(), 10, "{:?}", s.events);
        assert!((0.16..0.2).contains(&s.duration.0), "{:?}", s.duration);
        let first = s.events[0].time.0;
        assert!((0.0..0.02).contains(&first), "{first}");
        for (k, e) in s.events.iter().enumerate() {
            assert!((e.time.0 - first - 0.02 * k as f64).abs() < 1e-3, "{e:?}");
        }
        let intervals: Vec<f64> = s.intervals().map(|t| t.0).collect();
        assert!(intervals.iter().all(|t| (t - 0.02).abs() < 1e-3));
    }

    #[test]
    fn spread_is_zero_for_copies_and_gain_blind() {
        let fs = rate();
        let mut g = SplitMix64::new(3);
        let burst: Vec<f64> = (0..800).map(|_| g.symmetric()).collect();
        let mut x = vec![0.0; 16_000];
        x[1000..1800].copy_from_slice(&burst);
        for (i, v) in burst.iter().enumerate() {
            x[9000 + i] = 4.0 * v;
        }
        let cfg = StepConfig::default();
        let steps = describe_all(&x, fs, None, &cfg).unwrap();
        assert_eq!(steps.len(), 2);
        // The same burst 12 dB louder: the same step but for the onset, found a sample or
        // so apart at the two levels.
        assert!(spread(&steps).unwrap() < 0.05, "{:?}", spread(&steps));
        assert!(spectrum_distance(&steps[..1], &steps[1..]) < 0.05);
        let summary = summarize(&steps, &cfg);
        assert_eq!(summary.steps, 2);
        assert_eq!(summary.bands_hz.len(), summary.spectrum_db.len());
    }

    #[test]
    fn a_lone_impulse_is_short_and_peaky() {
        let fs = rate();
        let mut x = vec![0.0; 8000];
        x[2000] = 1.0;
        let cfg = StepConfig::default();
        let s = &describe_all(&x, fs, None, &cfg).unwrap()[0];
        assert!(s.duration.0 < 0.01, "{:?}", s.duration);
        assert!(s.events.len() <= 2, "{:?}", s.events);
        assert!(s.crest.0 > 20.0, "{:?}", s.crest);
    }

    #[test]
    fn band_centres_are_sixth_octaves_inside_the_band() {
        let c = band_centres(&StepConfig::default());
        assert_eq!(c.len(), 32);
        assert!((c[0] - 20.0 * 2f64.powf(1.0 / 12.0)).abs() < 1e-9);
        assert!(c.last().unwrap() * 2f64.powf(1.0 / 12.0) <= 900.0);
    }
}
