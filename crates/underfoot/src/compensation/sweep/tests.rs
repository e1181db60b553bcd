use super::*;
use crate::compensation::CompensationError;
use crate::units::{Band, Decibels, SampleRate, Seconds};

const RATE: SampleRate = SampleRate(48_000);

struct Wire;
impl Device for Wire {
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        Ok(excitation.to_vec())
    }
}

// The measurements of the simulated tile against its oracle are integration tests
// (`tests/library/compensation/sweep.rs`): the simulators live above this layer.

#[test]
fn flatness() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let flat = measure(&mut Wire, &sweep).unwrap();
    let dev = flat.deviation_from_flat_db().0;
    let level = flat.magnitude_db()[0].0;
    eprintln!("wire: deviation {dev:.2e} dB, level {level:.2e} dB");
    assert!(dev < 0.05, "{dev}");
    assert!(level.abs() < 0.05);
}

#[test]
fn bad_recordings_are_errors() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let n = sweep.excitation().len();
    assert!(matches!(
        sweep.response(&[]),
        Err(CompensationError::TooShort { len: 0, .. })
    ));
    assert!(matches!(
        sweep.response(&vec![0.0; n - 1]),
        Err(CompensationError::TooShort { .. })
    ));
    let mut rec = sweep.excitation().to_vec();
    rec[1234] = f64::NAN;
    assert_eq!(
        sweep.response(&rec),
        Err(CompensationError::NonFinite {
            what: "recording",
            index: 1234
        })
    );
    rec[1234] = f64::INFINITY;
    assert!(sweep.response(&rec).is_err());
    // Longer is fine; silence gives a zero response, not a panic.
    let fr = sweep.response(&vec![0.0; n + 100]).unwrap();
    assert!(fr.response.iter().all(|h| h.norm() == 0.0));
    assert!(fr.deviation_from_flat_db().0.is_finite());
}

#[test]
fn bad_configs_are_errors() {
    let ok = SweepConfig::new(RATE);
    let bad = [
        SweepConfig {
            rate: SampleRate(0),
            ..ok
        },
        SweepConfig {
            band: Band::new(0.0, 1024.0),
            ..ok
        },
        SweepConfig {
            band: Band::new(500.0, 100.0),
            ..ok
        },
        SweepConfig {
            band: Band::new(40.0, 23_000.0),
            ..ok
        },
        SweepConfig {
            band: Band::new(f64::NAN, 1024.0),
            ..ok
        },
        SweepConfig {
            duration: Seconds(0.0),
            ..ok
        },
        SweepConfig {
            duration: Seconds(0.05),
            ..ok
        },
        SweepConfig {
            duration: Seconds(f64::INFINITY),
            ..ok
        },
        SweepConfig {
            fade: Seconds(1.5),
            ..ok
        },
        SweepConfig {
            fade: Seconds(-0.1),
            ..ok
        },
        SweepConfig { repeats: 0, ..ok },
        SweepConfig {
            gap: Seconds(0.1),
            ..ok
        },
        SweepConfig {
            window: Seconds(0.0),
            ..ok
        },
        SweepConfig {
            level: Decibels(3.0),
            ..ok
        },
        SweepConfig { points: 1, ..ok },
    ];
    for cfg in bad {
        assert!(
            matches!(
                Sweep::new(cfg),
                Err(CompensationError::InvalidParameter { .. })
            ),
            "{cfg:?}"
        );
    }
}

#[test]
fn excitation_layout() {
    let cfg = SweepConfig::new(RATE);
    let sweep = Sweep::new(cfg).unwrap();
    let n = RATE.samples_in(cfg.duration);
    let g = RATE.samples_in(cfg.gap);
    assert_eq!(sweep.excitation().len(), 3 * (n + g));
    assert!(sweep.excitation()[n..n + g].iter().all(|&v| v == 0.0));
    let peak = sweep.single().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!((peak - cfg.level.to_amplitude()).abs() < 1e-3);
    assert_eq!(sweep.single()[0], 0.0);
}
