//! The equalizer tuned on the noisy simulated tile, and the static inverse FIR it replaces
//! (moved from the unit tests of `compensation::equalizer`, which cannot use the
//! simulators above them).

use underfoot::compensation::equalizer::{
    EqualizerConfig, EqualizerFilter, Inverted, Realisation, StaticInverse, equalize, flatness,
};
use underfoot::compensation::sweep::{Sweep, SweepConfig, measure};
use underfoot::sim::{SimulatedTile, TileConfig};
use underfoot::units::{Decibels, SampleRate};

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
