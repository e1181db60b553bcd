use super::*;
use crate::units::{Hz, Seconds};
use proptest::prelude::*;

const RATE: SampleRate = SampleRate(8_000);

fn modes() -> [SurfaceMode; 3] {
    [
        SurfaceMode {
            frequency: Hz(300.0),
            decay: Seconds(0.03),
            gain: 2e-3,
        },
        SurfaceMode {
            frequency: Hz(900.0),
            decay: Seconds(0.02),
            gain: 1e-3,
        },
        SurfaceMode {
            frequency: Hz(1700.0),
            decay: Seconds(0.01),
            gain: 5e-4,
        },
    ]
}

fn aggregate(params: &AggregateParams, seed: u64) -> Aggregate {
    Aggregate::new(&modes(), params, RATE, seed).unwrap()
}

/// Events in each one-second window of a run at `rate(t)` events/s.
fn counts(agg: &mut Aggregate, seconds: usize, rate: impl Fn(f64) -> f32) -> Vec<u64> {
    let fs = RATE.0 as usize;
    let mut rates = vec![0.0f32; fs];
    let mut out = vec![0.0f32; fs];
    let mut counts = Vec::with_capacity(seconds);
    for s in 0..seconds {
        for (n, r) in rates.iter_mut().enumerate() {
            *r = rate(s as f64 + n as f64 / fs as f64);
        }
        let before = agg.events();
        // Odd blocks, so events fall across block edges.
        for (r, o) in rates.chunks(333).zip(out.chunks_mut(333)) {
            agg.process(r, o);
        }
        counts.push(agg.events() - before);
    }
    counts
}

fn within_4_sigma(count: u64, mean: f64) -> bool {
    (count as f64 - mean).abs() < 4.0 * mean.sqrt()
}

#[test]
fn a_constant_rate_gives_poisson_counts() {
    let mut agg = aggregate(&AggregateParams::default(), 1);
    let c = counts(&mut agg, 200, |_| 50.0);
    let total: u64 = c.iter().sum();
    let mean = total as f64 / c.len() as f64;
    let var = c.iter().map(|&k| (k as f64 - mean).powi(2)).sum::<f64>() / (c.len() - 1) as f64;
    eprintln!(
        "200 s at 50/s: {total} events (expected 10000 ± 100), dispersion {:.3}",
        var / mean
    );
    assert!(within_4_sigma(total, 10_000.0), "{total}");
    assert!(
        (0.7..1.3).contains(&(var / mean)),
        "dispersion {}",
        var / mean
    );
}

#[test]
fn a_ramp_gives_its_integral() {
    // N(t) = 2 t over 100 s: 2500 events in the first half, 7500 in the second.
    let mut agg = aggregate(&AggregateParams::default(), 2);
    let c = counts(&mut agg, 100, |t| (2.0 * t) as f32);
    let first: u64 = c[..50].iter().sum();
    let second: u64 = c[50..].iter().sum();
    eprintln!("ramp: {first} (2500) then {second} (7500)");
    assert!(within_4_sigma(first, 2500.0), "{first}");
    assert!(within_4_sigma(second, 7500.0), "{second}");
    // Window by window, too: a 1 s window at N = 2t holds 2t + 1 events on average.
    let worst = c
        .iter()
        .enumerate()
        .map(|(s, &k)| (k as f64 - (2.0 * s as f64 + 1.0)) / (2.0 * s as f64 + 1.0).sqrt())
        .fold(0.0f64, |m, z| m.max(z.abs()));
    assert!(worst < 4.5, "worst window {worst} sigma");
}

#[test]
fn silence_without_events_and_sound_only_after_them() {
    let mut agg = aggregate(&AggregateParams::default(), 3);
    let fs = RATE.0 as usize;
    let mut out = vec![1.0f32; 2 * fs];
    agg.process(&vec![0.0; 2 * fs], &mut out);
    assert!(out.iter().all(|&v| v == 0.0));
    assert_eq!(agg.events(), 0);

    // Half a second of events, then none for three.
    let mut rates = vec![0.0f32; 4 * fs];
    rates[fs..fs + fs / 2].fill(100.0);
    let mut out = vec![0.0f32; 4 * fs];
    let mut after = 0;
    for (r, o) in rates.chunks(128).zip(out.chunks_mut(128)) {
        agg.process(r, o);
        if r[0] > 0.0 {
            after = agg.events();
        }
    }
    assert!(after > 20, "{after}");
    assert_eq!(agg.events(), after, "events without a rate");
    assert!(out[..fs].iter().all(|&v| v == 0.0), "sound before events");
    assert!(out[fs..fs + fs / 2].iter().any(|&v| v != 0.0));
    // The ringing dies away and every slot comes to rest: exactly silent.
    assert!(out[3 * fs..].iter().all(|&v| v == 0.0), "no rest");
    assert!(agg.slots.iter().all(|v| !v.active));
}

#[test]
fn no_spread_rings_at_the_given_frequencies() {
    let params = AggregateParams {
        size_spread: 0.0,
        ..AggregateParams::default()
    };
    let reference = ResonatorBank::new(&modes(), RATE).unwrap();
    let mut agg = aggregate(&params, 4);
    let mut out = vec![0.0f32; RATE.0 as usize];
    agg.process(&vec![200.0; out.len()], &mut out);
    assert!(agg.events() > 100);
    for v in &agg.slots {
        let bank = v.impact.surface().unwrap();
        assert_eq!(bank.frequency_scale(), 1.0);
        assert_eq!(bank.poles(), reference.poles());
    }
    // And the sound's spectrum peaks at the single mode's frequency.
    let one = [SurfaceMode {
        frequency: Hz(440.0),
        decay: Seconds(0.05),
        gain: 1e-3,
    }];
    let mut agg = Aggregate::new(&one, &params, RATE, 5).unwrap();
    agg.process(&vec![100.0; out.len()], &mut out);
    let peak = (100..=2000)
        .step_by(5)
        .map(|f| (f, goertzel(&out, f64::from(f) / RATE.hz())))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap()
        .0;
    assert_eq!(peak, 440);
}

/// Power of `x` at `f` cycles per sample.
fn goertzel(x: &[f32], f: f64) -> f64 {
    let c = 2.0 * (std::f64::consts::TAU * f).cos();
    let (mut s1, mut s2) = (0.0, 0.0);
    for &v in x {
        let s = f64::from(v) + c * s1 - s2;
        s2 = s1;
        s1 = s;
    }
    s1 * s1 + s2 * s2 - c * s1 * s2
}

#[test]
fn sizes_scale_the_frequencies_within_the_spread() {
    let spread = 0.3;
    let params = AggregateParams {
        size_spread: spread,
        ..AggregateParams::default()
    };
    let reference = ResonatorBank::new(&modes(), RATE).unwrap();
    let mut agg = aggregate(&params, 6);
    let mut scales = Vec::new();
    let (mut one, mut out) = ([300.0f32], [0.0f32]);
    while scales.len() < 2000 {
        let before = agg.events();
        agg.process(&one, &mut out);
        if agg.events() == before + 1 {
            // The slot just struck is the one whose hammer is out.
            let v = agg.slots.iter().find(|v| v.impact.is_striking()).unwrap();
            let bank = v.impact.surface().unwrap();
            let scale = bank.frequency_scale();
            for (p, q) in bank.poles().iter().zip(reference.poles()) {
                // Observed: the pole angle is 2π f / f_s.
                let observed = p.arg() / q.arg();
                assert!((observed / scale - 1.0).abs() < 1e-12);
            }
            scales.push(scale);
        }
        one[0] = 300.0;
    }
    let (lo, hi) = scales
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, h), &s| (l.min(s), h.max(s)));
    let mean_log = scales.iter().map(|s| s.ln()).sum::<f64>() / scales.len() as f64;
    eprintln!("scales in [{lo:.4}, {hi:.4}], mean log {mean_log:.4}");
    let bound = 1.0 + spread;
    assert!(lo >= 1.0 / bound && hi <= bound);
    // Log-uniform: the extremes are reached and the logs centre on zero.
    assert!(lo < 1.0 / bound * 1.01 && hi > bound / 1.01);
    let sd = bound.ln() / 3f64.sqrt() / (scales.len() as f64).sqrt();
    assert!(mean_log.abs() < 4.0 * sd, "{mean_log}");
}

#[test]
fn a_seed_fixes_the_stream_and_bad_rates_are_zero() {
    let params = AggregateParams::default();
    let rates: Vec<f32> = (0..16_000)
        .map(|n| 80.0 + 60.0 * ((n / 900) % 3) as f32)
        .collect();
    let run = |seed, rates: &[f32]| {
        let mut agg = aggregate(&params, seed);
        let mut out = vec![0.0f32; rates.len()];
        for (r, o) in rates.chunks(100).zip(out.chunks_mut(100)) {
            agg.process(r, o);
        }
        (out, agg.events())
    };
    let a = run(7, &rates);
    assert!(a.1 > 0);
    assert_eq!(a, run(7, &rates));
    assert_ne!(a.0, run(8, &rates).0);
    // Non-finite and negative rates are zero, and break nothing.
    let mut bad = rates.clone();
    let mut zeroed = rates.clone();
    for (n, (b, z)) in bad.iter_mut().zip(&mut zeroed).enumerate() {
        if n % 7 == 0 {
            *b = [f32::NAN, -5.0, f32::INFINITY, f32::NEG_INFINITY][n / 7 % 4];
            *z = 0.0;
        }
    }
    let b = run(7, &bad);
    assert!(b.0.iter().all(|v| v.is_finite()));
    assert_eq!(b, run(7, &zeroed));
    // Only the shorter of the two slices is run.
    let mut agg = aggregate(&params, 7);
    let mut out = [9.0f32; 10];
    agg.process(&[1e6; 4], &mut out);
    assert_eq!(out[4..], [9.0; 6]);
}

#[test]
fn reset_silences_and_the_stream_goes_on() {
    let mut agg = aggregate(&AggregateParams::default(), 9);
    let rates = vec![400.0f32; 4000];
    let mut first = vec![0.0f32; 4000];
    agg.process(&rates, &mut first);
    assert!(agg.events() > 0);
    agg.reset();
    assert_eq!(agg.events(), 0);
    let mut silent = vec![1.0f32; 100];
    agg.process(&[0.0; 100], &mut silent);
    assert!(silent.iter().all(|&v| v == 0.0));
    let mut second = vec![0.0f32; 4000];
    agg.process(&rates, &mut second);
    assert_ne!(first, second, "a reset must not replay the stream");
}

#[test]
fn a_strike_rings_without_counting_as_an_event() {
    let mut agg = aggregate(&AggregateParams::default(), 10);
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        agg.strike(bad);
    }
    let mut out = vec![0.0f32; 800];
    agg.process(&[0.0; 800], &mut out);
    assert!(out.iter().all(|&v| v == 0.0));
    agg.strike(1.0);
    agg.process(&[0.0; 800], &mut out);
    assert!(out.iter().any(|&v| v != 0.0));
    assert_eq!(agg.events(), 0);
    // A stronger strike is louder: the contact is nonlinear, but monotone.
    let peak = |s: &[f32]| s.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let mut loud = vec![0.0f32; 800];
    let mut agg = aggregate(&AggregateParams::default(), 10);
    agg.strike(4.0);
    agg.process(&[0.0; 800], &mut loud);
    assert!(peak(&loud) > 1.5 * peak(&out));
}

#[test]
fn a_flood_of_events_is_capped_per_sample() {
    let params = AggregateParams::default();
    let mut agg = aggregate(&params, 11);
    let mut out = vec![0.0f32; 1000];
    agg.process(&vec![f32::MAX; 1000], &mut out);
    assert_eq!(agg.events(), 1000 * params.impacts_in_flight as u64);
    assert!(out.iter().all(|v| v.is_finite()));
}

#[test]
fn sensible_parameters_never_trip_the_safeguard() {
    for (rate, spread) in [(RATE, 0.15), (SampleRate(48_000), 0.5)] {
        let params = AggregateParams {
            size_spread: spread,
            ..AggregateParams::default()
        };
        let mut agg = Aggregate::new(&modes(), &params, rate, 12).unwrap();
        let n = rate.0 as usize;
        let mut out = vec![0.0f32; n];
        // Dense bursts (every slot restruck while ringing), then a sparse stream.
        for burst in [3000.0, 20_000.0, 50.0] {
            agg.process(&vec![burst; n], &mut out);
        }
        assert!(agg.events() > 20_000);
        assert_eq!(agg.runaways, 0, "at {rate}, spread {spread}");
    }
}

#[test]
fn default_micro_impacts_are_short_and_lossy() {
    let p = AggregateParams::default().impact;
    let mut impact = Impact::new(p, Surface::Rigid, SampleRate(48_000)).unwrap();
    let mut out = vec![0.0f32; 480];
    impact.process(&mut out);
    let t = impact.contact_time().unwrap().0;
    let e = -impact.hammer_velocity() / p.velocity;
    eprintln!(
        "default grain: contact {:.3} ms, restitution {e:.3}",
        t * 1e3
    );
    assert!(t > 0.1e-3 && t < 0.5e-3, "{t}");
    assert!(e > 0.6 && e < 0.9, "{e}");
}

#[test]
fn bad_parameters_are_errors() {
    let good = AggregateParams::default();
    let bad = [
        AggregateParams {
            impacts_in_flight: 0,
            ..good
        },
        AggregateParams {
            impacts_in_flight: MAX_IMPACT_POOL + 1,
            ..good
        },
        AggregateParams {
            size_spread: -0.1,
            ..good
        },
        AggregateParams {
            size_spread: f64::NAN,
            ..good
        },
        AggregateParams {
            impact: ImpactParams {
                velocity: f64::NAN,
                ..good.impact
            },
            ..good
        },
        AggregateParams {
            impact: ImpactParams {
                mass: 0.0,
                ..good.impact
            },
            ..good
        },
    ];
    for p in bad {
        assert!(
            matches!(
                Aggregate::new(&modes(), &p, RATE, 0),
                Err(PhysicalError::InvalidParameter { .. })
            ),
            "{p:?}"
        );
    }
    assert_eq!(
        Aggregate::new(&[], &good, RATE, 0).err(),
        Some(PhysicalError::NoModes)
    );
    assert_eq!(
        Aggregate::new(&modes(), &good, SampleRate(0), 0).err(),
        Some(PhysicalError::ZeroRate)
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Any valid parameters and any rates, finite or not: finite output.
    #[test]
    fn output_stays_finite(
        seed in any::<u64>(),
        mass in 1e-5f64..10.0,
        log_k in 2.0f64..12.0,
        alpha in 1.0f64..3.0,
        log_damping in -3.0f64..10.0,
        velocity in 0.0f64..20.0,
        spread in 0.0f64..=MAX_SIZE_SPREAD,
        slots in 1usize..=8,
        freqs in prop::collection::vec((0.001f64..0.4999, 1e-4f64..2.0, 0.0f64..1.0), 1..6),
        rates in prop::collection::vec(
            prop_oneof![
                4 => 0.0f32..5000.0,
                1 => Just(f32::NAN),
                1 => Just(-1.0f32),
                1 => Just(f32::INFINITY),
                1 => 1e5f32..1e30,
            ],
            1..64,
        ),
    ) {
        let modes: Vec<SurfaceMode> = freqs
            .iter()
            .map(|&(f, tau, g)| SurfaceMode {
                frequency: Hz(f * RATE.hz()),
                decay: Seconds(tau),
                gain: g,
            })
            .collect();
        let params = AggregateParams {
            impact: ImpactParams {
                mass,
                stiffness: 10f64.powf(log_k),
                alpha,
                damping: 10f64.powf(log_damping),
                velocity,
            },
            size_spread: spread,
            impacts_in_flight: slots,
        };
        let mut agg = Aggregate::new(&modes, &params, RATE, seed).unwrap();
        let mut out = vec![0.0f32; 200];
        for k in 0..20 {
            let block: Vec<f32> = (0..200).map(|n| rates[(n + k * 200) / 50 % rates.len()]).collect();
            agg.process(&block, &mut out);
            prop_assert!(out.iter().all(|v| v.is_finite()), "block {k}: {out:?}");
            if k == 10 {
                agg.strike(3.0);
            }
        }
    }
}
