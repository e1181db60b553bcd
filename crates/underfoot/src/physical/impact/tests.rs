use super::*;
use crate::physical::SurfaceMode;
use crate::units::Hz;

const RATE: SampleRate = SampleRate(48_000);

fn params(alpha: f64, stiffness: f64, damping: f64) -> ImpactParams {
    ImpactParams {
        mass: 0.5,
        stiffness,
        alpha,
        damping,
        velocity: 1.0,
    }
}

/// `∫_0^1 du / sqrt(1 - u^(α+1))`, with `u = 1 - t^2` to remove the singularity at 1.
fn contact_integral(alpha: f64) -> f64 {
    let f = |t: f64| {
        if t == 0.0 {
            2.0 / (alpha + 1.0).sqrt()
        } else {
            2.0 * t / (1.0 - (1.0 - t * t).powf(alpha + 1.0)).sqrt()
        }
    };
    let n = 10_000;
    let h = 1.0 / n as f64;
    let odd: f64 = (1..n).step_by(2).map(|i| f(i as f64 * h)).sum();
    let even: f64 = (2..n).step_by(2).map(|i| f(i as f64 * h)).sum();
    h / 3.0 * (f(0.0) + 4.0 * odd + 2.0 * even + f(1.0))
}

/// Runs until the hammer has left, returning the energy after every sample.
fn run_strike(impact: &mut Impact) -> Vec<f64> {
    let mut energy = vec![impact.contact_energy()];
    let mut one = [0.0f32];
    for _ in 0..RATE.0 {
        impact.process(&mut one);
        energy.push(impact.contact_energy());
        if impact.contact_time().is_some() && impact.x < 0.0 {
            break;
        }
    }
    energy
}

#[test]
fn contact_integral_matches_known_values() {
    assert!((contact_integral(1.0) - std::f64::consts::FRAC_PI_2).abs() < 1e-6);
    assert!((contact_integral(1.5) - 1.4716).abs() < 1e-4);
}

#[test]
fn undamped_rigid_strike_follows_hertz_theory() {
    for (alpha, k) in [(1.5, 1e7), (1.0, 1e6)] {
        let p = params(alpha, k, 0.0);
        let mut impact = Impact::new(p, Surface::Rigid, RATE).unwrap();
        let energy = run_strike(&mut impact);
        let v = p.velocity;
        let x_max = ((alpha + 1.0) * p.mass * v * v / (2.0 * k)).powf(1.0 / (alpha + 1.0));
        let peak = k * x_max.powf(alpha);
        let duration = 2.0 * x_max / v * contact_integral(alpha);
        let t = impact.contact_time().unwrap().0;
        let f = impact.peak_force().0;
        let rebound = -impact.hammer_velocity() / v;
        let drift = energy
            .iter()
            .map(|e| (e / energy[0] - 1.0).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "alpha {alpha}: contact {:.4} ms ({} samples) err {:.2e}, peak {f:.1} N err {:.2e}, \
             rebound/impact {rebound:.9}, energy drift {drift:.1e}",
            t * 1e3,
            (t * RATE.hz()).round(),
            t / duration - 1.0,
            f / peak - 1.0
        );
        assert!(
            (t / duration - 1.0).abs() < 0.01,
            "alpha {alpha}: {t} vs {duration}"
        );
        assert!(
            (f / peak - 1.0).abs() < 0.01,
            "alpha {alpha}: {f} vs {peak}"
        );
        assert!(
            (rebound - 1.0).abs() < 0.01,
            "alpha {alpha}: rebound {rebound}"
        );
        assert!(drift < 1e-6, "alpha {alpha}: energy drift {drift}");
        if alpha == 1.0 {
            let linear = std::f64::consts::PI * (p.mass / k).sqrt();
            assert!((t / linear - 1.0).abs() < 0.01);
        }
    }
}

#[test]
fn damped_strike_loses_energy_every_sample_and_follows_hunt_crossley() {
    let k = 1e7;
    let mut last = f64::INFINITY;
    for loss in [0.005, 0.01, 0.03, 0.1, 0.3] {
        // (2/3) lambda v / k = loss
        let lambda = 1.5 * loss * k;
        for alpha in [1.0, 1.5] {
            let p = params(alpha, k, lambda);
            let mut impact = Impact::new(p, Surface::Rigid, RATE).unwrap();
            let energy = run_strike(&mut impact);
            for w in energy.windows(2) {
                assert!(
                    w[1] <= w[0] * (1.0 + 1e-12),
                    "energy grew: {} -> {}",
                    w[0],
                    w[1]
                );
            }
            let e = -impact.hammer_velocity() / p.velocity;
            let predicted = 1.0 - loss;
            eprintln!(
                "alpha {alpha}, (2/3) lambda v/k = {loss}: e = {e:.5}, 1 - (2/3) lambda v / k = {predicted:.5}"
            );
            assert!(e > 0.0 && e < 1.0);
            if loss <= 0.03 {
                // First-order theory: the error is second order in the loss.
                assert!(
                    (e - predicted).abs() < 0.1 * loss,
                    "alpha {alpha}: e {e} vs {predicted}"
                );
            }
            if alpha == 1.5 {
                assert!(e < last, "restitution must fall as damping grows");
                last = e;
            }
        }
    }
}

#[test]
fn a_new_strike_repeats_the_first() {
    let mut impact = Impact::new(params(1.5, 1e7, 0.0), Surface::Rigid, RATE).unwrap();
    let mut buffer = vec![0.0f32; 4800];
    impact.process(&mut buffer);
    let (t1, f1) = (impact.contact_time().unwrap(), impact.peak_force());
    impact.strike(1.0).unwrap();
    assert!(impact.contact_time().is_none());
    impact.process(&mut buffer);
    assert_eq!(impact.contact_time().unwrap(), t1);
    assert_eq!(impact.peak_force(), f1);
    // A rigid surface's output is the contact force.
    let max = buffer.iter().fold(0.0f32, |m, v| m.max(*v));
    assert!((f64::from(max) / f1.0 - 1.0).abs() < 1e-6);
}

#[test]
fn a_resonant_surface_rings_and_takes_energy() {
    let modes = [
        SurfaceMode {
            frequency: Hz(80.0),
            decay: Seconds(0.1),
            gain: 2e-3,
        },
        SurfaceMode {
            frequency: Hz(300.0),
            decay: Seconds(0.04),
            gain: 1e-3,
        },
        SurfaceMode {
            frequency: Hz(900.0),
            decay: Seconds(0.02),
            gain: 5e-4,
        },
    ];
    let bank = ResonatorBank::new(&modes, RATE).unwrap();
    let p = params(1.5, 1e7, 0.0);
    let mut impact = Impact::new(p, Surface::Resonant(bank), RATE).unwrap();
    let mut out = vec![0.0f32; 9600];
    impact.process(&mut out);
    assert!(out.iter().all(|v| v.is_finite()));
    let peak = out.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(peak > 0.0);
    // The surface keeps some of the energy: the hammer leaves slower than it came.
    let e = -impact.hammer_velocity() / p.velocity;
    eprintln!("resonant surface: rebound {e:.4}, peak surface velocity {peak:.4} m/s");
    assert!(e < 1.0);
    // It is still ringing after the hammer has gone, and decays.
    let tail = |s: &[f32]| s.iter().map(|v| v * v).sum::<f32>();
    assert!(tail(&out[4800..7200]) > 0.0);
    assert!(tail(&out[7200..]) < tail(&out[4800..7200]));
}

#[test]
fn a_retuned_impact_strikes_like_one_built_retuned() {
    let modes = [
        SurfaceMode {
            frequency: Hz(120.0),
            decay: Seconds(0.1),
            gain: 2e-3,
        },
        SurfaceMode {
            frequency: Hz(700.0),
            decay: Seconds(0.03),
            gain: 1e-3,
        },
    ];
    let scale = 0.8;
    let scaled = modes.map(|m| SurfaceMode {
        frequency: Hz(m.frequency.0 * scale),
        ..m
    });
    let p = params(1.5, 1e7, 1e5);
    let bank = |m: &[SurfaceMode]| Surface::Resonant(ResonatorBank::new(m, RATE).unwrap());
    let mut retuned = Impact::new(p, bank(&modes), RATE).unwrap();
    retuned.reset();
    retuned.retune(scale).unwrap();
    retuned.strike(p.velocity).unwrap();
    let mut fresh = Impact::new(p, bank(&scaled), RATE).unwrap();
    assert!((retuned.compliance / fresh.compliance - 1.0).abs() < 1e-12);
    let (mut a, mut b) = (vec![0.0f32; 4800], vec![0.0f32; 4800]);
    retuned.process(&mut a);
    fresh.process(&mut b);
    let peak = b.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let err = a
        .iter()
        .zip(&b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
    assert!(err < 1e-5 * peak, "{err} of {peak}");
    assert!(!retuned.is_striking());
    // A rigid surface has nothing to retune but still checks the scale.
    let mut rigid = Impact::new(p, Surface::Rigid, RATE).unwrap();
    assert!(rigid.retune(2.0).is_ok());
    assert!(rigid.retune(f64::NAN).is_err());
    assert!(rigid.surface().is_none());
}

#[test]
fn bad_parameters_are_errors() {
    let good = params(1.5, 1e7, 0.0);
    let bad = [
        ImpactParams { mass: 0.0, ..good },
        ImpactParams {
            stiffness: f64::NAN,
            ..good
        },
        ImpactParams { alpha: 0.5, ..good },
        ImpactParams {
            damping: -1.0,
            ..good
        },
        ImpactParams {
            velocity: f64::INFINITY,
            ..good
        },
    ];
    for p in bad {
        assert!(matches!(
            Impact::new(p, Surface::Rigid, RATE),
            Err(PhysicalError::InvalidParameter { .. })
        ));
    }
    let mut impact = Impact::new(good, Surface::Rigid, RATE).unwrap();
    assert!(impact.strike(-1.0).is_err());
    let mode = |gain| SurfaceMode {
        frequency: Hz(100.0),
        decay: Seconds(0.1),
        gain,
    };
    let other = ResonatorBank::new(&[mode(1.0)], SampleRate(8000)).unwrap();
    assert!(matches!(
        Impact::new(good, Surface::Resonant(other), RATE),
        Err(PhysicalError::RateMismatch { .. })
    ));
}

#[test]
fn a_signed_gain_changes_what_is_felt_not_the_contact() {
    // The contact sees the driving-point gains |g|; a negative gain only flips that
    // mode at the point felt.
    let params = ImpactParams {
        mass: 0.05,
        stiffness: 1e6,
        alpha: 1.5,
        damping: 0.0,
        velocity: 0.5,
    };
    let mode = |f: f64, gain: f64| SurfaceMode {
        frequency: Hz(f),
        decay: Seconds(0.05),
        gain,
    };
    let run = |g2: f64| {
        let bank = ResonatorBank::new(&[mode(100.0, 1e-3), mode(300.0, g2)], RATE).unwrap();
        let mut impact = Impact::new(params, Surface::Resonant(bank), RATE).unwrap();
        let mut out = vec![0.0f32; 4800];
        impact.process(&mut out);
        (out, impact.peak_force(), impact.contact_time())
    };
    let (plus, f_plus, t_plus) = run(5e-4);
    let (minus, f_minus, t_minus) = run(-5e-4);
    assert_eq!(f_plus, f_minus);
    assert_eq!(t_plus, t_minus);
    assert!(
        plus.iter()
            .zip(&minus)
            .any(|(p, m)| (p - m).abs() > 1e-3 * p.abs())
    );
}
