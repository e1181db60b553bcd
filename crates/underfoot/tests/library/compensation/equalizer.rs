//! The equalizer tuned on the noisy simulated tile, and the static inverse FIR it replaces
//! (moved from the unit tests of `compensation::equalizer`, which cannot use the
//! simulators above them).

use underfoot::compensation::equalizer::{
    EqualizerConfig, EqualizerFilter, Inverted, Realisation, StaticInverse, auto_taps, equalize,
    flatness,
};
use underfoot::compensation::sweep::{Sweep, SweepConfig, measure};
use underfoot::sim::{SimulatedTile, TileConfig, TileResonance};
use underfoot::units::{Decibels, Hz, SampleRate};

const RATE: SampleRate = SampleRate(48_000);

fn tile(noise: Option<Decibels>) -> SimulatedTile {
    let cfg = TileConfig {
        noise,
        ..TileConfig::default()
    };
    SimulatedTile::new(&cfg, RATE).unwrap()
}

#[test]
fn iterative_equalizer_flattens_the_noisy_tile() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    for realisation in [Realisation::default(), Realisation::Bank] {
        let mut device = tile(Some(Decibels(-40.0)));
        let eq = equalize(
            &mut device,
            &sweep,
            EqualizerConfig::default(),
            realisation,
            3,
            false,
        )
        .unwrap();
        let figures: Vec<(f64, f64)> = eq
            .passes
            .iter()
            .map(|p| (p.deviation.0, p.peak.0))
            .collect();
        eprintln!("{realisation:?}: {figures:?}");
        let last = eq.passes.last().unwrap();
        assert!(eq.passes[0].deviation.0 > 2.0);
        assert!(last.deviation.0 < 0.28, "{realisation:?}: {figures:?}");
        assert!(last.peak.0 < 1.0, "{realisation:?}: {figures:?}");
        // How soon the equalizer's output follows its input: the impulse response's
        // peak and the time by which half its energy is out.
        let mut filter = EqualizerFilter::new(&eq.weights, realisation).unwrap();
        let mut impulse = vec![0.0f32; 8192];
        impulse[0] = 1.0;
        let mut h = vec![0.0f32; impulse.len()];
        filter.process(&impulse, &mut h);
        let peak = (0..h.len())
            .max_by(|&a, &b| h[a].abs().total_cmp(&h[b].abs()))
            .unwrap();
        let total: f32 = h.iter().map(|v| v * v).sum();
        let mut sum = 0.0;
        let half = h
            .iter()
            .position(|v| {
                sum += v * v;
                sum >= 0.5 * total
            })
            .unwrap();
        eprintln!(
            "{realisation:?}: bulk delay {} samples, impulse peak at {peak}, half the energy by {half}",
            filter.latency()
        );
        if let Realisation::LowDelay { .. } = realisation {
            assert_eq!(filter.latency(), 0);
            assert!(peak < 48 && half < 48, "{peak} {half}");
        }
    }
}

#[test]
#[ignore = "slow tier: refits"]
fn static_inverse_fir_for_comparison() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut device = tile(Some(Decibels(-40.0)));
    let unloaded = measure(&mut device, &sweep).unwrap();
    let raw = flatness(&unloaded).unwrap().0.0;
    for order in [14, 128, 512, 2048] {
        let inverse = StaticInverse::fit(&unloaded, order, RATE).unwrap();
        let after = measure(
            &mut Inverted {
                inverse: &inverse,
                device: &mut device,
            },
            &sweep,
        )
        .unwrap();
        let (rms, peak) = flatness(&after).unwrap();
        eprintln!(
            "static inverse order {order}: {raw:.2} -> {:.2} dB rms, {:.2} peak",
            rms.0, peak.0
        );
        // The compensation paper's order has no resolution at 48 kHz; a long one works, with a delay.
        match order {
            14 => assert!(rms.0 > 0.9 * raw),
            2048 => assert!(rms.0 < 0.5 && inverse.delay == 1024),
            _ => {}
        }
    }
}

/// A family of devices as uneven as the compensation paper's tile (15.3 dB RMS from flat)
/// or milder, each measured through the simulated path with sensor noise at -40 dB.
fn uneven(kind: &str) -> TileConfig {
    let mode = |f: f64, q: f64, g: f64| TileResonance {
        freq: Hz(f),
        q,
        gain: Decibels(g),
    };
    let base = TileConfig {
        noise: Some(Decibels(-40.0)),
        ..TileConfig::default()
    };
    match kind {
        // A strong mid-band resonance and steep roll-offs on both sides.
        "steep" => TileConfig {
            modes: vec![mode(250.0, 1.4, 24.0)],
            highpass: Hz(240.0),
            lowpass: Hz(280.0),
            ..base
        },
        "resonant" => TileConfig {
            modes: vec![
                mode(150.0, 10.0, 14.0),
                mode(420.0, 12.0, 12.0),
                mode(760.0, 15.0, 12.0),
            ],
            ..base
        },
        "notched" => TileConfig {
            modes: vec![
                mode(180.0, 5.0, 9.0),
                mode(320.0, 3.0, -16.0),
                mode(650.0, 4.0, -12.0),
            ],
            ..base
        },
        "tilted" => TileConfig {
            modes: vec![],
            highpass: Hz(45.0),
            lowpass: Hz(200.0),
            ..base
        },
        other => panic!("no device {other}"),
    }
}

/// Tunes `kind` with boosts up to `max_boost` dB, the filter sized automatically.
fn tune_uneven(kind: &str, max_boost: f64) -> underfoot::compensation::equalizer::Equalization {
    tune_uneven_with(kind, max_boost, None, 3)
}

/// ... or with a filter of `taps` that never grows.
fn tune_uneven_with(
    kind: &str,
    max_boost: f64,
    taps: Option<usize>,
    passes: usize,
) -> underfoot::compensation::equalizer::Equalization {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let config = EqualizerConfig {
        max_boost: Decibels(max_boost),
        ..EqualizerConfig::default()
    };
    let mut device = SimulatedTile::new(&uneven(kind), RATE).unwrap();
    equalize(
        &mut device,
        &sweep,
        config,
        Realisation::LowDelay {
            taps: taps.unwrap_or_else(|| auto_taps(&config, RATE)),
        },
        passes,
        taps.is_none(),
    )
    .unwrap()
}

#[test]
#[ignore = "slow tier: refits"]
fn uneven_devices_flatten_and_no_pass_makes_it_worse() {
    for kind in ["steep", "resonant", "notched", "tilted"] {
        let eq = tune_uneven(kind, 40.0);
        let figures: Vec<String> = eq
            .passes
            .iter()
            .map(|p| {
                format!(
                    "{:.2} dB (peak {:.1}{}, {:?} taps)",
                    p.deviation.0,
                    p.peak.0,
                    if p.kept { "" } else { ", not kept" },
                    p.taps
                )
            })
            .collect();
        eprintln!(
            "{kind}: {figures:?}; best pass {}; capped {:?}",
            eq.best, eq.capped
        );
        let first = eq.passes[0].deviation.0;
        assert!(
            (2.0..=20.0).contains(&first),
            "{kind}: {first:.2} dB to start"
        );
        for w in eq.passes.windows(2) {
            assert!(
                w[1].deviation.0 <= w[0].deviation.0,
                "{kind}: a pass made it worse: {figures:?}"
            );
        }
        // The compensation paper: 0.28 dB after its third pass on a 15.3 dB tile. The
        // resonant device's Q 10-15 modes are narrower than the weights' 11.7 Hz bins
        // can follow exactly: within 0.5 dB there.
        let bound = if kind == "resonant" { 0.5 } else { 0.3 };
        let third = eq.passes[2].deviation.0;
        assert!(
            third <= bound,
            "{kind}: {third:.2} dB after pass 3: {figures:?}"
        );
        assert_eq!(eq.best, eq.passes.len());
    }
    // Too short a filter for the steep device: some passes come out worse, and are not
    // kept; the next tries a smaller step from the best weights, and the result is the
    // best measured.
    let eq = tune_uneven_with("steep", 40.0, Some(2048), 5);
    let figures: Vec<(f64, bool, f64)> = eq
        .passes
        .iter()
        .map(|p| (p.deviation.0, p.kept, p.step))
        .collect();
    eprintln!("steep, 2048 taps: {figures:?}; best pass {}", eq.best);
    let best = eq.passes[eq.best - 1].deviation.0;
    assert!(eq.passes.iter().all(|p| p.deviation.0 >= best));
    assert!(eq.passes.iter().any(|p| !p.kept), "{figures:?}");
    for w in eq.passes.windows(2) {
        let expected = if w[1].kept {
            w[0].step
        } else {
            w[0].step / 2.0
        };
        if w[1].pass < eq.passes.len() {
            assert!((w[1].step - expected).abs() < 1e-12, "{figures:?}");
        }
    }
}

#[test]
#[ignore = "slow tier: refits"]
fn the_default_cap_is_reported_where_it_binds() {
    let eq = tune_uneven("steep", EqualizerConfig::default().max_boost.0);
    eprintln!(
        "steep at +12 dB: {:?}; capped {:?}, residual {:.2} dB",
        eq.passes.iter().map(|p| p.deviation.0).collect::<Vec<_>>(),
        eq.capped,
        eq.cap_residual.0
    );
    assert!(!eq.capped.is_empty(), "the cap binds on the steep device");
    assert!(eq.capped.iter().all(|c| c.boost && c.short.0 > 0.25));
    // The low roll-off is where it binds.
    assert!(eq.capped.iter().any(|c| c.lo.0 < 100.0));
    let best = &eq.passes[eq.best - 1];
    assert!(eq.cap_residual.0 > 0.1 && eq.cap_residual.0 <= best.deviation.0 + 1e-9);
    // Allowed to boost, the same device has nothing capped.
    assert!(tune_uneven("steep", 40.0).capped.is_empty());
}
