//! underfoot against its C anchors (`anchors/anchors.c`, built by `build.rs` with the
//! system C compiler), timed interleaved: every criterion sample times the C anchor
//! (`-O3`), the same C at `-O3 -march=native`, and ours, one after the other, for the
//! same number of iterations, and the printed ratio (anchor time / ours) is the median
//! over the samples of each sample's ratio. Each pair does the same work (same sizes,
//! same samples) and a check before timing makes sure the C side computes what it claims
//! (outputs compared with underfoot's on the same input).
//!
//! - `engine/...`: the whole engine, 16 channels of the built-in materials walking, one
//!   64-frame block (as `benches/engine.rs`'s `engine/64-frame block, 16 channels`, IIR
//!   and physical), against C voices of 8 parallel biquads summed then 3 in series (an
//!   order-16 voice's modes and its post filter) for 16 voices and 64 frames, f32.
//! - `impact/K modes` (K = 3, 16): `benches/physical.rs`'s impact (a 0.5 kg hammer at
//!   1 m/s on K modes, a strike every 4 800 samples, 128-frame blocks), against a C
//!   resonator bank of the same modes alone (driven by a contact-length force pulse,
//!   every sample through every mode) and a C hammer on it through an explicit
//!   Hunt-Crossley contact (`F = k x^α + λ x^α ẋ` while `x > 0`), f64.
//! - `aggregate/K modes`: `benches/physical.rs`'s aggregate (default grain, four impacts
//!   in flight, 300 events/s, 4 800 samples in 128-frame blocks) against a plain C
//!   crumpling loop: the same Poisson process, energies, sizes and pool of four hammers
//!   on banks of the same modes, every slot run every sample.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use underfoot::engine::{self, EngineConfig, MaterialBank};
use underfoot::force::gait::nominal_step;
use underfoot::material::builtin::builtin;
use underfoot::physical::{
    Aggregate, AggregateParams, Impact, ImpactParams, ResonatorBank, Surface, SurfaceMode,
};
use underfoot::signal::noise::SplitMix64;
use underfoot::signal::{Biquad, Sos};
use underfoot::synthesis::{SynthModel, VoiceConfig};
use underfoot::units::{Newtons, SampleRate};
use underfoot_bench::anchors::{self, Bank, CImpact, Crumpling, Flavour, Hammer, Modes, Voices};
use underfoot_bench::{Samples, engine_walk_block, figure, surface_modes};

const RATE: SampleRate = SampleRate(48_000);
/// Criterion samples per bench; the ratios are medians over them.
const SAMPLES: usize = 40;

/// What one interleaved bench records: ours, and each C build that ran.
struct Rounds {
    ours: Samples,
    anchors: Vec<(Flavour, Samples)>,
}

impl Rounds {
    fn new() -> Self {
        Self {
            ours: Samples::default(),
            anchors: anchors::available()
                .into_iter()
                .map(|(f, _)| (f, Samples::default()))
                .collect(),
        }
    }

    /// Prints ours (its time per unit shown by `show`), then
    /// [`report_anchors`](Self::report_anchors), under `group`, `what`; `anchor` names
    /// what the C does.
    fn report_all(&self, group: &str, what: &str, anchor: &str, show: impl Fn(f64) -> String) {
        if let Some(t) = self.ours.median(SAMPLES) {
            figure(group, &format!("{what}: underfoot"), &show(t));
        }
        self.report_anchors(group, what, anchor, &show);
    }

    /// Prints each anchor's time and its ratio to ours.
    fn report_anchors(&self, group: &str, what: &str, anchor: &str, show: &dyn Fn(f64) -> String) {
        for (f, s) in &self.anchors {
            if let (Some(t), Some(r)) = (s.median(SAMPLES), s.ratio_to(&self.ours, SAMPLES)) {
                figure(group, &format!("{what}: {} {anchor}", f.label()), &show(t));
                figure(
                    group,
                    &format!("{what}: {} {anchor} / underfoot", f.label()),
                    &format!("{r:.2}x"),
                );
            }
        }
    }
}

fn per_block(t: f64) -> String {
    format!(
        "{:.1} us/block ({:.2}% of the 1.33 ms budget)",
        t * 1e6,
        100.0 * t / (64.0 / RATE.hz())
    )
}

fn per_sample(t: f64) -> String {
    format!("{:.2} ns/sample ({:.0} M samples/s)", t * 1e9, 1e-6 / t)
}

// ------------------------------------------------------------------------------------
// Engine

/// A resonant section of `f` Hz decaying in `tau` s, impulse invariant (`b = [0, r sin θ, 0]`).
fn mode_section(f: f64, tau: f64) -> Biquad {
    let r = (-1.0 / (tau * RATE.hz())).exp();
    let th = std::f64::consts::TAU * f / RATE.hz();
    Biquad {
        b: [0.0, r * th.sin(), 0.0],
        a: [1.0, -2.0 * r * th.cos(), r * r],
    }
}

/// An RBJ low-pass (`high == false`) or high-pass section.
fn pass_section(f: f64, q: f64, high: bool) -> Biquad {
    let w = std::f64::consts::TAU * f / RATE.hz();
    let (c, alpha) = (w.cos(), w.sin() / (2.0 * q));
    let a0 = 1.0 + alpha;
    let b = if high {
        [(1.0 + c) / 2.0, -(1.0 + c), (1.0 + c) / 2.0]
    } else {
        [(1.0 - c) / 2.0, 1.0 - c, (1.0 - c) / 2.0]
    };
    Biquad {
        b: b.map(|x| x / a0),
        a: [1.0, -2.0 * c / a0, (1.0 - alpha) / a0],
    }
}

/// Voice `v`'s 8 modes then its post filter (a fourth-order low-pass, a DC blocker): an
/// order-16 material's voice, each voice a little apart.
fn voice_sections(v: usize) -> Vec<Biquad> {
    let mut s: Vec<Biquad> = (0..8)
        .map(|k| {
            let f = 80.0 * 1.45f64.powi(k) * (1.0 + 0.01 * v as f64);
            mode_section(f, 6.0 / f + 0.01)
        })
        .collect();
    s.push(pass_section(900.0, 0.541, false));
    s.push(pass_section(900.0, 1.307, false));
    s.push(pass_section(20.0, std::f64::consts::FRAC_1_SQRT_2, true));
    s
}

fn voice_rows(voices: usize) -> Vec<f32> {
    (0..voices)
        .flat_map(voice_sections)
        .flat_map(|s| [s.b[0], s.b[1], s.b[2], s.a[1], s.a[2]].map(|x| x as f32))
        .collect()
}

/// The C voices against underfoot's own second-order sections (f64) on the same input:
/// the anchor computes every section it claims to.
fn check_voices(api: &'static anchors::Api, label: &str) {
    let (voices, frames) = (2, 4_096);
    let mut rng = SplitMix64::new(7);
    let input: Vec<f32> = (0..voices * frames)
        .map(|_| rng.symmetric() as f32)
        .collect();
    let mut out = vec![0.0f32; voices * frames];
    let mut c = Voices::new(api, voices, &voice_rows(voices));
    // One long block: the loop is the same whatever the block length.
    c.process(voices, &input, &mut out);
    for v in 0..voices {
        // The coefficients as the C has them (f32), so that only the arithmetic differs.
        let sections: Vec<Biquad> = voice_sections(v)
            .into_iter()
            .map(|s| Biquad {
                b: s.b.map(|x| f64::from(x as f32)),
                a: s.a.map(|x| f64::from(x as f32)),
            })
            .collect();
        let x: Vec<f64> = input[v * frames..(v + 1) * frames]
            .iter()
            .map(|&s| f64::from(s))
            .collect();
        let mut sum = vec![0.0; frames];
        for m in &sections[..8] {
            let mut y = x.clone();
            Sos::new(vec![*m]).filter_in_place(&mut y);
            sum.iter_mut().zip(&y).for_each(|(s, y)| *s += y);
        }
        Sos::new(sections[8..].to_vec()).filter_in_place(&mut sum);
        let c_out: Vec<f64> = (0..frames)
            .map(|n| f64::from(out[n * voices + v]))
            .collect();
        let err = rms_diff(&c_out, &sum) / rms(&sum);
        assert!(
            // f32 arithmetic in resonant sections of poles near 1 (measured 3e-4).
            rms(&sum) > 0.0 && err < 2e-3,
            "{label} voices disagree with underfoot's sections: relative RMS error {err:.2e}"
        );
    }
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

fn rms_diff(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
}

fn engine(c: &mut Criterion) {
    const CHANNELS: usize = 16;
    for (f, api) in anchors::available() {
        check_voices(api, f.label());
    }
    let mut group = c.benchmark_group("vs C engine");
    group.sample_size(SAMPLES);
    for model in [SynthModel::Iir, SynthModel::Physical] {
        // The engine as `benches/engine.rs` builds it.
        let bank = MaterialBank::prepare(
            builtin(),
            RATE,
            &VoiceConfig {
                model,
                ..VoiceConfig::default()
            },
            &nominal_step(70.0, 1.8, RATE.hz()),
            Newtons::weight_of(70.0),
        )
        .unwrap();
        let config = EngineConfig {
            channels: CHANNELS,
            max_block: 64,
            ..EngineConfig::default()
        };
        let initial: Vec<u16> = (0..CHANNELS).map(|c| (c % 11) as u16).collect();
        let (mut ctl, mut eng) = engine::build(&config, bank, &initial).unwrap();
        let mut out = vec![0.0f32; 64 * CHANNELS];
        let mut block = 0u64;
        // The C voices' input: a different stretch of noise each block, as a walk's
        // excitation changes (the C loop has no branch on it: any input costs the same).
        let mut rng = SplitMix64::new(3);
        let noise: Vec<f32> = (0..64 * CHANNELS * 16)
            .map(|_| rng.symmetric() as f32)
            .collect();
        let mut voices: Vec<Voices> = anchors::available()
            .into_iter()
            .map(|(_, api)| Voices::new(api, CHANNELS, &voice_rows(CHANNELS)))
            .collect();
        let mut c_out = vec![0.0f32; 64 * CHANNELS];
        let mut rounds = Rounds::new();
        let what = match model {
            SynthModel::Iir => "16 channels, 64 frames, IIR",
            SynthModel::Physical => "16 channels, 64 frames, physical",
        };
        group.bench_function(what, |b| {
            b.iter_custom(|iterations| {
                let mut total = std::time::Duration::ZERO;
                for ((_, samples), v) in rounds.anchors.iter_mut().zip(&mut voices) {
                    let mut k = 0;
                    total += samples.time(iterations, || {
                        let at = (k % 16) * 64 * CHANNELS;
                        k += 1;
                        v.process(
                            CHANNELS,
                            black_box(&noise[at..at + 64 * CHANNELS]),
                            &mut c_out,
                        );
                        black_box(&c_out);
                        1
                    });
                }
                total += rounds.ours.time(iterations, || {
                    engine_walk_block(&mut ctl, &mut eng, &mut out, CHANNELS, block);
                    block += 1;
                    1
                });
                total
            });
        });
        rounds.report_all(
            "engine",
            what,
            "16 voices of 8 parallel + 3 series biquads",
            per_block,
        );
    }
    group.finish();
}

// ------------------------------------------------------------------------------------
// Impact and aggregate

const STRIKE_EVERY: usize = 4_800;

fn c_modes(modes: &[SurfaceMode]) -> Modes {
    Modes {
        frequency: modes.iter().map(|m| m.frequency.0).collect(),
        decay: modes.iter().map(|m| m.decay.0).collect(),
        gain: modes.iter().map(|m| m.gain).collect(),
    }
}

fn hammer(p: &ImpactParams) -> Hammer {
    Hammer {
        mass: p.mass,
        stiffness: p.stiffness,
        alpha: p.alpha,
        damping: p.damping,
    }
}

/// A force pulse of the contact's length (3.9 ms, half a sine) then silence, as impulses
/// (N·s per sample): what drives the C bank alone.
fn pulse() -> Vec<f64> {
    let len = (0.0039 * RATE.hz()) as usize;
    let mut x = vec![0.0; STRIKE_EVERY];
    for (n, v) in x[..len].iter_mut().enumerate() {
        *v = 1e3 * (std::f64::consts::PI * (n as f64 + 0.5) / len as f64).sin() / RATE.hz();
    }
    x
}

/// The C bank against underfoot's `ResonatorBank` (velocity before each impulse, as
/// `velocity()` then `tick(J)`), and the C impact against underfoot's: the same modes
/// ring the same way, and the C hammer's strike is the same strike (its explicit contact
/// is not underfoot's implicit one, so within 10 % in RMS).
fn check_impact(api: &'static anchors::Api, label: &str, modes: &[SurfaceMode], p: ImpactParams) {
    let x = pulse();
    let mut bank = ResonatorBank::new(modes, RATE).unwrap();
    let ours: Vec<f64> = x
        .iter()
        .map(|&j| {
            let v = bank.velocity();
            bank.tick(j);
            v
        })
        .collect();
    let mut c_out = vec![0.0f32; x.len()];
    Bank::new(api, &c_modes(modes), RATE.hz()).process(&x, &mut c_out);
    let c_out: Vec<f64> = c_out.iter().map(|&v| f64::from(v)).collect();
    let err = rms_diff(&c_out, &ours) / rms(&ours);
    assert!(
        rms(&ours) > 0.0 && err < 1e-6,
        "{label} bank of {} modes disagrees with underfoot's: relative RMS error {err:.2e}",
        modes.len()
    );
    let mut impact = Impact::new(
        p,
        Surface::Resonant(ResonatorBank::new(modes, RATE).unwrap()),
        RATE,
    )
    .unwrap();
    let mut ours = vec![0.0f32; STRIKE_EVERY];
    impact.process(&mut ours);
    let mut c = CImpact::new(api, &c_modes(modes), RATE.hz(), hammer(&p));
    c.strike(p.velocity);
    let mut theirs = vec![0.0f32; STRIKE_EVERY];
    c.process(&mut theirs);
    let (a, b) = (
        rms(&ours.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()),
        rms(&theirs.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()),
    );
    assert!(
        a > 0.0 && (b / a - 1.0).abs() < 0.1,
        "{label} impact on {} modes is not underfoot's strike: RMS {b:.3e} against {a:.3e}",
        modes.len()
    );
}

fn impact(c: &mut Criterion) {
    let params = ImpactParams {
        mass: 0.5,
        stiffness: 1e7,
        alpha: 1.5,
        damping: 1e5,
        velocity: 1.0,
    };
    let mut group = c.benchmark_group("vs C impact");
    group.sample_size(SAMPLES);
    let x = pulse();
    for n in [3, 16] {
        let modes = surface_modes(n);
        for (f, api) in anchors::available() {
            check_impact(api, f.label(), &modes, params);
        }
        let mut ours = Impact::new(
            params,
            Surface::Resonant(ResonatorBank::new(&modes, RATE).unwrap()),
            RATE,
        )
        .unwrap();
        let mut out = vec![0.0f32; STRIKE_EVERY];
        let cm = c_modes(&modes);
        let mut banks: Vec<Bank> = anchors::available()
            .into_iter()
            .map(|(_, api)| Bank::new(api, &cm, RATE.hz()))
            .collect();
        let mut impacts: Vec<CImpact> = anchors::available()
            .into_iter()
            .map(|(_, api)| CImpact::new(api, &cm, RATE.hz(), hammer(&params)))
            .collect();
        let mut bank_rounds = Rounds::new();
        let mut contact_rounds = Rounds::new();
        let units = STRIKE_EVERY as u64;
        let what = format!("impact, {n} modes");
        group.bench_function(&what, |b| {
            b.iter_custom(|iterations| {
                let mut total = std::time::Duration::ZERO;
                for ((_, samples), bank) in bank_rounds.anchors.iter_mut().zip(&mut banks) {
                    total += samples.time(iterations, || {
                        for (x, y) in x.chunks(128).zip(out.chunks_mut(128)) {
                            bank.process(black_box(x), y);
                        }
                        black_box(&out);
                        units
                    });
                }
                for ((_, samples), imp) in contact_rounds.anchors.iter_mut().zip(&mut impacts) {
                    total += samples.time(iterations, || {
                        imp.strike(black_box(1.0));
                        for y in out.chunks_mut(128) {
                            imp.process(y);
                        }
                        black_box(&out);
                        units
                    });
                }
                total += bank_rounds.ours.time(iterations, || {
                    ours.strike(black_box(1.0)).expect("valid velocity");
                    for y in out.chunks_mut(128) {
                        ours.process(y);
                    }
                    black_box(&out);
                    units
                });
                total
            });
        });
        contact_rounds.ours = bank_rounds.ours.clone();
        bank_rounds.report_all("impact", &what, "resonators alone", per_sample);
        contact_rounds.report_anchors("impact", &what, "with a Hunt-Crossley contact", &per_sample);
    }
    group.finish();
}

fn aggregate(c: &mut Criterion) {
    let params = AggregateParams::default();
    let mut group = c.benchmark_group("vs C aggregate");
    group.sample_size(SAMPLES);
    let rates = vec![300.0f32; STRIKE_EVERY];
    for n in [3, 16] {
        let modes = surface_modes(n);
        let cm = c_modes(&modes);
        let new_c = |api| {
            Crumpling::new(
                api,
                &cm,
                RATE.hz(),
                hammer(&params.impact),
                params.impact.velocity,
                params.size_spread,
                params.impacts_in_flight,
                1,
            )
        };
        // Ten seconds of both: the same Poisson process (events within five standard
        // deviations of the 3000 expected) and strikes of the same size (RMS within a
        // factor of two: the contacts' discretisations differ).
        for (f, api) in anchors::available() {
            let mut ours = Aggregate::new(&modes, &params, RATE, 1).unwrap();
            let mut theirs = new_c(api);
            let (mut a, mut b) = (vec![0.0f32; 480_000], vec![0.0f32; 480_000]);
            let rate = vec![300.0f32; a.len()];
            ours.process(&rate, &mut a);
            theirs.process(&rate, &mut b);
            let (ra, rb) = (
                rms(&a.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()),
                rms(&b.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()),
            );
            for events in [ours.events(), theirs.events()] {
                assert!(
                    events.abs_diff(3_000) < 275,
                    "{} crumpling on {n} modes: {events} events in 10 s at 300/s",
                    f.label()
                );
            }
            assert!(
                ra > 0.0 && (0.5..2.0).contains(&(rb / ra)),
                "{} crumpling on {n} modes is not underfoot's: RMS {rb:.3e} against {ra:.3e}",
                f.label()
            );
        }
        let mut ours = Aggregate::new(&modes, &params, RATE, 1).unwrap();
        let mut crumplings: Vec<Crumpling> = anchors::available()
            .into_iter()
            .map(|(_, api)| new_c(api))
            .collect();
        let mut out = vec![0.0f32; STRIKE_EVERY];
        let mut rounds = Rounds::new();
        let units = STRIKE_EVERY as u64;
        let what = format!("aggregate, {n} modes");
        group.bench_function(&what, |b| {
            b.iter_custom(|iterations| {
                let mut total = std::time::Duration::ZERO;
                for ((_, samples), c) in rounds.anchors.iter_mut().zip(&mut crumplings) {
                    total += samples.time(iterations, || {
                        for (r, y) in rates.chunks(128).zip(out.chunks_mut(128)) {
                            c.process(black_box(r), y);
                        }
                        black_box(&out);
                        units
                    });
                }
                total += rounds.ours.time(iterations, || {
                    for (r, y) in rates.chunks(128).zip(out.chunks_mut(128)) {
                        ours.process(black_box(r), y);
                    }
                    black_box(&out);
                    units
                });
                total
            });
        });
        rounds.report_all("aggregate", &what, "crumpling loop", per_sample);
    }
    group.finish();
}

fn announce(_: &mut Criterion) {
    anchors::announce();
}

criterion_group!(benches, announce, engine, impact, aggregate);
criterion_main!(benches);
