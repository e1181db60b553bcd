//! Real-time cost of the physical model.
//!
//! - `impact/3 modes`, `impact/16 modes`: a Hertzian hammer (0.5 kg at 1 m/s, a 3.9 ms
//!   contact) striking a surface of 3 or 16 modes every 0.1 s at 48 kHz, in 128-frame
//!   blocks. Criterion's throughput is samples per second; divided by 48 000 it is the
//!   number of surfaces one core runs in real time.
//! - `impact/rigid`: the same hammer on a rigid surface, the cost of the contact alone.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use underfoot::physical::{Impact, ImpactParams, Mode, ResonatorBank, Surface};
use underfoot::units::{Hz, SampleRate, Seconds};

const RATE: SampleRate = SampleRate(48_000);
const STRIKE_EVERY: usize = 4_800;

fn surface(modes: usize) -> Surface {
    let modes: Vec<Mode> = (0..modes)
        .map(|k| {
            let f = 60.0 * 1.37f64.powi(k as i32);
            Mode {
                frequency: Hz(f),
                decay: Seconds(8.0 / f),
                gain: 1e-3 / (1.0 + k as f64),
            }
        })
        .collect();
    Surface::Resonant(ResonatorBank::new(&modes, RATE).expect("modes below Nyquist"))
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

criterion_group!(benches, impact);
criterion_main!(benches);
