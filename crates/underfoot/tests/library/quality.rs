//! The quality gate on the shared footstep recordings: every material passes it (the
//! thresholds refuse nothing real), noise made from the same recordings is refused, and the
//! leave-one-recording-out distance of gravel (three recordings) is reported and sane.
//!
//! Needs `../shared/data/footsteps` (skipped with a note when absent, unless
//! `UNDERFOOT_REQUIRE_DATA=1`, as in CI).

use crate::common;

use underfoot::analysis::{AnalysisConfig, condition};
use underfoot::material::build::{BuildConfig, Progress, build_material};
use underfoot::material::quality::{
    QualityConfig, check_rates, check_recordings, leave_one_out, strike_to_noise,
};
use underfoot::recording::{Recording, read};

fn recordings(files: &[std::path::PathBuf]) -> Vec<Recording> {
    files
        .iter()
        .map(|p| read(p, None).unwrap_or_else(|e| panic!("{e}")))
        .collect()
}

/// Every shared recording passes the recording checks with room to spare, and no
/// material's recordings disagree beyond the warning threshold.
#[test]
#[ignore = "slow tier: real recordings"]
fn every_shared_recording_passes_the_gate() {
    let Some(root) = common::footsteps_dir() else {
        return;
    };
    let analysis = AnalysisConfig::default();
    let q = QualityConfig::default();
    let mut lowest = f64::INFINITY;
    let mut warnings = Vec::new();
    for (name, files) in common::footsteps_by_material(&root) {
        let recs = recordings(&files);
        check_rates(&recs, &analysis).unwrap_or_else(|e| panic!("{name}: {e}"));
        let checked =
            check_recordings(&recs, &analysis, &q).unwrap_or_else(|e| panic!("{name}: {e}"));
        for s in &checked.strike_to_noise {
            println!(
                "{name:<8} {:<32} SNR {:6.1} dB, {} strikes",
                s.file, s.snr.0, s.strikes
            );
            lowest = lowest.min(s.snr.0);
        }
        if let Some(d) = &checked.disagreement {
            for s in &d.recordings {
                println!("{name:<8} {:<32} spread {:5.2} dB", s.file, s.lsd.0);
            }
            if let Some(w) = d.warning() {
                warnings.push(format!("{name}: {w}"));
            }
        }
    }
    assert!(warnings.is_empty(), "{warnings:#?}");
    assert!(
        lowest >= q.min_strike_to_noise.0 + 1.0,
        "lowest strike-to-noise {lowest:.1} dB is within 1 dB of the threshold"
    );
}

/// White noise as loud as each recording's peak, at its rate and length, is refused.
#[test]
#[ignore = "slow tier: real recordings"]
fn noise_from_the_shared_recordings_is_refused() {
    let Some(root) = common::footsteps_dir() else {
        return;
    };
    let analysis = AnalysisConfig::default();
    let q = QualityConfig::default();
    let mut rng = underfoot::signal::noise::SplitMix64::new(7);
    for (name, files) in common::footsteps_by_material(&root) {
        let rec = &recordings(&files)[0];
        // Loud white noise at the recording's rate and length: as loud as its peak.
        let peak = rec.samples.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let noise = Recording {
            name: format!("{name}-noise"),
            samples: rec.samples.iter().map(|_| peak * rng.symmetric()).collect(),
            ..rec.clone()
        };
        let x = condition(&noise, &analysis).expect("conditions");
        let snr = strike_to_noise(&x, analysis.rate, &q);
        println!("{name:<8} noise SNR {:.1} dB", snr.0);
        assert!(snr.0 < q.min_strike_to_noise.0 - 2.0, "{name}: {snr}");
    }
}

/// Gravel's three recordings: leave each out in turn; the figures are finite, the
/// in-sample distance is no larger than the left-out one on average, and both are of the
/// order of a dB or a few (not tens: the recordings are of one ground).
#[test]
#[ignore = "slow tier: real recordings"]
fn leave_one_out_on_gravel() {
    let Some(root) = common::footsteps_dir() else {
        return;
    };
    let files = common::footsteps_by_material(&root)
        .into_iter()
        .find(|(n, _)| n == "gravel")
        .expect("gravel")
        .1;
    assert_eq!(files.len(), 3, "gravel has three recordings");
    let recs = recordings(&files);
    let cfg = BuildConfig {
        physical: None,
        ..BuildConfig::default()
    };
    let mut checked = None;
    let full = build_material("gravel", &recs, &cfg, &mut |p| {
        if let Progress::Checked(c) = p {
            checked = Some(c.clone());
        }
    })
    .expect("gravel fits");
    assert!(checked.is_some(), "the gate reported its figures");
    let loo = leave_one_out(&recs, &cfg, &full)
        .expect("leave-one-out runs")
        .expect("three recordings");
    assert_eq!(loo.held_out.len(), 3);
    for h in &loo.held_out {
        println!(
            "{:<32} order {:2}, left out {:.2} dB, in sample {:.2} dB, gain {:+.1} dB",
            h.file, h.order, h.lsd.0, h.in_sample_lsd.0, h.gain.0
        );
        assert!(
            h.lsd.0.is_finite() && h.lsd.0 > 0.0 && h.lsd.0 < 10.0,
            "{h:?}"
        );
        assert!(
            h.in_sample_lsd.0.is_finite() && h.in_sample_lsd.0 < 10.0,
            "{h:?}"
        );
    }
    println!(
        "mean: left out {:.2} dB, in sample {:.2} dB",
        loo.mean_lsd().0,
        loo.mean_in_sample_lsd().0
    );
    assert!(loo.mean_in_sample_lsd().0 <= loo.mean_lsd().0 + 1e-9);
    // One recording: nothing to leave out.
    let one = build_material("gravel1", &recs[..1], &cfg, &mut |_| {}).expect("fits");
    assert!(
        leave_one_out(&recs[..1], &cfg, &one)
            .expect("runs")
            .is_none()
    );
}
