//! Real-time cost of the compensation filter bank.
//!
//! - `filterbank/N=256 R=64`: the default bank (sqrt-Hann) on one channel, 1 s at 48 kHz
//!   in 64-frame blocks, gains set to a smooth curve. Criterion's throughput is samples
//!   per second; 48 000 divided by it is the fraction of one core's real-time budget a
//!   channel takes. The latency is `N - 1` samples, 5.31 ms.
//! - `filterbank/N=1024 R=256`: the finer bank (46.9 Hz bins, 21.3 ms latency).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use underfoot::compensation::filterbank::{FilterBank, FilterBankConfig, Window};
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

criterion_group!(benches, filterbank);
criterion_main!(benches);
