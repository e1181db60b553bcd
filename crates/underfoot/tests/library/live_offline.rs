//! Live equals offline: the same force track played as a live session (stamped readings
//! sent without a frame, drained whenever the next block starts) and rendered offline
//! gives the same steps, as loud and as far apart, for every block size.
//!
//! The live sessions here are simulated on one thread, deterministically: the "device"
//! renders blocks of `B` frames at the wall-clock pace of its frames, and each reading
//! reaches the controller at its sensor time plus a pseudo-random delivery jitter (up to
//! 3 ms), to be drained by the first block that starts after it arrived. The real-time
//! versions are the CLI test (`underfoot run --output wav:`) and the JACK test in
//! `audio_device.rs`.

use underfoot::engine::offline::{render, track_events};
use underfoot::engine::{self, ClockAnchor, EngineConfig, Event, MaterialBank, TimedEvent};
use underfoot::force::gait::{self, GaitConfig};
use underfoot::force::steps::{ReadingTime, StepDetector};
use underfoot::force::track::ForceTrack;
use underfoot::material::builtin::builtin;
use underfoot::signal::noise::SplitMix64;
use underfoot::synthesis::{SynthModel, VoiceConfig};
use underfoot::units::{Newtons, SampleRate, Seconds};

const RATE: SampleRate = SampleRate(48_000);
const BUFFERS: [usize; 4] = [16, 64, 256, 1024];

fn bank(model: SynthModel) -> MaterialBank {
    MaterialBank::prepare(
        builtin(),
        RATE,
        &VoiceConfig {
            model,
            ..VoiceConfig::default()
        },
        &gait::nominal_step(70.0, 1.8, RATE.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap()
}

/// The walk: `gait:steps=6` (one channel) or both feet.
fn walk(channels: usize) -> ForceTrack {
    gait::generate(&GaitConfig {
        steps: 6,
        channels,
        ..GaitConfig::default()
    })
    .unwrap()
    .track
}

/// A live session of `track` in blocks of `block` frames, simulated; returns the output
/// and the telemetry at the end.
fn live(
    config: &EngineConfig,
    model: SynthModel,
    material: &str,
    track: &ForceTrack,
    block: usize,
    frames: usize,
    seed: u64,
) -> (Vec<f32>, engine::TelemetrySnapshot) {
    let bank = bank(model);
    let slot = bank.slot(material).unwrap();
    let channels = config.channels;
    let (mut ctl, mut eng) = engine::build(config, bank, &vec![slot; channels]).unwrap();
    let mut rng = SplitMix64::new(seed);
    // When each row reaches the controller, in frames: its time, a start-up offset (the
    // source opens after the device), and the jitter of its delivery.
    let startup = 0.137 * RATE.hz();
    let arrivals: Vec<f64> = track
        .rows
        .iter()
        .map(|r| startup + (r.time.0 + 0.003 * rng.uniform()) * RATE.hz())
        .collect();
    let mut out = vec![0.0f32; frames * channels];
    let (mut next, mut done) = (0, 0);
    while done < frames {
        let n = block.min(frames - done);
        // Everything that has arrived by the time this block starts.
        while next < track.rows.len() && arrivals[next] <= done as f64 {
            let row = &track.rows[next];
            for (c, reading) in row.readings.iter().enumerate() {
                ctl.send(TimedEvent::now(Event::Force {
                    channel: c as u16,
                    reading: reading.at(row.time),
                }))
                .unwrap();
            }
            next += 1;
        }
        eng.process(&mut out[done * channels..(done + n) * channels], channels);
        done += n;
        ctl.collect();
    }
    (out, ctl.telemetry())
}

/// The frame (in the offline render) of each heel strike of channel `c`: the frame of the
/// reading that crosses the detector's threshold.
fn strike_frames(config: &EngineConfig, track: &ForceTrack, c: usize) -> Vec<usize> {
    let mut d = StepDetector::new(&config.detector, config.sensor_rate);
    track
        .rows
        .iter()
        .filter(|r| {
            d.update(r.readings[c].total(), ReadingTime::Sensor(r.time))
                .is_some()
        })
        .map(|r| (r.time.0 * RATE.hz()).round() as usize)
        .collect()
}

/// Per-step peak (dBFS) and onset of channel `c` of `out` (interleaved, `channels`), for
/// steps expected near `strikes` shifted by `shift`: the peak over the step's stretch (to
/// the next strike), the onset the first sample from 20 ms before the strike that reaches
/// half that peak (the step's rise: the previous step's ring is well below it by then).
fn steps_of(
    out: &[f32],
    channels: usize,
    c: usize,
    strikes: &[usize],
    shift: usize,
) -> Vec<(f64, usize)> {
    let frames = out.len() / channels;
    let early = (0.02 * RATE.hz()) as usize;
    strikes
        .iter()
        .enumerate()
        .map(|(k, &s)| {
            let a = s + shift - early;
            let b = strikes.get(k + 1).map_or(frames, |n| n + shift - early);
            let y = |i: usize| out[i * channels + c];
            let peak = (a..b).map(|i| y(i).abs()).fold(0.0f32, f32::max);
            let onset = (a..b)
                .find(|&i| y(i).abs() >= 0.5 * peak)
                .expect("a step reaches its peak");
            (20.0 * f64::from(peak).log10(), onset - shift)
        })
        .collect()
}

/// Renders the walk offline and live at every buffer size, and checks the live steps
/// against the offline ones: peaks within 0.5 dB, onsets within one sample once shifted
/// by the sensor clock's offset, which is the documented rule's:
/// `A = F + B + M` for the block at `F` that drained the first reading.
fn check(config: &EngineConfig, model: SynthModel, material: &str, channels: usize) {
    let config = EngineConfig {
        channels,
        ..config.clone()
    };
    let track = walk(channels);
    let events = track_events(&track, RATE);
    let last = events.last().and_then(|e| e.at).unwrap() as usize;
    let offline_frames = last + RATE.hz() as usize;
    let slot = bank(model).slot(material).unwrap();
    let offline = render(
        &config,
        bank(model),
        &vec![slot; channels],
        &events,
        offline_frames,
        256,
    )
    .unwrap();
    assert_eq!(offline.telemetry.strikes, 6 * channels as u64);
    let margin = (config.sensor_latency.0 * RATE.hz()).round() as usize;
    for (i, &block) in BUFFERS.iter().enumerate() {
        let frames = offline_frames + RATE.hz() as usize;
        let (out, t) = live(
            &config,
            model,
            material,
            &track,
            block,
            frames,
            0xB10C + i as u64,
        );
        let what = format!("{model:?} {material} {:?}, buffer {block}", config.drive);
        assert_eq!(t.strikes, offline.telemetry.strikes, "{what}");
        assert_eq!((t.late, t.resyncs, t.dropped), (0, 0, 0), "{what}");
        // The first row arrives at 0.137 s plus up to 3 ms of jitter; the first block
        // that starts after that drains it and anchors the clock one budget later.
        let block_after = |t: f64| (t * RATE.hz() / block as f64).ceil() as usize * block;
        let (earliest, latest) = (block_after(0.137), block_after(0.140));
        let anchor = t.sensor_clock.expect("the clock is anchored");
        assert!(
            (earliest + block + margin..=latest + block + margin)
                .contains(&(anchor.frame as usize)),
            "{what}: anchor {anchor:?}, first block from {earliest} to {latest}"
        );
        assert_eq!(anchor.time, track.rows[0].time, "{what}");
        // The gait track starts at 0 s, so offline frame(t) = round(t fs): the shift is A.
        let shift = shift_of(anchor);
        for c in 0..channels {
            let strikes = strike_frames(&config, &track, c);
            assert_eq!(strikes.len(), 6);
            let want = steps_of(&offline.samples, channels, c, &strikes, 0);
            let got = steps_of(&out, channels, c, &strikes, shift);
            for (k, (w, g)) in want.iter().zip(&got).enumerate() {
                assert!(
                    (w.0 - g.0).abs() <= 0.5,
                    "{what}, channel {c}, step {k}: live {:.2} dBFS, offline {:.2}",
                    g.0,
                    w.0
                );
                assert!(
                    w.1.abs_diff(g.1) <= 1,
                    "{what}, channel {c}, step {k}: onset {} live, {} offline",
                    g.1,
                    w.1
                );
            }
            eprintln!(
                "{what}, channel {c}: peaks offline {:?} live {:?} dBFS",
                want.iter()
                    .map(|s| (s.0 * 100.0).round() / 100.0)
                    .collect::<Vec<_>>(),
                got.iter()
                    .map(|s| (s.0 * 100.0).round() / 100.0)
                    .collect::<Vec<_>>()
            );
        }
    }
}

fn shift_of(anchor: ClockAnchor) -> usize {
    anchor.frame as usize - (anchor.time.0 * RATE.hz()).round() as usize
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn a_replayed_walk_plays_live_as_offline_for_buffers_16_to_1024() {
    check(&EngineConfig::default(), SynthModel::Iir, "gravel", 1);
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn both_feet_and_the_force_drives_too() {
    for drive in ["impulse", "force", "force-rate"] {
        let config = EngineConfig {
            drive: drive.parse().unwrap(),
            ..EngineConfig::default()
        };
        check(&config, SynthModel::Iir, "wood", 2);
    }
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn the_physical_model_plays_live_as_offline() {
    check(&EngineConfig::default(), SynthModel::Physical, "gravel", 1);
}

/// Sample for sample, not just step by step: a live session is the offline render shifted
/// by the clock's offset (after the start-up fade, which the two start at different
/// places in the walk).
#[test]
#[ignore = "slow tier: paced in real time"]
fn live_output_is_the_offline_render_shifted() {
    let config = EngineConfig::default();
    let track = walk(1);
    let events = track_events(&track, RATE);
    let frames = events.last().and_then(|e| e.at).unwrap() as usize + 48_000;
    let slot = bank(SynthModel::Iir).slot("gravel").unwrap();
    let offline = render(&config, bank(SynthModel::Iir), &[slot], &events, frames, 64).unwrap();
    for block in BUFFERS {
        let (out, t) = live(
            &config,
            SynthModel::Iir,
            "gravel",
            &track,
            block,
            frames + 48_000,
            7,
        );
        let shift = shift_of(t.sensor_clock.unwrap());
        let skip = 4800;
        assert!(
            out[shift + skip..shift + frames] == offline.samples[skip..],
            "buffer {block}"
        );
    }
}

/// The old way, for contrast: the same readings without their sensor time are applied at
/// block starts, and the steps' loudness follows the block grid.
#[test]
fn unstamped_readings_still_play_and_are_counted_on_the_block_grid() {
    let config = EngineConfig::default();
    let bank = bank(SynthModel::Iir);
    let slot = bank.slot("gravel").unwrap();
    let (mut ctl, mut eng) = engine::build(&config, bank, &[slot]).unwrap();
    let track = walk(1);
    let mut out = vec![0.0f32; 256];
    let mut next = 0;
    let mut frame = 0usize;
    while next < track.rows.len() {
        while next < track.rows.len() && track.rows[next].time.0 * RATE.hz() <= frame as f64 {
            ctl.send(TimedEvent::now(Event::Force {
                channel: 0,
                reading: track.rows[next].readings[0],
            }))
            .unwrap();
            next += 1;
        }
        eng.process(&mut out, 1);
        frame += 256;
    }
    let t = ctl.telemetry();
    assert_eq!(t.strikes, 6);
    assert_eq!(
        t.sensor_clock, None,
        "unstamped readings leave the clock alone"
    );
}

#[test]
fn a_non_finite_sensor_time_is_rejected_and_does_not_anchor() {
    let config = EngineConfig::default();
    let bank = bank(SynthModel::Iir);
    let slot = bank.slot("gravel").unwrap();
    let (mut ctl, mut eng) = engine::build(&config, bank, &[slot]).unwrap();
    let reading = underfoot::force::SensorReading::single(100.0).at(Seconds(f64::NAN));
    ctl.send(TimedEvent::now(Event::Force {
        channel: 0,
        reading,
    }))
    .unwrap();
    let mut out = vec![0.0f32; 64];
    eng.process(&mut out, 1);
    let t = ctl.telemetry();
    assert_eq!((t.rejected, t.sensor_clock), (1, None));
}
