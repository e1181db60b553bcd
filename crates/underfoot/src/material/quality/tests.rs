use super::*;
use crate::analysis::{AnalysisConfig, condition};
use crate::fit::OrderChoice;
use crate::material::build::{BuildConfig, BuildError, build_material};
use crate::recording::Recording;
use crate::signal::noise::SplitMix64;
use crate::units::{Band, SampleRate};

const RATE: u32 = 8000;

/// Three seeded strikes through resonances at `f1` and `f2`, 2 s at 8 kHz, in a noise
/// floor of 1e-4.
fn strikes(name: &str, f1: f64, f2: f64, seed: u64) -> Recording {
    let mut rng = SplitMix64::new(seed);
    let fs = f64::from(RATE);
    let mut x: Vec<f64> = (0..2 * RATE as usize)
        .map(|_| 1e-4 * rng.symmetric())
        .collect();
    for onset in [0.2, 0.8, 1.4] {
        let start = (onset * fs) as usize;
        for n in 0..(0.4 * fs) as usize {
            let t = n as f64 / fs;
            let env = (-t / 0.04).exp();
            x[start + n] += 0.5
                * env
                * ((std::f64::consts::TAU * f1 * t).sin()
                    + 0.5 * (std::f64::consts::TAU * f2 * t).sin()
                    + 0.05 * rng.symmetric());
        }
    }
    recording(name, RATE, x)
}

fn recording(name: &str, rate: u32, samples: Vec<f64>) -> Recording {
    Recording {
        name: name.to_string(),
        rate: SampleRate(rate),
        samples,
        sha256: "00".repeat(32),
        excerpt: None,
    }
}

/// What a 16-bit file of nothing but its last bit holds: -1, 0 or +1 LSB.
fn lsb_noise(name: &str, seed: u64) -> Recording {
    let mut rng = SplitMix64::new(seed);
    let x = (0..2 * RATE as usize)
        .map(|_| ((rng.uniform() * 3.0).floor() - 1.0) / 32768.0)
        .collect();
    recording(name, RATE, x)
}

#[test]
fn rates_too_low_and_bands_above_nyquist_are_refused_with_a_band_that_fits() {
    let a = AnalysisConfig::default();
    let good = strikes("good.wav", 80.0, 300.0, 1);
    check_rates(std::slice::from_ref(&good), &a).expect("8 kHz holds 20-900 Hz");

    let one_hz = recording("one.wav", 1, vec![0.0, 1.0, 0.0, -1.0, 0.5, 0.2]);
    match check_rates(&[good.clone(), one_hz], &a) {
        Err(e @ QualityError::RateTooLow { .. }) => {
            let m = e.to_string();
            assert!(
                m.contains("one.wav (1 Hz)") && !m.contains("good.wav"),
                "{m}"
            );
            assert!(m.contains("at least 100 Hz"), "{m}");
        }
        other => panic!("{other:?}"),
    }

    let logger = recording("log.csv", 1000, vec![0.0; 1000]);
    match check_rates(&[good.clone(), logger], &a) {
        Err(
            e @ QualityError::BandAboveNyquist {
                suggested, needed, ..
            },
        ) => {
            assert_eq!(suggested, Band::new(20.0, 450.0));
            assert_eq!(needed, SampleRate(1801));
            let m = e.to_string();
            assert!(
                m.contains("log.csv (1000 Hz)") && !m.contains("good.wav"),
                "{m}"
            );
            assert!(m.contains("20-450 Hz"), "{m}");
        }
        other => panic!("{other:?}"),
    }
    // A band at or just below the Nyquist frequency: at is refused, below is not.
    let at = AnalysisConfig {
        band: Band::new(20.0, 500.0),
        ..a.clone()
    };
    let logger = recording("log.csv", 1000, vec![0.0; 1000]);
    assert!(check_rates(std::slice::from_ref(&logger), &at).is_err());
    let below = AnalysisConfig {
        band: Band::new(20.0, 450.0),
        ..a.clone()
    };
    check_rates(&[logger], &below).expect("450 Hz < 500 Hz");

    let analysis_too_slow = AnalysisConfig {
        rate: SampleRate(1000),
        ..a
    };
    match check_rates(&[good], &analysis_too_slow) {
        Err(QualityError::BandAboveAnalysisNyquist { suggested, .. }) => {
            assert_eq!(suggested, Band::new(20.0, 450.0));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn strike_to_noise_separates_strikes_from_noise() {
    let a = AnalysisConfig::default();
    let q = QualityConfig::default();
    let snr = |r: &Recording| strike_to_noise(&condition(r, &a).expect("c"), a.rate, &q).0;
    let strikes = snr(&strikes("s.wav", 80.0, 300.0, 2));
    assert!(strikes > 40.0, "strikes {strikes}");
    for seed in 0..5 {
        let lsb = snr(&lsb_noise("lsb.wav", seed));
        assert!(lsb < q.min_strike_to_noise.0 - 2.0, "LSB noise {lsb}");
        let mut rng = SplitMix64::new(seed);
        let white = recording(
            "w.wav",
            RATE,
            (0..4 * RATE as usize).map(|_| rng.normal()).collect(),
        );
        let white = snr(&white);
        assert!(white < q.min_strike_to_noise.0 - 1.0, "white noise {white}");
    }
    assert_eq!(
        strike_to_noise(&[0.0; 100], a.rate, &q).0,
        f64::NEG_INFINITY
    );
    assert_eq!(strike_to_noise(&[], a.rate, &q).0, f64::NEG_INFINITY);
}

#[test]
fn recordings_without_a_clear_strike_are_refused_by_name() {
    let a = AnalysisConfig::default();
    let q = QualityConfig::default();
    let lsb = lsb_noise("lsb.wav", 9);
    match check_recordings(std::slice::from_ref(&lsb), &a, &q) {
        Err(e @ QualityError::NoClearStrike { .. }) => {
            let m = e.to_string();
            assert!(m.contains("lsb.wav") && m.contains("dB short"), "{m}");
        }
        other => panic!("{other:?}"),
    }
    let good = strikes("good.wav", 80.0, 300.0, 3);
    match check_recordings(&[good.clone(), lsb, good.clone()], &a, &q) {
        Err(QualityError::NoClearStrike { files, .. }) => {
            assert_eq!(files.len(), 1);
            assert_eq!(files[0].file, "lsb.wav");
        }
        other => panic!("{other:?}"),
    }
    let ok = check_recordings(std::slice::from_ref(&good), &a, &q).expect("passes");
    assert_eq!(ok.strike_to_noise[0].strikes, 3);
    assert!(
        ok.disagreement.is_none(),
        "one recording: nothing to compare"
    );
    // Loud enough, but nothing the detector calls a strike: a steady tone.
    let tone = recording(
        "tone.wav",
        RATE,
        (0..2 * RATE as usize)
            .map(|n| {
                let t = n as f64 / f64::from(RATE);
                // Rises over the file, so its loudest 5 ms are far above its quietest.
                t * t * (std::f64::consts::TAU * 100.0 * t).sin()
            })
            .collect(),
    );
    let x = condition(&tone, &a).expect("c");
    let n = crate::recording::strikes::find_onsets(&x, a.rate, &a.onsets).len();
    if n == 0 {
        match check_recordings(&[good, tone], &a, &q) {
            Err(e @ QualityError::NoClearStrike { .. }) => {
                assert!(e.to_string().contains("finds no strike"), "{e}");
            }
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn the_odd_recording_out_is_named() {
    let a = AnalysisConfig::default();
    let q = QualityConfig::default();
    let alike: Vec<Recording> = (0..3)
        .map(|i| strikes(&format!("a{i}.wav"), 80.0, 300.0, 10 + i))
        .collect();
    let d = disagreement(&alike, &a, q.max_disagreement).expect("measures");
    assert!(!d.exceeds(), "{d:?}");
    assert!(d.warning().is_none());

    let mut odd = alike.clone();
    odd[1] = strikes("odd.wav", 200.0, 600.0, 20);
    let d = disagreement(&odd, &a, q.max_disagreement).expect("measures");
    assert!(d.exceeds(), "{d:?}");
    assert_eq!(d.worst().expect("three").file, "odd.wav");
    let w = d.warning().expect("a warning");
    assert!(w.starts_with("odd.wav is the odd one out"), "{w}");

    let two = [alike[0].clone(), odd[1].clone()];
    let d = disagreement(&two, &a, q.max_disagreement).expect("measures");
    assert!((d.recordings[0].lsd.0 - d.recordings[1].lsd.0).abs() < 1e-12);
    let w = d.warning().expect("a warning");
    assert!(w.contains("a0.wav and odd.wav"), "{w}");

    // The warning reaches the build's progress, and does not stop it.
    let mut warned = false;
    let cfg = BuildConfig {
        physical: None,
        ..BuildConfig::default()
    };
    build_material("mixed", &odd, &cfg, &mut |p| {
        if let crate::material::build::Progress::Checked(c) = p {
            warned = c.disagreement.as_ref().is_some_and(Disagreement::exceeds);
        }
    })
    .expect("a warning is not a refusal");
    assert!(warned);
}

#[test]
fn poor_fit_bounds() {
    let q = QualityConfig::default();
    assert!(!is_poor(0.5, 0.1, &q));
    assert!(is_poor(2.5, 0.1, &q), "LSD above 2 dB");
    assert!(
        !is_poor(0.8, 0.9, &q),
        "NRMSE high but the error is below the JND"
    );
    assert!(is_poor(1.5, 0.9, &q), "NRMSE high and LSD above the JND");
    assert!(is_poor(f64::NAN, 0.1, &q) && is_poor(1.5, f64::NAN, &q));
    assert!(
        !is_poor(0.5, f64::NAN, &q),
        "a flat response's NRMSE is undefined"
    );
}

#[test]
fn a_poor_fit_is_refused_or_kept_marked() {
    let rec = strikes("rich.wav", 80.0, 300.0, 4);
    let mut cfg = BuildConfig {
        physical: None,
        ..BuildConfig::default()
    };
    cfg.fit.order = OrderChoice::Fixed(1);
    match build_material("rich", std::slice::from_ref(&rec), &cfg, &mut |_| {}) {
        Err(BuildError::Quality(e @ QualityError::PoorFit { .. })) => {
            assert!(e.to_string().contains("order 1"), "{e}");
        }
        other => panic!("{other:?}"),
    }
    cfg.quality.accept_poor_fit = true;
    let m = build_material("rich", std::slice::from_ref(&rec), &cfg, &mut |_| {}).expect("kept");
    assert!(m.fit.poor_fit);
    assert!(is_poor(m.fit.lsd_db, m.fit.nrmse, &cfg.quality));
    // The mark survives the library file.
    let mut lib = crate::material::Library::new();
    lib.upsert(m);
    let back = crate::material::Library::from_json(&lib.to_json(), "test").expect("json");
    assert!(back.get("rich").expect("rich").fit.poor_fit);
    // A good fit is not marked, and the field is not even written.
    cfg.fit.order = OrderChoice::Auto { max: 16 };
    let good = build_material("good", std::slice::from_ref(&rec), &cfg, &mut |_| {}).expect("fits");
    assert!(!good.fit.poor_fit);
    assert!(
        !serde_json::to_string(&good.fit)
            .expect("json")
            .contains("poor_fit")
    );
}

#[test]
fn leave_one_out_needs_two_recordings_and_scores_each() {
    let recs: Vec<Recording> = (0..3)
        .map(|i| strikes(&format!("r{i}.wav"), 80.0, 300.0, 30 + i))
        .collect();
    let cfg = BuildConfig {
        physical: None,
        ..BuildConfig::default()
    };
    let full = build_material("m", &recs, &cfg, &mut |_| {}).expect("fits");
    let loo = leave_one_out(&recs, &cfg, &full)
        .expect("runs")
        .expect("three recordings");
    assert_eq!(loo.held_out.len(), 3);
    for (h, r) in loo.held_out.iter().zip(&recs) {
        assert_eq!(h.file, r.name);
        assert_eq!(h.strikes, 3);
        // Same resonances, different noise: the left-out model fits nearly as well.
        assert!(h.lsd.0 < 1.5, "{h:?}");
    }
    let one = build_material("m", &recs[..1], &cfg, &mut |_| {}).expect("fits");
    assert!(
        leave_one_out(&recs[..1], &cfg, &one)
            .expect("runs")
            .is_none()
    );
}

#[test]
fn aligned_lsd_ignores_gain() {
    let a = [0.0, 3.0, -2.0, 5.0];
    let b: Vec<f64> = a.iter().map(|v| v + 7.5).collect();
    assert!(aligned_lsd_db(&a, &b) < 1e-12);
    assert!((aligned_lsd_db(&[0.0, 2.0], &[0.0, 0.0]) - 1.0).abs() < 1e-12);
}
