//! What a whole `fit` of one material costs, and where it goes (issue 13's "Fast": a
//! whole `fit` of gravel under 100 ms, the IIR order search under 30 ms).
//!
//! On the shared recordings of each material (gravel first; the bench fails, saying
//! where it looked, when they are absent):
//!
//! - `calibration/excitation/NAME`: [`underfoot::excitation::estimate()`] alone, for the
//!   fitted filter (its deconvolution and its calibration renders);
//! - `calibration/physical/NAME`: [`estimate_measured`] alone, from the measured
//!   response the IIR fit has already computed, struck by the fitted excitation (what
//!   `build_material` does);
//! - `calibration/iir/NAME`: `build_material` without the excitation and the physical
//!   model (reading, conditioning and measuring the recordings, and the order search);
//! - `calibration/whole/NAME`: `build_material` with all three, what `underfoot fit` runs
//!   between reading the files and writing the library.
//!
//! The whole process (decoding the Ogg files, writing the library) is timed by
//! `scripts/time-fit`, the median of five runs of the release binary.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use underfoot::analysis::measure;
use underfoot::excitation::{EstimateConfig as ExcitationConfig, estimate};
use underfoot::material::build::{BuildConfig, build_material};
use underfoot::physical::EstimateConfig;
use underfoot::physical::estimate::estimate_measured;
use underfoot::recording::Recording;
use underfoot_bench::shared_recordings;

fn bench(c: &mut Criterion) {
    let materials: Vec<(&str, Vec<Recording>)> = ["gravel", "hard"]
        .into_iter()
        .map(|m| (m, shared_recordings(m)))
        .collect();
    let whole = BuildConfig::default();
    let iir = BuildConfig {
        physical: None,
        excitation: None,
        ..BuildConfig::default()
    };
    let cal = EstimateConfig::default();
    let exc = ExcitationConfig::default();
    let mut group = c.benchmark_group("calibration");
    for (name, recs) in &materials {
        let measured = measure(recs, &cal.analysis).expect("measurable");
        let filter = build_material(name, recs, &iir, &mut |_| {})
            .expect("fit")
            .sos()
            .expect("sections");
        let excitation = estimate(recs, &measured, &filter, &exc)
            .expect("an excitation")
            .model;
        group.bench_function(format!("excitation/{name}"), |b| {
            b.iter(|| estimate(black_box(recs), &measured, &filter, &exc).expect("an excitation"));
        });
        let model = estimate_measured(recs, &measured, &excitation, &cal).expect("estimates");
        eprintln!(
            "{name}: physical {}, {} modes, LSD {:.3} dB",
            model.kind.name(),
            model.modes.len(),
            model.record.lsd_db
        );
        group.bench_function(format!("physical/{name}"), |b| {
            b.iter(|| {
                estimate_measured(black_box(recs), &measured, &excitation, &cal).expect("estimates")
            });
        });
        group.bench_function(format!("iir/{name}"), |b| {
            b.iter(|| build_material(name, black_box(recs), &iir, &mut |_| {}).expect("fit"));
        });
        group.bench_function(format!("whole/{name}"), |b| {
            b.iter(|| build_material(name, black_box(recs), &whole, &mut |_| {}).expect("fit"));
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
