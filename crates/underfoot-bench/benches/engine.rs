//! Real-time cost of the synthesis.
//!
//! - `voice/order-12`: one voice of an order-12 material (`glass`: six modes, a fourth-order
//!   low-pass and the DC-blocking high-pass) for one second at 48 kHz, walking (a strike
//!   every half second). Criterion's throughput is voice-samples per second; divided by
//!   48 000 it is the number of channels one core runs in real time.
//! - `voice/order-12, 8 channels in lanes`: the same voice on eight channels, run together
//!   in 64-frame blocks as the engine runs its channels (`synthesis::VoiceLanes`); its
//!   throughput is channel-samples per second. The bench prints both as channels per
//!   core, and their ratio.
//! - `voice/order-12 modes only`: the same without the post filter, to show its share.
//! - `engine/64-frame block`: the whole engine (event handling, 16 channels walking,
//!   limiter, fades) for one 64-frame block; against the block's 1.33 ms of real time.
//!   `engine/64-frame block, 16 channels, physical` is the same with `--model physical`.
//! - `model/<material> iir` against `model/<material> physical`: one second of a walk (a
//!   nominal step every half second, each starting the material's fitted excitation at the
//!   nominal clock speed) through the material's IIR voice and its calibrated physical
//!   model, for an aggregate (`gravel`) and a solid (`hard`).
//! - `channel/<material> <model>, <excitation>, <play>`: one channel of an engine of 8 (its
//!   share of the engine's work included), with the material's fitted excitation
//!   (`Fitted`) and with one impulse a step (`Heel`: the plain voice, the IIR paper's
//!   drive). `gravel ..., Walk`: a generated gait at 2 steps/s on every channel, one foot
//!   (a heel strike a second; gravel's train runs for about a third of the walk).
//!   `sand ..., Steps`, the worst case: the densest train of the built-ins, and an explicit
//!   step every 0.3 s, shorter than its train, so that a train always runs. Throughput is
//!   channel-samples per second; the bench prints each median as nanoseconds per sample
//!   and channels per core at 48 kHz, and the ratio of the fitted excitation to the plain
//!   voice.
//! - `generator/...`: `Generator::next` alone, over gravel's trains on nominal steps (the
//!   samples while a train runs), in sand's densest bin at the nominal pace (a draw a
//!   sample), in the same bin with more than `MAX_DRAWS` micro-impacts due every sample (a
//!   clock a hundred times the nominal pace: no walk does that; the bound of the work per
//!   sample), and idle. Printed as nanoseconds per sample and as a share of one channel's
//!   budget at 1000 channels a core (20.8 ns).

use std::hint::black_box;

use criterion::{Criterion, SamplingMode, Throughput, criterion_group, criterion_main};
use underfoot::engine::{self, EngineConfig, Event, MaterialBank, TimedEvent};
use underfoot::excitation::clock::nominal_speeds;
use underfoot::excitation::{ExcitationModel, Generator, MAX_BINS, MAX_DRAWS, Tables};
use underfoot::force::SensorReading;
use underfoot::force::drive::DriveKind;
use underfoot::force::gait::{GaitConfig, generate, nominal_step};
use underfoot::material::builtin::builtin;
use underfoot::signal::noise::SplitMix64;
use underfoot::synthesis::{
    ExcitationChoice, LANE_WIDTH, Lane, PreparedMaterial, SynthModel, Voice, VoiceConfig,
    VoiceLanes,
};
use underfoot::units::{Newtons, SampleRate, Seconds};
use underfoot_bench::{Samples, channels_per_core, engine_walk_block};

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
    let mut alone = Samples::default();
    group.bench_function("order-12", |b| {
        b.iter_custom(|iterations| {
            alone.time(iterations, || {
                v.perturb(&mut rng, 0.01);
                black_box(v.process(black_box(&x), &mut y));
                x.len() as u64
            })
        });
    });
    // The same voice on eight channels, run together as the engine runs them, in its
    // 64-frame blocks.
    let mut voices: Vec<Voice> = (0..LANE_WIDTH).map(|_| v.clone()).collect();
    let mut ys = vec![vec![0.0f32; x.len()]; LANE_WIDTH];
    let mut lanes = VoiceLanes::new();
    let mut laned = Samples::default();
    group.throughput(Throughput::Elements((x.len() * LANE_WIDTH) as u64));
    group.bench_function("order-12, 8 channels in lanes", |b| {
        b.iter_custom(|iterations| {
            laned.time(iterations, || {
                for v in &mut voices {
                    v.perturb(&mut rng, 0.01);
                }
                for start in (0..x.len()).step_by(64) {
                    let input = black_box(&x[start..start + 64]);
                    let mut args: [Option<Lane<'_>>; LANE_WIDTH] = Default::default();
                    for ((arg, voice), y) in args.iter_mut().zip(&mut voices).zip(&mut ys) {
                        *arg = Some(Lane {
                            voice,
                            input,
                            output: &mut y[start..start + 64],
                        });
                    }
                    black_box(lanes.process(&mut args));
                }
                (x.len() * LANE_WIDTH) as u64
            })
        });
    });
    group.throughput(Throughput::Elements(x.len() as u64));
    if let (Some(alone), Some(laned)) = (alone.median(100), laned.median(100)) {
        println!(
            "\nAn order-12 voice at 48 kHz: alone {:.2} ns a sample = {:.0} channels/core; \
             8 in lanes {:.2} ns a channel's sample = {:.0} channels/core ({:.2}x)",
            alone * 1e9,
            channels_per_core(alone, RATE.hz()),
            laned * 1e9,
            channels_per_core(laned, RATE.hz()),
            alone / laned
        );
    }
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
    // Two nominal steps, half a second apart, each starting the material's excitation
    // with the nominal clock speed: what both models are driven by in the engine.
    let speeds = nominal_speeds(RATE);
    let mut speed = vec![0.0f32; 48_000];
    // A nominal step lasts longer than the half second between strikes (about 0.7 s at
    // 1.8 steps/s); the next strike cuts it, as the next heel strike does on a walk.
    let n = speeds.len().min(24_000);
    for start in [0, 24_000] {
        speed[start..start + n].copy_from_slice(&speeds[..n]);
    }
    let mut y = vec![0.0f32; 48_000];
    let mut rng = SplitMix64::new(1);
    let mut group = c.benchmark_group("model");
    group.throughput(Throughput::Elements(speed.len() as u64));
    for name in ["gravel", "hard"] {
        let model = builtin().get(name).expect("built-in material");
        let physical = VoiceConfig {
            model: SynthModel::Physical,
            ..VoiceConfig::default()
        };
        let m = PreparedMaterial::prepare(model, RATE, &physical).unwrap();
        let mut excitation = vec![0.0f32; 48_000];
        let mut g = Generator::new(1);
        for (k, (x, v)) in excitation
            .chunks_mut(24_000)
            .zip(speed.chunks(24_000))
            .enumerate()
        {
            g.strike(&m.excitation, if k == 0 { 1.0 } else { 0.8 });
            g.process(&m.excitation, v, x);
        }
        let mut v = Voice::new();
        v.load(&m, DriveKind::Impulse);
        group.bench_function(format!("{name} iir"), |b| {
            b.iter(|| {
                v.perturb(&mut rng, 0.01);
                black_box(v.process(black_box(&excitation), &mut y));
            });
        });
        let mut ground = m.ground.clone().expect("built-in physical model");
        group.bench_function(format!("{name} physical"), |b| {
            b.iter(|| black_box(ground.process(black_box(&excitation), &mut y)));
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
            engine_walk_block(&mut ctl, &mut eng, &mut out, channels, block);
            block += 1;
        });
    });
    group.finish();
}

/// Channels of the engine in the `channel` benches: a tile's worth, so that the engine's
/// work per block is shared out as it is in use.
const CHANNELS: usize = 8;
/// Samples of each `channel` bench: an iteration renders a whole second or more of every
/// channel, so fewer than criterion's default hundred give a stable median.
const CHANNEL_SAMPLES: usize = 20;
/// Frames between two explicit steps in the worst case: 0.3 s, shorter than the trains.
const STEP_EVERY: u64 = 14_400;

/// What a `channel` bench plays.
#[derive(Debug, Clone, Copy)]
enum Play {
    /// One foot walking at 2 steps/s (a heel strike a second), its readings at 500 Hz.
    Walk,
    /// An explicit step every 0.3 s, its train on the free-running clock.
    Steps,
}

/// One second of one foot walking at 2 steps/s, the gait model's force with no variation
/// (so that the second loops): each reading's frame in the second, and the reading.
fn walk_second() -> Vec<(u64, SensorReading)> {
    let gait = generate(&GaitConfig {
        steps: 3,
        channels: 1,
        cadence: 2.0,
        variation: 0.0,
        ..GaitConfig::default()
    })
    .expect("a valid gait");
    // From the swing before the second strike: the loop joins two swings.
    let from = gait.strikes[0][1].0 - 0.1;
    gait.track
        .rows
        .iter()
        .filter(|r| r.time.0 >= from && r.time.0 < from + 1.0)
        .map(|r| {
            (
                ((r.time.0 - from) * RATE.hz()).round() as u64,
                r.readings[0],
            )
        })
        .collect()
}

/// A material prepared as `MaterialBank::prepare` prepares it.
fn prepared(name: &str, voice: &VoiceConfig) -> PreparedMaterial {
    let model = builtin().get(name).expect("built-in material");
    let mut m = PreparedMaterial::prepare(model, RATE, voice).expect("a playable material");
    m.normalise_drives(
        &nominal_step(70.0, 1.8, RATE.hz()),
        Newtons::weight_of(70.0),
    );
    m
}

/// Per channel sample: the engine playing a material's fitted excitation against the same
/// engine playing one impulse a step, for both models, walking and in the worst case.
fn channel(c: &mut Criterion) {
    let walk = walk_second();
    let mut group = c.benchmark_group("channel");
    group.sampling_mode(SamplingMode::Flat);
    group.sample_size(CHANNEL_SAMPLES);
    let mut figures = Vec::new();
    for (material, play) in [("gravel", Play::Walk), ("sand", Play::Steps)] {
        for model in [SynthModel::Iir, SynthModel::Physical] {
            let mut medians = [None; 2];
            for (median, excitation) in medians
                .iter_mut()
                .zip([ExcitationChoice::Fitted, ExcitationChoice::Heel])
            {
                let voice = VoiceConfig {
                    model,
                    excitation,
                    ..VoiceConfig::default()
                };
                let bank = MaterialBank::from_prepared(vec![prepared(material, &voice)]);
                let config = EngineConfig {
                    channels: CHANNELS,
                    max_block: 64,
                    ..EngineConfig::default()
                };
                let (mut ctl, mut eng) = engine::build(&config, bank, &[0; CHANNELS]).unwrap();
                let period = match play {
                    Play::Walk => 48_000,
                    Play::Steps => 4 * STEP_EVERY,
                };
                let mut out = vec![0.0f32; 64 * CHANNELS];
                let mut base = 0u64;
                let mut samples = Samples::default();
                group.throughput(Throughput::Elements(period * CHANNELS as u64));
                let name = format!("{material} {}, {excitation:?}, {play:?}", model_name(model));
                group.bench_function(name, |b| {
                    b.iter_custom(|iterations| {
                        samples.time(iterations, || {
                            let mut next = 0;
                            for start in (base..base + period).step_by(64) {
                                let end = start + 64;
                                let mut send = |at: u64, event: &dyn Fn(u16) -> Event| {
                                    for channel in 0..CHANNELS as u16 {
                                        let _ = ctl.send(TimedEvent::at(at, event(channel)));
                                    }
                                };
                                match play {
                                    Play::Walk => {
                                        while let Some((frame, reading)) = walk.get(next)
                                            && base + frame < end
                                        {
                                            let at = base + frame;
                                            let time = Seconds(at as f64 / RATE.hz());
                                            send(at, &|channel| Event::Force {
                                                channel,
                                                reading: reading.at(time),
                                            });
                                            next += 1;
                                        }
                                    }
                                    // Mid-block, as a strike found between two readings.
                                    Play::Steps if (start - base).is_multiple_of(STEP_EVERY) => {
                                        send(start + 17, &|channel| Event::Step {
                                            channel,
                                            intensity: 1.0,
                                        });
                                    }
                                    Play::Steps => {}
                                }
                                eng.process(black_box(&mut out), CHANNELS);
                            }
                            base += period;
                            period * CHANNELS as u64
                        })
                    });
                });
                *median = samples.median(CHANNEL_SAMPLES);
            }
            let what = match play {
                Play::Walk => "walking",
                Play::Steps => "a step every 0.3 s",
            };
            figures.push((format!("{material} {}, {what}", model_name(model)), medians));
        }
    }
    group.finish();
    println!(
        "\nOne channel's sample in an engine of {CHANNELS} at 48 kHz (medians of criterion's samples), \
         with the fitted excitation and with one impulse a step:"
    );
    for (label, medians) in figures {
        if let [Some(fitted), Some(heel)] = medians {
            println!(
                "  {label:<34} fitted {:6.1} ns = {:5.0} channels/core; \
                 heel {:6.1} ns = {:5.0} channels/core; fitted/heel {:.2}",
                fitted * 1e9,
                channels_per_core(fitted, RATE.hz()),
                heel * 1e9,
                channels_per_core(heel, RATE.hz()),
                fitted / heel
            );
        }
    }
}

fn model_name(model: SynthModel) -> &'static str {
    match model {
        SynthModel::Iir => "iir",
        SynthModel::Physical => "physical",
    }
}

/// `Generator::next` alone: over the trains of nominal steps, in the densest bin of the
/// built-ins at the nominal pace and at its cap of draws a sample, and idle.
fn generator(c: &mut Criterion) {
    let gravel = prepared("gravel", &VoiceConfig::default()).excitation;
    let sand = builtin()
        .get("sand")
        .expect("built-in sand")
        .excitation
        .clone()
        .expect("sand's fitted excitation");
    let densest = sand.rate_hz.iter().copied().fold(0.0, f64::max);
    // Sand's densest bin over the whole profile, so that a train stays in it.
    let flat = ExcitationModel {
        rate_hz: vec![densest; MAX_BINS],
        energy: vec![(1.0 - sand.heel) / MAX_BINS as f64; MAX_BINS],
        duration_spread: 0.0,
        ..sand
    };
    let flat = Tables::new(&flat, RATE).expect("a valid excitation");
    let speeds = nominal_speeds(RATE);
    let mut out = vec![0.0f32; 48_000];
    let mut group = c.benchmark_group("generator");
    // A second of the densest case takes milliseconds: as many iterations in every sample.
    group.sampling_mode(SamplingMode::Flat);
    group.throughput(Throughput::Elements(out.len() as u64));
    let mut figures = Vec::new();
    let mut g = Generator::new(1);
    let mut samples = Samples::default();
    group.bench_function("gravel, nominal steps while the train runs", |b| {
        b.iter_custom(|iterations| {
            samples.time(iterations, || {
                g.strike(&gravel, 1.0);
                let mut n = 0;
                for (y, v) in out.iter_mut().zip(&speeds) {
                    if !g.is_active() {
                        break;
                    }
                    *y = g.next(&gravel, *v);
                    n += 1;
                }
                black_box(&out);
                n
            })
        });
    });
    figures.push(("gravel, nominal steps".to_owned(), samples.median(100)));
    let mut samples = Samples::default();
    let pace = vec![1.0f32; out.len()];
    group.bench_function("sand's densest bin, nominal pace", |b| {
        b.iter_custom(|iterations| {
            samples.time(iterations, || {
                // 1.28 s of clock: the train outlasts the second.
                g.strike(&flat, 1.0);
                g.process(&flat, black_box(&pace), &mut out);
                black_box(&out);
                out.len() as u64
            })
        });
    });
    figures.push(("sand's densest bin".to_owned(), samples.median(100)));
    let mut samples = Samples::default();
    // Fast enough that more than `MAX_DRAWS` events are due in every sample.
    let fast = vec![(1.25 * f64::from(MAX_DRAWS) * RATE.hz() / densest) as f32; out.len()];
    group.bench_function(
        format!("sand's densest bin, {MAX_DRAWS} draws a sample"),
        |b| {
            b.iter_custom(|iterations| {
                samples.time(iterations, || {
                    for (y, v) in out.iter_mut().zip(&fast) {
                        if !g.is_active() {
                            g.strike(&flat, 1.0);
                        }
                        *y = g.next(&flat, *v);
                    }
                    black_box(&out);
                    out.len() as u64
                })
            });
        },
    );
    figures.push((format!("{MAX_DRAWS} draws a sample"), samples.median(100)));
    let mut samples = Samples::default();
    g.stop();
    // Through `process`, whose fast path fills a silent block.
    group.bench_function("idle", |b| {
        b.iter_custom(|iterations| {
            samples.time(iterations, || {
                g.process(&flat, black_box(&pace), &mut out);
                black_box(&out);
                out.len() as u64
            })
        });
    });
    figures.push(("idle".to_owned(), samples.median(100)));
    group.finish();
    println!("\nThe generator alone at 48 kHz (medians of criterion's samples):");
    for (label, median) in figures {
        if let Some(t) = median {
            println!(
                "  {label:<22} {:6.2} ns/sample, {:3.0}% of a channel's budget at 1000 a core",
                t * 1e9,
                100.0 * t * 1000.0 * RATE.hz()
            );
        }
    }
}

criterion_group!(benches, voice, models, engine_block, channel, generator);
criterion_main!(benches);
