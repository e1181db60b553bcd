//! The built-in presets are what `scripts/refit-builtin` makes from the shared recordings:
//! refitting each from its sources gives the same order and the same response.
//!
//! Needs `../shared/data/footsteps` (skipped with a note when absent, unless
//! `UNDERFOOT_REQUIRE_DATA=1`, as in CI).

use crate::common;

use underfoot::material::build::{BuildConfig, build_material};
use underfoot::material::builtin::builtin;
use underfoot::recording::read;
use underfoot::synthesis::{PreparedMaterial, VoiceConfig};
use underfoot::units::SampleRate;

/// What is stored is what plays: every built-in keeps within its stored decay limit, so
/// the voice's own limit (the same 0.5 s by default) changes no mode; the record describes
/// the stored filter; and the dense check was made.
#[test]
fn builtin_filters_are_what_the_voice_plays() {
    let lib = builtin();
    assert_eq!(
        lib.format,
        underfoot::material::library::FORMAT,
        "refit the built-ins"
    );
    for m in &lib.materials {
        assert!(
            m.slowest_decay().0 <= m.fit.longest_decay.0 * (1.0 + 1e-9),
            "{}: slowest decay {:?} beyond its limit {:?}",
            m.name,
            m.slowest_decay(),
            m.fit.longest_decay
        );
        for rate in [SampleRate(44_100), SampleRate(48_000)] {
            let p = PreparedMaterial::prepare(m, rate, &VoiceConfig::default())
                .unwrap_or_else(|e| panic!("{}: {e}", m.name));
            assert_eq!(
                p.limited_modes, 0,
                "{} at {rate}: the voice changed modes",
                m.name
            );
        }
        let sos = m.sos().unwrap();
        for (f, stored) in m.fit.grid_hz.iter().zip(&m.fit.model) {
            let now = sos
                .response(m.sample_rate.omega(underfoot::units::Hz(*f)))
                .norm();
            assert!(
                (now / stored - 1.0).abs() < 1e-9,
                "{} at {f} Hz: the record is not of the stored filter",
                m.name
            );
        }
        let worst = m
            .fit
            .worst
            .unwrap_or_else(|| panic!("{}: no dense check", m.name));
        assert!(
            worst.db >= 0.0 && worst.db.is_finite(),
            "{}: {worst:?}",
            m.name
        );
    }
}

#[test]
fn builtin_library_covers_the_papers_materials() {
    let lib = builtin();
    for name in ["gravel", "hard", "sand", "dirt", "snow"] {
        let m = lib.get(name).unwrap_or_else(|e| panic!("{e}"));
        assert!(m.sos().is_some_and(|s| s.is_stable()), "{name}");
        assert!(m.fit.lsd_db <= 1.0, "{name}: {}", m.fit.lsd_db);
    }
}

#[test]
#[ignore = "slow tier: real recordings"]
fn builtin_library_is_current() {
    let Some(root) = common::footsteps_dir() else {
        return;
    };
    for preset in &builtin().materials {
        let recs: Vec<_> = preset
            .sources
            .iter()
            .map(|s| {
                read(&root.join(&preset.name).join(&s.file), None).unwrap_or_else(|e| panic!("{e}"))
            })
            .collect();
        for (rec, src) in recs.iter().zip(&preset.sources) {
            assert_eq!(
                rec.sha256, src.sha256,
                "{}: {} changed since the presets were fitted",
                preset.name, src.file
            );
        }
        let refit =
            build_material(&preset.name, &recs, &BuildConfig::default(), &mut |_| {}).unwrap();
        assert_eq!(
            refit.order, preset.order,
            "{}: run scripts/refit-builtin",
            preset.name
        );
        for (f, (a, b)) in preset
            .fit
            .grid_hz
            .iter()
            .zip(refit.fit.model.iter().zip(&preset.fit.model))
        {
            let db = 20.0 * (a / b).log10();
            assert!(
                db.abs() < 0.1,
                "{} at {f} Hz: refit differs by {db} dB; run scripts/refit-builtin",
                preset.name
            );
        }
        // The physical model is estimated by the same fit, deterministically.
        let (got, want) = (refit.physical.as_ref(), preset.physical.as_ref());
        let (got, want) = (
            got.expect("the refit estimates a physical model"),
            want.unwrap_or_else(|| panic!("{}: run scripts/refit-builtin", preset.name)),
        );
        assert_eq!(
            got.kind, want.kind,
            "{}: run scripts/refit-builtin",
            preset.name
        );
        assert_eq!(
            got.modes.len(),
            want.modes.len(),
            "{}: run scripts/refit-builtin",
            preset.name
        );
        assert!(
            (got.record.lsd_db - want.record.lsd_db).abs() < 0.05
                && (got.output_gain / want.output_gain - 1.0).abs() < 1e-3,
            "{}: physical model differs; run scripts/refit-builtin",
            preset.name
        );
        // The excitation and the level are fitted by the same run, deterministically.
        let (got, want) = (
            refit
                .excitation
                .as_ref()
                .expect("the refit fits an excitation"),
            preset
                .excitation
                .as_ref()
                .unwrap_or_else(|| panic!("{}: run scripts/refit-builtin", preset.name)),
        );
        assert!(
            got.energy.len() == want.energy.len()
                && (got.heel - want.heel).abs() < 1e-6
                && got.rate_hz == want.rate_hz
                && got.amplitude_shape == want.amplitude_shape
                && (refit.level_db - preset.level_db).abs() < 0.05,
            "{}: excitation or level differs; run scripts/refit-builtin",
            preset.name
        );
    }
}
