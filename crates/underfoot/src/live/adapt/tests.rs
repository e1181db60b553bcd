//! The adaptation loop offline: the engine rendered as fast as it goes on a generated
//! walk, its drive (through the tap, as the output callback hands it) through a simulated
//! leg (Table 1's mean user, the limb model's `H_u`) into the sensor ring, which starts a
//! known number of samples early, and the loop polled between blocks as the session polls
//! it. The JACK test
//! (`tests/audio_device.rs`) runs the same loop in real time through a server.

use super::*;
use crate::compensation::chain::Compensation;
use crate::compensation::equalizer::{EqualizerConfig, Realisation};
use crate::compensation::limb::{DEFAULT_G2, LimbModel, LimbParams};
use crate::engine::offline::track_events;
use crate::engine::{self, EngineConfig, MaterialBank, TelemetrySnapshot};
use crate::force::gait::{self, GaitConfig, nominal_step};
use crate::material::builtin::builtin;
use crate::signal::Sos;
use crate::signal::noise::SplitMix64;
use crate::sim::SimulatedUser;
use crate::synthesis::VoiceConfig;
use crate::units::Band;

const RATE: SampleRate = SampleRate(48_000);

/// The leg of Table 1's mean user at `RATE`: what stands between the actuator and the
/// accelerometer on the skin (the device itself is a wire here, as in the JACK test).
pub(crate) fn leg() -> Sos {
    let limb = LimbModel::new(LimbParams::TABLE1_MEAN, DEFAULT_G2, 1.0).unwrap();
    SimulatedUser::limb_sections(&limb, RATE).unwrap()
}

/// The deviation from flat over 40-1024 Hz (the equalizer's band) of `weights` in front
/// of `plant`, from the plant's true response: RMS about the mean, in dB.
fn deviation(weights: &SpectralWeights, plant: &Sos) -> f64 {
    let v: Vec<f64> = Band::new(40.0, 1024.0)
        .log_grid(128)
        .into_iter()
        .map(|f| weights.gain_db_at(f) + 20.0 * plant.response(RATE.omega(f)).norm().log10())
        .collect();
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
}

struct Run {
    initial: f64,
    /// `(seconds of walk, deviation)` at each update.
    history: Vec<(f64, f64)>,
    status: AdaptStatus,
    telemetry: TelemetrySnapshot,
}

/// `seconds` of walking on `material`, the sensor's stream started `offset` samples early
/// (late when negative), the engine in blocks of `block`.
fn simulate(seconds: f64, offset: i64, block: usize, material: &str) -> Run {
    let weights = SpectralWeights::flat(EqualizerConfig::default(), RATE).unwrap();
    let bank = MaterialBank::prepare(
        builtin(),
        RATE,
        &VoiceConfig::default(),
        &nominal_step(70.0, 1.8, RATE.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap();
    let slot = bank.slot(material).unwrap();
    let config = EngineConfig {
        rate: RATE,
        channels: 1,
        compensation: Compensation {
            equalizer: Some((weights.clone(), Realisation::Bank)),
            limb: None,
        },
        ..EngineConfig::default()
    };
    let (mut controller, mut engine) = engine::build(&config, bank, &[slot]).unwrap();
    let parts = AdaptParts::new(
        &AdaptSettings::default(),
        &weights,
        RATE,
        controller.telemetry_handle(),
    )
    .unwrap();
    let (mut drive_tap, mut sensor_tap, mut adapt) = (parts.drive, parts.sensor, parts.adapt);
    controller
        .set_equalizer_weights(0, &adapt.weights().gains_db)
        .unwrap();

    let walk = gait::generate(
        &GaitConfig::from_spec(&format!(
            "steps={},channels=1,lead_in=0.2",
            (seconds * 1.2) as usize
        ))
        .unwrap(),
    )
    .unwrap();
    let mut events = track_events(&walk.track, RATE).into_iter().peekable();

    let plant = leg();
    let mut state = vec![[0.0; 2]; plant.sections.len()];
    let mut rng = SplitMix64::new(9);
    let initial = deviation(adapt.weights(), &plant);
    // The sensor's stream started `offset` samples before the output's, or missed the
    // first `-offset`.
    sensor_tap.push(&vec![0.0; offset.max(0) as usize], 1);
    let mut missed = (-offset).max(0) as usize;

    let total = (seconds * RATE.hz()) as u64;
    let mut out = vec![0.0f32; block];
    let mut history = Vec::new();
    let mut frame = 0u64;
    let mut updates = 0;
    while frame < total {
        while let Some(e) = events.next_if(|e| e.at.is_some_and(|at| at < frame + block as u64)) {
            controller.send(e).unwrap();
        }
        engine.process(&mut out, 1);
        drive_tap.push(&out, 1);
        let mut wide: Vec<f64> = out.iter().map(|&v| f64::from(v)).collect();
        plant.filter_with_state(&mut wide, &mut state);
        // Sensor noise about 65 dB under the steps' peaks (gravel's steps peak near
        // -30 dBFS at its playback level).
        let sensed: Vec<f32> = wide
            .iter()
            .map(|&v| (v + 1e-5 * rng.normal()) as f32)
            .collect();
        let skip = missed.min(sensed.len());
        missed -= skip;
        sensor_tap.push(&sensed[skip..], 1);
        frame += block as u64;
        // The session polls every 20 ms.
        if frame % 960 < block as u64 {
            adapt.poll(&mut controller);
            controller.collect();
            if adapt.status().updates > updates {
                updates = adapt.status().updates;
                history.push((frame as f64 / RATE.hz(), deviation(adapt.weights(), &plant)));
            }
        }
    }
    Run {
        initial,
        history,
        status: adapt.status(),
        telemetry: controller.telemetry(),
    }
}

#[test]
fn the_loop_finds_the_delay_and_flattens_the_leg_while_walking_on_gravel() {
    check(1500, 256);
}

#[test]
fn a_sensor_that_starts_late_and_small_blocks_change_nothing() {
    check(-700, 64);
}

fn check(offset: i64, block: usize) {
    let run = simulate(30.0, offset, block, "gravel");
    let every_5s: Vec<String> = run
        .history
        .windows(2)
        .filter(|w| (w[0].0 / 5.0).floor() < (w[1].0 / 5.0).floor())
        .map(|w| format!("{:.1} s: {:.2}", w[1].0, w[1].1))
        .collect();
    eprintln!(
        "initial {:.2} dB; {:?}; {every_5s:?}; engine applied {} refused {}",
        run.initial, run.status, run.telemetry.equalizer_updates, run.telemetry.equalizer_refused
    );
    // The sensor's sample n + offset is what the drive's sample n caused (plus the
    // leg's own few samples of group delay).
    let lag = run.status.delay.expect("the delay was never found");
    assert!((0..=32).contains(&(lag - offset)), "lag {lag}");
    assert_eq!(run.status.realignments, 0);
    assert_eq!(run.status.dropped, 0);
    assert!(
        run.initial > 2.0,
        "the leg must need equalizing: {}",
        run.initial
    );
    let last = run.history.last().expect("no update").1;
    assert!(last < 1.0, "still {last:.2} dB from flat after 30 s");
    // Every update reached the engine and was applied there (plus the starting weights).
    assert_eq!(run.telemetry.equalizer_updates, run.status.updates + 1);
    assert_eq!(run.telemetry.equalizer_refused, 0);
}
