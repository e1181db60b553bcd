use super::*;
use crate::units::{Hz, Seconds};
use nalgebra::{DMatrix, DVector};

thread_local! {
    /// Set by a test to run the loops' baseline build even where AVX is available.
    pub(super) static BASELINE_ONLY: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// The AVX build of the free loops (where the machine has it) gives the baseline's
/// output bit for bit, for any number of modes and any block size.
#[test]
fn the_vector_builds_agree_bit_for_bit() {
    let rate = SampleRate(48_000);
    for count in [1, 3, 4, 5, 16, 31] {
        let modes: Vec<SurfaceMode> = (0..count)
            .map(|k| SurfaceMode {
                frequency: Hz(60.0 * 1.15f64.powi(k)),
                decay: Seconds(8.0 / (60.0 * 1.15f64.powi(k))),
                gain: if k % 3 == 1 { -1e-3 } else { 1e-3 } / (1.0 + f64::from(k)),
            })
            .collect();
        let run = |baseline: bool| {
            BASELINE_ONLY.with(|b| b.set(baseline));
            let mut bank = ResonatorBank::new(&modes, rate).unwrap();
            let mut out = vec![0.0f32; 700];
            let mut steps = Vec::new();
            for (n, block) in out.chunks_mut(77).enumerate() {
                bank.add_delayed_impulse(0.01 * n as f64);
                steps.push(bank.advance_free());
                bank.add_free_velocity(block);
            }
            BASELINE_ONLY.with(|b| b.set(false));
            (out, steps, bank.state())
        };
        assert_eq!(run(true), run(false), "{count} modes");
    }
}

fn three_modes() -> [SurfaceMode; 3] {
    [
        SurfaceMode {
            frequency: Hz(60.0),
            decay: Seconds(0.2),
            gain: 1.0,
        },
        SurfaceMode {
            frequency: Hz(250.0),
            decay: Seconds(0.08),
            gain: 0.5,
        },
        SurfaceMode {
            frequency: Hz(1200.0),
            decay: Seconds(0.03),
            gain: 0.2,
        },
    ]
}

/// Prony's method: the modes of a sum of damped sinusoids from its samples alone, by
/// the least-squares linear recursion `y[n] = -Σ a_i y[n-i]` and its roots.
fn prony(y: &[f64], modes: usize, rate: SampleRate) -> Vec<(f64, f64)> {
    let order = 2 * modes;
    let rows = y.len() - order;
    let m = DMatrix::from_fn(rows, order, |r, c| y[r + order - 1 - c]);
    let rhs = DVector::from_fn(rows, |r, _| -y[r + order]);
    let a = m.svd(true, true).solve(&rhs, 1e-300).unwrap();
    let mut poly = vec![1.0];
    poly.extend(a.iter());
    let mut found: Vec<(f64, f64)> = crate::numeric::roots(&poly)
        .unwrap()
        .into_iter()
        .filter(|p| p.im > 0.0)
        .map(|p| {
            (
                p.arg() * rate.hz() / std::f64::consts::TAU,
                -1.0 / (rate.hz() * p.norm().ln()),
            )
        })
        .collect();
    found.sort_by(|a, b| a.0.total_cmp(&b.0));
    found
}

#[test]
fn impulse_response_has_the_requested_frequencies_and_decays() {
    for rate in [SampleRate(48_000), SampleRate(8_000)] {
        let bank = ResonatorBank::new(&three_modes(), rate).unwrap();
        // Long enough for the slowest mode, short of the fastest one's underflow.
        let h = bank.impulse_response(rate.samples_in(Seconds(0.5)));
        let found = prony(&h, 3, rate);
        assert_eq!(found.len(), 3, "at {rate}");
        for (m, (f, tau)) in three_modes().iter().zip(&found) {
            let df = (f / m.frequency.0 - 1.0).abs();
            let dtau = (tau / m.decay.0 - 1.0).abs();
            eprintln!(
                "{rate}: {} -> f err {df:.2e}, tau err {dtau:.2e}",
                m.frequency
            );
            assert!(
                df < 0.01 && dtau < 0.01,
                "{rate}: {m:?} measured {f} Hz, {tau} s"
            );
        }
    }
}

#[test]
fn one_mode_zero_crossings_and_log_envelope() {
    for rate in [SampleRate(48_000), SampleRate(8_000)] {
        for m in three_modes() {
            let bank = ResonatorBank::new(&[m], rate).unwrap();
            let h = bank.impulse_response(rate.samples_in(Seconds(4.0 * m.decay.0)));
            // Upward zero crossings, interpolated: one per period.
            let ups: Vec<f64> = (1..h.len())
                .filter(|&n| h[n - 1] < 0.0 && h[n] >= 0.0)
                .map(|n| (n - 1) as f64 + h[n - 1] / (h[n - 1] - h[n]))
                .collect();
            let periods = (ups.len() - 1) as f64;
            let f = periods * rate.hz() / (ups[ups.len() - 1] - ups[0]);
            // Log-envelope: the RMS over each whole period falls as e^{-t/tau}; the
            // slope of its logarithm, by least squares, is -1/tau.
            let (mut t, mut l) = (Vec::new(), Vec::new());
            for w in ups.windows(2) {
                let (a, b) = (w[0].ceil() as usize, w[1].ceil() as usize);
                let ms: f64 = h[a..b].iter().map(|v| v * v).sum::<f64>() / (b - a) as f64;
                t.push(0.5 * (w[0] + w[1]) / rate.hz());
                l.push(0.5 * ms.ln());
            }
            let n = t.len() as f64;
            let (mt, ml) = (t.iter().sum::<f64>() / n, l.iter().sum::<f64>() / n);
            let slope = t
                .iter()
                .zip(&l)
                .map(|(a, b)| (a - mt) * (b - ml))
                .sum::<f64>()
                / t.iter().map(|a| (a - mt).powi(2)).sum::<f64>();
            let tau = -1.0 / slope;
            let df = (f / m.frequency.0 - 1.0).abs();
            let dtau = (tau / m.decay.0 - 1.0).abs();
            eprintln!(
                "{rate}: {} -> crossings f err {df:.2e}, envelope tau err {dtau:.2e}",
                m.frequency
            );
            assert!(df < 0.01, "{rate}: {m:?} measured {f} Hz");
            assert!(dtau < 0.01, "{rate}: {m:?} measured {tau} s");
        }
    }
}

#[test]
fn sections_give_the_same_impulse_response() {
    for rate in [SampleRate(48_000), SampleRate(8_000)] {
        let bank = ResonatorBank::new(&three_modes(), rate).unwrap();
        let sos = bank.to_sos().unwrap();
        assert!(sos.is_stable());
        assert_eq!(sos.sections.len(), 3);
        let n = rate.samples_in(Seconds(0.3));
        let a = bank.impulse_response(n);
        let b = sos.impulse_response(n);
        let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = a
            .iter()
            .zip(&b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        eprintln!("{rate}: sos max error {:.2e} of peak", err / peak);
        assert!(err < 1e-8 * peak, "{rate}: {err} against {peak}");
    }
}

#[test]
fn tick_and_block_agree_and_velocity_is_the_derivative() {
    let rate = SampleRate(48_000);
    let mut a = ResonatorBank::new(&three_modes(), rate).unwrap();
    let mut b = a.clone();
    let mut x: Vec<f64> = (0..500).map(|n| ((n * 7919) % 13) as f64 - 6.0).collect();
    let ticked: Vec<f64> = x.iter().map(|&v| a.tick(v)).collect();
    for chunk in x.chunks_mut(37) {
        b.process_in_place(chunk);
    }
    assert_eq!(ticked, x);
    // After an impulse the bank rings freely: its velocity is the slope of its path.
    let mut c = ResonatorBank::new(&three_modes(), rate).unwrap();
    c.tick(1.0);
    for _ in 0..100 {
        c.tick(0.0);
    }
    let (y0, v0) = (c.displacement(), c.velocity());
    let y1 = c.tick(0.0);
    let _ = y1;
    let y2 = c.displacement();
    let slope = (y2 - y0) * rate.hz();
    assert!(
        (slope - v0).abs() < 0.02 * v0.abs().max(1e-3),
        "{slope} vs {v0}"
    );
}

#[test]
fn retune_gives_exact_frequencies_and_keeps_the_state() {
    let rate = SampleRate(8000);
    let mut bank = ResonatorBank::new(&three_modes(), rate).unwrap();
    bank.tick(1.0);
    for _ in 0..37 {
        bank.tick(0.0);
    }
    let (y, state) = (bank.displacement(), bank.state());
    let scale = 1.37;
    bank.retune(scale).unwrap();
    assert_eq!(bank.frequency_scale(), scale);
    assert_eq!(bank.state(), state);
    assert_eq!(bank.displacement(), y);
    assert_eq!(bank.modes(), three_modes());
    // The same coefficients as a bank built at the scaled frequencies.
    let scaled: Vec<SurfaceMode> = three_modes()
        .iter()
        .map(|m| SurfaceMode {
            frequency: Hz(m.frequency.0 * scale),
            ..*m
        })
        .collect();
    let fresh = ResonatorBank::new(&scaled, rate).unwrap();
    for (p, q) in bank.poles().iter().zip(fresh.poles()) {
        assert!((p - q).norm() < 1e-14, "{p} vs {q}");
    }
    for (p, m) in bank.poles().iter().zip(&scaled) {
        let f = p.arg() * rate.hz() / std::f64::consts::TAU;
        assert!(
            (f / m.frequency.0 - 1.0).abs() < 1e-12,
            "{f} vs {}",
            m.frequency
        );
    }
    assert!((bank.first_sample_gain() / fresh.first_sample_gain() - 1.0).abs() < 1e-12);
    // And the impulse response's modes are there (Prony).
    let h = bank.impulse_response(rate.samples_in(Seconds(0.5)));
    for (m, (f, tau)) in scaled.iter().zip(prony(&h, 3, rate)) {
        assert!(
            (f / m.frequency.0 - 1.0).abs() < 0.01,
            "{f} vs {}",
            m.frequency
        );
        assert!((tau / m.decay.0 - 1.0).abs() < 0.01, "{tau} vs {}", m.decay);
    }
    // Absolute, not cumulative.
    bank.retune(1.0).unwrap();
    let original = ResonatorBank::new(&three_modes(), rate).unwrap();
    for (p, q) in bank.poles().iter().zip(original.poles()) {
        assert!((p - q).norm() < 1e-15);
    }
}

#[test]
fn retune_clamps_below_nyquist_and_rejects_bad_scales() {
    let rate = SampleRate(8000);
    let mut bank = ResonatorBank::new(&three_modes(), rate).unwrap();
    // 1200 Hz * 4 = 4800 Hz, past Nyquist: clamped to 0.49 f_s = 3920 Hz.
    bank.retune(4.0).unwrap();
    let top = bank.poles()[2];
    let f = top.arg() * rate.hz() / std::f64::consts::TAU;
    assert!((f - 3920.0).abs() < 1e-9, "{f}");
    assert!(top.im > 0.0 && bank.first_sample_gain() > 0.0);
    let before = bank.clone();
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            bank.retune(bad),
            Err(PhysicalError::InvalidParameter { .. })
        ));
    }
    assert_eq!(bank, before);
}

#[test]
fn energy_is_the_modal_kinetic_energy_and_decays() {
    let rate = SampleRate(48_000);
    let m = three_modes()[1];
    let mut bank = ResonatorBank::new(&[m], rate).unwrap();
    let impulse = 0.3;
    bank.tick(impulse);
    // J^2 / (2 m_k) with m_k = 1 / (2π f g).
    let expected = impulse * impulse * std::f64::consts::TAU * m.frequency.0 * m.gain / 2.0;
    let e0 = bank.energy();
    // One sample of decay has passed.
    let decayed = expected * (-2.0 / (m.decay.0 * rate.hz())).exp();
    assert!((e0 / decayed - 1.0).abs() < 1e-12, "{e0} vs {decayed}");
    let n = rate.samples_in(m.decay);
    for _ in 0..n {
        bank.tick(0.0);
    }
    let ratio = bank.energy() / e0;
    let theory = (-2.0 * n as f64 / (m.decay.0 * rate.hz())).exp();
    assert!((ratio / theory - 1.0).abs() < 1e-9, "{ratio} vs {theory}");
}

#[test]
fn the_fused_free_step_matches_tick() {
    let rate = SampleRate(48_000);
    let mut a = ResonatorBank::new(&three_modes(), rate).unwrap();
    let mut b = a.clone();
    for n in 0..300 {
        let j = if n % 50 < 3 { 0.1 * n as f64 } else { 0.0 };
        // The velocity is a sum of large terms that cancel: compare to their size.
        let size: f64 = a
            .state()
            .iter()
            .zip(&a.gain_slope)
            .map(|(z, gs)| z.norm() * gs.norm())
            .sum();
        let v = a.velocity();
        a.tick(j);
        let (vb, free) = b.advance_free();
        b.add_delayed_impulse(j);
        assert!((v - vb).abs() <= 1e-12 * size.max(1.0), "{v} vs {vb}");
        let y = b.displacement();
        assert!((free + b.first_sample_gain() * j - y).abs() <= 1e-12 * y.abs().max(1e-9));
        assert!((a.displacement() - y).abs() <= 1e-12 * y.abs().max(1e-9));
    }
}

#[test]
fn the_free_loop_matches_tick_for_any_number_of_modes() {
    let rate = SampleRate(48_000);
    for count in [1, 3, 4, 6, 9] {
        let modes: Vec<SurfaceMode> = (0..count)
            .map(|k| SurfaceMode {
                frequency: Hz(70.0 * 1.6f64.powi(k)),
                decay: Seconds(0.05),
                gain: 1e-3,
            })
            .collect();
        let mut a = ResonatorBank::new(&modes, rate).unwrap();
        a.tick(0.01);
        let mut b = a.clone();
        let expected: Vec<f32> = (0..201)
            .map(|_| {
                let v = a.velocity();
                a.tick(0.0);
                0.5 + v as f32
            })
            .collect();
        let mut out = vec![0.5f32; 201];
        b.add_free_velocity(&mut out);
        for (x, y) in expected.iter().zip(&out) {
            assert!(
                (x - y).abs() <= 1e-6 * x.abs().max(1.0),
                "{count} modes: {x} vs {y}"
            );
        }
        assert!((a.displacement() - b.displacement()).abs() <= 1e-12 * a.amplitude_bound());
    }
}

#[test]
fn culling_drops_only_quiet_modes_and_restoring_brings_them_back() {
    let rate = SampleRate(48_000);
    // Decays from 1 ms to 40 ms: after 20 ms the fastest are far below the slowest.
    let modes: Vec<SurfaceMode> = (0..9)
        .map(|k| SurfaceMode {
            frequency: Hz(90.0 * 1.5f64.powi(k)),
            decay: Seconds(if k % 3 == 0 {
                0.04
            } else {
                0.0005 * (k + 1) as f64
            }),
            gain: 1e-3 / (k + 1) as f64,
        })
        .collect();
    let mut full = ResonatorBank::new(&modes, rate).unwrap();
    full.tick(0.01);
    let mut warm = vec![0.0f32; 960];
    full.add_free_velocity(&mut warm);
    let peak = full.energy();
    let mut culled = full.clone();
    let floor = 1e-12 * peak;
    culled.cull(floor);
    let live = culled.live_modes();
    assert!(live > 0 && live < modes.len(), "{live} live");
    // Every mode kept is above the floor; every mode dropped was at most at it.
    let share =
        |b: &ResonatorBank, k: usize| 0.5 * b.gain_slope[k].im.abs() * b.state()[k].norm_sqr();
    assert!((0..live).all(|k| share(&culled, k) > floor));
    assert!(
        culled.state()[live..]
            .iter()
            .all(|z| *z == Complex64::new(0.0, 0.0))
    );
    let dropped = full.energy() - culled.energy();
    assert!(dropped >= 0.0 && dropped <= (modes.len() - live) as f64 * floor);
    // The free loop carries on as before, but for the dropped modes' tiny share.
    let (mut a, mut b) = (vec![0.0f32; 2000], vec![0.0f32; 2000]);
    full.add_free_velocity(&mut a);
    culled.add_free_velocity(&mut b);
    let size = a.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let err = a
        .iter()
        .zip(&b)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
    assert!(err <= 1e-5 * size, "{err} of {size}");
    // A retune (or an impulse) restores every mode, in the modes' order.
    culled.retune(1.0).unwrap();
    assert_eq!(culled.live_modes(), modes.len());
    assert_eq!(
        culled.poles(),
        ResonatorBank::new(&modes, rate).unwrap().poles()
    );
    culled.cull(f64::INFINITY);
    assert_eq!(culled.live_modes(), 0);
    assert_eq!(culled.velocity(), 0.0);
    culled.tick(0.01);
    assert_eq!(culled.live_modes(), modes.len());
    let fresh = ResonatorBank::new(&modes, rate)
        .unwrap()
        .impulse_response(50);
    assert_eq!(culled.impulse_response(50), fresh);
}

#[test]
fn bad_modes_are_errors() {
    let rate = SampleRate(8000);
    let good = three_modes()[0];
    let with = |f: f64, tau: f64, g: f64| {
        ResonatorBank::new(
            &[
                good,
                SurfaceMode {
                    frequency: Hz(f),
                    decay: Seconds(tau),
                    gain: g,
                },
            ],
            rate,
        )
    };
    assert!(matches!(
        with(4000.0, 0.1, 1.0),
        Err(PhysicalError::FrequencyOutOfRange { index: 1, .. })
    ));
    assert!(matches!(
        with(0.0, 0.1, 1.0),
        Err(PhysicalError::FrequencyOutOfRange { .. })
    ));
    assert!(matches!(
        with(f64::NAN, 0.1, 1.0),
        Err(PhysicalError::FrequencyOutOfRange { .. })
    ));
    assert!(matches!(
        with(100.0, 0.0, 1.0),
        Err(PhysicalError::BadDecay { .. })
    ));
    assert!(matches!(
        with(100.0, f64::INFINITY, 1.0),
        Err(PhysicalError::BadDecay { .. })
    ));
    assert!(matches!(
        with(100.0, 0.1, f64::NAN),
        Err(PhysicalError::BadGain { .. })
    ));
    assert_eq!(ResonatorBank::new(&[], rate), Err(PhysicalError::NoModes));
    assert_eq!(
        ResonatorBank::new(&[good], SampleRate(0)),
        Err(PhysicalError::ZeroRate)
    );
}
