//! A walk across every built-in material, rendered by the engine and analysed with the
//! fitting pipeline: each material's stretch has that material's measured response.

use underfoot::engine::offline::{render, segment_lsd, walk_across};
use underfoot::engine::{EngineConfig, MaterialBank};
use underfoot::force::gait::{GaitConfig, nominal_step};
use underfoot::material::builtin::builtin;
use underfoot::synthesis::VoiceConfig;
use underfoot::units::{Newtons, SampleRate};

#[test]
fn each_stretch_of_a_walk_matches_its_material_within_2_db() {
    let rate = SampleRate(48_000);
    let lib = builtin();
    let bank = MaterialBank::prepare(
        lib,
        rate,
        &VoiceConfig::default(),
        &nominal_step(70.0, 1.8, rate.hz()),
        Newtons::weight_of(70.0),
    )
    .unwrap();
    let names = lib.names();
    let walk = walk_across(&bank, &names, 4, &GaitConfig::default(), rate).unwrap();
    let first = walk.segments[0].slot;
    let out = render(
        &EngineConfig {
            gain: underfoot::units::Decibels(-30.0),
            ..EngineConfig::default()
        },
        bank,
        &[first],
        &walk.events,
        walk.frames,
        256,
    )
    .unwrap();
    assert_eq!(
        out.telemetry.strikes,
        4 * names.len() as u64,
        "every step detected once"
    );
    assert_eq!(out.telemetry.non_finite, 0);
    let mut worst = 0.0f64;
    for seg in &walk.segments {
        let (a, b) = (
            rate.samples_in(seg.start),
            rate.samples_in(seg.end).min(walk.frames),
        );
        let model = lib.get(&seg.material).unwrap();
        let lsd = segment_lsd(
            &out.samples[a..b],
            rate,
            model,
            underfoot::units::Decibels(-30.0),
        )
        .unwrap();
        println!("{:>8}: {lsd:.2} dB", seg.material);
        worst = worst.max(lsd);
    }
    println!(
        "limited samples: {}, peak {:.3}",
        out.telemetry.limited, out.telemetry.peak
    );
    assert!(worst < 2.0, "worst segment {worst:.2} dB");
}
