//! Time of a full automatic fit of one material: all its recordings, conditioning, strike
//! detection, measurement, and the order search with every start and refinement.
//!
//! Uses the shared gravel recordings when present, else a synthetic material (three
//! seeded strikes through a known filter) so the benchmark runs anywhere.

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion};
use underfoot::material::build::{build_material, BuildConfig};
use underfoot::recording::{read, Recording};
use underfoot::signal::sos::{Biquad, RootPair};
use underfoot::signal::Sos;
use underfoot::units::SampleRate;

fn gravel() -> Option<Vec<Recording>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/footsteps/gravel");
    let mut files: Vec<_> = std::fs::read_dir(dir).ok()?.filter_map(Result::ok).map(|e| e.path()).collect();
    files.sort();
    files.iter().map(|p| read(p, None).ok()).collect()
}

fn synthetic() -> Vec<Recording> {
    let rate = SampleRate(44_100);
    let filter = Sos::new(vec![
        Biquad::from_roots(RootPair::Real(0.99, -0.5), RootPair::Conjugate(num_complex::Complex64::from_polar(0.995, 0.01)), 1.0),
        Biquad::from_roots(RootPair::Real(0.9, 0.0), RootPair::Conjugate(num_complex::Complex64::from_polar(0.99, 0.04)), 1.0),
    ]);
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    let mut noise = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    (0..3)
        .map(|i| {
            let mut x: Vec<f64> = (0..rate.0 as usize).map(|_| 1e-4 * noise()).collect();
            for k in 0..400 {
                x[8000 + k] += noise() * (-(k as f64) / 80.0).exp();
            }
            filter.filter_in_place(&mut x);
            Recording { name: format!("synthetic-{i}.wav"), rate, samples: x, sha256: String::new() }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let (label, recs) = match gravel() {
        Some(r) => ("gravel (shared recordings)", r),
        None => ("synthetic material (shared data absent)", synthetic()),
    };
    let cfg = BuildConfig::default();
    let model = build_material("bench", &recs, &cfg, &mut |_| {}).expect("fit");
    eprintln!("benchmarking {label}: order {}, LSD {:.3} dB", model.order, model.fit.lsd_db);
    c.bench_function("automatic fit of one material", |b| {
        b.iter(|| build_material("bench", black_box(&recs), &cfg, &mut |_| {}).expect("fit"));
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
