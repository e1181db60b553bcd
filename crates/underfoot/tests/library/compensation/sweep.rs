//! Sweep measurements of the simulated tile against its noiseless response, and of a
//! replay of a measurement (moved from the unit tests of `compensation::sweep`, which
//! cannot use the simulators above them).

use underfoot::compensation::sweep::{
    FrequencyResponse, MeasuredDevice, Sweep, SweepConfig, measure,
};
use underfoot::sim::{SimulatedTile, TileConfig};
use underfoot::units::{Decibels, SampleRate};

const RATE: SampleRate = SampleRate(48_000);

/// Largest magnitude error (dB) and phase error (degrees) against the tile's oracle.
fn errors(tile: &SimulatedTile, fr: &FrequencyResponse) -> (f64, f64, f64) {
    let mut max_db = 0.0f64;
    let mut max_deg = 0.0f64;
    let mut sq = 0.0;
    for (f, h) in fr.freqs.iter().zip(&fr.response) {
        let t = tile.true_response(*f);
        let db = 20.0 * (h.norm() / t.norm()).log10();
        let deg = (h / t).arg().to_degrees();
        max_db = max_db.max(db.abs());
        max_deg = max_deg.max(deg.abs());
        sq += db * db;
    }
    (max_db, max_deg, (sq / fr.freqs.len() as f64).sqrt())
}

fn tile(noise: Option<Decibels>, seed: u64) -> SimulatedTile {
    let cfg = TileConfig {
        noise,
        seed,
        ..TileConfig::default()
    };
    SimulatedTile::new(&cfg, RATE).unwrap()
}

#[test]
fn a_replayed_measurement_has_the_measured_magnitude() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut device = tile(Some(Decibels(-40.0)), 3);
    let measured = measure(&mut device, &sweep).unwrap();
    let mut replay = MeasuredDevice::new(&measured, RATE).unwrap();
    let again = measure(&mut replay, &sweep).unwrap();
    for (a, b) in again.magnitude_db().iter().zip(measured.magnitude_db()) {
        assert!((a.0 - b.0).abs() < 0.2, "{} vs {}", a.0, b.0);
    }
}

#[test]
fn noiseless_tile_matches_oracle() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut t = tile(None, 1);
    let fr = measure(&mut t, &sweep).unwrap();
    let (db, deg, rms) = errors(&t, &fr);
    eprintln!("noiseless: max {db:.2e} dB, max {deg:.2e} deg, rms {rms:.2e} dB");
    assert_eq!(fr.freqs.len(), 128);
    assert!(db < 0.1, "{db} dB");
    assert!(deg < 2.0, "{deg} deg");
}

#[test]
fn noisy_tile_and_averaging() {
    let mut one = SweepConfig::new(RATE);
    one.repeats = 1;
    let sweep1 = Sweep::new(one).unwrap();
    let sweep3 = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut rms1 = 0.0;
    let mut rms3 = 0.0;
    let seeds = 4;
    for seed in 0..seeds {
        let mut t = tile(Some(Decibels(-40.0)), seed);
        let fr1 = measure(&mut t, &sweep1).unwrap();
        let (db1, _, r1) = errors(&t, &fr1);
        let fr3 = measure(&mut t, &sweep3).unwrap();
        let (db3, _, r3) = errors(&t, &fr3);
        eprintln!(
            "-40 dB noise, seed {seed}: 1 repeat max {db1:.3} rms {r1:.4}; 3 repeats max {db3:.3} rms {r3:.4} dB"
        );
        assert!(db3 < 0.5 && db1 < 0.5, "{db1} {db3}");
        rms1 += r1 / seeds as f64;
        rms3 += r3 / seeds as f64;
    }
    eprintln!("mean rms error: 1 repeat {rms1:.4} dB, 3 repeats {rms3:.4} dB");
    assert!(rms3 < 0.8 * rms1, "{rms3} vs {rms1}");
}

#[test]
fn flatness_of_the_tile() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut t = tile(None, 0);
    let dev_tile = measure(&mut t, &sweep).unwrap().deviation_from_flat_db().0;
    eprintln!("tile: deviation {dev_tile:.2} dB");
    assert!(dev_tile > 2.0, "{dev_tile}");
}
