//! The limb fit on sweeps of the simulated tile and simulated users (moved from the unit
//! tests of `compensation::limb`, which cannot use the simulators above them).

use underfoot::compensation::limb::{DEFAULT_G2, LimbFitConfig, LimbModel, LimbParams, fit_limb};
use underfoot::compensation::sweep::{Sweep, SweepConfig, measure};
use underfoot::sim::{SimulatedTile, SimulatedUser, TileConfig};
use underfoot::units::{Band, Decibels, Hz, SampleRate};

const RATE: SampleRate = SampleRate(48_000);
const BAND: Band = Band::new(40.0, 1024.0);

fn model(p: LimbParams) -> LimbModel {
    LimbModel::new(p, DEFAULT_G2, 1.0).unwrap()
}

#[test]
fn simulated_user_measures_as_its_oracle() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut user =
        SimulatedUser::new(&TileConfig::default(), model(LimbParams::TABLE1_MEAN), RATE).unwrap();
    let fr = measure(&mut user, &sweep).unwrap();
    let worst = fr
        .freqs
        .iter()
        .zip(&fr.response)
        .map(|(&f, h)| (20.0 * (h.norm() / user.true_response(f).norm()).log10()).abs())
        .fold(0.0, f64::max);
    eprintln!("simulated user: measured vs oracle, max {worst:.4} dB");
    assert!(worst < 0.1, "{worst}");
    assert_eq!(user.limb().params, LimbParams::TABLE1_MEAN);
    assert!(user.limb_sos().is_stable());
}

/// Loaded over unloaded, in dB, from noisy sweeps of the simulated tile and user.
fn measured_ratio(p: LimbParams, seed: u64) -> (Vec<Hz>, Vec<f64>) {
    measured_ratio_at(p, seed, -40.0)
}

fn measured_ratio_at(p: LimbParams, seed: u64, noise_db: f64) -> (Vec<Hz>, Vec<f64>) {
    let tile_cfg = TileConfig {
        noise: Some(Decibels(noise_db)).filter(|n| n.0.is_finite()),
        seed,
        ..TileConfig::default()
    };
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut tile = SimulatedTile::new(&tile_cfg, RATE).unwrap();
    let unloaded = measure(&mut tile, &sweep).unwrap();
    let user_cfg = TileConfig {
        seed: seed + 1000,
        ..tile_cfg
    };
    let mut user = SimulatedUser::new(&user_cfg, model(p), RATE).unwrap();
    let loaded = measure(&mut user, &sweep).unwrap();
    let ratio = loaded
        .magnitude_db()
        .iter()
        .zip(unloaded.magnitude_db())
        .map(|(l, u)| l.0 - u.0)
        .collect();
    (loaded.freqs, ratio)
}

#[test]
fn acceptance_fit_recovers_simulated_users_from_noisy_sweeps() {
    let mut failures = Vec::new();
    for ((name, p), seed) in LimbParams::TABLE1_SPREAD
        .into_iter()
        .flat_map(|u| [(u, 7), (u, 8)])
    {
        let m = model(p);
        let skin = BAND
            .log_grid(256)
            .iter()
            .map(|&f| (20.0 * (m.response(f).norm() / m.h_l(f).norm()).log10()).abs())
            .fold(0.0, f64::max);
        let (freqs, ratio) = measured_ratio(p, seed);
        let t0 = std::time::Instant::now();
        let fit = fit_limb(&freqs, &ratio, &LimbFitConfig::default()).unwrap();
        let dt = t0.elapsed();
        let got = fit.model.params.to_array();
        let err: Vec<f64> = got
            .iter()
            .zip(p.to_array())
            .map(|(g, w)| 100.0 * (g / w - 1.0))
            .collect();
        eprintln!(
            "{name} (seed {seed}): skin term up to {skin:.2} dB; fit {got:?}, error % {err:.2?}, \
             predicted 1-sigma % {:.2?}, rms {:.3} dB, level {:.3} dB, {} iterations \
             ({} over {} starts), {:.1} ms",
            fit.relative_std.map(|s| 100.0 * s),
            fit.rms_error_db,
            20.0 * fit.model.level.log10(),
            fit.iterations,
            fit.total_iterations,
            fit.starts,
            dt.as_secs_f64() * 1e3
        );
        for (i, e) in err.iter().enumerate() {
            if e.abs() >= 5.0 {
                failures.push(format!("{name}: parameter {i} off by {e:.2} %"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

/// How recovery degrades with sensor noise: the leg's time constant, which shapes the
/// whole slope, stays well determined; the skin's parameters, which only show as a
/// ripple of tenths of a dB, go first. Checks that the predicted 1-σ uncertainty
/// tracks the actual error.
#[test]
fn recovery_against_noise_level() {
    let p = LimbParams::TABLE1_MEAN;
    for noise in [f64::NEG_INFINITY, -40.0, -30.0, -20.0] {
        let (freqs, ratio) = measured_ratio_at(p, 11, noise);
        let fit = fit_limb(&freqs, &ratio, &LimbFitConfig::default()).unwrap();
        let err = fit
            .model
            .params
            .to_array()
            .iter()
            .zip(p.to_array())
            .map(|(g, w)| 100.0 * (g / w - 1.0))
            .collect::<Vec<f64>>();
        let sd = fit.relative_std.map(|s| 100.0 * s);
        eprintln!(
            "noise {noise} dB: rms {:.3} dB, error % {err:.2?}, predicted 1-sigma % {sd:.2?}",
            fit.rms_error_db
        );
        assert!(err[0].abs() < 5.0, "{err:?}");
        // The uncertainty is indicative (see `LimbFit::relative_std`), hence 5 σ; the
        // 1.5 % covers the simulation's own systematic error (the noiseless row): the
        // bilinear user is not exactly the analog model that is fitted.
        for (e, s) in err.iter().zip(sd) {
            assert!(e.abs() < 5.0 * s + 1.5, "{err:?} vs {sd:?}");
        }
    }
}
