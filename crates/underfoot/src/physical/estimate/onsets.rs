//! Steps 2 and 3 of the estimation: impact onsets, the event rate, and solid or aggregate.
//!
//! **Impact onsets and the event rate** ([`super::crumpling`]). At the recording's
//! rate, the Daubechies detail level whose band reaches closest to 12 kHz (level 2,
//! 6-12 kHz at 48 kHz, as in the tile paper; level 1 at 22.05 kHz) isolates impact onsets.
//! They are counted in each strike window (`K` per strike), and the crumpling measure
//! `I(t)` with the scale `a` of `N(t) = e^{a I(t)} - 1` is fitted so that the expected
//! number of events equals the count (recorded as `rate_scale`).
//!
//! **Solid or aggregate** ([`KindChoice::Auto`]). A solid answers
//! a step with one impact, whose energy arrives at once; an aggregate with a stream of
//! micro-impacts spread over the loading. The rule: the median time a strike takes to go
//! from 5% to 50% of its energy (at the recording's own rate; counting from the first 5%
//! rather than the detected onset keeps a quiet lead-in out of it), below
//! `solid_half_energy` (30 ms) for a solid.
//! On the shared recordings this puts concrete, wood, glass and ice with the solids
//! (0-17 ms) and gravel, sand, snow, dirt, grass, water and metal with the aggregates
//! (38-215 ms; the metal recordings are rattling gratings).

use super::crumpling::{crumpling_measure, estimate_rate_scale, impact_onsets};
use super::{EstimateConfig, EstimateError, KindChoice};
use crate::analysis::MeasuredResponse;
use crate::physical::model::GroundKind;
use crate::recording::Recording;
use crate::units::{SampleRate, Seconds};

/// What the onsets of the recordings say.
pub(super) struct StrikeEvents {
    /// Impact onsets per strike, on average.
    pub(super) onsets_per_strike: f64,
    /// The median time a strike takes from 5% to half its energy, in ms.
    pub(super) half_energy_ms: f64,
    /// The median over the recordings of the event-rate scale `a` (0 when no recording
    /// had an onset in a strike).
    pub(super) rate_scale: f64,
    /// Every impact onset of each recording.
    pub(super) onsets_by_recording: Vec<Vec<Seconds>>,
}

/// Counts the impact onsets of each strike of `measured` and times the arrival of its
/// energy, at each recording's own rate, and fits each recording's event-rate scale.
pub(super) fn analyse(
    recordings: &[Recording],
    measured: &MeasuredResponse,
    cfg: &EstimateConfig,
) -> Result<StrikeEvents, EstimateError> {
    let a = &cfg.analysis;
    // Per strike: its energy's arrival and its impact onsets, at the recording's rate.
    let mut half_energy = Vec::new();
    let mut onset_counts = Vec::new();
    let mut onsets_by_recording = Vec::with_capacity(recordings.len());
    let mut rate_scales = Vec::new();
    for (index, rec) in recordings.iter().enumerate() {
        let wrap = |source| EstimateError::Crumpling {
            name: rec.name.clone(),
            source,
        };
        let level = onset_level(rec.rate);
        let onsets =
            impact_onsets(&rec.samples, rec.rate, level, cfg.wavelet, &cfg.onsets).map_err(wrap)?;
        let strikes: Vec<f64> = measured
            .strikes
            .iter()
            .filter(|s| s.recording == index)
            .map(|s| s.onset.0)
            .collect();
        let mut count_here = 0;
        for &t0 in &strikes {
            let from = t0 - a.pre_onset.0;
            let to = t0 + a.strike_length.0;
            let n = onsets.iter().filter(|t| t.0 >= from && t.0 < to).count();
            onset_counts.push(n as f64);
            count_here += n;
            half_energy.push(half_energy_time(rec, from, to));
        }
        if count_here > 0 {
            let measure = crumpling_measure(&rec.samples, rec.rate, level, cfg.wavelet, cfg.window)
                .map_err(wrap)?;
            // Per recording: the expected count over it equals the onsets counted in it.
            let total = onsets.len();
            let scale = estimate_rate_scale(&measure, rec.rate, total).map_err(wrap)?;
            if scale > 0.0 {
                rate_scales.push(scale);
            }
        }
        onsets_by_recording.push(onsets);
    }
    Ok(StrikeEvents {
        onsets_per_strike: mean(&onset_counts),
        half_energy_ms: 1e3 * crate::numeric::median(&mut half_energy),
        rate_scale: if rate_scales.is_empty() {
            0.0
        } else {
            crate::numeric::median(&mut rate_scales)
        },
        onsets_by_recording,
    })
}

/// Solid or aggregate, as `choice` says: with [`KindChoice::Auto`], a solid when a
/// strike's energy arrives within `solid_half_energy`.
pub(super) fn ground_kind(
    choice: KindChoice,
    half_energy_ms: f64,
    solid_half_energy: Seconds,
) -> GroundKind {
    match choice {
        KindChoice::Fixed(k) => k,
        KindChoice::Auto if half_energy_ms < 1e3 * solid_half_energy.0 => GroundKind::Solid,
        KindChoice::Auto => GroundKind::Aggregate,
    }
}

/// The Daubechies level whose detail band's top is closest (in octaves) to 12 kHz.
fn onset_level(rate: SampleRate) -> usize {
    let distance = |j: usize| (rate.hz() / 2f64.powi(j as i32) / 12_000.0).log2().abs();
    (1..=6)
        .min_by(|&p, &q| distance(p).total_cmp(&distance(q)))
        .unwrap_or(2)
}

/// Seconds from the time 5% of the energy of `[from, to)` has arrived to the time half of
/// it has: how long a strike takes to deliver its energy, from its first sizeable part on
/// (so a detected onset a little early, or a quiet scuff before, does not count).
fn half_energy_time(rec: &Recording, from: f64, to: f64) -> f64 {
    let fs = rec.rate.hz();
    let lo = ((from.max(0.0)) * fs) as usize;
    let hi = ((to * fs) as usize).min(rec.samples.len());
    if hi <= lo {
        return 0.0;
    }
    let seg = &rec.samples[lo..hi];
    let total: f64 = seg.iter().map(|v| v * v).sum();
    let mut acc = 0.0;
    let mut start = None;
    for (i, v) in seg.iter().enumerate() {
        acc += v * v;
        if start.is_none() && acc >= 0.05 * total {
            start = Some(i);
        }
        if acc >= 0.5 * total {
            return (i - start.unwrap_or(i)) as f64 / fs;
        }
    }
    0.0
}

fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().sum::<f64>() / x.len() as f64
    }
}
