use super::*;
use crate::compensation::equalizer::EqualizerConfig;
use crate::units::{Newtons, SampleRate, Seconds};

const RATE: SampleRate = SampleRate(48_000);

// The adapter on the loaded simulated tile (convergence, block sizes, trust, non-finite
// input) is tested in `tests/library/compensation/adapt.rs`: the simulators live above
// this layer.

fn flat() -> SpectralWeights {
    SpectralWeights::flat(EqualizerConfig::default(), RATE).unwrap()
}

#[test]
fn bad_configs_are_rejected() {
    let ok = AdaptConfig::default();
    let bad = [
        AdaptConfig {
            frame: Some(1000),
            ..ok
        },
        AdaptConfig {
            frame: Some(32),
            ..ok
        },
        AdaptConfig {
            memory: Seconds(0.0),
            ..ok
        },
        AdaptConfig {
            interval: Seconds(f64::NAN),
            ..ok
        },
        AdaptConfig {
            min_frames: 1,
            ..ok
        },
        AdaptConfig { step: 0.0, ..ok },
        AdaptConfig { step: 1.5, ..ok },
        AdaptConfig {
            max_change: Decibels(0.0),
            ..ok
        },
        AdaptConfig {
            coherence: 0.0,
            ..ok
        },
        AdaptConfig {
            coherence: 1.1,
            ..ok
        },
        AdaptConfig {
            load_threshold: Newtons(-1.0),
            ..ok
        },
        AdaptConfig {
            min_drive: Decibels(3.0),
            ..ok
        },
    ];
    for cfg in bad {
        assert!(
            matches!(
                Adapter::new(&flat(), cfg),
                Err(CompensationError::InvalidParameter { .. })
            ),
            "{cfg:?}"
        );
    }
    let mut w = flat();
    w.gains_db[100] = f64::NAN;
    assert!(matches!(
        Adapter::new(&w, ok),
        Err(CompensationError::NonFinite { .. })
    ));
    assert!(Adapter::new(&flat(), ok).is_ok());
    // It is built on the control thread and moved to the audio thread.
    fn send<T: Send>() {}
    send::<Adapter>();
}

#[test]
fn balance_keeps_the_sum_and_the_bounds() {
    let mut v = vec![3.0, -1.0, 0.2, 0.0, -0.4];
    let lo = vec![-0.5, -0.5, -0.5, 0.0, -0.5];
    let hi = vec![0.5, 0.5, 0.5, 0.0, 0.1];
    balance(&mut v, &lo, &hi);
    assert!(v.iter().sum::<f64>().abs() < 1e-9, "{v:?}");
    for ((x, l), h) in v.iter().zip(&lo).zip(&hi) {
        assert!(x >= l && x <= h);
    }
    assert_eq!(v[3], 0.0);
}
