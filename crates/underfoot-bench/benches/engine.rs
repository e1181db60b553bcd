//! Real-time cost of the synthesis.
//!
//! - `voice/order-12`: one voice of an order-12 material (`glass`: six modes, a fourth-order
//!   low-pass and the DC-blocking high-pass) for one second at 48 kHz, walking (a strike
//!   every half second). Criterion's throughput is voice-samples per second; divided by
//!   48 000 it is the number of channels one core runs in real time.
//! - `voice/order-12 modes only`: the same without the post filter, to show its share.
//! - `engine/64-frame block`: the whole engine (event handling, 16 channels walking,
//!   limiter, fades) for one 64-frame block; against the block's 1.33 ms of real time.
//!   `engine/64-frame block, 16 channels, physical` is the same with `--model physical`.
//! - `model/<material> iir` against `model/<material> physical`: one second of a walk (a
//!   nominal step every half second) through the material's IIR voice and its calibrated
//!   physical model, for an aggregate (`gravel`) and a solid (`hard`).

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use underfoot::engine::{self, EngineConfig, Event, MaterialBank, TimedEvent};
use underfoot::force::SensorReading;
use underfoot::force::drive::DriveKind;
use underfoot::force::gait::nominal_step;
use underfoot::material::builtin::builtin;
use underfoot::physical::Ground;
use underfoot::signal::noise::SplitMix64;
use underfoot::synthesis::{PreparedMaterial, SynthModel, Voice, VoiceConfig};
use underfoot::units::{Newtons, SampleRate};

const RATE: SampleRate = SampleRate(48_000);

fn voice(c: &mut Criterion) {
    let model = builtin().get("glass").expect("built-in glass");
    assert_eq!(model.order, 12);
    let m = PreparedMaterial::prepare(model, RATE, &VoiceConfig::default()).unwrap();
    let mut v = Voice::new();
    v.load(&m, DriveKind::Impulse);
    let mut x = vec![0.0f32; 48_000];
    x[0] = 1.0;
    x[24_000] = 0.8;
    let mut y = vec![0.0f32; 48_000];
    let mut rng = SplitMix64::new(1);
    let mut group = c.benchmark_group("voice");
    group.throughput(Throughput::Elements(x.len() as u64));
    group.bench_function("order-12", |b| {
        b.iter(|| {
            v.perturb(&mut rng, 0.01);
            black_box(v.process(black_box(&x), &mut y));
        });
    });
    let bare = PreparedMaterial::prepare(
        model,
        RATE,
        &VoiceConfig {
            lowpass_order: 0,
            highpass_cutoff: Some(underfoot::units::Hz(0.0)),
            ..VoiceConfig::default()
        },
    )
    .unwrap();
    let mut w = Voice::new();
    w.load(&bare, DriveKind::Impulse);
    group.bench_function("order-12 modes only", |b| {
        b.iter(|| {
            w.perturb(&mut rng, 0.01);
            black_box(w.process(black_box(&x), &mut y));
        });
    });
    group.finish();
}

fn models(c: &mut Criterion) {
    // The loading rate of a nominal step every half second, and an impulse at each strike.
    let step =
        DriveKind::ForceRate.offline(&nominal_step(70.0, 1.8, RATE.hz()), RATE, Newtons(1.0));
    let mut loading = vec![0.0f32; 48_000];
    let mut impulses = vec![0.0f32; 48_000];
    // A nominal step lasts longer than the half second between strikes (about 0.7 s at
    // 1.8 steps/s); the next strike cuts it, as the next heel strike does on a walk.
    let n = step.len().min(24_000);
    for start in [0, 24_000] {
        loading[start..start + n].copy_from_slice(&step[..n]);
        impulses[start] = 1.0;
    }
    let mut y = vec![0.0f32; 48_000];
    let mut rng = SplitMix64::new(1);
    let mut group = c.benchmark_group("model");
    group.throughput(Throughput::Elements(loading.len() as u64));
    for name in ["gravel", "hard"] {
        let model = builtin().get(name).expect("built-in material");
        let m = PreparedMaterial::prepare(model, RATE, &VoiceConfig::default()).unwrap();
        let mut v = Voice::new();
        v.load(&m, DriveKind::Impulse);
        group.bench_function(format!("{name} iir"), |b| {
            b.iter(|| {
                v.perturb(&mut rng, 0.01);
                black_box(v.process(black_box(&impulses), &mut y));
            });
        });
        let physical = model.physical.as_ref().expect("built-in physical model");
        let mut g = Ground::new(physical, RATE, 1, 256).unwrap();
        group.bench_function(format!("{name} physical"), |b| {
            b.iter(|| {
                g.strike(1.0);
                black_box(g.process(black_box(&loading), &mut y));
                g.strike(1.0);
            });
        });
    }
    group.finish();
}

fn engine_block(c: &mut Criterion) {
    for model in [SynthModel::Iir, SynthModel::Physical] {
        engine_block_with(c, model);
    }
}

fn engine_block_with(c: &mut Criterion, model: SynthModel) {
    let channels = 16;
    let weight = Newtons::weight_of(70.0);
    let bank = MaterialBank::prepare(
        builtin(),
        RATE,
        &VoiceConfig {
            model,
            ..VoiceConfig::default()
        },
        &nominal_step(70.0, 1.8, RATE.hz()),
        weight,
    )
    .unwrap();
    let config = EngineConfig {
        channels,
        max_block: 64,
        ..EngineConfig::default()
    };
    let initial: Vec<u16> = (0..channels).map(|c| (c % 11) as u16).collect();
    let (mut ctl, mut eng) = engine::build(&config, bank, &initial).unwrap();
    let mut out = vec![0.0f32; 64 * channels];
    let mut block = 0u64;
    let mut group = c.benchmark_group("engine");
    group.throughput(Throughput::Elements(64));
    let name = match model {
        SynthModel::Iir => "64-frame block, 16 channels",
        SynthModel::Physical => "64-frame block, 16 channels, physical",
    };
    group.bench_function(name, |b| {
        b.iter(|| {
            // A 500 Hz reading every 96 frames on every channel, a step every 0.5 s.
            if block.is_multiple_of(3) {
                let t = block as f32 * 64.0 / 48_000.0;
                let f = if t % 0.5 < 0.3 { 700.0 } else { 0.0 };
                for ch in 0..channels as u16 {
                    let _ = ctl.send(TimedEvent::now(Event::Force {
                        channel: ch,
                        reading: SensorReading::single(f),
                    }));
                }
            }
            eng.process(black_box(&mut out), channels);
            block += 1;
        });
    });
    group.finish();
}

criterion_group!(benches, voice, models, engine_block);
criterion_main!(benches);
