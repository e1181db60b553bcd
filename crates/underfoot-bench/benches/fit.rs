//! Time of a full automatic fit of one material: all its recordings, conditioning, strike
//! detection, measurement, and the order search with every start and refinement.
//!
//! Times a synthetic material (three seeded strikes through a known filter) and the
//! shared gravel, concrete and snow recordings; without the shared recordings the bench
//! fails and says where it looked, rather than print a figure of something else.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use underfoot::material::build::{BuildConfig, build_material};
use underfoot::recording::Recording;
use underfoot::signal::Sos;
use underfoot::signal::noise::SplitMix64;
use underfoot::signal::sos::{Biquad, RootPair};
use underfoot::units::SampleRate;
use underfoot_bench::shared_recordings;

fn synthetic() -> Vec<Recording> {
    let rate = SampleRate(44_100);
    let filter = Sos::new(vec![
        Biquad::from_roots(
            RootPair::Real(0.99, -0.5),
            RootPair::Conjugate(num_complex::Complex64::from_polar(0.995, 0.01)),
            1.0,
        ),
        Biquad::from_roots(
            RootPair::Real(0.9, 0.0),
            RootPair::Conjugate(num_complex::Complex64::from_polar(0.99, 0.04)),
            1.0,
        ),
    ]);
    let mut rng = SplitMix64::new(0x2545_f491_4f6c_dd1d);
    let mut noise = move || rng.uniform() - 0.5;
    (0..3)
        .map(|i| {
            let mut x: Vec<f64> = (0..rate.0 as usize).map(|_| 1e-4 * noise()).collect();
            for k in 0..400 {
                x[8000 + k] += noise() * (-(k as f64) / 80.0).exp();
            }
            filter.filter_in_place(&mut x);
            Recording {
                name: format!("synthetic-{i}.wav"),
                rate,
                samples: x,
                sha256: String::new(),
                excerpt: None,
            }
        })
        .collect()
}

/// Gravel's search stops at the bound (one fit); concrete's and snow's reach the targets
/// and bisect (five fits, snow's all at high orders): the two ends of the automatic search.
fn bench(c: &mut Criterion) {
    let cfg = BuildConfig::default();
    // The synthetic material runs anywhere; the shared ones, which the README's figures
    // are of, are required (the bench fails, saying where it looked, without them).
    let mut materials = vec![("synthetic".to_string(), synthetic())];
    materials.extend(
        ["gravel", "hard", "snow"]
            .iter()
            .map(|m| ((*m).to_string(), shared_recordings(m))),
    );
    for (name, recs) in &materials {
        let model = build_material(name, recs, &cfg, &mut |_| {}).expect("fit");
        eprintln!(
            "{name}: order {}, LSD {:.3} dB, NRMSE {:.4}",
            model.order, model.fit.lsd_db, model.fit.nrmse
        );
        c.bench_function(&format!("automatic fit/{name}"), |b| {
            b.iter(|| build_material(name, black_box(recs), &cfg, &mut |_| {}).expect("fit"));
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
