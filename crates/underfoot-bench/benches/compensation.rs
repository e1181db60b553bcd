//! Real-time cost of the compensation filter bank.
//!
//! - `filterbank/N=256 R=64`: the default bank (sqrt-Hann) on one channel, 1 s at 48 kHz
//!   in 64-frame blocks, gains set to a smooth curve. Criterion's throughput is samples
//!   per second; 48 000 divided by it is the fraction of one core's real-time budget a
//!   channel takes. The latency is `N - 1` samples, 5.31 ms.
//! - `filterbank/N=1024 R=256`: the finer bank (46.9 Hz bins, 21.3 ms latency).
//! - `equalizer/...`: the device equalizer as the engine runs it on a channel, with the
//!   weights tuned on the simulated tile: `bank N=4096` (11.7 Hz bins, latency 4095
//!   samples, 85.3 ms) and `low-delay taps=L` (a minimum-phase FIR, no bulk delay).
//! - `equalizer/redesign taps=2048`: one low-delay redesign (what online adaptation pays
//!   per update), in seconds per call.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use underfoot::compensation::equalizer::{
    EqualizerConfig, EqualizerFilter, Realisation, SpectralWeights, equalize,
};
use underfoot::compensation::filterbank::{FilterBank, FilterBankConfig, Window};
use underfoot::compensation::sweep::{Sweep, SweepConfig};
use underfoot::sim::{SimulatedTile, TileConfig};
use underfoot::units::SampleRate;

const RATE: SampleRate = SampleRate(48_000);
const BLOCK: usize = 64;

fn filterbank(c: &mut Criterion) {
    let input: Vec<f32> = (0..RATE.0 as usize)
        .map(|n| ((n as f32 * 0.0131).sin() + 0.3 * (n as f32 * 0.41).sin()) * 0.5)
        .collect();
    let mut output = vec![0.0f32; input.len()];
    let mut group = c.benchmark_group("filterbank");
    group.throughput(Throughput::Elements(input.len() as u64));
    for (bands, hop) in [(256, 64), (1024, 256)] {
        let config = FilterBankConfig {
            bands,
            hop,
            window: Window::SqrtHann,
        };
        let mut bank = FilterBank::new(config, RATE).expect("valid configuration");
        bank.set_gains_with(|f| 1.0 / (1.0 + f.0 as f32 / 2000.0));
        group.bench_function(format!("N={bands} R={hop}"), |b| {
            b.iter(|| {
                for (x, y) in input.chunks(BLOCK).zip(output.chunks_mut(BLOCK)) {
                    bank.process(black_box(x), y);
                }
                black_box(&output);
            })
        });
    }
    group.finish();
}

fn equalizer(c: &mut Criterion) {
    let input: Vec<f32> = (0..RATE.0 as usize)
        .map(|n| ((n as f32 * 0.0131).sin() + 0.3 * (n as f32 * 0.41).sin()) * 0.5)
        .collect();
    let mut output = vec![0.0f32; input.len()];
    let sweep = Sweep::new(SweepConfig::new(RATE)).expect("default sweep");
    let mut tile = SimulatedTile::new(&TileConfig::default(), RATE).expect("default tile");
    let weights: SpectralWeights = equalize(
        &mut tile,
        &sweep,
        EqualizerConfig::default(),
        Realisation::default(),
        2,
        false,
    )
    .expect("equalizes")
    .weights;
    let mut group = c.benchmark_group("equalizer");
    group.throughput(Throughput::Elements(input.len() as u64));
    for (name, realisation) in [
        ("bank N=4096".to_string(), Realisation::Bank),
        (
            "low-delay taps=1024".to_string(),
            Realisation::LowDelay { taps: 1024 },
        ),
        (
            "low-delay taps=2048".to_string(),
            Realisation::LowDelay { taps: 2048 },
        ),
    ] {
        let mut filter = EqualizerFilter::new(&weights, realisation).expect("realisable");
        eprintln!("{name}: latency {} samples", filter.latency());
        group.bench_function(name, |b| {
            b.iter(|| {
                for (x, y) in input.chunks(BLOCK).zip(output.chunks_mut(BLOCK)) {
                    filter.process(black_box(x), y);
                }
                black_box(&output);
            })
        });
    }
    group.finish();
    let mut filter = EqualizerFilter::new(&weights, Realisation::default()).expect("realisable");
    let gains = weights.gains_db.clone();
    c.bench_function("equalizer/redesign taps=2048", |b| {
        b.iter(|| black_box(filter.set_weights(black_box(&gains))))
    });
}

criterion_group!(benches, filterbank, equalizer);
criterion_main!(benches);
