use super::check::Checker;
use super::quantise::limit_decay;
use super::*;
use crate::material::MaterialModel;
use crate::material::builtin::builtin;
use crate::numeric::dtft;
use crate::signal::fixed::to_q15;
use crate::signal::{Biquad, Sos};
use crate::units::{Band, Decibels, SampleRate, Seconds};

#[test]
fn every_format_of_every_builtin_passes_and_gain_undoes_the_scaling() {
    // The figures first, whatever they are (the module doc quotes them).
    let loose = ExportConfig {
        tolerance: Decibels(1e3),
        margin_fraction: 0.0,
        ..ExportConfig::default()
    };
    let e = export_library(builtin(), "built-in", &[], &loose).unwrap();
    for m in &e.materials {
        let (q15, q31) = (&m.q15_check, &m.q31_check);
        let per_level = |c: &FormatCheck| {
            c.levels
                .iter()
                .map(|l| format!("{:.3}", l.impulse_db))
                .collect::<Vec<_>>()
                .join(" ")
        };
        eprintln!(
            "{:<8} impulse dB at {:?} dBFS: Q15 {}; Q31 {}; 16-bit output of the float model {}",
            m.name,
            DEFAULT_LEVELS,
            per_level(q15),
            per_level(q31),
            rounded_float_figures(builtin().get(&m.name).unwrap(), m)
        );
        eprintln!(
            "{:<8} Q15 {:.3e}/{:.3e} dB margin {:.3e}; Q31 {:.1e}/{:.1e} dB; \
             f32 {:.1e}/{:.1e} dB; float margin {:.3e}",
            m.name,
            q15.coefficients_db,
            q15.impulse_db,
            q15.pole_margin,
            q31.coefficients_db,
            q31.impulse_db,
            m.f32_check.coefficients_db,
            m.f32_check.impulse_db,
            m.pole_margin
        );
    }
    let e = export_library(builtin(), "built-in", &[], &ExportConfig::default()).unwrap();
    assert_eq!(e.materials.len(), builtin().materials.len());
    for m in &e.materials {
        assert!(m.with_q15 && m.with_q31);
        for check in [&m.q15_check, &m.q31_check, &m.f32_check] {
            assert!(check.worst_db() <= 0.5 && check.pole_margin > 0.0);
        }
        // Every level of 0..-30 dBFS, each within the tolerance.
        for check in [&m.q15_check, &m.q31_check] {
            let levels: Vec<f64> = check.levels.iter().map(|l| l.level.0).collect();
            assert_eq!(levels, DEFAULT_LEVELS, "{}", m.name);
            assert!(
                check.levels.iter().all(|l| l.impulse_db <= 0.5),
                "{}",
                m.name
            );
        }
        // The scaled sections times the gain are the (decay-limited) model.
        let model = builtin().get(&m.name).unwrap();
        let f = model.band_hz.log_grid(3)[1];
        let w = model.sample_rate.omega(f);
        let limited = limit_decay(&model.sos().unwrap(), model.sample_rate, Seconds(0.5));
        let ratio =
            Sos::new(m.sections.clone()).response(w).norm() * m.gain / limited.response(w).norm();
        assert!((ratio - 1.0).abs() < 1e-12, "{}: {ratio}", m.name);
    }
}

#[test]
fn a_failing_format_is_refused_naming_material_and_frequency() {
    // Q15 of a 16th-order fit at a tolerance no 16-bit output can meet.
    let config = ExportConfig {
        q15: true,
        tolerance: Decibels(1e-3),
        ..ExportConfig::default()
    };
    let err = prepare(builtin().get("gravel").unwrap(), &config).unwrap_err();
    let ExportError::CheckFailed {
        name,
        format,
        worst_db,
        worst_hz,
        ..
    } = &err
    else {
        panic!("{err}");
    };
    assert_eq!((name.as_str(), *format), ("gravel", "Q15"));
    assert!(*worst_db > 1e-3 && (20.0..=900.0).contains(worst_hz));
    let text = err.to_string();
    assert!(text.contains("gravel") && text.contains("Q15") && text.contains(" Hz"));
}

/// The worst deviation (dB) at each default level of the float model's own impulse
/// response, scaled as exported and rounded to Q15: what a 16-bit output costs any
/// filter (the reason the Q15 cascade's output stays 32-bit).
fn rounded_float_figures(model: &MaterialModel, m: &Exported) -> String {
    let reference = Sos::new(m.sections.clone());
    let checker = Checker::new(
        model,
        &reference,
        &ExportConfig::default(),
        m.impulse_samples,
    );
    let mut unit = vec![0.0; m.impulse_samples];
    unit[0] = 1.0;
    reference.filter_in_place(&mut unit);
    DEFAULT_LEVELS
        .iter()
        .map(|&l| {
            let x = f64::from(to_q15(Decibels(l).to_amplitude() as f32));
            let ir: Vec<f64> = unit.iter().map(|h| (h * x).round() / x).collect();
            let (d, _) = checker.worst(
                checker
                    .grid
                    .iter()
                    .map(|&f| dtft(&ir, model.sample_rate.omega(f)).norm()),
            );
            format!("{d:.2}")
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// A built-in model with its filter replaced: poles at the decay limit (radius
/// `exp(-1/(0.5 s 2 kHz))`) at each of `hz`; zeros at DC and Nyquist (`floor`
/// `None`: a bare resonance) or at the poles' angles and radius `floor` (a
/// resonance over a flat floor, as the fits pair them).
fn at_the_decay_limit(hz: &[f64], floor: Option<f64>) -> MaterialModel {
    let mut model = builtin().get("hard").unwrap().clone();
    assert_eq!(model.sample_rate, SampleRate(2000));
    let r = (-1.0f64 / 1000.0).exp();
    let sos = Sos::new(
        hz.iter()
            .map(|&f| {
                let th = std::f64::consts::TAU * f / 2000.0;
                let b = match floor {
                    // About unit peak gain.
                    None => [1.0 - r, 0.0, r - 1.0],
                    Some(z) => [1.0, -2.0 * z * th.cos(), z * z],
                };
                Biquad {
                    b,
                    a: [1.0, -2.0 * r * th.cos(), r * r],
                }
            })
            .collect(),
    );
    model.order = sos.order();
    model.filter = crate::material::FilterCoefficients::from_sos(&sos);
    model.name = format!("limit-{hz:?}");
    model
}

#[test]
fn cascades_with_poles_at_the_decay_limit_pass_at_every_level() {
    // Not the built-ins' particular coefficients: the slowest poles any model may
    // hold, low in the band where the 16-bit remainders are the finest.
    // A cascade of the bare resonances spans some 170 dB over the band (each falls
    // 60-76 dB from its peak to 900 Hz), beyond any 32-bit format; the fits pair
    // each resonance with zeros, as `floor` does (peaks of 26-34 dB over it).
    let cases = [
        (&[20.0][..], None),
        (&[50.0], None),
        (&[200.0], None),
        (&[20.0], Some(0.95)),
        (&[20.0, 50.0, 200.0], Some(0.95)),
        (&[200.0, 20.0, 50.0], Some(0.9)),
    ];
    for (hz, floor) in cases {
        let model = at_the_decay_limit(hz, floor);
        let m = prepare(&model, &ExportConfig::default()).unwrap_or_else(|e| panic!("{hz:?}: {e}"));
        for check in [&m.q15_check, &m.q31_check] {
            assert_eq!(check.levels.len(), DEFAULT_LEVELS.len());
            eprintln!(
                "{hz:?}: coefficients {:.4} dB, impulses {:?}",
                check.coefficients_db,
                check
                    .levels
                    .iter()
                    .map(|l| l.impulse_db)
                    .collect::<Vec<_>>()
            );
            assert!(check.worst_db() <= 0.5 && check.pole_margin > 0.0, "{hz:?}");
        }
    }
}

#[test]
fn the_grid_is_the_dft_bins_in_the_band_and_its_spectrum_is_the_dtft() {
    // An oracle for the check's one FFT per response: at every grid frequency its
    // magnitude is a naive DTFT's, and the grid is what the module doc says it is.
    let model = builtin().get("gravel").unwrap();
    let config = ExportConfig::default();
    let m = prepare(model, &config).unwrap();
    let reference = Sos::new(m.sections.clone());
    let n = m.impulse_samples;
    let mut checker = Checker::new(model, &reference, &config, n);
    let (rate, band) = (model.sample_rate, model.band_hz);
    let spacing = checker.grid[1].0 - checker.grid[0].0;
    let size = (rate.hz() / spacing).round() as usize;
    assert!(size.is_power_of_two() && size >= n.max(4096), "{size}");
    assert!(checker.grid.len() >= 256, "{}", checker.grid.len());
    assert!(checker.grid[0].0 >= band.lo.0 && checker.grid[0].0 - spacing < band.lo.0);
    let last = checker.grid.last().unwrap().0;
    assert!(last <= band.hi.0 && last + spacing > band.hi.0);
    // A response that is not the reference's, so that the deviation is not zero
    // everywhere: the reference's own, with a seeded ripple added.
    let mut ir = vec![0.0; n];
    ir[0] = 1.0;
    reference.filter_in_place(&mut ir);
    let mut state = 12_345u64;
    for v in &mut ir[..600] {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1);
        *v += 1e-3 * ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
    }
    let (fast_db, fast_hz) = checker.impulse_worst(&ir);
    let (naive_db, naive_hz) = checker.worst(
        checker
            .grid
            .iter()
            .map(|&f| dtft(&ir, rate.omega(f)).norm()),
    );
    assert!(fast_db > 1e-3, "{fast_db}");
    assert!((fast_db - naive_db).abs() < 1e-9, "{fast_db} vs {naive_db}");
    assert_eq!(fast_hz, naive_hz);
    // A response longer than the checker was made for is never passed as checked.
    ir.push(0.0);
    assert_eq!(checker.impulse_worst(&ir).0, f64::INFINITY);
}

#[test]
fn a_narrow_band_still_gets_its_grid() {
    let mut model = builtin().get("hard").unwrap().clone();
    model.band_hz = Band::new(200.0, 202.0);
    let reference = model.sos().unwrap();
    let checker = Checker::new(&model, &reference, &ExportConfig::default(), 4096);
    // 2 Hz at 2 kHz: 256 bins would need 2^18 points; that many are allowed.
    assert!(checker.grid.len() >= 256, "{}", checker.grid.len());
    assert!(checker.grid.iter().all(|f| (200.0..=202.0).contains(&f.0)));
}

#[test]
fn a_level_that_fails_is_named() {
    // An oracle: the reference's own impulse response passes at every level; one
    // level doubled (+6 dB) must fail, and the error names that level.
    let model = builtin().get("hard").unwrap();
    let config = ExportConfig::default();
    let m = prepare(model, &config).unwrap();
    let reference = Sos::new(m.sections.clone());
    let mut checker = Checker::new(model, &reference, &config, m.impulse_samples);
    let mut ir = vec![0.0; m.impulse_samples];
    ir[0] = 1.0;
    reference.filter_in_place(&mut ir);
    let mut impulses: Vec<(Decibels, Vec<f64>)> =
        config.levels.iter().map(|&l| (l, ir.clone())).collect();
    let (ok, err) = checker.check("hard", "Q15", &reference, &impulses);
    assert!(err.is_none() && ok.impulse_db < 1e-3, "{ok:?}");
    impulses[3].1.iter_mut().for_each(|v| *v *= 2.0);
    let (bad, err) = checker.check("hard", "Q15", &reference, &impulses);
    assert_eq!(bad.worst_level, Decibels(-18.0));
    assert!((bad.impulse_db - 20.0 * 2f64.log10()).abs() < 1e-3);
    let err = err.unwrap();
    assert!(
        matches!(&err, ExportError::CheckFailed { level: Some(l), format: "Q15", .. } if l.0 == -18.0),
        "{err}"
    );
    let text = err.to_string();
    assert!(
        text.contains("hard") && text.contains("-18 dBFS") && text.contains(" Hz"),
        "{text}"
    );
}

#[test]
fn levels_outside_the_range_are_refused() {
    for levels in [
        vec![],
        vec![Decibels(3.0)],
        vec![Decibels(-100.0)],
        vec![Decibels(f64::NAN)],
    ] {
        let config = ExportConfig {
            levels,
            ..ExportConfig::default()
        };
        let err = prepare(builtin().get("hard").unwrap(), &config).unwrap_err();
        assert!(matches!(err, ExportError::BadModel { .. }), "{err}");
    }
}

#[test]
fn unknown_material_and_bad_model_are_errors() {
    let names = vec!["lava".to_string()];
    let err = export_library(builtin(), "built-in", &names, &ExportConfig::default());
    assert!(matches!(err, Err(ExportError::UnknownMaterial { .. })));
    let mut model = builtin().get("sand").unwrap().clone();
    model.filter.sos[0][4] = -2.5; // a pole outside the unit circle
    model.filter.sos[0][5] = 1.5;
    let err = prepare(&model, &ExportConfig::default()).unwrap_err();
    assert!(matches!(err, ExportError::BadModel { .. }), "{err}");
    let empty = crate::material::Library::new();
    assert!(matches!(
        export_library(&empty, "x", &[], &ExportConfig::default()),
        Err(ExportError::Empty)
    ));
}

/// The definitions of `static const {what}*` tables in a header.
fn defined(header: &str, what: &str) -> usize {
    header
        .lines()
        .filter(|l| l.starts_with(&format!("static const {what}")))
        .count()
}

#[test]
fn each_material_carries_its_excitation_and_shared_tables_are_written_once() {
    use crate::excitation::Tables;
    let e = export_library(builtin(), "built-in", &[], &ExportConfig::default()).unwrap();
    for m in &e.materials {
        let model = builtin().get(&m.name).unwrap();
        let tables = Tables::new(&model.excitation_or_heel(), model.sample_rate).unwrap();
        assert_eq!(m.excitation, tables, "{}", m.name);
    }
    // One table of magnitudes per shape (of the materials with micro-impacts), one of
    // time scales per duration spread (all at one rate).
    let header = c::header(&e);
    let distinct = |of: &dyn Fn(&MaterialModel) -> Option<f64>| {
        builtin()
            .materials
            .iter()
            .filter_map(|m| of(m).map(f64::to_bits))
            .collect::<std::collections::BTreeSet<_>>()
            .len()
    };
    let shapes = distinct(&|m| {
        let x = m.excitation_or_heel();
        (!x.energy.is_empty()).then_some(x.amplitude_shape)
    });
    let spreads = distinct(&|m| Some(m.excitation_or_heel().duration_spread));
    assert_eq!(defined(&header, "float uf_exc_quantiles_"), shapes);
    assert_eq!(defined(&header, "double uf_exc_steps_"), spreads);
    assert!(header.contains("UF_NO_EXCITATION leaves it out"));
    assert!(header.contains(" * All of them: "));
    // The same material twice: its shared tables once.
    let names = ["gravel", "gravel"].map(String::from);
    let twice = c::header(
        &export_library(builtin(), "built-in", &names, &ExportConfig::default()).unwrap(),
    );
    assert_eq!(defined(&twice, "float uf_exc_quantiles_"), 1);
    assert_eq!(defined(&twice, "double uf_exc_steps_"), 1);
    assert_eq!(defined(&twice, "double uf_m"), 2);
}

#[test]
fn a_material_without_micro_impacts_has_no_per_bin_tables() {
    // C99 has no empty arrays: a heel-only material's per-bin pointers are null, and so
    // is its magnitudes' (never read).
    let mut model = builtin().get("gravel").unwrap().clone();
    model.excitation = None;
    let m = prepare(&model, &ExportConfig::default()).unwrap();
    assert_eq!(m.excitation.bins(), 0);
    let header = c::header(&Export {
        origin: "test".into(),
        library_sha256: "0".repeat(64),
        materials: vec![m],
    });
    assert!(
        header.contains("static const uf_excitation uf_m0_gravel_exc = {0, 0, uf_exc_steps_0, 0, "),
        "{header}"
    );
    assert_eq!(defined(&header, "float uf_exc_quantiles_"), 0);
    assert_eq!(defined(&header, "double uf_exc_steps_"), 1);
}

#[test]
fn an_invalid_excitation_is_refused_naming_the_material() {
    let mut model = builtin().get("gravel").unwrap().clone();
    if let Some(e) = model.excitation.as_mut() {
        e.heel = 2.0;
    }
    let err = prepare(&model, &ExportConfig::default()).unwrap_err();
    assert!(
        matches!(&err, ExportError::BadModel { name, reason } if name == "gravel" && reason.contains("heel")),
        "{err}"
    );
}
