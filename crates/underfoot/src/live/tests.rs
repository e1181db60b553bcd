//! Sessions run end to end, in real time, on short generated walks.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use super::*;
use crate::engine::{EngineConfig, MaterialBank};
use crate::force::gait::nominal_step;
use crate::io::spec::{InputSpec, OutputSpec};
use crate::material::builtin::builtin;
use crate::synthesis::VoiceConfig;
use crate::units::{Newtons, SampleRate, Seconds};

const RATE: SampleRate = SampleRate(16_000);

/// A walk of `steps` steps on one channel, with little lead-in and tail.
fn walk(steps: usize) -> SessionInput {
    let spec = format!("gait:steps={steps},channels=1,lead_in=0.1,tail=0.1");
    SessionInput::Spec(spec.parse().unwrap())
}

fn engine(channels: usize) -> (EngineConfig, MaterialBank, Vec<u16>) {
    let bank = MaterialBank::prepare(
        builtin(),
        RATE,
        &VoiceConfig::default(),
        &nominal_step(70.0, 1.8, RATE.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap();
    let slot = bank.slot("gravel").unwrap();
    let config = EngineConfig {
        rate: RATE,
        channels,
        ..EngineConfig::default()
    };
    (config, bank, vec![slot; channels])
}

/// An error and its sources, as the command line prints them.
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text = format!("{text}: {s}");
        source = s.source();
    }
    text
}

fn run(config: &SessionConfig, stop: bool) -> Summary {
    let session = Session::open(config).unwrap();
    let (engine, bank, slots) = engine(session.channels().unwrap_or(1));
    let running = session.start(&engine, bank, &slots).unwrap();
    running
        .run(&AtomicBool::new(stop), |e| {
            panic!("a walk has no link: {e}")
        })
        .unwrap()
}

/// The paced output's report: every output of these tests is paced.
fn paced(report: &OutputReport) -> &PacedReport {
    match report {
        OutputReport::Paced(paced) => paced,
        #[cfg(feature = "audio")]
        OutputReport::Audio(_) => panic!("{report:?}"),
    }
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn a_walk_plays_out_into_nothing() {
    let config = SessionConfig::new(walk(1), OutputSpec::Null);
    let session = Session::open(&config).unwrap();
    assert_eq!(session.channels(), Some(1));
    assert!(session.ends() && session.interface().is_none());
    let summary = run(&config, false);
    assert_eq!(summary.telemetry.strikes, 1);
    assert!(summary.input.events > 0 && summary.input.rejected == 0);
    assert!(summary.telemetry.sensor_clock.is_some());
    assert!(summary.lost.is_none() && summary.interface.is_none());
    // The walk (about 0.8 s) plays in real time, then rings out for a second.
    assert!(summary.elapsed.as_secs_f64() > 1.5, "{:?}", summary.elapsed);
    let paced = paced(&summary.output);
    assert!(paced.blocks > 0 && paced.wav.is_none(), "{paced:?}");
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn a_walk_is_recorded_into_a_wav_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("live.wav");
    let config = SessionConfig {
        buffer: Some(64),
        ..SessionConfig::new(walk(1), OutputSpec::Wav { path: path.clone() })
    };
    let summary = run(&config, false);
    let paced = paced(&summary.output);
    let (written, wav) = paced.wav.as_ref().expect("a WAV file");
    assert_eq!(written, &path);
    assert_eq!(wav.frames, paced.blocks * 64);
    assert!(wav.peak > 0.0);
    assert!(path.exists());
}

#[test]
fn a_stopped_session_ends_at_once_and_a_duration_bounds_it() {
    let config = SessionConfig::new(walk(4), OutputSpec::Null);
    let summary = run(&config, true);
    assert!(summary.elapsed.as_secs_f64() < 1.0, "{:?}", summary.elapsed);
    assert_eq!(summary.telemetry.strikes, 0);
    let config = SessionConfig {
        duration: Some(Seconds(0.2)),
        ..config
    };
    let summary = run(&config, false);
    assert!(summary.elapsed.as_secs_f64() < 1.5, "{:?}", summary.elapsed);
}

#[test]
fn the_wav_output_may_not_be_a_file_the_session_reads() {
    let dir = tempfile::tempdir().unwrap();
    let track = dir.path().join("steps.csv");
    std::fs::write(&track, "time_s,force\n0,0\n0.01,10\n").unwrap();
    let replay = SessionInput::Spec(InputSpec::Replay {
        file: track.clone(),
        speed: 2.0,
    });
    let output = OutputSpec::Wav {
        path: track.clone(),
    };
    let e = Session::open(&SessionConfig::new(replay, output)).unwrap_err();
    assert!(matches!(e, LiveError::Output(_)), "{e:?}");
    assert!(chain(&e).contains("which this command reads"), "{e}");
    // Nor any file it is told it reads.
    let library = dir.path().join("library.json");
    std::fs::write(&library, "{}").unwrap();
    let config = SessionConfig {
        reads: vec![library.clone()],
        ..SessionConfig::new(walk(1), OutputSpec::Wav { path: library })
    };
    assert!(matches!(Session::open(&config), Err(LiveError::Output(_))));
    assert_eq!(
        std::fs::read_to_string(&track).unwrap(),
        "time_s,force\n0,0\n0.01,10\n"
    );
}

#[test]
fn inputs_that_do_not_open_are_typed_errors() {
    let missing = SessionInput::Spec(InputSpec::Replay {
        file: PathBuf::from("/nonexistent/steps.csv"),
        speed: 1.0,
    });
    let e = Session::open(&SessionConfig::new(missing, OutputSpec::Null)).unwrap_err();
    assert!(matches!(e, LiveError::Track(_)), "{e:?}");
    assert!(chain(&e).contains("/nonexistent/steps.csv"), "{e}");
    let interface = SessionInput::Interface(PathBuf::from("/nonexistent/prosthetic.toml"));
    let e = Session::open(&SessionConfig::new(interface, OutputSpec::Null)).unwrap_err();
    assert!(matches!(e, LiveError::Interface(_)), "{e:?}");
}

#[cfg(not(feature = "audio"))]
#[test]
fn an_audio_output_needs_the_feature() {
    let config = SessionConfig::new(walk(1), OutputSpec::Audio { device: None });
    let session = Session::open(&config).unwrap();
    let (engine, bank, slots) = engine(1);
    let e = session.start(&engine, bank, &slots).unwrap_err();
    assert!(matches!(e, LiveError::NoAudio), "{e:?}");
}

/// A remote steers a running session from another thread: a material switch, a trim, a
/// material added into a spare slot, then a stop that ends the session early. Each
/// command is answered by the session's loop; after the end, a remote says so.
#[test]
#[ignore = "slow tier: a session paced in real time (about 1.5 s)"]
fn a_remote_steers_a_running_session_from_another_thread() {
    use crate::synthesis::PreparedMaterial;
    use crate::units::Decibels;
    let config = SessionConfig::new(walk(40), OutputSpec::Null);
    let session = Session::open(&config).unwrap();
    let (mut engine, bank, slots) = engine(1);
    engine.spare_slots = 1;
    let materials = bank.materials().len();
    let sand = bank.slot("sand").unwrap();
    let running = session.start(&engine, bank, &slots).unwrap();
    let remote = running.remote();
    let steering = std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert_eq!(
            remote
                .send(RemoteCommand::Material {
                    channel: 0,
                    slot: sand
                })
                .unwrap(),
            None
        );
        remote
            .send(RemoteCommand::Trim {
                channel: 0,
                gain: Decibels(-6.0),
            })
            .unwrap();
        let refused = remote
            .send(RemoteCommand::Material {
                channel: 3,
                slot: sand,
            })
            .unwrap_err();
        // Index 3 is the person's channel 4: the message uses their number.
        assert!(
            refused
                .to_string()
                .contains("channel 4: the session plays 1"),
            "{refused}"
        );
        let mut snow = PreparedMaterial::prepare(
            builtin().get("snow").unwrap(),
            RATE,
            &VoiceConfig::default(),
        )
        .unwrap();
        snow.normalise_drives(
            &nominal_step(70.0, 1.8, RATE.hz()),
            Newtons::weight_of(70.0),
        );
        let slot = remote.send(RemoteCommand::Add(Box::new(snow))).unwrap();
        assert_eq!(slot, Some(materials as u16));
        remote
            .send(RemoteCommand::Material {
                channel: 0,
                slot: materials as u16,
            })
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(300));
        remote.send(RemoteCommand::Stop).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(700));
        // The session has ended and dropped its end of the channel.
        assert!(matches!(
            remote.send(RemoteCommand::Stop),
            Err(RemoteError::Ended)
        ));
    });
    let mut last = Status::default();
    let summary = running
        .run_with_status(
            &AtomicBool::new(false),
            |e| panic!("a walk has no link: {e}"),
            std::time::Duration::ZERO,
            |s| last.clone_from(s),
        )
        .unwrap();
    steering.join().unwrap();
    assert!(
        summary.elapsed.as_secs_f64() < 3.0,
        "stopped early: {:?}",
        summary.elapsed
    );
    assert!(summary.telemetry.stopped);
    assert_eq!(last.materials.len(), materials + 1);
    assert_eq!(last.materials.last().unwrap(), "snow");
    let ch = last.channels[0];
    assert_eq!(ch.slot, Some(materials as u16));
    assert!((ch.trim - 0.501).abs() < 0.001, "{ch:?}");
}

/// A recorded walk on two feet, with markers from another thread: the record holds every
/// reading (the same as the walk generated offline), every strike the engine counted,
/// every marker in order, and every output frame.
#[test]
#[ignore = "slow tier: paced in real time"]
fn a_recorded_walk_keeps_every_reading_strike_and_marker() {
    use crate::force::gait::{GaitConfig, generate};
    use crate::force::track::ForceTrack;

    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("session");
    let spec = "steps=4,channels=2,lead_in=0.1,tail=0.1";
    let mut config = SessionConfig::new(
        SessionInput::Spec(format!("gait:{spec}").parse().unwrap()),
        OutputSpec::Null,
    );
    config.record = Some(RecordSettings::new(&folder));
    let session = Session::open(&config).unwrap();
    let (engine, bank, slots) = engine(2);
    let running = session.start(&engine, bank, &slots).unwrap();
    let remote = running.remote();
    let marking = std::thread::spawn(move || {
        for trial in 1..=3 {
            std::thread::sleep(std::time::Duration::from_millis(300));
            let marker = Marker {
                trial: Some(trial),
                participant: Some("P07".into()),
                ..Marker::new(format!("trial {trial}"))
            };
            remote.send(RemoteCommand::Marker(marker)).unwrap();
        }
        // Refused, with a reason, and not recorded.
        let refused = remote.send(RemoteCommand::Marker(Marker::new("two\nlines")));
        assert!(
            format!("{refused:?}").contains("control character"),
            "{refused:?}"
        );
    });
    let summary = running
        .run(&AtomicBool::new(false), |e| panic!("{e}"))
        .unwrap();
    marking.join().unwrap();
    assert_eq!(summary.ended, EndReason::InputEnded);
    let counts = summary.record.clone().unwrap();

    // Every reading: the very track the walk is, read back by the track reader.
    let recorded = ForceTrack::read(&folder.join("force.csv")).unwrap();
    let gait = generate(&GaitConfig::from_spec(spec).unwrap()).unwrap();
    let walk = gait.track;
    let steps: usize = gait.strikes.iter().map(Vec::len).sum();
    assert_eq!(recorded.rows.len(), walk.rows.len());
    assert_eq!(counts.force_rows as usize, walk.rows.len());
    assert_eq!(counts.force_out_of_order + counts.force_mismatched, 0);
    for (r, w) in recorded.rows.iter().zip(&walk.rows) {
        assert!((r.time.0 - w.time.0).abs() < 1e-12);
        for (a, b) in r.readings.iter().zip(&w.readings) {
            assert_eq!(a.as_slice(), b.as_slice());
        }
    }

    // Every strike the engine counted, on its channel, at frames that only increase.
    let strikes = std::fs::read_to_string(folder.join("strikes.csv")).unwrap();
    let rows: Vec<Vec<&str>> = strikes
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len() as u64, summary.telemetry.strikes);
    assert_eq!(summary.telemetry.strikes as usize, steps);
    assert_eq!(summary.telemetry.unlogged_strikes, 0);
    for row in &rows {
        assert!(row[2] == "1" || row[2] == "2", "{row:?}");
        assert_eq!(row[4], "gravel");
        let frame: u64 = row[1].parse().unwrap();
        let time: f64 = row[0].parse().unwrap();
        assert!((time - frame as f64 / f64::from(RATE.0)).abs() < 1e-9);
    }

    // The markers, in order, with their fields; the start and the end around them.
    let events = std::fs::read_to_string(folder.join("events.jsonl")).unwrap();
    let events: Vec<serde_json::Value> = events
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(events.first().unwrap()["kind"], "start");
    assert_eq!(events.last().unwrap()["kind"], "end");
    assert_eq!(events.last().unwrap()["reason"], "input_ended");
    let markers: Vec<&serde_json::Value> =
        events.iter().filter(|e| e["kind"] == "marker").collect();
    assert_eq!(markers.len(), 3);
    assert_eq!(counts.markers, 3);
    for (i, m) in markers.iter().enumerate() {
        assert_eq!(m["trial"], i as u64 + 1);
        assert_eq!(m["participant"], "P07");
        assert_eq!(m["text"], format!("trial {}", i + 1));
    }
    let times: Vec<f64> = markers.iter().map(|m| m["t"].as_f64().unwrap()).collect();
    assert!(times.windows(2).all(|w| w[1] - w[0] > 0.2), "{times:?}");

    // Every output frame, as many as the engine rendered.
    let wav = hound::WavReader::open(folder.join("output.wav")).unwrap();
    assert_eq!(wav.spec().channels, 2);
    assert_eq!(u64::from(wav.duration()), summary.telemetry.frames);
    assert_eq!(counts.output_frames, summary.telemetry.frames);
    assert_eq!(counts.output_frames_dropped, 0);

    // The manifest, ended.
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("manifest.json")).unwrap())
            .unwrap();
    assert_eq!(manifest["version"], record::RECORD_VERSION);
    assert_eq!(manifest["channels"][1]["material"], "gravel");
    assert_eq!(manifest["ended"]["reason"], "input_ended");
    assert_eq!(manifest["ended"]["strikes"], steps);
    assert!(manifest["started"]["utc"].as_str().unwrap().ends_with('Z'));
    let status = std::fs::read_to_string(folder.join("status.jsonl")).unwrap();
    assert!(status.lines().count() >= 2, "{status}");
}

#[test]
fn a_record_never_goes_into_a_folder_that_holds_something() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("notes.txt"), "participant 3").unwrap();
    let mut config = SessionConfig::new(walk(1), OutputSpec::Null);
    config.record = Some(RecordSettings::new(dir.path()));
    let e = Session::open(&config).unwrap_err();
    assert!(chain(&e).contains("not empty"), "{}", chain(&e));
    assert_eq!(
        std::fs::read_to_string(dir.path().join("notes.txt")).unwrap(),
        "participant 3"
    );
    config.record = Some(RecordSettings::new(dir.path().join("notes.txt")));
    let e = Session::open(&config).unwrap_err();
    assert!(chain(&e).contains("not a folder"), "{}", chain(&e));
    config.record = Some(RecordSettings::new(dir.path().join("no/such/parent")));
    let e = Session::open(&config).unwrap_err();
    assert!(chain(&e).contains("parent"), "{}", chain(&e));
}
