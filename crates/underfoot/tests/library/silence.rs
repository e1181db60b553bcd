//! Silence means silence (issue 14, "Output safety"): whatever the model, the compensation
//! and the path, the output is exactly zero within 100 ms of the last input, a lone step
//! is silent within 100 ms of its documented window, no mode rings longer than the decay
//! cap, and quantisation never passes the ceiling.

use underfoot::compensation::chain::Compensation;
use underfoot::compensation::equalizer::{EqualizerConfig, Realisation, SpectralWeights};
use underfoot::engine::event::STEP_WINDOW;
use underfoot::engine::offline::render;
use underfoot::engine::{self, EngineConfig, Event, MaterialBank, TimedEvent};
use underfoot::force::SensorReading;
use underfoot::material::builtin::builtin;
use underfoot::signal::{Biquad, Sos};
use underfoot::synthesis::{SynthModel, VoiceConfig};
use underfoot::units::{Decibels, Newtons, SampleRate, Seconds};

const RATE: SampleRate = SampleRate(48_000);

fn bank_for(model: SynthModel) -> MaterialBank {
    MaterialBank::prepare(
        builtin(),
        RATE,
        &VoiceConfig {
            model,
            ..VoiceConfig::default()
        },
        &underfoot::force::gait::nominal_step(70.0, 1.8, RATE.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap()
}

/// A limb filter with a long ring of its own: a resonance at 120 Hz decaying by `e` in
/// 0.3 s, as a badly damped user's `Z_c` could be. Whatever runs after the watchdog keeps
/// ringing for about a second.
fn ringing_limb() -> Sos {
    let r = (-1.0 / (0.3 * RATE.hz())).exp();
    let w = std::f64::consts::TAU * 120.0 / RATE.hz();
    Sos::new(vec![Biquad {
        b: [4.0 * (1.0 - r), 0.0, 0.0],
        a: [1.0, -2.0 * r * w.cos(), r * r],
    }])
}

/// The `--eq` and `--user` cascade: a device equalizer with a boost, then the limb.
fn compensation(with_eq: bool) -> Compensation {
    let equalizer = with_eq.then(|| {
        let mut w = SpectralWeights::flat(EqualizerConfig::default(), RATE).unwrap();
        w.add_in_band(|f| 6.0 * (-((f.0 - 200.0) / 80.0).powi(2)).exp());
        (w, Realisation::LowDelay { taps: 256 })
    });
    Compensation {
        equalizer,
        limb: Some(ringing_limb()),
    }
}

/// Two stances of a walk on channel 0 (readings at 500 Hz), the last reading mid-stance
/// under full load, as when a cable is pulled. Returns the events and the last frame.
fn two_stances_then_cut() -> (Vec<TimedEvent>, u64) {
    let period = RATE.0 as u64 / 500;
    let mut events = Vec::new();
    let mut frame = 0;
    let end = (0.7 * RATE.hz()) as u64;
    while frame <= end {
        let t = frame as f64 / RATE.hz();
        let phase = t % 0.5;
        let f = if phase < 0.05 {
            phase / 0.05 * 750.0
        } else if phase < 0.3 {
            750.0 + 200.0 * (t * 40.0).sin()
        } else if phase < 0.35 {
            (0.35 - phase) / 0.05 * 750.0
        } else {
            0.0
        };
        events.push(TimedEvent::at(
            frame,
            Event::Force {
                channel: 0,
                reading: SensorReading::new(&[0.6 * f as f32, 0.4 * f as f32]).unwrap(),
            },
        ));
        frame += period;
    }
    let last = events.last().and_then(|e| e.at).unwrap();
    (events, last)
}

/// Renders the cut walk on `material` and checks that every sample from 100 ms after the
/// last reading on is exactly zero, and that there was sound before.
fn silent_after_cut(model: SynthModel, material: &str, drive: &str, with_eq: bool) {
    let config = EngineConfig {
        drive: drive.parse().unwrap(),
        compensation: compensation(with_eq),
        gain: Decibels(12.0),
        ..EngineConfig::default()
    };
    let bank = bank_for(model);
    let slot = bank.slot(material).unwrap();
    let (events, last) = two_stances_then_cut();
    let frames = last as usize + RATE.0 as usize;
    let out = render(&config, bank, &[slot], &events, frames, 64).unwrap();
    let before = out.samples[..last as usize]
        .iter()
        .fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(
        before > 1e-4,
        "{material}: no sound before the cut ({before})"
    );
    let deadline = last as usize + RATE.samples_in(Seconds(0.1));
    let last_loud = out.samples.iter().rposition(|v| *v != 0.0).unwrap_or(0);
    eprintln!(
        "{model:?} {material} ({drive}, eq {with_eq}): last non-zero sample {:.1} ms after \
         the last reading",
        (last_loud as f64 - last as f64) / RATE.hz() * 1000.0
    );
    assert!(
        last_loud < deadline,
        "{model:?} {material} ({drive}, eq {with_eq}): the last non-zero sample is {:.1} ms \
         after the last reading",
        (last_loud as f64 - last as f64) / RATE.hz() * 1000.0
    );
    assert!(out.telemetry.watchdog_trips >= 1);
}

#[test]
fn iir_with_user_compensation_is_silent_within_100_ms_of_lost_input() {
    silent_after_cut(SynthModel::Iir, "gravel", "force-rate", false);
    silent_after_cut(SynthModel::Iir, "metal", "impulse", false);
}

#[test]
fn iir_with_eq_and_user_compensation_is_silent_within_100_ms_of_lost_input() {
    silent_after_cut(SynthModel::Iir, "wood", "force", true);
}

#[test]
fn physical_with_eq_and_user_compensation_is_silent_within_100_ms_of_lost_input() {
    silent_after_cut(SynthModel::Physical, "gravel", "force-rate", true);
    silent_after_cut(SynthModel::Physical, "metal", "impulse", false);
}

/// One OSC `/underfoot/step` on a channel that gets no force: decoded as a VR engine's
/// datagram would be, sent to a live engine, then nothing.
#[test]
fn one_osc_step_is_silent_within_100_ms_after_its_window() {
    use underfoot::io::osc::wire::{Arg, encode_message};
    use underfoot::io::osc::{OscDecoder, STEP_ADDRESS};
    for (model, compensated) in [
        (SynthModel::Iir, false),
        (SynthModel::Iir, true),
        (SynthModel::Physical, true),
    ] {
        let bank = bank_for(model);
        let decoder = OscDecoder::new(bank.names(), 1).unwrap();
        let slot = bank.slot("metal").unwrap();
        let config = EngineConfig {
            compensation: if compensated {
                compensation(true)
            } else {
                Compensation::default()
            },
            ..EngineConfig::default()
        };
        let (mut ctl, mut eng) = engine::build(&config, bank, &[slot]).unwrap();
        // Channel 1: the engine's first (OSC numbers channels from 1).
        let datagram = encode_message(STEP_ADDRESS, &[Arg::Int(1), Arg::Float(1.0)]);
        let mut events = Vec::new();
        decoder.decode(&datagram, &mut |e| match e.unwrap() {
            underfoot::io::osc::Decoded::Event(e) => events.push(e),
            other => panic!("{other:?}"),
        });
        assert_eq!(events.len(), 1);
        let mut out = vec![0.0f32; 2 * RATE.0 as usize];
        let mut sent = false;
        for chunk in out.chunks_mut(128) {
            if !sent {
                ctl.send(TimedEvent::now(events[0])).unwrap();
                sent = true;
            }
            eng.process(chunk, 1);
        }
        assert!(
            out[..4800].iter().any(|v| v.abs() > 1e-4),
            "{model:?}: the step plays"
        );
        let deadline = RATE.samples_in(Seconds(STEP_WINDOW.0 + 0.1));
        let last_loud = out.iter().rposition(|v| *v != 0.0).unwrap_or(0);
        eprintln!(
            "{model:?} (compensated {compensated}): last non-zero sample {:.1} ms after one step",
            last_loud as f64 / RATE.hz() * 1000.0
        );
        assert!(
            last_loud < deadline,
            "{model:?} (compensated {compensated}): non-zero until {:.0} ms after one step \
             (window {} s)",
            last_loud as f64 / RATE.hz() * 1000.0,
            STEP_WINDOW.0
        );
    }
}

/// A library whose physical model has a mode that rings for 1e6 s is refused on load; a
/// model built in code with it is played with the mode capped.
#[test]
fn a_physical_mode_of_a_million_seconds_is_refused_on_load_and_capped_at_play() {
    use underfoot::material::Library;
    use underfoot::physical::resonator::{LONGEST_DECAY, ResonatorBank, SurfaceMode};
    let mut lib = builtin().clone();
    lib.materials
        .retain(|m| m.name == "metal" && m.physical.is_some());
    lib.materials[0].physical.as_mut().unwrap().modes[0].decay = Seconds(1e6);
    let text = lib.to_json();
    match Library::from_json(&text, "test") {
        Ok(_) => panic!("a library with a mode decaying in 1e6 s was accepted"),
        Err(e) => assert!(e.to_string().contains("decay"), "{e}"),
    }

    // Built in code: the bank plays the mode with the capped decay.
    let mode = SurfaceMode {
        frequency: underfoot::units::Hz(200.0),
        decay: Seconds(1e6),
        gain: 1e-3,
    };
    let bank = ResonatorBank::new(&[mode], RATE).unwrap();
    let h = bank.impulse_response(RATE.samples_in(Seconds(8.0 * LONGEST_DECAY.0)));
    let peak = |s: &[f64]| s.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let early = peak(&h[..RATE.samples_in(Seconds(0.05))]);
    let late = peak(&h[h.len() - RATE.samples_in(Seconds(0.05))..]);
    // 8 decay times: e^-8 = -69 dB, with the 50 ms window's slack.
    assert!(late < early * 1e-3, "late {late} vs early {early}");

    // And through the engine, from a model that never went through a file.
    let mut model = builtin().get("metal").unwrap().clone();
    let p = model.physical.as_mut().unwrap();
    p.kind = underfoot::physical::GroundKind::Solid;
    for m in &mut p.modes {
        m.decay = Seconds(1e6);
    }
    let prepared = underfoot::synthesis::PreparedMaterial::prepare(
        &model,
        RATE,
        &VoiceConfig {
            model: SynthModel::Physical,
            ..VoiceConfig::default()
        },
    );
    // Either refused at preparation or played capped; never a ring of a million seconds.
    if let Ok(prepared) = prepared {
        let bank = MaterialBank::from_prepared(vec![prepared]);
        let config = EngineConfig {
            watchdog: underfoot::safety::WatchdogConfig {
                step_hold: Seconds(10.0),
                ..Default::default()
            },
            ..EngineConfig::default()
        };
        let events = [TimedEvent::at(
            0,
            Event::Step {
                channel: 0,
                intensity: 1.0,
            },
        )];
        let frames = RATE.samples_in(Seconds(6.0));
        let out = render(&config, bank, &[0], &events, frames, 256).unwrap();
        let s = &out.samples;
        let early = s[..4800].iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let late = s[frames - 4800..]
            .iter()
            .fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(early > 0.0);
        assert!(late < early * 1e-3, "late {late} vs early {early}");
    }
}

/// Quantisation to 16 and 24 bits never writes a code past the limiter's ceiling: the
/// -6 dB ceiling is 16422.9 codes in 16 bits, and a rounded sample at it was 16423.
#[test]
fn integer_wav_never_passes_the_ceiling() {
    use underfoot::io::wav::{WavFormat, WavSink};
    let ceiling = underfoot::safety::ceiling_amplitude(Decibels(-6.0));
    let dir = tempfile::tempdir().unwrap();
    // The engine's own loudest output, limited at the ceiling.
    let config = EngineConfig {
        gain: Decibels(30.0),
        ..EngineConfig::default()
    };
    let bank = bank_for(SynthModel::Iir);
    let slot = bank.slot("metal").unwrap();
    let events: Vec<TimedEvent> = (0..4)
        .map(|k| {
            TimedEvent::at(
                k * 12_000,
                Event::Step {
                    channel: 0,
                    intensity: 4.0,
                },
            )
        })
        .collect();
    let out = render(&config, bank, &[slot], &events, 48_000, 64).unwrap();
    let mut samples = out.samples;
    samples.extend([ceiling, -ceiling, f32::from_bits(ceiling.to_bits() - 1)]);
    for (format, full) in [
        (WavFormat::Int16, 32_768.0),
        (WavFormat::Int24, 8_388_608.0),
    ] {
        let path = dir.path().join(format!("{format:?}.wav"));
        let mut sink = WavSink::create(&path, RATE, 1, format).unwrap();
        sink.write_interleaved(&samples).unwrap();
        sink.finish().unwrap();
        let mut r = hound::WavReader::open(&path).unwrap();
        let codes: Vec<i32> = r.samples::<i32>().map(Result::unwrap).collect();
        let limit = f64::from(ceiling) * full;
        let peak = codes.iter().map(|c| c.unsigned_abs()).max().unwrap();
        assert!(
            f64::from(peak) <= limit,
            "{format:?}: code {peak} against a ceiling of {limit:.2}"
        );
        assert_eq!(f64::from(peak), limit.floor(), "{format:?}");
    }
}

/// The IIR voice's decay cap has no "unlimited": an infinite, zero or absurd limit is
/// refused when the material is prepared, instead of letting a pole at the edge of
/// stability ring for hours.
#[test]
fn the_voice_refuses_an_unbounded_decay_limit() {
    let model = builtin().get("metal").unwrap();
    for bad in [f64::INFINITY, f64::NAN, 0.0, -1.0, 1e6] {
        let config = VoiceConfig {
            longest_decay: Seconds(bad),
            ..VoiceConfig::default()
        };
        let err = underfoot::synthesis::PreparedMaterial::prepare(model, RATE, &config);
        assert!(err.is_err(), "longest_decay {bad} was accepted");
    }
    let fine = VoiceConfig {
        longest_decay: Seconds(2.0),
        ..VoiceConfig::default()
    };
    assert!(underfoot::synthesis::PreparedMaterial::prepare(model, RATE, &fine).is_ok());
}
