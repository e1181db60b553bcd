//! Tests of the calibration: fits recover known curves, bad data and files are refused
//! by name, the run-time apply clamps and counts.

use std::path::Path;

use proptest::prelude::*;

use super::curve::power;
use super::fit::min_max;
use super::*;
use crate::document::{self, DocumentError};

/// A seeded normal generator (splitmix64 and Box-Muller), so the tests are repeatable
/// without a random-number crate.
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

const A: f64 = 0.0119;
const B: f64 = 1.4;
const R0: f64 = 200.0;

fn truth(r: f64) -> f64 {
    power(A, B, R0, r)
}

/// A lab-scale session: loads 0 to 1000 N, a 12-bit reading from the true curve, the
/// scale's error normal with `sigma` newtons.
fn session(n: usize, sigma: f64, seed: u64) -> Vec<(f64, Newtons)> {
    let mut noise = Noise(seed);
    (0..n)
        .map(|i| {
            let load = 1000.0 * i as f64 / (n - 1) as f64;
            let raw = R0 + (load / A).powf(1.0 / B);
            (raw.round(), Newtons(load + sigma * noise.normal()))
        })
        .collect()
}

fn check_recovery(curve: &SensorCurve, samples: &[(f64, Newtons)]) -> f64 {
    let (lo, hi) = min_max(&samples.iter().map(|s| s.0).collect::<Vec<_>>());
    let mut worst = 0.0_f64;
    for k in 0..=200 {
        let r = lo + (hi - lo) * f64::from(k) / 200.0;
        let (f, _) = curve.force(r).unwrap();
        worst = worst.max((f.0 - truth(r)).abs());
    }
    worst
}

#[test]
fn power_law_recovers_a_known_curve() {
    for seed in 1..=5 {
        let samples = session(120, 3.0, seed);
        let (curve, report) = fit_sensor("heel", &samples, CurveKind::Power).unwrap();
        let CurveModel::Power { a, b, r0 } = curve.model else {
            panic!("not a power law");
        };
        assert!((b - B).abs() / B < 0.03, "seed {seed}: b {b}");
        // r0 is weakly determined when b > 1 (the curve leaves zero tangentially), so
        // it is judged against the span of readings.
        assert!((r0 - R0).abs() / 3300.0 < 0.02, "seed {seed}: r0 {r0}");
        assert!((a - A).abs() / A < 0.15, "seed {seed}: a {a}");
        let worst = check_recovery(&curve, &samples);
        eprintln!(
            "seed {seed}: a {:+.2}%, b {:+.2}%, r0 {r0:.1} (true {R0}), worst {worst:.2} N, \
             rms {:.2} N, max {:.2} N",
            100.0 * (a / A - 1.0),
            100.0 * (b / B - 1.0),
            report.rms_error.0,
            report.max_error.0
        );
        assert!(worst < 10.0, "seed {seed}: worst {worst} N");
        assert!(report.rms_error.0 < 4.0, "{report:?}");
        assert_eq!(report.points, 120);
    }
}

#[test]
fn piecewise_recovers_a_known_curve() {
    let samples = session(400, 3.0, 7);
    let (curve, report) = fit_sensor("toe", &samples, CurveKind::Piecewise).unwrap();
    curve.validate("test").unwrap();
    let worst = check_recovery(&curve, &samples);
    eprintln!("piecewise: worst {worst:.2} N, {report:?}");
    assert!(worst < 10.0, "worst {worst} N");
    assert!(report.rms_error.0 < 6.0, "{report:?}");
}

#[test]
fn robust_fit_shrugs_off_a_few_bad_loads() {
    let mut samples = session(120, 3.0, 11);
    for k in [10, 50, 90] {
        samples[k].1 = Newtons(samples[k].1.0 + 300.0);
    }
    let (curve, report) = fit_sensor("heel", &samples, CurveKind::Power).unwrap();
    assert!(report.downweighted >= 3, "{report:?}");
    assert!(check_recovery(&curve, &samples) < 15.0);
}

#[test]
fn bad_data_is_refused_by_name() {
    let good = session(40, 1.0, 3);
    let e = fit_sensor("heel", &good[..3], CurveKind::Power).unwrap_err();
    assert!(
        matches!(e, SensorCalibrationError::TooFewPoints { found: 3, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("heel"));
    let e = fit_sensor("heel", &good[..10], CurveKind::Piecewise).unwrap_err();
    assert!(
        matches!(e, SensorCalibrationError::TooFewPoints { needed: 12, .. }),
        "{e}"
    );

    let mut nan = good.clone();
    nan[4].0 = f64::NAN;
    assert!(matches!(
        fit_sensor("heel", &nan, CurveKind::Power),
        Err(SensorCalibrationError::NonFinite { index: 4, .. })
    ));

    let inverted: Vec<_> = good.iter().map(|&(r, l)| (-r, l)).collect();
    let e = fit_sensor("toe", &inverted, CurveKind::Power).unwrap_err();
    assert!(
        matches!(e, SensorCalibrationError::NonMonotone { .. }),
        "{e}"
    );
    assert!(e.to_string().contains("toe"));

    let two_loads: Vec<_> = (0..10)
        .map(|i| (f64::from(i), Newtons(if i < 5 { 0.0 } else { 50.0 })))
        .collect();
    assert!(matches!(
        fit_sensor("x", &two_loads, CurveKind::Power),
        Err(SensorCalibrationError::NarrowRange { .. })
    ));
    let tiny: Vec<_> = (0..10)
        .map(|i| (f64::from(i), Newtons(0.01 * f64::from(i))))
        .collect();
    assert!(matches!(
        fit_sensor("x", &tiny, CurveKind::Power),
        Err(SensorCalibrationError::NarrowRange { .. })
    ));
    let flat: Vec<_> = (0..10).map(|i| (5.0, Newtons(f64::from(i)))).collect();
    assert!(matches!(
        fit_sensor("x", &flat, CurveKind::Power),
        Err(SensorCalibrationError::NarrowRange { .. })
    ));
}

#[test]
fn apply_clamps_and_counts() {
    let samples = session(60, 2.0, 5);
    let (curve, _) = fit_sensor("heel", &samples, CurveKind::Power).unwrap();
    let cal = SensorCalibration {
        sensors: vec![curve.clone(), curve],
    };
    let top = cal.sensors[0].force(cal.sensors[0].raw_range[1]).unwrap().0;
    let mut out = [9.0_f32; 3];
    let stats = cal.apply(&[1e9, f32::NAN], &mut out);
    assert!((f64::from(out[0]) - top.0).abs() < 1e-3 * top.0);
    assert_eq!(out[1], 0.0);
    assert_eq!(out[2], 0.0);
    assert_eq!(
        stats,
        ApplyStats {
            non_finite: 1,
            above_range: 1,
            below_range: 0,
            missing: 1
        }
    );
    let stats = cal.apply(&[-1e9, 0.0, 7.0], &mut out[..2]);
    assert_eq!(stats.below_range, 2);

    let huge = SensorCalibration {
        sensors: vec![SensorCurve {
            name: "edited".to_owned(),
            model: CurveModel::Power {
                a: 1e300,
                b: 1.0,
                r0: 0.0,
            },
            raw_range: [0.0, 10.0],
            drift: 0.0,
        }],
    };
    huge.validate("edited.json").unwrap();
    let stats = huge.apply(&[5.0], &mut out[..1]);
    assert_eq!((out[0], stats.non_finite), (0.0, 1));
    assert!(out[0] >= 0.0 && out[0] < 1.0);
}

#[test]
fn tare_removes_an_offset() {
    let samples = session(80, 2.0, 9);
    for kind in [CurveKind::Power, CurveKind::Piecewise] {
        let (curve, _) = fit_sensor("heel", &samples, kind).unwrap();
        let mut cal = SensorCalibration {
            sensors: vec![curve],
        };
        let probe = R0 + (500.0 / A).powf(1.0 / B);
        let before = cal.sensors[0].force(probe).unwrap().0.0;
        let rest_before = cal.sensors[0].force(R0).unwrap().0.0;
        // The sensor drifted up by 150 counts.
        let drift = 150.0;
        let rest: Vec<f32> = (0..20)
            .map(|i| (R0 + drift) as f32 + (i % 3) as f32 - 1.0)
            .collect();
        let removed = cal.tare(&rest).unwrap()[0];
        let after = cal.sensors[0].force(probe + drift).unwrap().0.0;
        let at_rest = cal.sensors[0].force(R0 + drift).unwrap().0.0;
        assert!((after - before).abs() < 10.0, "{kind}: {before} -> {after}");
        assert!(
            (at_rest - rest_before).abs() < 5.0,
            "{kind}: rest {at_rest}"
        );
        assert!((removed - drift).abs() < 30.0, "{kind}: removed {removed}");
    }
    let mut cal = SensorCalibration::default();
    assert!(cal.tare(&[1.0]).is_err());
}

#[test]
fn file_round_trip_and_refusals() {
    let session = vec![
        SensorSamples {
            name: "left.heel".to_owned(),
            samples: session(60, 2.0, 1),
        },
        SensorSamples {
            name: "left.toe".to_owned(),
            samples: session(60, 2.0, 2),
        },
    ];
    let (mut cal, reports) = SensorCalibration::fit(&session, CurveKind::Power).unwrap();
    assert_eq!(reports.len(), 2);
    cal.sensors[1] = fit_sensor("left.toe", &session[1].samples, CurveKind::Piecewise)
        .unwrap()
        .0;
    cal.sensors[0].drift = 12.5;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sensors.json");
    cal.save(&path).unwrap();
    assert_eq!(SensorCalibration::load(&path).unwrap(), cal);

    let text = cal.to_json().unwrap();
    assert!(text.starts_with("{\n  \"format\": \"underfoot.sensor-calibration/1\""));
    let v2 = text.replace("sensor-calibration/1", "sensor-calibration/2");
    let e = SensorCalibration::from_json_str(&v2, "v2.json").unwrap_err();
    assert!(
        matches!(
            e,
            SensorCalibrationError::Document(DocumentError::Version { .. })
        ),
        "{e}"
    );
    assert!(e.to_string().contains("v2.json"));
    let other = text.replace(FILE_KIND, "underfoot-library");
    assert!(matches!(
        SensorCalibration::from_json_str(&other, "x"),
        Err(SensorCalibrationError::Document(
            DocumentError::WrongKind { .. }
        ))
    ));
    assert!(matches!(
        SensorCalibration::from_json_str("{", "x"),
        Err(SensorCalibrationError::Document(DocumentError::Json { .. }))
    ));
    let mut bad = cal.clone();
    bad.sensors[0].model = CurveModel::Power {
        a: 1.0,
        b: 9.0,
        r0: 0.0,
    };
    let invalid_curve = |e: &SensorCalibrationError| {
        matches!(e, SensorCalibrationError::Document(d)
            if d.reason().is_some_and(|r| r.is::<CurveError>()))
    };
    let e = bad.save(&path).unwrap_err();
    assert!(invalid_curve(&e), "{e}");
    assert!(matches!(
        bad.validate("x"),
        Err(SensorCalibrationError::InvalidCurve { .. })
    ));
    // The text of the bad calibration, written without the check a save makes.
    let bad_text = format!(
        "{{\"format\": \"{}\", \"sensors\": {}}}",
        document::tag::<SensorCalibration>(),
        serde_json::to_string(&bad.sensors).unwrap()
    );
    let e = SensorCalibration::from_json_str(&bad_text, "x").unwrap_err();
    assert!(invalid_curve(&e), "{e}");
    // The refused save left the good file alone.
    assert_eq!(SensorCalibration::load(&path).unwrap(), cal);
}

#[test]
fn files_written_before_the_format_tag_still_load() {
    let legacy = format!(
        "{{\"kind\": \"{LEGACY_FILE_KIND}\", \"version\": 1,\n \"sensors\": [{{\"name\": \"heel\", \
         \"model\": {{\"power\": {{\"a\": 0.012, \"b\": 1.4, \"r0\": 200.0}}}},\n \
         \"raw_range\": [190.0, 3500.0], \"drift\": 0.0}}]}}\n"
    );
    let cal = SensorCalibration::from_json_str(&legacy, "old.json").unwrap();
    assert_eq!(cal.sensors[0].name, "heel");
    assert_eq!(cal.sensors[0].raw_range, [190.0, 3500.0]);
    // Written back with the one header, and read back the same.
    let text = cal.to_json().unwrap();
    assert!(!text.contains("\"kind\""), "{text}");
    assert_eq!(
        SensorCalibration::from_json_str(&text, "new.json").unwrap(),
        cal
    );
    let v2 = legacy.replace("\"version\": 1", "\"version\": 2");
    assert!(matches!(
        SensorCalibration::from_json_str(&v2, "v2.json"),
        Err(SensorCalibrationError::Document(
            DocumentError::Version { .. }
        ))
    ));
    // A misspelt key is refused, as it was before the format tag.
    let unknown = legacy.replace("\"version\": 1,", "\"version\": 1, \"sensros\": [],");
    assert!(matches!(
        SensorCalibration::from_json_str(&unknown, "typo.json"),
        Err(SensorCalibrationError::Document(DocumentError::Json { .. }))
    ));
}

#[test]
fn session_csv_reads_and_refuses() {
    let text =
        "\u{feff}# scale session\nsensor,raw,load_n\nheel,200,0\n\ntoe, 210 ,0\nheel,900,250.5\n";
    let s = session_from_csv_str(text, "cal.csv").unwrap();
    assert_eq!(s.len(), 2);
    assert_eq!(s[0].name, "heel");
    assert_eq!(
        s[0].samples,
        vec![(200.0, Newtons(0.0)), (900.0, Newtons(250.5))]
    );
    assert_eq!(s[1].samples, vec![(210.0, Newtons(0.0))]);

    let err = |t: &str| session_from_csv_str(t, "cal.csv").unwrap_err();
    assert!(matches!(err(""), SensorCalibrationError::Empty { .. }));
    assert!(matches!(
        err("sensor,raw,load_n\n"),
        SensorCalibrationError::Empty { .. }
    ));
    assert!(matches!(
        err("# c\nsensor,raw\n"),
        SensorCalibrationError::BadHeader { line: 2, .. }
    ));
    assert!(matches!(
        err("sensor,raw,load_n\nheel,1\n"),
        SensorCalibrationError::FieldCount {
            line: 2,
            found: 2,
            ..
        }
    ));
    let e = err("sensor,raw,load_n\nheel,1,0\nheel,x,5\n");
    assert!(
        matches!(
            e,
            SensorCalibrationError::BadValue {
                line: 3,
                column: "raw",
                ..
            }
        ),
        "{e}"
    );
    let message = e.to_string();
    assert!(
        message.contains("cal.csv") && message.contains("line 3"),
        "{message}"
    );
    assert!(matches!(
        err("sensor,raw,load_n\nheel,1,inf\n"),
        SensorCalibrationError::BadValue {
            column: "load_n",
            ..
        }
    ));
    assert!(matches!(
        err("sensor,raw,load_n\nhe el,1,2\n"),
        SensorCalibrationError::BadValue {
            column: "sensor",
            ..
        }
    ));
    assert!(matches!(
        read_session(Path::new("/nonexistent/cal.csv")),
        Err(SensorCalibrationError::File(_))
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn fitting_and_applying_never_panic(
        points in prop::collection::vec((-1e6f64..1e6, -1e4f64..1e4), 0..60),
        piecewise in any::<bool>(),
        probes in prop::collection::vec(any::<f32>(), 0..8),
    ) {
        // Half the cases trend upwards, so that they reach the solver rather than
        // stop at the monotonicity check.
        let trend = if piecewise == (points.len() % 2 == 0) { 0.01 } else { 0.0 };
        let samples: Vec<(f64, Newtons)> = points
            .iter()
            .map(|&(r, l)| (r, Newtons(l * (1.0 - 99.0 * trend) + trend * r)))
            .collect();
        let kind = if piecewise { CurveKind::Piecewise } else { CurveKind::Power };
        if let Ok((curve, report)) = fit_sensor("any", &samples, kind) {
            prop_assert!(report.rms_error.0.is_finite());
            let cal = SensorCalibration { sensors: vec![curve.clone(), curve] };
            let mut out = [0.0_f32; 4];
            cal.apply(&probes, &mut out);
            prop_assert!(out.iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn unvalidated_curves_never_panic(
        knots in prop::collection::vec(prop::array::uniform2(any::<f64>()), 0..6),
        range in prop::array::uniform2(any::<f64>()),
        probes in prop::collection::vec(any::<f32>(), 0..8),
    ) {
        let cal = SensorCalibration {
            sensors: vec![SensorCurve {
                name: "raw".to_owned(),
                model: CurveModel::Piecewise { knots },
                raw_range: range,
                drift: 0.0,
            }],
        };
        let mut out = [0.0_f32; 2];
        cal.apply(&probes, &mut out);
        prop_assert!(out.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn piecewise_is_monotone_for_any_input(
        points in prop::collection::vec((0.0f64..4096.0, -20.0f64..1000.0), 12..200),
        probes in prop::collection::vec(-1e6f64..1e6, 1..50),
    ) {
        // Give the data an upward trend so that it passes the monotonicity check;
        // the noise on top is arbitrary.
        let samples: Vec<(f64, Newtons)> = points
            .iter()
            .map(|&(r, l)| (r, Newtons(l * 0.2 + r * 0.5)))
            .collect();
        let Ok((curve, _)) = fit_sensor("p", &samples, CurveKind::Piecewise) else {
            return Ok(());
        };
        curve.validate("p").unwrap();
        let mut probes = probes;
        probes.sort_by(f64::total_cmp);
        let mut previous = f64::NEG_INFINITY;
        for r in probes {
            let f = curve.force(r).unwrap().0.0;
            prop_assert!(f.is_finite());
            prop_assert!(f >= previous, "{} after {}", f, previous);
            previous = f;
        }
    }
}
