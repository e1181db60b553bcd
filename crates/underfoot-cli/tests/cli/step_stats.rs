//! The tests' own measure of a step in time, written from the definitions and
//! kept apart from the library's (`underfoot::analysis::steps`, which the excitation is
//! fitted with): a render is judged by a ruler the fit never saw. It borrows only signal
//! primitives that are tested against scipy elsewhere (the Butterworth design, the FFT
//! magnitude).
//!
//! Both sides are band-limited to 20-900 Hz (4th-order Butterworth band-pass, run forward
//! and backward on the signal padded with a second of silence at each end). A step starts
//! where the 5 ms RMS envelope first comes within 40 dB of the signal's loudest after
//! 300 ms below it, and is cut from 50 ms before to 600 ms after that:
//!
//! - **D90**: from 5% to 95% of the step's cumulative energy;
//! - **micro-events**: peaks of the 1.5 ms RMS envelope at most 25 dB under its maximum,
//!   at least 3 ms from a higher one, at least 6 dB prominent;
//! - **crest**: peak over RMS of the 350 ms from 50 ms before the onset;
//! - **spectrum**: the power in sixth-octave bands from 20 to 900 Hz (rate-normalised),
//!   whose gain-aligned log-spectral distance between two steps is their **spread**.

use underfoot::signal::butterworth;
use underfoot::signal::spectrum::SpectrumPlan;
use underfoot::units::{Band, SampleRate};

/// One step's figures.
#[derive(Debug, Clone)]
pub struct StepFigures {
    pub onset: usize,
    pub d90_ms: f64,
    pub events: usize,
    pub crest_db: f64,
    pub peak: f64,
    pub bands: Vec<f64>,
}

fn band_limited(x: &[f64], rate: u32) -> Vec<f64> {
    let sos = butterworth::bandpass(4, Band::new(20.0, 900.0), SampleRate(rate)).unwrap();
    let pad = rate as usize;
    let mut y = vec![0.0; x.len() + 2 * pad];
    y[pad..pad + x.len()].copy_from_slice(x);
    sos.filter_in_place(&mut y);
    y.reverse();
    sos.filter_in_place(&mut y);
    y.reverse();
    y[pad..pad + x.len()].to_vec()
}

/// Centred moving RMS over `n` samples.
fn rms(x: &[f64], n: usize) -> Vec<f64> {
    let mut acc = vec![0.0; x.len() + 1];
    for (i, v) in x.iter().enumerate() {
        acc[i + 1] = acc[i] + v * v;
    }
    (0..x.len())
        .map(|i| {
            let lo = i.saturating_sub(n / 2);
            let hi = (i + n - n / 2).min(x.len());
            ((acc[hi] - acc[lo]).max(0.0) / n as f64).sqrt()
        })
        .collect()
}

/// Peaks at least `height`, thinned to one per `distance` (the higher kept), at least
/// `prominence` above the higher of their two surrounding minima.
fn peaks(y: &[f64], height: f64, distance: usize, prominence: f64) -> usize {
    let mut found: Vec<usize> = (1..y.len().saturating_sub(1))
        .filter(|&i| y[i] > y[i - 1] && y[i] >= y[i + 1] && y[i] >= height)
        .collect();
    let mut by_height = found.clone();
    by_height.sort_by(|a, b| y[*b].total_cmp(&y[*a]).then(a.cmp(b)));
    let mut removed = std::collections::HashSet::new();
    for &p in &by_height {
        if removed.contains(&p) {
            continue;
        }
        for &q in &found {
            if q != p && q.abs_diff(p) < distance && !removed.contains(&q) {
                removed.insert(q);
            }
        }
    }
    found.retain(|p| !removed.contains(p));
    found
        .iter()
        .filter(|&&p| {
            let side = |it: &mut dyn Iterator<Item = usize>| {
                let mut low = y[p];
                for j in it {
                    if y[j] > y[p] {
                        break;
                    }
                    low = low.min(y[j]);
                }
                low
            };
            let (l, r) = (side(&mut (0..p).rev()), side(&mut (p + 1..y.len())));
            y[p] - l.max(r) >= prominence
        })
        .count()
}

/// The steps of `x` at `rate`.
pub fn steps(x: &[f64], rate: u32) -> Vec<StepFigures> {
    let fs = f64::from(rate);
    let y = band_limited(x, rate);
    let env5 = rms(&y, (0.005 * fs).round() as usize);
    let loudest = env5.iter().copied().fold(0.0, f64::max);
    let threshold = loudest * 10f64.powf(-40.0 / 20.0);
    let gap = (0.3 * fs) as usize;
    let mut onsets = Vec::new();
    let mut last: Option<usize> = None;
    for (i, e) in env5.iter().enumerate() {
        if *e > threshold {
            if last.is_none_or(|l| i - l > gap) {
                onsets.push(i);
            }
            last = Some(i);
        }
    }
    let (before, after) = ((0.05 * fs) as usize, (0.6 * fs) as usize);
    onsets
        .iter()
        .map(|&o| {
            let mut w = vec![0.0; before + after];
            for (k, v) in w.iter_mut().enumerate() {
                let n = o as isize - before as isize + k as isize;
                if n >= 0 && (n as usize) < y.len() {
                    *v = y[n as usize];
                }
            }
            figures(o, &w, fs, before)
        })
        .collect()
}

fn figures(onset: usize, w: &[f64], fs: f64, before: usize) -> StepFigures {
    let total: f64 = w.iter().map(|v| v * v).sum();
    let mut acc = 0.0;
    let (mut a, mut b) = (0, 0);
    for (i, v) in w.iter().enumerate() {
        acc += v * v;
        if acc < 0.05 * total {
            a = i + 1;
        }
        if acc < 0.95 * total {
            b = i + 1;
        }
    }
    let env = rms(w, (0.0015 * fs).round() as usize);
    let top = env.iter().copied().fold(0.0, f64::max);
    let db: Vec<f64> = env
        .iter()
        .map(|e| 20.0 * (e / top).max(1e-15).log10())
        .collect();
    let events = peaks(&db, -25.0, (0.003 * fs).round() as usize, 6.0);
    let span = &w[..((before as f64 + 0.3 * fs) as usize).min(w.len())];
    let peak = span.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let r = (span.iter().map(|v| v * v).sum::<f64>() / span.len() as f64).sqrt();
    let whole_peak = w.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    StepFigures {
        onset,
        d90_ms: 1e3 * (b - a) as f64 / fs,
        events,
        crest_db: 20.0 * (peak / r).log10(),
        peak: whole_peak,
        bands: bands(w, fs),
    }
}

fn bands(w: &[f64], fs: f64) -> Vec<f64> {
    let n = (4 * w.len()).next_power_of_two();
    let mut plan = SpectrumPlan::new(n);
    let mut mag = vec![0.0; n / 2 + 1];
    plan.magnitude(w, &mut mag).unwrap();
    let bin = fs / n as f64;
    let half = 2f64.powf(1.0 / 12.0);
    let mut out = Vec::new();
    let mut c = 20.0 * half;
    while c * half <= 900.0 * (1.0 + 1e-9) {
        let (lo, hi) = (
            (c / half / bin).ceil() as usize,
            (c * half / bin).ceil() as usize,
        );
        let p: f64 =
            mag[lo..hi].iter().map(|m| (m / fs).powi(2)).sum::<f64>() / (hi - lo).max(1) as f64;
        out.push(p);
        c *= half * half;
    }
    out
}

fn aligned_distance(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(x, y)| 10.0 * (x / y).log10())
        .collect();
    let m = d.iter().sum::<f64>() / d.len() as f64;
    (d.iter().map(|v| (v - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
}

/// Median.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The mean distance between two steps; `None` for fewer than two.
pub fn spread(steps: &[StepFigures]) -> Option<f64> {
    let mut sum = 0.0;
    let mut n = 0;
    for (i, a) in steps.iter().enumerate() {
        for b in &steps[i + 1..] {
            sum += aligned_distance(&a.bands, &b.bands);
            n += 1;
        }
    }
    (n > 0).then(|| sum / f64::from(n))
}

/// The distance between the average spectra of two sets of steps.
pub fn spectrum_distance(a: &[StepFigures], b: &[StepFigures]) -> f64 {
    let mean = |s: &[StepFigures]| -> Vec<f64> {
        (0..s[0].bands.len())
            .map(|k| s.iter().map(|x| x.bands[k]).sum::<f64>() / s.len() as f64)
            .collect()
    };
    aligned_distance(&mean(a), &mean(b))
}

/// The medians of a set of steps: D90 (ms), micro-events, crest (dB).
pub fn medians(steps: &[StepFigures]) -> (f64, f64, f64) {
    (
        median(steps.iter().map(|s| s.d90_ms).collect()),
        median(steps.iter().map(|s| s.events as f64).collect()),
        median(steps.iter().map(|s| s.crest_db).collect()),
    )
}
