//! The conditioning chain of the IIR paper (section III-A) on a synthetic heel strike:
//! Savitzky-Golay denoising at the recording rate, resampling to the analysis rate,
//! zero-phase Butterworth band-pass, then a smoothed magnitude spectrum.

use std::f64::consts::PI;

use underfoot::signal::butterworth::bandpass;
use underfoot::signal::filtfilt::filtfilt;
use underfoot::signal::resample::resample;
use underfoot::signal::savgol::SavitzkyGolay;
use underfoot::signal::spectrum::{SpectrumPlan, fractional_octave_smooth};
use underfoot::units::{Band, Decibels, Hz, SampleRate};

/// A 70 Hz resonance decaying in ~50 ms, starting at `onset` seconds.
fn strike(t: f64, onset: f64) -> f64 {
    let u = t - onset;
    if u < 0.0 {
        0.0
    } else {
        (-u / 0.05).exp() * (2.0 * PI * 70.0 * u).sin()
    }
}

#[test]
fn chain_recovers_a_strike_from_trend_and_noise() {
    let (rec, analysis) = (SampleRate(48_000), SampleRate(2000));
    let band = Band::new(35.0, 120.0);
    let n = rec.0 as usize;
    let mut seed = 0x2545_F491_4F6C_DD1Du64;
    let mut noise = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    // Strike + the slow swing of the foot + broadband sensor noise.
    let raw: Vec<f64> = (0..n)
        .map(|i| {
            let t = i as f64 / rec.hz();
            strike(t, 0.3) + 2.0 * (2.0 * PI * 1.5 * t).sin() + 0.2 * noise()
        })
        .collect();

    let sg = SavitzkyGolay::widest_within(rec, Hz(900.0), Decibels(0.1), 3, 501).unwrap();
    let smooth = sg.apply(&raw).unwrap();
    let low = resample(&smooth, rec, analysis).unwrap();
    let bp = bandpass(4, band, analysis).unwrap();
    let cleaned = filtfilt(&bp, &low).unwrap();

    // The same band-pass applied to the clean strike sampled directly at the analysis rate.
    let clean: Vec<f64> = (0..low.len())
        .map(|m| strike(m as f64 / analysis.hz(), 0.3))
        .collect();
    let reference = filtfilt(&bp, &clean).unwrap();
    let err: f64 = cleaned
        .iter()
        .zip(&reference)
        .map(|(a, b)| (a - b).powi(2))
        .sum();
    let energy: f64 = reference.iter().map(|v| v * v).sum();
    let nrmse = (err / energy).sqrt();
    assert!(nrmse < 0.05, "normalised RMS error {nrmse}");

    // Its spectrum peaks at the resonance.
    let strike_part = &cleaned[500..1500];
    let mut plan = SpectrumPlan::new(2000);
    let mut mag = vec![0.0; 1001];
    plan.magnitude(strike_part, &mut mag).unwrap();
    let smoothed = fractional_octave_smooth(&mag, 1.0, 6.0);
    let peak = (1..smoothed.len())
        .max_by(|&a, &b| smoothed[a].total_cmp(&smoothed[b]))
        .unwrap();
    assert!((peak as f64 - 70.0).abs() <= 3.0, "peak at {peak} Hz");
}
