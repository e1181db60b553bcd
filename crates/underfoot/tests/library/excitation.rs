//! The step's excitation follows the foot: played by the engine from generated walks, a
//! slower roll crunches longer, a heavier walker's step is louder (and, with the engine set
//! for that walker's weight, as long), and activity that a material's recordings hold at
//! the time of the toe-off plays when the foot unloads.

use underfoot::analysis::steps::{StepConfig, describe_all};
use underfoot::engine::offline::{render, track_events};
use underfoot::engine::{EngineConfig, MaterialBank};
use underfoot::excitation::ExcitationModel;
use underfoot::force::gait::{GaitConfig, generate, nominal_step};
use underfoot::material::Library;
use underfoot::material::builtin::builtin;
use underfoot::synthesis::VoiceConfig;
use underfoot::units::{Newtons, SampleRate, Seconds};

const RATE: SampleRate = SampleRate(48_000);

/// `gait` on `library`'s `material`, rendered by the engine at the default settings but
/// for a walker of `weight_kg`: the output and the strikes.
fn walk(
    library: &Library,
    material: &str,
    gait: &GaitConfig,
    weight_kg: f64,
) -> (Vec<f32>, Vec<Seconds>) {
    let bank = MaterialBank::prepare(
        library,
        RATE,
        &VoiceConfig::default(),
        &nominal_step(70.0, 1.8, RATE.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap();
    let slot = bank.slot(material).unwrap();
    let g = generate(gait).unwrap();
    let events = track_events(&g.track, RATE);
    let frames = RATE.samples_in(g.track.rows.last().unwrap().time) + 48_000;
    let config = EngineConfig {
        nominal_weight: Newtons::weight_of(weight_kg),
        ..EngineConfig::default()
    };
    let out = render(&config, bank, &[slot], &events, frames, 256).unwrap();
    (out.samples, g.strikes[0].clone())
}

/// The duration (ms) of the steps at `strikes` on average, and their median energy. The
/// duration is the time from 5% to 95% of the energy of their mean envelope (each step's
/// squared signal over the second from its strike, scaled to unit energy): a single step's
/// D90 jumps with where its loud micro-impacts fall, the mean's does not.
fn measure(samples: &[f32], strikes: &[Seconds]) -> (f64, f64) {
    let x: Vec<f64> = samples.iter().map(|v| f64::from(*v)).collect();
    let steps = describe_all(&x, RATE, Some(strikes), &StepConfig::default()).unwrap();
    let mut energies: Vec<f64> = steps.iter().map(|s| s.energy).collect();
    energies.sort_by(f64::total_cmp);
    let len = RATE.samples_in(Seconds(1.0));
    let mut mean = vec![0.0; len];
    for t in strikes {
        let a = RATE.samples_in(*t);
        let seg = &x[a..(a + len).min(x.len())];
        let e: f64 = seg.iter().map(|v| v * v).sum();
        for (m, v) in mean.iter_mut().zip(seg) {
            *m += v * v / e;
        }
    }
    let total: f64 = mean.iter().sum();
    let mut acc = 0.0;
    let (mut first, mut last) = (0, 0);
    for (i, m) in mean.iter().enumerate() {
        acc += m;
        if acc < 0.05 * total {
            first = i + 1;
        }
        if acc < 0.95 * total {
            last = i + 1;
        }
    }
    (
        1e3 * (last - first) as f64 / RATE.hz(),
        energies[energies.len() / 2],
    )
}

fn gait(cadence: f64, weight_kg: f64) -> GaitConfig {
    GaitConfig {
        steps: 24,
        channels: 1,
        cadence,
        weight_kg,
        variation: 0.0,
        ..GaitConfig::default()
    }
}

#[test]
fn a_slower_roll_crunches_longer_and_a_heavier_step_louder() {
    let lib = builtin();
    let (x, s) = walk(lib, "gravel", &gait(1.8, 70.0), 70.0);
    let (nominal_ms, nominal_energy) = measure(&x, &s);
    // At 1.2 steps a second the foot rolls over the ground in 1.03 s instead of 0.69.
    let (x, s) = walk(lib, "gravel", &gait(1.2, 70.0), 70.0);
    let (slow_ms, _) = measure(&x, &s);
    // A walker 40% heavier, the engine set for their weight (`--weight 98`): the step
    // clock, normalised by it, keeps its pace; the strikes come down 40% faster.
    let (x, s) = walk(lib, "gravel", &gait(1.8, 98.0), 98.0);
    let (heavy_ms, heavy_energy) = measure(&x, &s);
    // The same walker, the engine set for 70 kg: the force changes 40% faster than the
    // clock expects, so it runs ahead and the crunch is over sooner.
    let (x, s) = walk(lib, "gravel", &gait(1.8, 98.0), 70.0);
    let (unset_ms, _) = measure(&x, &s);
    println!(
        "duration: nominal {nominal_ms:.0} ms, slow roll {slow_ms:.0} ms, heavy {heavy_ms:.0} ms \
         ({unset_ms:.0} ms with the engine set for 70 kg); energy heavy / nominal {:.2}",
        heavy_energy / nominal_energy
    );
    assert!(slow_ms > 1.3 * nominal_ms, "{slow_ms} against {nominal_ms}");
    assert!(
        heavy_energy > 1.4 * nominal_energy,
        "{heavy_energy} against {nominal_energy}"
    );
    assert!(
        (heavy_ms / nominal_ms - 1.0).abs() < 0.15,
        "{heavy_ms} against {nominal_ms}"
    );
    assert!(unset_ms < heavy_ms, "{unset_ms} against {heavy_ms}");
}

#[test]
fn activity_recorded_at_the_toe_off_plays_when_the_foot_unloads() {
    // Gravel with its whole train moved to the last tenth of the step clock: where the
    // nominal step's clock is when the foot unloads (the clock runs fast there).
    let mut lib = builtin().clone();
    let gravel = lib.get("gravel").unwrap().clone();
    let span = (0.67 / 0.005) as usize;
    let late = ExcitationModel {
        heel: 0.0,
        bin_s: 0.005,
        rate_hz: (0..span)
            .map(|b| if b >= span * 9 / 10 { 3000.0 } else { 0.0 })
            .collect(),
        energy: (0..span)
            .map(|b| {
                if b >= span * 9 / 10 {
                    1.0 / (span - span * 9 / 10) as f64
                } else {
                    0.0
                }
            })
            .collect(),
        duration_spread: 0.0,
        ..gravel.excitation.clone().unwrap()
    };
    let model = underfoot::material::MaterialModel {
        excitation: Some(late),
        ..gravel
    };
    lib.upsert(model);
    let g = gait(1.8, 70.0);
    let (x, strikes) = walk(&lib, "gravel", &g, 70.0);
    let toe_offs = &generate(&g).unwrap().toe_offs[0];
    // Where each step's energy lies: its centre of energy, against its strike and toe-off.
    for (strike, toe_off) in strikes.iter().zip(toe_offs).take(20) {
        let (a, b) = (RATE.samples_in(*strike), RATE.samples_in(*toe_off));
        let seg = &x[a..(b + RATE.samples_in(Seconds(0.1))).min(x.len())];
        let energy: f64 = seg.iter().map(|v| f64::from(*v).powi(2)).sum();
        let centre = seg
            .iter()
            .enumerate()
            .map(|(n, v)| n as f64 * f64::from(*v).powi(2))
            .sum::<f64>()
            / energy;
        let at = centre / RATE.hz();
        let stance = toe_off.0 - strike.0;
        assert!(
            at > 0.75 * stance && at < stance + 0.05,
            "the step's energy centres {at:.3} s after its strike, toe-off at {stance:.3} s"
        );
    }
}
