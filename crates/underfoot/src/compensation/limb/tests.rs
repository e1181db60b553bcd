use super::*;
use crate::units::{Band, SampleRate};

const RATE: SampleRate = SampleRate(48_000);
const BAND: Band = Band::new(40.0, 1024.0);

fn model(p: LimbParams) -> LimbModel {
    LimbModel::new(p, DEFAULT_G2, 1.0).unwrap()
}

#[test]
fn model_limits() {
    let m = model(LimbParams::TABLE1_MEAN);
    assert!((m.response(Hz(1e-3)) - 1.0).norm() < 1e-4);
    assert!((m.response(Hz(1e8)) - DEFAULT_G2).norm() < 1e-5);
    // The numerator over the denominator equals H_l + H_s.
    let f = Hz(321.0);
    let s = jw(f);
    let [a3, a2, a1, a0] = m.numerator();
    let p = m.params;
    let h = (a3 * s * s * s + a2 * s * s + a1 * s + a0)
        / ((1.0 + p.b3_k3 * s) * (s * s + p.b2_m2 * s + p.k2_m2));
    assert!((h - m.response(f)).norm() < 1e-12);
    assert!(m.is_invertible());
    assert!(LimbModel::new(LimbParams::TABLE1_MEAN, 0.0, 1.0).is_err());
    assert!(
        LimbModel::new(
            LimbParams {
                b3_k3: f64::NAN,
                ..LimbParams::TABLE1_MEAN
            },
            DEFAULT_G2,
            1.0
        )
        .is_err()
    );
}

#[test]
fn discretised_limb_matches_model() {
    for (name, p) in LimbParams::TABLE1_SPREAD {
        let m = model(p);
        let sos = m.sos(RATE, p.skin_resonance()).unwrap();
        assert!(sos.is_stable());
        let worst = BAND
            .log_grid(200)
            .iter()
            .map(|&f| {
                (20.0 * (sos.response(RATE.omega(f)).norm() / m.response(f).norm()).log10()).abs()
            })
            .fold(0.0, f64::max);
        eprintln!("{name}: bilinear H_u vs analog, max {worst:.4} dB");
        assert!(worst < 0.02, "{worst}");
    }
}

#[test]
fn compensation_inverts_the_limb_in_band() {
    for (name, p) in LimbParams::TABLE1_SPREAD {
        let m = model(p);
        let zc = m.compensation(RATE, BAND).unwrap();
        assert!(zc.is_stable());
        let grid = BAND.log_grid(256);
        let dev: Vec<f64> = grid
            .iter()
            .map(|&f| {
                let d = zc.response(RATE.omega(f)).norm() * m.response(f).norm();
                20.0 * d.log10()
            })
            .collect();
        let mean = dev.iter().sum::<f64>() / dev.len() as f64;
        let worst = dev.iter().map(|d| (d - mean).abs()).fold(0.0, f64::max);
        let mean_gain = grid
            .iter()
            .map(|&f| 20.0 * zc.response(RATE.omega(f)).norm().log10())
            .sum::<f64>()
            / grid.len() as f64;
        // Up to Nyquist, on a fine log grid.
        let peak = Band::new(1.0, RATE.nyquist().0 - 1.0)
            .log_grid(4000)
            .iter()
            .map(|&f| 20.0 * zc.response(RATE.omega(f)).norm().log10())
            .fold(f64::NEG_INFINITY, f64::max);
        eprintln!(
            "{name}: Z_c vs 1/H_u in band: max {worst:.3} dB; mean gain {mean_gain:.1e} dB; peak to Nyquist {peak:.1} dB"
        );
        assert!(worst < 0.5, "{worst}");
        assert!(mean_gain.abs() < 1e-9);
        assert!(peak < 30.0, "{peak}");
    }
}

#[test]
fn non_hurwitz_limb_is_refused() {
    let m = model(LimbParams {
        b3_k3: 0.02,
        k2_m2: 5e7,
        b2_m2: 50.0,
    });
    assert!(!m.is_invertible());
    assert!(matches!(
        m.compensation(RATE, BAND),
        Err(CompensationError::Unstable { .. })
    ));
    // Its forward model is still a stable filter (the zeros may lie anywhere).
    assert!(m.sos(RATE, Hz(1000.0)).unwrap().is_stable());
    let ok = model(LimbParams::TABLE1_MEAN);
    assert!(ok.compensation(RATE, Band::new(40.0, 30_000.0)).is_err());
}

#[test]
fn noiseless_fit_recovers_the_model_exactly() {
    for (name, p) in LimbParams::TABLE1_SPREAD {
        let m = LimbModel::new(p, DEFAULT_G2, 0.3).unwrap();
        let freqs = BAND.log_grid(128);
        let y: Vec<f64> = freqs
            .iter()
            .map(|&f| 20.0 * m.response(f).norm().log10())
            .collect();
        let fit = fit_limb(&freqs, &y, &LimbFitConfig::default()).unwrap();
        let got = fit.model.params.to_array();
        let want = p.to_array();
        eprintln!(
            "{name}: noiseless fit {got:?}, rms {:.1e} dB, {} iterations ({} over {} starts)",
            fit.rms_error_db, fit.iterations, fit.total_iterations, fit.starts
        );
        for (g, w) in got.iter().zip(want) {
            assert!((g / w - 1.0).abs() < 1e-5, "{g} vs {w}");
        }
        assert!((fit.model.level / 0.3 - 1.0).abs() < 1e-6);
    }
}

#[test]
fn fixed_level_fit() {
    let m = model(LimbParams::TABLE1_MEAN);
    let freqs = BAND.log_grid(64);
    let y: Vec<f64> = freqs
        .iter()
        .map(|&f| 20.0 * m.response(f).norm().log10())
        .collect();
    let cfg = LimbFitConfig {
        fit_level: false,
        ..LimbFitConfig::default()
    };
    let fit = fit_limb(&freqs, &y, &cfg).unwrap();
    assert_eq!(fit.model.level, 1.0);
    for (g, w) in fit.model.params.to_array().iter().zip(m.params.to_array()) {
        assert!((g / w - 1.0).abs() < 1e-6, "{g} vs {w}");
    }
}

// The fits to sweeps of the simulated tile and users are integration tests
// (`tests/library/compensation/limb.rs`): the simulators live above this layer.

#[test]
fn bad_fit_inputs_are_errors() {
    let freqs = BAND.log_grid(10);
    let y = vec![0.0; 10];
    let cfg = LimbFitConfig::default();
    assert!(matches!(
        fit_limb(&[], &[], &cfg),
        Err(CompensationError::TooShort { .. })
    ));
    assert!(matches!(
        fit_limb(&freqs, &y[..9], &cfg),
        Err(CompensationError::Mismatch { .. })
    ));
    let mut bad = y.clone();
    bad[3] = f64::NAN;
    assert!(matches!(
        fit_limb(&freqs, &bad, &cfg),
        Err(CompensationError::NonFinite { index: 3, .. })
    ));
    let mut f0 = freqs.clone();
    f0[0] = Hz(0.0);
    assert!(fit_limb(&f0, &y, &cfg).is_err());
    let swapped = LimbFitConfig {
        bounds: LimbBounds {
            lower: LimbBounds::default().upper,
            upper: LimbBounds::default().lower,
        },
        ..cfg.clone()
    };
    assert!(fit_limb(&freqs, &y, &swapped).is_err());
    // A flat response is fitted, not refused (the leg term is then pushed to a bound).
    assert!(fit_limb(&freqs, &y, &cfg).is_ok());
}
