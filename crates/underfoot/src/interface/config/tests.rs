use super::*;

const GOOD: &str = r#"
[link]
port = "simulated"
servo_rate_hz = 100

[insole]
newtons_per_count = 0.5

[[sensor]]
name = "heel"
index = 0
[[sensor]]
name = "midfoot"
index = 1
newtons_per_count = 0.25
[[sensor]]
name = "toe"
index = 2

[[servo]]
id = 0
sensors = ["heel", "midfoot"]
weights = [1.0, 0.5]
range_us = [1000, 2000]
rest_us = 1100
full_us = 1900
threshold_n = 20
full_force_n = 500
dead_band_us = 8
rate_us_per_s = 2000

[[channel]]
name = "disc"
sensors = ["heel", "toe"]

[simulated]
gait = "steps=4"
"#;

fn parse(text: &str) -> Result<InterfaceConfig, ConfigError> {
    InterfaceConfig::parse(text, Path::new("p.toml"), |name| {
        Err(SensorCalibrationError::Tare {
            reason: format!("no file {name} in this test"),
        })
    })
}

fn invalid(text: &str) -> (String, Option<usize>, String) {
    match parse(text) {
        Err(ConfigError::Invalid {
            key, line, reason, ..
        }) => (key, line, reason),
        other => panic!("expected Invalid, got {other:?}"),
    }
}

#[test]
fn a_good_file_parses_into_frame_indices() {
    let c = parse(GOOD).unwrap();
    assert_eq!(c.frame_sensors, 3);
    assert_eq!(c.servo_rate, Hz(100.0));
    assert_eq!(c.insole_timeout, Seconds(0.2));
    assert_eq!(c.servos[0].inputs, vec![(0, 1.0), (1, 0.5)]);
    assert_eq!(c.channels[0].sensors, vec![0, 2]);
    let mut out = [0.0; 3];
    c.scale.apply(&[10, 10, 10], &mut out);
    assert_eq!(out, [5.0, 2.5, 5.0]);
    let Link::Simulated(sim) = &c.link else {
        panic!("simulated")
    };
    assert_eq!(sim.gait.channels, 1);
    assert_eq!(sim.gait.steps, 4);
    assert_eq!(sim.heel_midfoot_toe, [0, 1, 2]);
}

#[test]
fn errors_name_key_and_line() {
    let (key, line, _) =
        invalid(&GOOD.replace("range_us = [1000, 2000]", "range_us = [2000, 1000]"));
    assert_eq!(key, "servo[0].range_us");
    let servo_line = GOOD.lines().position(|l| l == "[[servo]]").unwrap() + 1;
    assert_eq!(line, Some(servo_line));
    let (key, _, reason) = invalid(&GOOD.replace("\"heel\", \"midfoot\"]", "\"heel\", \"arch\"]"));
    assert_eq!(key, "servo[0].sensors");
    assert!(reason.contains("arch"), "{reason}");
    let (key, _, _) = invalid(&GOOD.replace("index = 2", "index = 1"));
    assert_eq!(key, "sensor[2].index");
    let (key, _, _) = invalid(&GOOD.replace("index = 2", "index = 7"));
    assert_eq!(key, "sensor[2].index");
    let (key, _, _) = invalid(&GOOD.replace("servo_rate_hz = 100", "servo_rate_hz = 0"));
    assert_eq!(key, "link.servo_rate_hz");
    let (key, _, _) = invalid(&GOOD.replace("gait = \"steps=4\"", "gait = \"steps=x\""));
    assert_eq!(key, "simulated.gait");
    let (key, _, _) = invalid(&GOOD.replace("newtons_per_count = 0.25", "curve = \"mid\""));
    assert_eq!(key, "sensor[1].curve");
    let (key, _, _) = invalid(&GOOD.replace("[insole]\nnewtons_per_count = 0.5", ""));
    assert_eq!(key, "sensor[0].name");
    let (key, _, _) = invalid(&GOOD.replace("dead_band_us = 8", "dead_band_us = -8"));
    assert_eq!(key, "servo[0].dead_band_us");
    let (key, _, _) = invalid(
        &GOOD
            .replace("name = \"midfoot\"", "name = \"ball\"")
            .replace("\"heel\", \"midfoot\"]", "\"heel\", \"ball\"]"),
    );
    assert_eq!(key, "simulated");
    // Syntax: an unknown key and a wrong type, with their lines.
    for (from, to) in [
        ("rate_us_per_s = 2000", "rate_us_per_sec = 2000"),
        ("rest_us = 1100", "rest_us = \"1100\""),
        ("rest_us = 1100", "rest_us = 70000"),
    ] {
        match parse(&GOOD.replace(from, to)) {
            Err(ConfigError::Syntax { line, message, .. }) => {
                let want = GOOD.lines().position(|l| l == from).unwrap() + 1;
                assert_eq!(line, Some(want), "{message}");
            }
            other => panic!("{to}: {other:?}"),
        }
    }
    match parse(&GOOD.replace(
        "[insole]\nnewtons_per_count = 0.5",
        "[insole]\ncalibration = \"s.json\"",
    )) {
        Err(e @ ConfigError::Calibration { .. }) => {
            assert!(e.to_string().contains("s.json"), "{e}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_example_file_parses() {
    let text = include_str!("../../../../../examples/prosthetic.toml");
    let sim = parse(text).unwrap();
    assert!(matches!(sim.link, Link::Simulated(_)));
    assert_eq!(
        (sim.sensors.len(), sim.servos.len(), sim.channels.len()),
        (3, 3, 4)
    );
    // The reversed toe servo.
    assert!(sim.servos[2].calibration.full < sim.servos[2].calibration.rest);
    // The same file for a real board: only the port changes.
    let board = text.replacen("port = \"simulated\"", "port = \"/dev/ttyACM0\"", 1);
    let serial = parse(&board).unwrap();
    assert!(
        matches!(serial.link, Link::Serial { ref port, baud: 115_200 } if port == "/dev/ttyACM0")
    );
    assert_eq!(sim.servos, serial.servos);
}

#[test]
fn serial_link_and_calibration_file() {
    use crate::force::calibration::{CurveModel, SensorCurve};
    let text = GOOD
        .replace(
            "port = \"simulated\"",
            "port = \"/dev/ttyACM0\"\nbaud = 57600",
        )
        .replace(
            "[insole]\nnewtons_per_count = 0.5",
            "[insole]\nnewtons_per_count = 0.5\ncalibration = \"cal/s.json\"",
        );
    let c = InterfaceConfig::parse(&text, Path::new("p.toml"), |name| {
        assert_eq!(name, "cal/s.json");
        Ok(SensorCalibration {
            sensors: vec![SensorCurve {
                name: "toe".into(),
                model: CurveModel::Power {
                    a: 2.0,
                    b: 1.0,
                    r0: 10.0,
                },
                raw_range: [0.0, 1000.0],
                drift: 0.0,
            }],
        })
    })
    .unwrap();
    assert_eq!(
        c.link,
        Link::Serial {
            port: "/dev/ttyACM0".into(),
            baud: 57600
        }
    );
    let mut out = [0.0; 3];
    c.scale.apply(&[10, 10, 20], &mut out);
    // Heel by the fallback factor, midfoot by its own, toe by its curve.
    assert_eq!(out, [5.0, 2.5, 20.0]);
}
