//! Tests of force tracks: the file format round-trips exactly, and every fault is named
//! with its file and line.

use std::path::Path;

use proptest::prelude::*;

use super::*;
use crate::document::FileError;
use crate::force::MAX_SENSORS;

fn reading(values: &[f32]) -> SensorReading {
    SensorReading::new(values).unwrap()
}

fn feet() -> ForceTrack {
    let channel = |name: &str| ChannelSensors {
        name: name.to_owned(),
        sensors: vec!["heel".to_owned(), "toe".to_owned()],
    };
    ForceTrack {
        channels: vec![channel("left"), channel("right")],
        rows: vec![
            ForceRow {
                time: Seconds(0.0),
                readings: vec![reading(&[0.0, 0.0]), reading(&[-0.25, 0.0])],
            },
            ForceRow {
                time: Seconds(0.002),
                readings: vec![reading(&[0.1, 1e-7]), reading(&[812.345_6, 3.0])],
            },
            ForceRow {
                time: Seconds(0.004),
                readings: vec![reading(&[1.0 / 3.0, 2.5e30]), reading(&[7.0, 0.0])],
            },
        ],
    }
}

fn error(text: &str) -> TrackError {
    ForceTrack::from_csv_str(text, "walk.csv").unwrap_err()
}

#[test]
fn round_trip_is_exact() {
    let track = feet();
    let text = track.to_csv();
    assert!(text.starts_with("time_s,left.heel,left.toe,right.heel,right.toe\n"));
    assert_eq!(ForceTrack::from_csv_str(&text, "mem").unwrap(), track);
    track.validate("mem").unwrap();
    assert_eq!(track.channel_count(), 2);
    assert!((track.duration().0 - 0.004).abs() < 1e-15);
    assert!((track.sensor_rate().unwrap() - 500.0).abs() < 1e-9);
}

#[test]
fn reads_the_documented_example_and_lone_columns() {
    let text = "\u{feff}# walking, 70 kg; newtons\n\
                time_s,left.heel,left.toe,right.heel,right.toe\n\
                0,0,0,0,0\n\
                \n\
                0.002, 0.51 ,0,0,0\n\
                0.004,2.04,0,-0.3,0.1\n";
    let track = ForceTrack::from_csv_str(text, "doc").unwrap();
    assert_eq!(track.rows.len(), 3);
    assert_eq!(track.channels[1].name, "right");
    assert_eq!(track.rows[2].readings[1].as_slice(), &[-0.3, 0.1]);

    let lone = ForceTrack::from_csv_str("time_s,force\n0,1\n0.01,2.5\n", "lone").unwrap();
    assert_eq!(
        lone.channels,
        vec![ChannelSensors {
            name: "0".to_owned(),
            sensors: vec!["force".to_owned()]
        }]
    );
    assert_eq!(lone.to_csv(), "time_s,force\n0,1\n0.01,2.5\n");
    assert!((lone.sensor_rate().unwrap() - 100.0).abs() < 1e-9);
    // A lone column with a dot is an ordinary channel.
    let tile = ForceTrack::from_csv_str("time_s,tile0.c0\n0,1\n", "t").unwrap();
    assert_eq!(tile.channels[0].name, "tile0");
    assert_eq!(tile.sensor_rate(), None);
    assert_eq!(tile.duration(), Seconds(0.0));
}

#[test]
fn header_faults_are_named() {
    assert!(matches!(error(""), TrackError::Empty { .. }));
    assert!(matches!(
        error("# only a comment\n\n"),
        TrackError::Empty { .. }
    ));
    assert!(matches!(
        error("0,1,2\n0.1,1,2\n"),
        TrackError::NoTimeColumn { line: 1, ref found, .. } if found == "0"
    ));
    assert!(matches!(
        error("# c\ntime_s\n0\n"),
        TrackError::NoSensorColumns { line: 2, .. }
    ));
    assert!(matches!(
        error("time_s,left.heel,toe\n"),
        TrackError::BadColumn { position: 3, ref column, .. } if column == "toe"
    ));
    assert!(matches!(
        error("time_s,left.heel,left.\n"),
        TrackError::BadColumn { position: 3, .. }
    ));
    assert!(matches!(
        error("time_s,le ft.heel\n"),
        TrackError::BadColumn { position: 2, .. }
    ));
    assert!(matches!(
        error("time_s,a.x,a.y,a.x\n"),
        TrackError::BadColumn { position: 4, .. }
    ));
    assert!(matches!(
        error("time_s,time_s\n"),
        TrackError::BadColumn { position: 2, .. }
    ));
    assert!(matches!(
        error("time_s,left.heel,right.heel,left.toe\n0,1,2,3\n"),
        TrackError::NonContiguous { position: 4, ref channel, .. } if channel == "left"
    ));
    let nine: Vec<String> = (0..=MAX_SENSORS).map(|k| format!("tile.c{k}")).collect();
    assert!(matches!(
        error(&format!("time_s,{}\n", nine.join(","))),
        TrackError::TooManySensors { position: 10, ref channel, .. } if channel == "tile"
    ));
    assert!(matches!(
        error("time_s,force\n# no rows\n"),
        TrackError::NoRows { .. }
    ));
}

#[test]
fn row_faults_give_their_line() {
    let head = "# comment\ntime_s,l.heel,l.toe\n0,1,2\n";
    assert!(matches!(
        error(&format!("{head}0.1,1\n")),
        TrackError::FieldCount {
            line: 4,
            expected: 3,
            found: 2,
            ..
        }
    ));
    assert!(matches!(
        error(&format!("{head}0.1,1,2,3\n")),
        TrackError::FieldCount {
            line: 4,
            found: 4,
            ..
        }
    ));
    assert!(matches!(
        error(&format!("{head}\n0.1,1,x\n")),
        TrackError::BadValue { line: 5, ref column, ref text, .. }
            if column == "l.toe" && text == "x"
    ));
    assert!(matches!(
        error(&format!("{head}0.1,NaN,2\n")),
        TrackError::BadValue { line: 4, ref column, .. } if column == "l.heel"
    ));
    // Beyond f32 range parses as infinity: reported as typed, with what is wrong.
    let e = error(&format!("{head}0.1,1e300,2\n"));
    assert!(
        matches!(e, TrackError::BadValue { line: 4, ref text, reason, .. }
            if text == "1e300" && reason == super::BEYOND_F32),
        "{e}"
    );
    assert!(e.to_string().contains("\"1e300\" is beyond"), "{e}");
    let e = error(&format!("{head}0.1,-inf,2\n"));
    assert!(
        matches!(e, TrackError::BadValue { ref text, reason, .. }
            if text == "-inf" && reason == super::NOT_FINITE),
        "{e}"
    );
    assert!(matches!(
        error(&format!("{head}inf,1,2\n")),
        TrackError::BadValue { line: 4, ref column, .. } if column == "time_s"
    ));
    assert!(matches!(
        error(&format!("{head}0.1,1,2\n0.1,1,2\n")),
        TrackError::TimeOrder { line: 5, .. }
    ));
    assert!(matches!(
        error(&format!("{head}-0.1,1,2\n")),
        TrackError::TimeOrder { line: 4, .. }
    ));
    // Drifting sensors read slightly negative; that is not an error.
    ForceTrack::from_csv_str(&format!("{head}0.1,-0.4,2\n"), "drift").unwrap();
}

#[test]
fn a_gap_beyond_the_bound_is_refused_with_its_line() {
    let head = "time_s,l.heel,l.toe\n0,1,2\n0.002,1,2\n";
    // A last row at 1e300 s (issue 14): refused, not silently played as 1 s of nothing.
    let e = error(&format!("{head}1e300,1,2\n"));
    assert!(
        matches!(e, TrackError::TimeGap { line: 4, previous, .. } if previous == 0.002),
        "{e:?}"
    );
    assert!(e.to_string().contains("line 4"), "{e}");
    assert!(matches!(
        error(&format!("{head}10.1,1,2\n")),
        TrackError::TimeGap { line: 4, .. }
    ));
    // Exactly the bound is fine; a logger's clock is fine.
    ForceTrack::from_csv_str(&format!("{head}10.002,1,2\n"), "t").unwrap();
    let logger =
        ForceTrack::from_csv_str("time_s,force\n1700000000,1\n1700000000.002,2\n", "logger")
            .unwrap();
    assert!((logger.duration().0 - 0.002).abs() < 1e-6);
    let mut far = feet();
    far.rows[2].time = Seconds(1e300);
    assert!(matches!(
        far.validate("far"),
        Err(TrackError::TimeGap { line: 4, .. })
    ));
}

#[cfg(unix)]
#[test]
fn an_endless_device_is_refused_as_too_large() {
    let e = ForceTrack::read(Path::new("/dev/zero")).unwrap_err();
    assert!(
        matches!(&e, TrackError::File(FileError { source, .. })
            if source.kind() == std::io::ErrorKind::FileTooLarge),
        "{e:?}"
    );
}

#[test]
fn messages_name_the_file_and_line() {
    let message = error("time_s,force\n0,1\n0.5,oops\n").to_string();
    assert!(
        message.contains("walk.csv") && message.contains("line 3"),
        "{message}"
    );
    assert!(
        message.contains("force") && message.contains("oops"),
        "{message}"
    );
    let missing = ForceTrack::read(Path::new("/nonexistent/walk.csv")).unwrap_err();
    assert!(matches!(missing, TrackError::File(_)));
    assert!(missing.to_string().contains("/nonexistent/walk.csv"));
}

#[test]
fn validate_catches_tracks_built_wrongly() {
    let mut track = feet();
    track.rows[2].time = Seconds(0.001);
    assert!(matches!(
        track.validate("mem"),
        Err(TrackError::TimeOrder { line: 4, .. })
    ));
    let mut track = feet();
    track.rows[1].readings.pop();
    assert!(matches!(
        track.validate("mem"),
        Err(TrackError::Inconsistent { .. })
    ));
    let mut track = feet();
    track.rows[1].readings[1] = reading(&[1.0, 2.0, 3.0]);
    assert!(matches!(
        track.validate("mem"),
        Err(TrackError::Inconsistent { .. })
    ));
    let mut track = feet();
    track.rows[0].readings[1] = reading(&[1.0, f32::INFINITY]);
    assert!(matches!(
        track.validate("mem"),
        Err(TrackError::BadValue { line: 2, ref column, .. }) if column == "right.toe"
    ));
    let mut track = feet();
    track.channels[1].name = "left".to_owned();
    assert!(matches!(
        track.validate("mem"),
        Err(TrackError::Inconsistent { .. })
    ));
    let mut track = feet();
    track.channels[0].sensors[1] = "to.e".to_owned();
    assert!(matches!(
        track.validate("mem"),
        Err(TrackError::BadColumn { .. })
    ));
    let mut track = feet();
    track.rows.clear();
    assert!(matches!(
        track.validate("mem"),
        Err(TrackError::NoRows { .. })
    ));
}

#[test]
fn save_is_readable_and_refuses_bad_tracks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("walk.csv");
    let track = feet();
    track.save(&path).unwrap();
    assert_eq!(ForceTrack::read(&path).unwrap(), track);

    let mut bad = track.clone();
    bad.rows[1].time = Seconds(-1.0);
    let e = bad.save(&path).unwrap_err();
    assert!(e.to_string().contains("walk.csv"), "{e}");
    assert_eq!(ForceTrack::read(&path).unwrap(), track);

    let e = track
        .save(&dir.path().join("missing/walk.csv"))
        .unwrap_err();
    assert!(matches!(e, TrackError::File(_)), "{e}");
}

fn track_strategy() -> impl Strategy<Value = ForceTrack> {
    let value = prop_oneof![
        prop::num::f32::NORMAL,
        prop::num::f32::SUBNORMAL,
        prop::num::f32::ZERO,
        -2000.0f32..2000.0,
    ];
    prop::collection::vec(1usize..=MAX_SENSORS, 1..4)
        .prop_flat_map(move |sensors| {
            let width: usize = sensors.iter().sum();
            let row = (
                1e-6f64..1.0,
                prop::collection::vec(value.clone(), width..=width),
            );
            (
                Just(sensors),
                -10.0f64..10.0,
                prop::collection::vec(row, 1..20),
            )
        })
        .prop_map(|(sensors, start, rows)| {
            let channels: Vec<ChannelSensors> = sensors
                .iter()
                .enumerate()
                .map(|(c, &n)| ChannelSensors {
                    name: format!("ch{c}"),
                    sensors: (0..n).map(|k| format!("s{k}")).collect(),
                })
                .collect();
            let mut time = start;
            let rows = rows
                .into_iter()
                .map(|(step, values)| {
                    time += step;
                    let mut rest = values.as_slice();
                    let readings = sensors
                        .iter()
                        .map(|&n| {
                            let (now, later) = rest.split_at(n);
                            rest = later;
                            reading(now)
                        })
                        .collect();
                    ForceRow {
                        time: Seconds(time),
                        readings,
                    }
                })
                .collect();
            ForceTrack { channels, rows }
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn csv_round_trip(track in track_strategy()) {
        track.validate("generated").unwrap();
        let back = ForceTrack::from_csv_str(&track.to_csv(), "generated").unwrap();
        prop_assert_eq!(back, track);
    }
}
