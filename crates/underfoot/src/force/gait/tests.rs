//! Tests of the gait: the curve's shape and impulse, the walk's timing, the spec.

use super::step::{PEAK1, PEAK2, Shape, TOE_FROM, TOE_TO, VALLEY};
use super::*;
use crate::units::Newtons;

fn totals(track: &ForceTrack, channel: usize) -> Vec<f64> {
    track
        .rows
        .iter()
        .map(|r| f64::from(r.readings[channel].total()))
        .collect()
}

fn weight(config: &GaitConfig) -> f64 {
    Newtons::weight_of(config.weight_kg).0
}

#[test]
fn shape_area_matches_quadrature() {
    let shape = Shape::new(PEAK1, VALLEY, PEAK2);
    let n = 100_000;
    let sum: f64 = (0..n)
        .map(|i| shape.eval((i as f64 + 0.5) / n as f64))
        .sum();
    assert!((sum / n as f64 - shape.area()).abs() < 1e-9);
}

#[test]
fn force_is_zero_outside_stance_and_never_negative() {
    let config = GaitConfig {
        steps: 10,
        variation: 0.2,
        ..GaitConfig::default()
    };
    let gait = generate(&config).unwrap();
    let rate = config.sensor_rate;
    for c in 0..2 {
        let stances: Vec<(f64, f64)> = gait.strikes[c]
            .iter()
            .zip(&gait.toe_offs[c])
            .map(|(a, b)| (a.0, b.0))
            .collect();
        for (row, total) in gait.track.rows.iter().zip(totals(&gait.track, c)) {
            let t = row.time.0;
            assert!(row.readings[c].as_slice().iter().all(|&v| v >= 0.0));
            let in_stance = stances.iter().any(|&(a, b)| t > a && t < b);
            if !in_stance {
                assert!(total == 0.0, "channel {c} at {t} s: {total} N");
            }
        }
        // Strictly inside a stance, away from its ends, there is load.
        for &(a, b) in &stances {
            let mid = ((a + b) / 2.0 * rate).round() as usize;
            assert!(totals(&gait.track, c)[mid] > 0.25 * weight(&config));
        }
    }
}

#[test]
fn peaks_and_valley_are_near_their_fractions_of_body_weight() {
    let config = GaitConfig {
        steps: 1,
        channels: 1,
        variation: 0.0,
        ..GaitConfig::default()
    };
    let gait = generate(&config).unwrap();
    let w = weight(&config);
    let f = totals(&gait.track, 0);
    let rate = config.sensor_rate;
    let strike = gait.strikes[0][0].0;
    let stance = gait.toe_offs[0][0].0 - strike;
    let at = |u: f64| ((strike + u * stance) * rate).round() as usize;
    let max_in = |a: f64, b: f64| f[at(a)..at(b)].iter().copied().fold(0.0, f64::max);
    let min_in = |a: f64, b: f64| f[at(a)..at(b)].iter().copied().fold(f64::MAX, f64::min);
    let (p1, q, p2) = (max_in(0.0, 0.4), min_in(0.35, 0.65), max_in(0.6, 1.0));
    assert!((1.1..1.2).contains(&(p1 / w)), "first peak {}", p1 / w);
    assert!((0.7..0.8).contains(&(q / w)), "valley {}", q / w);
    assert!((1.05..1.15).contains(&(p2 / w)), "second peak {}", p2 / w);
    // Where they are: at 25%, 50% and 75% of stance, to a sample.
    let argmax = |a: f64, b: f64| {
        (at(a)..at(b))
            .max_by(|&i, &j| f[i].total_cmp(&f[j]))
            .unwrap()
    };
    assert!(argmax(0.0, 0.4).abs_diff(at(0.25)) <= 1);
    assert!(argmax(0.6, 1.0).abs_diff(at(0.75)) <= 1);
    // The heel-strike rise: about body weight within 80 ms.
    let after = |seconds: f64| f[((strike + seconds) * rate).round() as usize] / w;
    assert!(
        after(0.080) > 0.95 && after(0.050) > 0.5,
        "{}",
        after(0.080)
    );
}

#[test]
fn mean_force_over_whole_cycles_is_body_weight() {
    for (seed, cadence, variation) in [(1, 1.8, 0.05), (2, 1.0, 0.2), (3, 3.0, 0.0)] {
        let config = GaitConfig {
            steps: 24,
            cadence,
            variation,
            seed,
            ..GaitConfig::default()
        };
        let gait = generate(&config).unwrap();
        let (left, right) = (totals(&gait.track, 0), totals(&gait.track, 1));
        // Whole cycles away from the ends, where the other foot's steps are all there.
        let rate = config.sensor_rate;
        let from = (gait.strikes[0][2].0 * rate).round() as usize;
        let to = (gait.strikes[0][22].0 * rate).round() as usize;
        let mean = (from..to).map(|i| left[i] + right[i]).sum::<f64>() / (to - from) as f64;
        let ratio = mean / weight(&config);
        assert!((ratio - 1.0).abs() < 0.05, "cadence {cadence}: {ratio}");
        assert!((ratio - 1.0).abs() < 0.01 || variation > 0.0, "{ratio}");
    }
}

#[test]
fn heel_and_toe_add_up_to_the_nominal_step() {
    let config = GaitConfig {
        steps: 1,
        channels: 1,
        variation: 0.0,
        ..GaitConfig::default()
    };
    let gait = generate(&config).unwrap();
    let step = nominal_step(config.weight_kg, config.cadence, config.sensor_rate);
    let first = (config.lead_in.0 * config.sensor_rate).round() as usize;
    let rows = &gait.track.rows[first..first + step.len()];
    for (k, (row, expected)) in rows.iter().zip(&step).enumerate() {
        let [heel, toe] = row.readings[0].as_slice() else {
            panic!("two sensors")
        };
        let total = f64::from(*heel) + f64::from(*toe);
        assert!((total - expected).abs() < 1e-3, "sample {k}");
        let u = k as f64 / (config.sensor_rate * config.stance_fraction * 2.0 / config.cadence);
        if u < TOE_FROM {
            assert_eq!(*toe, 0.0);
        }
        if u > TOE_TO {
            assert_eq!(*heel, 0.0);
        }
    }
    assert_eq!(step.first(), Some(&0.0));
    assert!(step.last().is_some_and(|&f| f < 1.0));
    assert!(nominal_step(70.0, 0.0, 500.0).is_empty());
}

#[test]
fn the_force_is_smooth() {
    let config = GaitConfig {
        steps: 8,
        ..GaitConfig::default()
    };
    let gait = generate(&config).unwrap();
    let w = weight(&config);
    for c in 0..2 {
        let f = totals(&gait.track, c);
        let jump = f
            .windows(2)
            .map(|p| (p[1] - p[0]).abs())
            .fold(0.0, f64::max);
        // A kink (slope jump) of 10 W/s would give a second difference of 0.02 W at
        // 500 Hz; the curve's own curvature stays well below that.
        let bend = f
            .windows(3)
            .map(|p| (p[2] - 2.0 * p[1] + p[0]).abs())
            .fold(0.0, f64::max);
        assert!(jump < 0.05 * w, "jump {}", jump / w);
        assert!(bend < 0.008 * w, "bend {}", bend / w);
    }
}

#[test]
fn strikes_keep_the_cadence_and_alternate() {
    let config = GaitConfig {
        steps: 40,
        cadence: 2.0,
        ..GaitConfig::default()
    };
    let gait = generate(&config).unwrap();
    let (left, right) = (&gait.strikes[0], &gait.strikes[1]);
    assert_eq!((left.len(), right.len()), (40, 40));
    assert_eq!(left[0], config.lead_in);
    let cycle = (left[39].0 - left[0].0) / 39.0;
    assert!((cycle - 1.0).abs() < 0.03, "cycle {cycle}");
    for (l, r) in left.iter().zip(right) {
        let offset = r.0 - l.0;
        assert!((0.3..0.7).contains(&offset), "offset {offset}");
    }
    let end = gait.track.rows.last().unwrap().time.0;
    assert!((end - gait.toe_offs[1][39].0 - config.tail.0).abs() < 0.003);
    gait.track.validate("gait").unwrap();

    let one = generate(&GaitConfig {
        channels: 1,
        ..config
    })
    .unwrap();
    assert_eq!(one.track.channels[0].name, "left");
    assert_eq!(one.strikes, vec![left.clone()]);
}

#[test]
fn the_seed_decides_the_walk() {
    let config = GaitConfig::default();
    let a = generate(&config).unwrap();
    assert_eq!(a, generate(&config).unwrap());
    let b = generate(&GaitConfig { seed: 2, ..config }).unwrap();
    assert_ne!(a.strikes, b.strikes);
    assert_ne!(a.track, b.track);
}

#[test]
fn generated_tracks_survive_the_file_format() {
    let gait = generate(&GaitConfig::from_spec("steps=2,rate=200").unwrap()).unwrap();
    let back = ForceTrack::from_csv_str(&gait.track.to_csv(), "gait").unwrap();
    assert_eq!(back, gait.track);
    assert!((back.sensor_rate().unwrap() - 200.0).abs() < 1e-6);
}

#[test]
fn specs_parse_and_faults_are_named() {
    let config = GaitConfig::from_spec(
        " steps=12, cadence=1.6,weight=82.5,channels=1,variation=0,rate=1000,seed=9,\
         stance=0.62,lead_in=0,tail=2 ",
    )
    .unwrap();
    assert_eq!(
        config,
        GaitConfig {
            steps: 12,
            cadence: 1.6,
            weight_kg: 82.5,
            channels: 1,
            variation: 0.0,
            sensor_rate: 1000.0,
            seed: 9,
            stance_fraction: 0.62,
            lead_in: Seconds(0.0),
            tail: Seconds(2.0),
        }
    );
    assert_eq!(GaitConfig::from_spec("").unwrap(), GaitConfig::default());

    let fault = |spec: &str| GaitConfig::from_spec(spec).unwrap_err();
    assert!(matches!(fault("steps"), GaitError::Malformed { .. }));
    assert!(matches!(
        fault("speed=3"),
        GaitError::UnknownKey { ref key, ref value } if key == "speed" && value == "3"
    ));
    assert!(matches!(
        fault("steps=1.5"),
        GaitError::BadNumber { ref key, ref value, .. } if key == "steps" && value == "1.5"
    ));
    assert!(matches!(fault("weight=heavy"), GaitError::BadNumber { .. }));
    assert!(matches!(fault("seed=-1"), GaitError::BadNumber { .. }));
    assert!(matches!(
        fault("steps=2,steps=3"),
        GaitError::DuplicateKey { .. }
    ));
    for (spec, key) in [
        ("steps=0", "steps"),
        ("cadence=0.4", "cadence"),
        ("cadence=4.5", "cadence"),
        ("weight=19", "weight"),
        ("weight=301", "weight"),
        ("weight=NaN", "weight"),
        ("channels=3", "channels"),
        ("channels=0", "channels"),
        ("variation=0.31", "variation"),
        ("variation=-0.1", "variation"),
        ("rate=49", "rate"),
        ("rate=10001", "rate"),
        ("stance=0.5", "stance"),
        ("lead_in=-1", "lead_in"),
        ("tail=inf", "tail"),
    ] {
        let e = fault(spec);
        assert!(
            matches!(e, GaitError::OutOfRange { key: k, .. } if k == key),
            "{spec}: {e}"
        );
    }
    assert!(matches!(
        fault("steps=100000000000,rate=10000"),
        GaitError::TooLong { .. }
    ));
    let message = fault("cadence=9").to_string();
    assert!(
        message.contains("cadence") && message.contains('9'),
        "{message}"
    );
}

/// `--help` shows [`SPEC_HELP`]: it names every key, and the defaults it states are the
/// defaults (read back through the spec parser).
#[test]
fn the_spec_help_names_every_key_with_its_default() {
    let d = GaitConfig::default();
    for key in SPEC_KEYS {
        let line = SPEC_HELP
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{key}=")))
            .unwrap_or_else(|| panic!("{key} is not in SPEC_HELP"));
        let default = line
            .split("; default ")
            .nth(1)
            .and_then(|t| t.split([',', ' ']).next())
            .unwrap_or_else(|| panic!("no default in {line}"));
        let given = GaitConfig::from_spec(&format!("{key}={default}")).expect(line);
        assert_eq!(given, d, "{line}");
    }
}
