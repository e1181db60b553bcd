//! Estimating the physical model: oracles on signals the tests make, and
//! estimate-then-synthesise on every real material.
//!
//! The real-data test needs `../shared/data/footsteps` (skipped with a note when absent,
//! unless `UNDERFOOT_REQUIRE_DATA=1`).

use crate::common;

use underfoot::excitation::{ExcitationModel, Generator, Tables};
use underfoot::material::builtin::builtin;
use underfoot::material::library::Library;
use underfoot::physical::estimate::{hammer_for, held_out_seed, score_render};
use underfoot::physical::{
    EstimateConfig, Ground, GroundKind, Impact, KindChoice, Surface, estimate,
};
use underfoot::recording::{self, Recording};
use underfoot::signal::noise::SplitMix64;
use underfoot::units::{SampleRate, Seconds};

#[test]
#[ignore = "slow tier: real recordings"]
fn calibrate_then_synthesise_every_real_material_within_3_25_db() {
    let Some(root) = common::footsteps_dir() else {
        return;
    };
    let cfg = EstimateConfig::default();
    let mut worst: f64 = 0.0;
    for (name, files) in common::footsteps_by_material(&root) {
        let recordings: Vec<Recording> = files
            .iter()
            .map(|f| recording::read(f, None).expect("readable recording"))
            .collect();
        // Struck by the material's excitation, as the fit estimates it.
        let excitation = builtin()
            .get(&name)
            .expect("a built-in of each shared material")
            .excitation_or_heel();
        let model = estimate(&recordings, &excitation, &cfg).expect("estimates");
        let grid = cfg.analysis.band.log_grid(96);
        let measured = underfoot::analysis::measure(&recordings, &cfg.analysis)
            .expect("measurable")
            .on_grid(&grid);
        // The recorded figure is the estimation render's, at the stored gain: scoring
        // that render again gives it back.
        let (_, again) = score_render(&model, &excitation, &cfg, &grid, &measured, cfg.seed)
            .expect("render analyses");
        assert!(
            (again.lsd_db - model.record.lsd_db).abs() < 0.01,
            "{name}: recorded {:.3} dB, scored again {:.3} dB",
            model.record.lsd_db,
            again.lsd_db
        );
        // Score a render the estimation has not seen (another seed).
        let (_, held_out) = score_render(
            &model,
            &excitation,
            &cfg,
            &grid,
            &measured,
            held_out_seed(&cfg),
        )
        .expect("render analyses");
        let lsd = held_out.lsd_db;
        eprintln!(
            "{name}: {} with {} modes, LSD {lsd:.2} dB held out (estimation {:.2} dB)",
            model.kind.name(),
            model.modes.len(),
            model.record.lsd_db
        );
        // 3.25 dB: struck by the fitted excitation, whose steps differ from one another as
        // much as recorded ones do (4-7 dB between two steps of sand, water or ice), a
        // held-out render of 16 steps keeps about a quarter of a decibel of that variety
        // in its average (it was 3.0 dB with the single-rate stream of micro-impacts,
        // whose steps were near copies).
        assert!(lsd <= 3.25, "{name}: LSD {lsd:.2} dB");
        worst = worst.max(lsd);
    }
    eprintln!("worst LSD {worst:.2} dB");
}

/// Strikes on a surface of known modes, as a recording at 48 kHz.
fn struck_floor(modes: &[(f64, f64, f64)], strikes: usize, seed: u64) -> Recording {
    let rate = SampleRate(48_000);
    let fs = rate.hz();
    let mut noise = SplitMix64::new(seed);
    let len = (0.8 * fs) as usize * strikes;
    let mut samples: Vec<f64> = (0..len).map(|_| 1e-5 * noise.symmetric()).collect();
    for s in 0..strikes {
        let start = (0.1 * fs) as usize + s * (0.8 * fs) as usize;
        let level = 0.8 + 0.4 * noise.uniform();
        for n in 0..(0.6 * fs) as usize {
            let t = n as f64 / fs;
            samples[start + n] += level
                * modes
                    .iter()
                    .map(|&(f, tau, a)| {
                        a * (-t / tau).exp() * (std::f64::consts::TAU * f * t).sin()
                    })
                    .sum::<f64>();
        }
    }
    Recording {
        name: format!("floor-{seed}.wav"),
        rate,
        samples,
        sha256: String::new(),
        excerpt: None,
    }
}

#[test]
fn a_struck_floor_is_a_solid_with_its_modes_and_its_spectrum() {
    let truth = [(62.0, 0.06, 1.0), (145.0, 0.04, 0.6), (410.0, 0.025, 0.4)];
    let recordings: Vec<Recording> = (0..3).map(|s| struck_floor(&truth, 2, s)).collect();
    let cfg = EstimateConfig::default();
    let model = estimate(&recordings, &ExcitationModel::heel_only(), &cfg).expect("estimates");
    assert_eq!(model.kind, GroundKind::Solid, "{:?}", model.record);
    // The estimated surface rings where the floor does: its response (velocity per unit
    // impulse, modes summed with their signs) peaks at each true mode.
    let response = |f: f64| {
        let s = num_complex::Complex64::new(0.0, std::f64::consts::TAU * f);
        model
            .modes
            .iter()
            .map(|m| {
                let wd = std::f64::consts::TAU * m.frequency.0;
                s * wd * m.gain / ((s + 1.0 / m.decay.0).powi(2) + wd * wd)
            })
            .sum::<num_complex::Complex64>()
            .norm()
    };
    for (f, _, _) in truth {
        let peak = (0..=40)
            .map(|i| f * (0.8 + 0.01 * f64::from(i)))
            .max_by(|a, b| response(*a).total_cmp(&response(*b)))
            .expect("candidates");
        assert!(
            (peak / f - 1.0).abs() < 0.03,
            "the response near {f} Hz peaks at {peak:.1} Hz"
        );
    }
    assert!(
        model.record.lsd_db < 3.0,
        "LSD {:.2} dB",
        model.record.lsd_db
    );
}

#[test]
fn the_kind_can_be_fixed_and_bad_settings_are_refused() {
    let recordings = [struck_floor(&[(100.0, 0.05, 1.0)], 2, 9)];
    let cfg = EstimateConfig {
        kind: KindChoice::Fixed(GroundKind::Aggregate),
        ..EstimateConfig::default()
    };
    let heel = ExcitationModel::heel_only();
    let model = estimate(&recordings, &heel, &cfg).expect("estimates");
    assert_eq!(model.kind, GroundKind::Aggregate);
    for bad in [
        EstimateConfig {
            lpc_orders: vec![],
            ..EstimateConfig::default()
        },
        EstimateConfig {
            restitution: 1.5,
            ..EstimateConfig::default()
        },
        EstimateConfig {
            contact_time: Seconds(f64::NAN),
            ..EstimateConfig::default()
        },
    ] {
        assert!(estimate(&recordings, &heel, &bad).is_err());
    }
    assert!(estimate(&[], &heel, &EstimateConfig::default()).is_err());
    let broken = ExcitationModel {
        heel: 2.0,
        ..ExcitationModel::heel_only()
    };
    assert!(estimate(&recordings, &broken, &cfg).is_err());
}

#[test]
fn the_hammer_has_the_contact_time_asked_for() {
    for (mass, contact, speed) in [(0.005, 2.5e-4, 0.5), (0.5, 1e-3, 1.0), (2.0, 4e-3, 0.2)] {
        let mut params = hammer_for(mass, Seconds(contact), speed, 0.999_999, 1.5);
        params.damping = 0.0;
        let rate = SampleRate(192_000);
        let mut impact = Impact::new(params, Surface::Rigid, rate).expect("valid hammer");
        let mut out = vec![0.0f32; rate.samples_in(Seconds(10.0 * contact))];
        impact.process(&mut out);
        let got = impact.contact_time().expect("the hammer left").0;
        assert!(
            (got / contact - 1.0).abs() < 0.01,
            "asked {contact} s, got {got} s"
        );
    }
}

#[test]
fn every_builtin_material_has_a_valid_physical_model() {
    for m in &builtin().materials {
        let p = m.physical.as_ref().expect("built-in physical model");
        p.validate().expect("valid");
        assert!(p.record.lsd_db <= 3.0, "{}: {}", m.name, p.record.lsd_db);
        let tables = Tables::new(&m.excitation_or_heel(), SampleRate(48_000)).expect("valid");
        Ground::new(p, SampleRate(48_000), 1, tables.mean_impulse_energy())
            .expect("runs at 48 kHz");
    }
}

#[test]
fn a_broken_physical_model_in_a_library_file_is_refused() {
    let mut lib = builtin().clone();
    let model = lib.materials[0].physical.as_mut().expect("physical");
    model.modes[0].decay = Seconds(-1.0);
    let err = Library::from_json(&lib.to_json(), "test.json").expect_err("refused");
    assert!(err.to_string().contains("physical"), "{err}");
    let mut lib = builtin().clone();
    lib.materials[0]
        .physical
        .as_mut()
        .expect("physical")
        .impacts_in_flight = 0;
    assert!(Library::from_json(&lib.to_json(), "test.json").is_err());
}

#[test]
fn an_aggregate_sounds_only_when_its_excitation_strikes() {
    let gravel = builtin().get("gravel").expect("gravel");
    let p = gravel.physical.as_ref().expect("physical");
    assert_eq!(p.kind, GroundKind::Aggregate);
    let rate = SampleRate(48_000);
    let tables = Tables::new(&gravel.excitation_or_heel(), rate).expect("valid");
    let mut ground = Ground::new(p, rate, 3, tables.mean_impulse_energy()).expect("prepares");
    let mut out = vec![0.0f32; 48_000];
    // No excitation: nothing.
    ground.process(&vec![0.0f32; 48_000], &mut out);
    assert!(out.iter().all(|v| *v == 0.0));
    assert_eq!(ground.events(), 0);
    // A nominal step's excitation (clock at speed 1): a grain for each impulse, those
    // within 2 ms of the last strike merged into the next.
    let mut generator = Generator::new(5);
    let mut x = vec![0.0f32; 48_000];
    generator.step(&tables, 1.0);
    generator.process(&tables, &vec![1.0; 48_000], &mut x);
    let impulses = x.iter().filter(|v| **v != 0.0).count() as u64;
    assert!(impulses > 10, "{impulses}");
    ground.process(&x, &mut out);
    let last = x.iter().rposition(|v| *v != 0.0).expect("impulses") as f64;
    assert!(
        ground.events() <= impulses && ground.events() > 10,
        "{}",
        ground.events()
    );
    assert!((ground.events() as f64) <= last / 96.0 + 2.0);
    assert!(out.iter().any(|v| *v != 0.0));
}

/// What single precision would cost the resonator banks (issue 33): every built-in
/// physical model's modes, struck by a walk (a heel impulse every 0.5 s and random
/// micro-impulses at 300/s, 4 s at 48 kHz), rendered as `ResonatorBank` renders it (f64,
/// velocity out) and by the same recursion in f32 (poles, gains and state rounded to
/// f32). The relative RMS error of the velocity is printed per material; the banks stay
/// in f64 (see `physical::resonator`), and this measures the margin that decision keeps.
#[test]
fn single_precision_banks_error_per_material() {
    use num_complex::Complex;
    use underfoot::physical::ResonatorBank;
    let rate = SampleRate(48_000);
    let mut worst: f64 = 0.0;
    for m in &builtin().materials {
        let Some(model) = m.physical.as_ref() else {
            continue;
        };
        let mut bank = ResonatorBank::new(&model.modes, rate).unwrap();
        let poles: Vec<Complex<f32>> = bank
            .poles()
            .iter()
            .map(|p| Complex::new(p.re as f32, p.im as f32))
            .collect();
        let slopes: Vec<Complex<f32>> = model
            .modes
            .iter()
            .map(|md| {
                let s = Complex::new(
                    -1.0 / md.played_decay().0,
                    std::f64::consts::TAU * md.frequency.0,
                ) * md.gain;
                Complex::new(s.re as f32, s.im as f32)
            })
            .collect();
        let mut z32 = vec![Complex::new(0.0f32, 0.0); model.modes.len()];
        let mut rng = SplitMix64::new(5);
        let (mut err2, mut ref2) = (0.0f64, 0.0f64);
        for n in 0..4 * 48_000 {
            let mut j = if n % 24_000 == 0 { 1e-2 } else { 0.0 };
            if rng.uniform() < 300.0 / 48_000.0 {
                j += 1e-4 * rng.symmetric();
            }
            let v64 = bank.velocity();
            bank.tick(j);
            let mut v32 = 0.0f32;
            for ((z, p), s) in z32.iter_mut().zip(&poles).zip(&slopes) {
                v32 += s.re * z.im + s.im * z.re;
                *z = p * (*z + j as f32);
            }
            err2 += (f64::from(v32) - v64).powi(2);
            ref2 += v64 * v64;
        }
        let rel = (err2 / ref2).sqrt();
        println!(
            "{:<10} {} modes: f32 bank relative RMS error {rel:.1e}",
            m.name,
            model.modes.len()
        );
        assert!(rel.is_finite() && rel > 0.0, "{}: {rel}", m.name);
        worst = worst.max(rel);
    }
    // Measured: 2.5e-6 (water) to 1.3e-4 (dirt) by material (long, low modes worst); a change of
    // the built-in modes that made f32 far worse would show here.
    assert!(worst < 1e-2, "worst f32 error {worst:.1e}");
}
