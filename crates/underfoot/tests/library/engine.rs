//! The engine's contract: block-size invariance, sample-accurate onsets, material
//! crossfades without clicks, the watchdog, the limiter, and non-finite handling.

use underfoot::engine::{self, Controller, Engine, EngineConfig, Event, MaterialBank, TimedEvent};
use underfoot::force::SensorReading;
use underfoot::material::builtin::builtin;
use underfoot::synthesis::{ExcitationChoice, SynthModel, VoiceConfig};
use underfoot::units::{Newtons, SampleRate};

const RATE: SampleRate = SampleRate(48_000);

/// The gait model's nominal step, which calibrates the force drives.
fn nominal_step() -> Vec<f64> {
    underfoot::force::gait::nominal_step(70.0, 1.8, RATE.hz())
}

fn bank() -> MaterialBank {
    bank_for(SynthModel::Iir)
}

fn bank_for(model: SynthModel) -> MaterialBank {
    bank_with(&VoiceConfig {
        model,
        ..VoiceConfig::default()
    })
}

fn bank_with(voice: &VoiceConfig) -> MaterialBank {
    MaterialBank::prepare(
        builtin(),
        RATE,
        voice,
        &nominal_step(),
        Newtons::weight_of(70.0),
    )
    .unwrap()
}

fn engine_with(config: &EngineConfig, material: &str) -> (Controller, Engine) {
    engine_for(config, material, SynthModel::Iir)
}

fn engine_for(config: &EngineConfig, material: &str, model: SynthModel) -> (Controller, Engine) {
    engine_with_voice(
        config,
        material,
        &VoiceConfig {
            model,
            ..VoiceConfig::default()
        },
    )
}

fn engine_with_voice(
    config: &EngineConfig,
    material: &str,
    voice: &VoiceConfig,
) -> (Controller, Engine) {
    let bank = bank_with(voice);
    let slot = bank.slot(material).unwrap();
    let initial = vec![slot; config.channels];
    engine::build(config, bank, &initial).unwrap()
}

/// Steps every 0.5 s: force readings at 500 Hz, a trapezoid per stance, on every channel.
fn walk_events(channels: usize, seconds: f64) -> Vec<TimedEvent> {
    let period = RATE.0 as u64 / 500;
    let frames = (seconds * RATE.hz()) as u64;
    let mut events = Vec::new();
    let mut frame = 0;
    while frame < frames {
        let t = frame as f64 / RATE.hz();
        let phase = t % 0.5;
        let f = if phase < 0.05 {
            phase / 0.05 * 750.0
        } else if phase < 0.3 {
            750.0
        } else if phase < 0.35 {
            (0.35 - phase) / 0.05 * 750.0
        } else {
            0.0
        };
        for c in 0..channels {
            let reading = SensorReading::new(&[0.6 * f as f32, 0.4 * f as f32]).unwrap();
            events.push(TimedEvent::at(
                frame,
                Event::Force {
                    channel: c as u16,
                    reading,
                },
            ));
        }
        frame += period;
    }
    events
}

fn render(
    config: &EngineConfig,
    material: &str,
    events: &[TimedEvent],
    block: usize,
    frames: usize,
) -> Vec<f32> {
    render_model(config, material, events, block, frames, SynthModel::Iir)
}

fn render_model(
    config: &EngineConfig,
    material: &str,
    events: &[TimedEvent],
    block: usize,
    frames: usize,
    model: SynthModel,
) -> Vec<f32> {
    let voice = VoiceConfig {
        model,
        ..VoiceConfig::default()
    };
    render_voice(config, material, events, block, frames, &voice)
}

fn render_voice(
    config: &EngineConfig,
    material: &str,
    events: &[TimedEvent],
    block: usize,
    frames: usize,
    voice: &VoiceConfig,
) -> Vec<f32> {
    let (mut ctl, mut eng) = engine_with_voice(config, material, voice);
    let dc = config.channels;
    let mut out = vec![0.0; frames * dc];
    let mut next = 0;
    let mut done = 0;
    while done < frames {
        let n = block.min(frames - done);
        // Send what is due before the end of this block, as a live source would.
        while next < events.len() && events[next].at.unwrap() < (done + n) as u64 {
            ctl.send(events[next]).unwrap();
            next += 1;
        }
        eng.process(&mut out[done * dc..(done + n) * dc], dc);
        done += n;
    }
    out
}

/// The walk of [`walk_events`] on two channels, and an explicit step on channel 1 between
/// two of its strikes: its train runs on the free clock, over the walk's.
fn walk_and_step() -> Vec<TimedEvent> {
    let mut events = walk_events(2, 1.0);
    events.push(TimedEvent::at(
        20_011,
        Event::Step {
            channel: 1,
            intensity: 1.2,
        },
    ));
    events.sort_by_key(|e| e.at);
    events
}

/// The share of channel 0's energy from 0.1 s into each of [`walk_events`]' steps to the
/// next: where a step's train still plays (its clock runs while the force changes, loading
/// and unloading), and one impulse through gravel's filter has rung out.
fn late_share(out: &[f32], channels: usize) -> f64 {
    let (mut late, mut all) = (0.0, 0.0);
    for (n, frame) in out.chunks(channels).enumerate() {
        let e = f64::from(frame[0]).powi(2);
        all += e;
        if (n as f64 / RATE.hz()) % 0.5 >= 0.1 {
            late += e;
        }
    }
    late / all.max(f64::MIN_POSITIVE)
}

/// Gravel's fitted excitation, a heel and a train of micro-impacts (about 1600 over a
/// nominal step), is what the walk plays: it lasts, where one impulse a step rings out. A
/// drive that feeds the IIR voice the force itself plays no excitation.
#[test]
#[ignore = "slow tier: long renders"]
fn output_is_identical_for_blocks_of_1_7_64_and_512_frames() {
    let gravel = builtin().get("gravel").unwrap().excitation.clone().unwrap();
    assert!(gravel.expected_events() > 1000.0);
    for drive in ["impulse", "force", "force-rate"] {
        let config = EngineConfig {
            channels: 2,
            drive: drive.parse().unwrap(),
            ..EngineConfig::default()
        };
        let frames = 48_000;
        let events = walk_and_step();
        let reference = render(&config, "gravel", &events, 512, frames);
        let energy: f64 = reference.iter().map(|v| f64::from(*v).powi(2)).sum();
        assert!(energy > 1e-6, "{drive}: the walk is audible ({energy})");
        if drive == "impulse" {
            let heel = VoiceConfig {
                excitation: ExcitationChoice::Heel,
                ..VoiceConfig::default()
            };
            let heel = render_voice(&config, "gravel", &events, 512, frames, &heel);
            let (train, one) = (late_share(&reference, 2), late_share(&heel, 2));
            assert!(train > 0.2 && train > 10.0 * one, "{train} against {one}");
        }
        for block in [1, 7, 64] {
            let out = render(&config, "gravel", &events, block, frames);
            assert!(out == reference, "{drive}: block {block} differs");
        }
    }
}

#[test]
#[ignore = "slow tier: long renders"]
fn the_physical_model_is_block_size_invariant_too() {
    // An aggregate (gravel: micro-impacts at a rate following the loading) and a solid
    // (hard: one impact per strike), with a material switch between them mid-walk.
    let config = EngineConfig {
        channels: 2,
        ..EngineConfig::default()
    };
    let frames = 48_000;
    let mut events = walk_and_step();
    let hard = bank_for(SynthModel::Physical).slot("hard").unwrap();
    events.push(TimedEvent::at(
        30_000,
        Event::Material {
            channel: 1,
            slot: hard,
        },
    ));
    events.sort_by_key(|e| e.at);
    let reference = render_model(
        &config,
        "gravel",
        &events,
        512,
        frames,
        SynthModel::Physical,
    );
    let energy: f64 = reference.iter().map(|v| f64::from(*v).powi(2)).sum();
    assert!(energy > 1e-6, "the physical walk is audible ({energy})");
    let iir = render(&config, "gravel", &events, 512, frames);
    assert!(iir != reference, "the physical model is not the filter");
    // Struck by gravel's train, not by one impulse a step.
    let heel = VoiceConfig {
        model: SynthModel::Physical,
        excitation: ExcitationChoice::Heel,
        ..VoiceConfig::default()
    };
    let heel = render_voice(&config, "gravel", &events, 512, frames, &heel);
    let (train, one) = (late_share(&reference, 2), late_share(&heel, 2));
    assert!(train > 0.2 && train > 10.0 * one, "{train} against {one}");
    for block in [1, 7, 64] {
        let out = render_model(
            &config,
            "gravel",
            &events,
            block,
            frames,
            SynthModel::Physical,
        );
        assert!(out == reference, "block {block} differs");
    }
}

#[test]
fn a_strike_reaches_the_output_at_the_frame_of_its_reading() {
    let config = EngineConfig::default();
    let (mut ctl, mut eng) = engine_with(&config, "hard");
    let mut out = vec![0.0f32; 64];
    // Idle readings keep the watchdog fed; then the crossing, mid-block.
    for k in 0..20 {
        ctl.send(TimedEvent::at(
            k * 64,
            Event::Force {
                channel: 0,
                reading: SensorReading::single(0.0),
            },
        ))
        .unwrap();
    }
    let crossing = 20 * 64 + 23;
    ctl.send(TimedEvent::at(
        crossing,
        Event::Force {
            channel: 0,
            reading: SensorReading::single(700.0),
        },
    ))
    .unwrap();
    let mut first = None;
    for b in 0..40u64 {
        eng.process(&mut out, 1);
        if first.is_none()
            && let Some(i) = out.iter().position(|v| v.abs() > 1e-6)
        {
            first = Some(b * 64 + i as u64);
        }
    }
    assert_eq!(first, Some(crossing), "onset at the crossing's own sample");
    assert_eq!(ctl.telemetry().strikes, 1);
}

#[test]
fn live_events_take_effect_in_the_next_block() {
    let config = EngineConfig::default();
    let (mut ctl, mut eng) = engine_with(&config, "wood");
    let mut out = vec![0.0f32; 128];
    eng.process(&mut out, 1);
    ctl.send(TimedEvent::now(Event::Force {
        channel: 0,
        reading: SensorReading::single(0.0),
    }))
    .unwrap();
    ctl.send(TimedEvent::now(Event::Force {
        channel: 0,
        reading: SensorReading::single(700.0),
    }))
    .unwrap();
    eng.process(&mut out, 1);
    assert!(
        out[0] != 0.0,
        "the step sounds from the first sample of the next block"
    );
}

#[test]
fn switching_material_mid_walk_does_not_click() {
    let config = EngineConfig {
        drive: "force".parse().unwrap(),
        ..EngineConfig::default()
    };
    let bank = bank();
    let (gravel, snow) = (bank.slot("gravel").unwrap(), bank.slot("snow").unwrap());
    let (mut ctl, mut eng) = engine::build(&config, bank, &[gravel]).unwrap();
    let mut events = walk_events(1, 2.0);
    let switch = 48_000 + 7_000; // mid-stance, while the voice rings
    events.push(TimedEvent::at(
        switch,
        Event::Material {
            channel: 0,
            slot: snow,
        },
    ));
    events.sort_by_key(|e| e.at);
    for e in events {
        ctl.send(e).unwrap();
    }
    let mut out = vec![0.0f32; 96_000];
    for chunk in out.chunks_mut(256) {
        eng.process(chunk, 1);
    }
    // A click is a sample-to-sample jump far beyond the signal's own largest jumps.
    let jump = |s: &[f32]| {
        s.windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f32::max)
    };
    let around = jump(&out[switch as usize - 200..switch as usize + 2_000]);
    let before = jump(&out[switch as usize - 24_000..switch as usize - 200]);
    assert!(
        around <= 1.5 * before.max(1e-6),
        "jump {around} at the switch, {before} before"
    );
}

#[test]
fn watchdog_fades_out_within_100_ms_when_readings_stop() {
    let config = EngineConfig {
        drive: "force".parse().unwrap(),
        ..EngineConfig::default()
    };
    let (mut ctl, mut eng) = engine_with(&config, "gravel");
    // A steady loaded foot (the force drive sounds while force changes), then nothing.
    for k in 0..250u64 {
        let f = 400.0 + 300.0 * ((k as f32) * 0.3).sin();
        ctl.send(TimedEvent::at(
            k * 96,
            Event::Force {
                channel: 0,
                reading: SensorReading::single(f),
            },
        ))
        .unwrap();
    }
    let last = 249 * 96;
    let mut out = vec![0.0f32; 48_000];
    for chunk in out.chunks_mut(64) {
        eng.process(chunk, 1);
    }
    let after = &out[last as usize + RATE.samples_in(underfoot::units::Seconds(0.1))..];
    assert!(
        after.iter().all(|v| *v == 0.0),
        "silent 100 ms after the last reading"
    );
    assert!(out[..last as usize].iter().any(|v| v.abs() > 1e-5));
    assert_eq!(ctl.telemetry().watchdog_trips, 1);
}

#[test]
fn the_limiter_holds_the_ceiling_and_non_finite_input_is_rejected() {
    let config = EngineConfig {
        gain: underfoot::units::Decibels(80.0),
        ..EngineConfig::default()
    };
    let (mut ctl, mut eng) = engine_with(&config, "metal");
    for k in 0..50u64 {
        let f = if k % 10 < 5 { 2000.0 } else { 0.0 };
        ctl.send(TimedEvent::at(
            k * 480,
            Event::Force {
                channel: 0,
                reading: SensorReading::single(f),
            },
        ))
        .unwrap();
    }
    ctl.send(TimedEvent::at(
        100,
        Event::Force {
            channel: 0,
            reading: SensorReading::single(f32::NAN),
        },
    ))
    .unwrap();
    ctl.send(TimedEvent::at(
        200,
        Event::Step {
            channel: 0,
            intensity: f32::INFINITY,
        },
    ))
    .unwrap();
    ctl.send(TimedEvent::at(
        300,
        Event::Step {
            channel: 9,
            intensity: 1.0,
        },
    ))
    .unwrap();
    let mut out = vec![0.0f32; 24_000];
    for chunk in out.chunks_mut(100) {
        eng.process(chunk, 1);
    }
    let ceiling = underfoot::safety::ceiling_amplitude(underfoot::units::Decibels(-6.0));
    assert!(out.iter().all(|v| v.is_finite() && v.abs() <= ceiling));
    let t = ctl.telemetry();
    assert!(t.limited > 0 && t.peak <= ceiling);
    assert_eq!(t.rejected, 3);
}

#[test]
fn start_and_stop_fade_without_a_pop() {
    let config = EngineConfig::default();
    let (mut ctl, mut eng) = engine_with(&config, "wood");
    ctl.send(TimedEvent::at(
        0,
        Event::Step {
            channel: 0,
            intensity: 1.0,
        },
    ))
    .unwrap();
    let mut out = vec![0.0f32; 960];
    eng.process(&mut out, 1);
    // The first 10 ms are ramped: the first sample is a tiny fraction of the step's peak.
    let peak = out.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(out[0].abs() < 0.01 * peak.max(1e-9) || out[0] == 0.0);
    ctl.stop().unwrap();
    let mut tail = vec![0.0f32; 960];
    eng.process(&mut tail, 1);
    assert!(ctl.telemetry().stopped);
    assert!(tail[480..].iter().all(|v| *v == 0.0));
    let steps = tail
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .fold(0.0, f32::max);
    assert!(steps < 0.5 * peak.max(1e-9));
}

/// A material no fit would produce: a resonance at the edge of stability with a gain of
/// a million. The limiter still lets nothing above the ceiling through.
#[test]
fn the_limiter_holds_against_a_pathological_filter() {
    use underfoot::material::{FilterCoefficients, FitRecord, MaterialModel};
    use underfoot::signal::{Biquad, Sos};
    use underfoot::synthesis::PreparedMaterial;
    use underfoot::units::{Band, Decibels};

    let r: f64 = 0.999_999;
    let theta = 2.0 * std::f64::consts::PI * 100.0 / 2000.0;
    let sos = Sos::new(vec![Biquad {
        b: [1e6, 0.0, -1e6],
        a: [1.0, -2.0 * r * theta.cos(), r * r],
    }]);
    let model = MaterialModel {
        name: "pathological".into(),
        sample_rate: SampleRate(2000),
        band_hz: Band::new(20.0, 900.0),
        order: 2,
        filter: FilterCoefficients::from_sos(&sos),
        fit: FitRecord {
            grid_hz: vec![],
            measured: vec![],
            model: vec![],
            nrmse: 0.0,
            lsd_db: 0.0,
            method: String::new(),
            poor_fit: false,
            strikes: 0,
            fit_seconds: 0.0,
            longest_decay: underfoot::units::Seconds(0.5),
            worst: None,
        },
        sources: vec![],
        physical: None,
        excitation: None,
        time: None,
        level_db: 0.0,
    };
    let prepared = PreparedMaterial::prepare(&model, RATE, &VoiceConfig::default()).unwrap();
    assert_eq!(prepared.limited_modes, 1, "its decay is limited");
    let bank = MaterialBank::from_prepared(vec![prepared]);
    let config = EngineConfig {
        ceiling: Decibels(-12.0),
        ..EngineConfig::default()
    };
    let (mut ctl, mut eng) = engine::build(&config, bank, &[0]).unwrap();
    for k in 0..20u64 {
        ctl.send(TimedEvent::at(
            k * 2400,
            Event::Step {
                channel: 0,
                intensity: 4.0,
            },
        ))
        .unwrap();
    }
    let mut out = vec![0.0f32; 48_000];
    for chunk in out.chunks_mut(64) {
        eng.process(chunk, 1);
    }
    let ceiling = underfoot::safety::ceiling_amplitude(Decibels(-12.0));
    let peak = out.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(out.iter().all(|v| v.is_finite()));
    assert!(
        peak <= ceiling && peak > 0.9 * ceiling,
        "peak {peak}, ceiling {ceiling}"
    );
    assert!(ctl.telemetry().limited > 1000);
}

/// A walk rendered block by block with `each` called after every block: the
/// controller, the engine and the block just rendered (one channel).
fn play(
    ctl: &mut Controller,
    eng: &mut Engine,
    events: &[TimedEvent],
    block: usize,
    frames: usize,
    mut each: impl FnMut(&mut Controller, usize, &[f32]),
) {
    let mut out = vec![0.0f32; block];
    let mut next = 0;
    let mut done = 0;
    while done < frames {
        while next < events.len() && events[next].at.unwrap() < (done + block) as u64 {
            ctl.send(events[next]).unwrap();
            next += 1;
        }
        eng.process(&mut out, 1);
        done += block;
        each(ctl, done, &out);
    }
}

/// The per-channel meters against the rendered output itself: the peak and RMS over each
/// reader's interval, the limiter's smallest gain, the sensors, the slot, the watchdog.
#[test]
fn the_channel_meters_agree_with_the_output() {
    let config = EngineConfig {
        // Gravel's steps peak near -30 dBFS at its playback level: so that the limiter works.
        gain: underfoot::units::Decibels(40.0),
        ..EngineConfig::default()
    };
    let (mut ctl, mut eng) = engine_with(&config, "gravel");
    let gravel = bank().slot("gravel").unwrap();
    let meters = ctl.telemetry_handle();
    let events = walk_events(1, 1.6);
    // Readings stop at 1.6 s; the walk's output is read every 4 blocks of 256 (~21 ms),
    // as a panel would, and again after the watchdog has faded the channel out.
    let mut since = Vec::new();
    let mut reads = 0;
    let mut loud = 0;
    play(
        &mut ctl,
        &mut eng,
        &events,
        256,
        48_000 * 2,
        |_, done, out| {
            since.extend_from_slice(out);
            if done % 1024 != 0 {
                return;
            }
            let m = meters.take_channel(0).unwrap();
            let peak = since.iter().fold(0.0f32, |p, v| p.max(v.abs()));
            let rms = (since.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>()
                / since.len() as f64)
                .sqrt();
            assert_eq!(m.peak, peak, "the peak over exactly the reader's interval");
            assert!(
                (f64::from(m.rms) - rms).abs() <= 1e-6 + 1e-4 * rms,
                "rms {} against {rms} from the output",
                m.rms
            );
            assert!(m.limiter_gain <= 1.0 && m.limiter_gain > 0.0);
            if peak >= 0.5 * 0.99 {
                // At the ceiling (-6 dB): the limiter reduced the gain in this interval.
                assert!(m.limiter_gain < 0.9, "{m:?}");
                loud += 1;
            }
            assert_eq!(m.slot, Some(gravel));
            assert_eq!(m.trim, 1.0);
            if done <= 48_000 {
                assert!(m.live, "readings arrive: the watchdog lets it play");
                assert_eq!(m.sensor_count, 2);
                assert!((m.sensors[0] + m.sensors[1] - m.force).abs() < 1e-3);
            }
            if done >= 48_000 * 2 - 1024 {
                assert!(!m.live, "readings stopped 0.4 s ago: faded out");
                assert_eq!(m.peak, 0.0);
            }
            since.clear();
            reads += 1;
        },
    );
    assert!(
        reads > 80 && loud > 0,
        "{reads} reads, {loud} at the ceiling"
    );
    assert_eq!(meters.take_channel(0).unwrap().strikes, 4);
}

/// A trim lowers the output by what it says, smoothly; it can never raise it (a trim
/// above 0 dB is clamped), and the limiter's ceiling does not move.
#[test]
fn a_trim_only_lowers_the_output() {
    // Quiet enough that the limiter never acts: the ratio is the trim's alone.
    let config = EngineConfig {
        gain: underfoot::units::Decibels(-20.0),
        ..EngineConfig::default()
    };
    let events = walk_events(1, 1.0);
    let render_with = |trim: Option<f64>| {
        let (mut ctl, mut eng) = engine_with(&config, "snow");
        if let Some(db) = trim {
            ctl.set_trim(0, underfoot::units::Decibels(db)).unwrap();
        }
        let mut all = Vec::new();
        play(&mut ctl, &mut eng, &events, 64, 48_000, |_, _, out| {
            all.extend_from_slice(out);
        });
        all
    };
    let plain = render_with(None);
    assert!(plain.iter().any(|v| *v != 0.0));
    assert!(plain.iter().all(|v| v.abs() < 0.45), "below the ceiling");
    // +6 dB is clamped to 0 dB: the same output, sample for sample.
    assert_eq!(render_with(Some(6.0)), plain);
    // -6 dB: once the 10 ms smoothing has settled (125 ms: 12.5 time constants), half
    // the amplitude.
    let trimmed = render_with(Some(-6.0));
    let expected = underfoot::safety::ceiling_amplitude(underfoot::units::Decibels(-6.0));
    for (a, b) in trimmed.iter().zip(&plain).skip(6000) {
        assert!(
            (a - b * expected).abs() <= 1e-6 + 1e-4 * b.abs(),
            "{a} against {b}"
        );
    }
    // Refused on the control side: a channel it does not have, a NaN.
    let (mut ctl, _eng) = engine_with(&config, "snow");
    assert!(ctl.set_trim(1, underfoot::units::Decibels(-3.0)).is_err());
    assert!(
        ctl.set_trim(0, underfoot::units::Decibels(f64::NAN))
            .is_err()
    );
}

/// A material added while the engine runs plays exactly as it would have from a bank
/// built with it; a full bank refuses more on the control side.
#[test]
fn a_material_added_while_playing_sounds_as_if_it_had_been_there() {
    let voice = VoiceConfig::default();
    let prepared = |name: &str| {
        let mut p = underfoot::synthesis::PreparedMaterial::prepare(
            builtin().get(name).unwrap(),
            RATE,
            &voice,
        )
        .unwrap();
        p.normalise_drives(&nominal_step(), Newtons::weight_of(70.0));
        p
    };
    let events = walk_events(1, 1.5);
    let gravel = bank().slot("gravel").unwrap();
    let render_switching = |ctl: &mut Controller, eng: &mut Engine, slot: u16| {
        let mut all = Vec::new();
        play(ctl, eng, &events, 128, 72_000, |ctl, done, out| {
            if done == 128 * 150 {
                ctl.send(TimedEvent::now(Event::Material { channel: 0, slot }))
                    .unwrap();
            }
            all.extend_from_slice(out);
        });
        all
    };
    // Added: one spare slot.
    let config = EngineConfig {
        spare_slots: 1,
        ..EngineConfig::default()
    };
    let (mut ctl, mut eng) = engine::build(&config, bank(), &[gravel]).unwrap();
    let slot = ctl.add_material(prepared("snow")).unwrap();
    assert_eq!(usize::from(slot), builtin().materials.len());
    assert_eq!(ctl.material_names().last().unwrap(), "snow");
    assert!(matches!(
        ctl.add_material(prepared("ice")),
        Err(engine::EngineError::BankFull { capacity: 12 })
    ));
    let added = render_switching(&mut ctl, &mut eng, slot);
    // There from the start: the same bank with the material appended.
    let mut materials = bank().materials().to_vec();
    materials.push(prepared("snow"));
    let (mut ctl, mut eng) = engine::build(
        &EngineConfig::default(),
        MaterialBank::from_prepared(materials),
        &[gravel],
    )
    .unwrap();
    let built = render_switching(&mut ctl, &mut eng, slot);
    assert_eq!(added, built);
    assert_eq!(
        eng_slot(&ctl),
        Some(slot),
        "the meter says which slot plays"
    );
}

fn eng_slot(ctl: &Controller) -> Option<u16> {
    ctl.telemetry_handle().take_channel(0).unwrap().slot
}
