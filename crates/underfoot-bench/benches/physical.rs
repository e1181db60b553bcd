//! Real-time cost of the physical model.
//!
//! - `impact/3 modes`, `impact/16 modes`: a Hertzian hammer (0.5 kg at 1 m/s, a 3.9 ms
//!   contact) striking a surface of 3 or 16 modes every 0.1 s at 48 kHz, in 128-frame
//!   blocks. Criterion's throughput is samples per second; divided by 48 000 it is the
//!   number of surfaces one core runs in real time.
//! - `impact/rigid`: the same hammer on a rigid surface, the cost of the contact alone.
//! - `aggregate/3 modes`, `aggregate/16 modes`: the crumpling model with its default
//!   grain (four impacts in flight) on the same surfaces, at a constant 300 events/s, at 48 kHz in
//!   128-frame blocks; throughput in samples per second.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use underfoot::physical::{
    Aggregate, AggregateParams, Impact, ImpactParams, ResonatorBank, Surface,
};
use underfoot::units::SampleRate;
use underfoot_bench::surface_modes;

const RATE: SampleRate = SampleRate(48_000);
const STRIKE_EVERY: usize = 4_800;

fn surface(n: usize) -> Surface {
    Surface::Resonant(ResonatorBank::new(&surface_modes(n), RATE).expect("modes below Nyquist"))
}

fn impact(c: &mut Criterion) {
    let params = ImpactParams {
        mass: 0.5,
        stiffness: 1e7,
        alpha: 1.5,
        damping: 1e5,
        velocity: 1.0,
    };
    let mut group = c.benchmark_group("impact");
    group.throughput(Throughput::Elements(STRIKE_EVERY as u64));
    let mut out = vec![0.0f32; STRIKE_EVERY];
    for (name, s) in [
        ("3 modes", surface(3)),
        ("16 modes", surface(16)),
        ("rigid", Surface::Rigid),
    ] {
        let mut impact = Impact::new(params, s, RATE).expect("valid parameters");
        group.bench_function(name, |b| {
            b.iter(|| {
                impact.strike(black_box(1.0)).expect("valid velocity");
                for block in out.chunks_mut(128) {
                    impact.process(block);
                }
                black_box(&out);
            });
        });
    }
    group.finish();
}

/// Samples per measured iteration: 0.1 s, about 30 events.
const AGGREGATE_SPAN: usize = 4_800;

fn aggregate(c: &mut Criterion) {
    let mut group = c.benchmark_group("aggregate");
    group.throughput(Throughput::Elements(AGGREGATE_SPAN as u64));
    let rates = vec![300.0f32; 128];
    let mut out = vec![0.0f32; AGGREGATE_SPAN];
    for n in [3, 16] {
        let mut agg = Aggregate::new(&surface_modes(n), &AggregateParams::default(), RATE, 1)
            .expect("valid parameters");
        group.bench_function(format!("{n} modes"), |b| {
            b.iter(|| {
                for block in out.chunks_mut(128) {
                    agg.process(black_box(&rates[..block.len()]), block);
                }
                black_box(&out);
            });
        });
    }
    group.finish();
}

criterion_group!(benches, impact, aggregate);
criterion_main!(benches);
