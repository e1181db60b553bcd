//! `underfoot demo`: the walk across every material, its fit table, spectra and spectrogram.

use std::fs;

use underfoot::units::SampleRate;

use crate::common::{assert_ok, read_wav, run, s, stdout, write_library};

#[test]
fn demo_prints_fit_table_and_writes_spectra() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = write_library(dir.path(), &["gravel", "concrete", "snow"]);
    let out_dir = dir.path().join("out");
    let o = run(&["demo", "--library", s(&lib), "--out-dir", s(&out_dir)]);
    assert_ok(&o);
    let out = stdout(&o);
    let row: Vec<&str> = out
        .lines()
        .find(|l| l.starts_with("concrete"))
        .expect("row")
        .split_whitespace()
        .collect();
    assert_eq!(row, ["concrete", "2", "0.0488", "0.42"]);
    let svg = fs::read_to_string(out_dir.join("spectra.svg")).expect("spectra.svg");
    for name in ["gravel", "concrete", "snow"] {
        assert!(
            svg.contains(&format!(">\n{name}: order 2")),
            "panel for {name}"
        );
    }
    // Curves are the polylines with many points; axes, ticks and legend have two.
    let curves = svg
        .lines()
        .filter(|l| l.starts_with("<polyline") && l.matches(',').count() >= 24);
    assert_eq!(curves.count(), 6, "measured and model per panel");
}

/// The acceptance test of the demo: every material's stretch of `walk.wav`, analysed
/// with the fitting pipeline, matches that material's measured response within 2 dB.
#[test]
fn demo_walks_across_every_builtin_material_and_each_stretch_matches_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = run(&["demo", "--out-dir", s(dir.path())]);
    assert_ok(&o);
    let (spec, samples) = read_wav(&dir.path().join("walk.wav"));
    assert_eq!((spec.channels, spec.sample_rate), (1, 48_000));
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(dir.path().join("walk.json")).unwrap()).unwrap();
    let gain = underfoot::units::Decibels(report["gain_db"].as_f64().unwrap());
    let segments = report["segments"].as_array().unwrap();
    let lib = underfoot::material::builtin::builtin();
    assert_eq!(segments.len(), lib.materials.len());
    assert_eq!(report["limited_samples"], 0);
    let rate = SampleRate(48_000);
    for seg in segments {
        let name = seg["material"].as_str().unwrap();
        let a = rate.samples_in(underfoot::units::Seconds(seg["start_s"].as_f64().unwrap()));
        let b = rate.samples_in(underfoot::units::Seconds(seg["end_s"].as_f64().unwrap()));
        let lsd = underfoot::material::evaluate::segment_lsd(
            &samples[a..b.min(samples.len())],
            rate,
            lib.get(name).unwrap(),
            gain,
        )
        .unwrap();
        assert!(lsd < 2.0, "{name}: {lsd:.2} dB");
    }
    for file in ["walk.svg", "spectra.svg", "walk-force.csv"] {
        assert!(
            fs::metadata(dir.path().join(file)).unwrap().len() > 1000,
            "{file}"
        );
    }
    assert!(stdout(&o).contains("LSD dB"));
}
