use super::*;
use crate::force::drive::DriveKind;
use crate::material::builtin::builtin;
use crate::signal::noise::SplitMix64;
use crate::units::Seconds;
use crate::units::{Hz, SampleRate};
use num_complex::Complex64;

fn prepared(name: &str) -> PreparedMaterial {
    let model = builtin().get(name).unwrap();
    PreparedMaterial::prepare(model, SampleRate(48_000), &VoiceConfig::default()).unwrap()
}

/// The DFT at each of `grid`'s frequencies of `n` samples of what `voice` plays for a
/// unit impulse, from rest.
fn impulse_spectrum(voice: &mut Voice, rate: SampleRate, n: usize, grid: &[Hz]) -> Vec<Complex64> {
    let mut x = vec![0.0f32; n];
    x[0] = 1.0;
    let mut y = vec![0.0f32; n];
    voice.reset();
    voice.process(&x, &mut y);
    grid.iter()
        .map(|f| {
            let omega = rate.omega(*f);
            y.iter()
                .enumerate()
                .map(|(k, v)| f64::from(*v) * Complex64::from_polar(1.0, -omega * k as f64))
                .sum()
        })
        .collect()
}

#[test]
fn voice_runs_its_prepared_response() {
    let m = prepared("gravel");
    let mut voice = Voice::new();
    voice.load(&m, DriveKind::Impulse);
    let n = 1 << 16;
    let mut x = vec![0.0f32; n];
    x[0] = 1.0;
    let mut y = vec![0.0f32; n];
    assert_eq!(voice.process(&x, &mut y), 0);
    // A naive DFT of the impulse response at a few frequencies against the model.
    for f in [40.0, 100.0, 250.0, 500.0] {
        let omega = SampleRate(48_000).omega(Hz(f));
        let dft: Complex64 = y
            .iter()
            .enumerate()
            .map(|(k, v)| f64::from(*v) * Complex64::from_polar(1.0, -omega * k as f64))
            .sum();
        // The voice plays at the material's level; the response is the filter's.
        let want = m.response(omega) * f64::from(m.level);
        let err = (dft - want).norm() / want.norm();
        assert!(err < 5e-3, "{f} Hz: {dft} vs {want} ({err})");
    }
}

/// The rate change and the post filter together: every built-in material's voice at
/// 48 kHz has its model's response (times the rate ratio) across the band.
#[test]
fn every_builtin_voice_matches_its_model_in_the_band() {
    let rate = SampleRate(48_000);
    for model in &builtin().materials {
        let m = PreparedMaterial::prepare(model, rate, &VoiceConfig::default()).unwrap();
        let sos = model.sos().unwrap();
        let ratio = rate.hz() / model.sample_rate.hz();
        let grid = model.band_hz.log_grid(96);
        let db: Vec<f64> = grid
            .iter()
            .map(|f| {
                let want = sos.response(model.sample_rate.omega(*f)).norm() * ratio;
                20.0 * (m.response(rate.omega(*f)).norm() / want).log10()
            })
            .collect();
        let lsd = (db.iter().map(|d| d * d).sum::<f64>() / db.len() as f64).sqrt();
        // The low-pass sits on the band's top edge; below 80% of it the match is close.
        let inner = grid
            .iter()
            .zip(&db)
            .filter(|(f, _)| f.0 < 0.8 * model.band_hz.hi.0)
            .map(|(_, d)| d.abs())
            .fold(0.0, f64::max);
        println!("{}: lsd {lsd:.2} dB, worst {inner:.2} dB", model.name);
        // Within 0.5 dB RMS: wood and glass, whose fits lean on the aliases of broad modes
        // near the 1 kHz Nyquist frequency, were 1.26 and 0.72 dB (2.4 dB worst) before
        // two modes above the band stood in for those aliases (0.23 and 0.02 dB now).
        // Sand's worst (1.35 dB) is on a narrow notch, under the threshold for them.
        assert!(
            lsd < 0.5 && inner < 1.5,
            "{}: lsd {lsd:.2} dB, worst {inner:.2} dB",
            model.name
        );
    }
}

/// Every step sounds a little different: the magnitude spectrum of each perturbed
/// step differs from the unperturbed one by a few percent (RMS over the band), and
/// no two steps are alike.
#[test]
fn each_step_has_its_own_spectrum_a_few_percent_off() {
    let rate = SampleRate(48_000);
    let model = builtin().get("gravel").unwrap();
    let m = PreparedMaterial::prepare(model, rate, &VoiceConfig::default()).unwrap();
    let grid = model.band_hz.log_grid(48);
    let n = rate.samples_in(Seconds(0.5));
    let spectrum = |voice: &mut Voice| -> Vec<f64> {
        impulse_spectrum(voice, rate, n, &grid)
            .iter()
            .map(|h| h.norm())
            .collect()
    };
    let mut voice = Voice::new();
    voice.load(&m, DriveKind::Impulse);
    let base = spectrum(&mut voice);
    let mut rng = SplitMix64::new(11);
    let mut steps = Vec::new();
    for _ in 0..20 {
        voice.perturb(&mut rng, 0.01);
        steps.push(spectrum(&mut voice));
    }
    let rel = |a: &[f64], b: &[f64]| {
        (a.iter()
            .zip(b)
            .map(|(x, y)| ((x - y) / y).powi(2))
            .sum::<f64>()
            / a.len() as f64)
            .sqrt()
    };
    let changes: Vec<f64> = steps.iter().map(|s| rel(s, &base)).collect();
    let mean = changes.iter().sum::<f64>() / changes.len() as f64;
    assert!(
        changes.iter().all(|c| (0.002..0.1).contains(c)),
        "{changes:?}"
    );
    assert!((0.005..0.05).contains(&mean), "mean change {mean}");
    for i in 0..steps.len() {
        for j in i + 1..steps.len() {
            assert!(rel(&steps[i], &steps[j]) > 1e-3, "steps {i} and {j} alike");
        }
    }
    println!(
        "per-step spectral change: mean {:.2}%, max {:.2}%",
        100.0 * mean,
        100.0 * changes.iter().fold(0.0f64, |m, c| m.max(*c))
    );
}

#[test]
fn perturbation_keeps_poles_and_changes_numerators_by_about_one_percent() {
    let m = prepared("snow");
    let mut voice = Voice::new();
    voice.load(&m, DriveKind::Impulse);
    let poles: Vec<_> = voice.poles().collect();
    let mut rng = SplitMix64::new(3);
    let mut ratios = Vec::new();
    for _ in 0..200 {
        voice.perturb(&mut rng, 0.01);
        assert_eq!(voice.poles().collect::<Vec<_>>(), poles);
        let (re, _, _) = voice.numerators();
        for (k, r) in re.iter().enumerate() {
            if m.res_re[k] != 0.0 {
                ratios.push(f64::from(r / m.res_re[k]) - 1.0);
            }
        }
    }
    let sd = (ratios.iter().map(|r| r * r).sum::<f64>() / ratios.len() as f64).sqrt();
    assert!((sd - 0.01).abs() < 0.001, "{sd}");
}

/// The per-step perturbation makes steps differ without moving their average spectrum:
/// for every built-in with one, the power spectrum averaged over perturbed steps of the
/// voice itself (a DFT of what it plays, not the sizing's residue sum) stays within
/// about the sizing's 0.5 dB of the unperturbed voice's.
#[test]
fn the_perturbation_leaves_the_average_spectrum_where_it_was() {
    let rate = SampleRate(48_000);
    let n = rate.samples_in(Seconds(0.25));
    for model in &builtin().materials {
        let m = PreparedMaterial::prepare(model, rate, &VoiceConfig::default()).unwrap();
        if m.perturbation <= 0.0 {
            continue;
        }
        let grid = model.band_hz.log_grid(40);
        let power = |voice: &mut Voice| -> Vec<f64> {
            impulse_spectrum(voice, rate, n, &grid)
                .iter()
                .map(|h| h.norm_sqr())
                .collect()
        };
        let mut voice = Voice::new();
        voice.load(&m, DriveKind::Impulse);
        let plain = power(&mut voice);
        let mut rng = SplitMix64::new(5);
        let draws = 64;
        let mut average = vec![0.0; plain.len()];
        for _ in 0..draws {
            voice.load(&m, DriveKind::Impulse);
            voice.perturb(&mut rng, m.perturbation);
            for (a, p) in average.iter_mut().zip(power(&mut voice)) {
                *a += p / f64::from(draws);
            }
        }
        let d: Vec<f64> = average
            .iter()
            .zip(&plain)
            .map(|(a, p)| 10.0 * (a / p).log10())
            .collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let bias = (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
        println!("{}: σ {:.3}, bias {bias:.2} dB", model.name, m.perturbation);
        assert!(
            bias < 0.75,
            "{}: {bias:.2} dB at σ {}",
            model.name,
            m.perturbation
        );
    }
}

/// Eight voices in lanes give, to the bit, what each gives alone: every built-in material
/// (from 2 to 16 modes, 3 or 4 post sections), numerators perturbed at random steps, the
/// voices' flush clocks out of phase, blocks of random lengths, a lane or two left out
/// at times, and a non-finite input that resets one lane and not the others. Both the
/// baseline and (where the processor has it) the AVX copy of the loop.
#[test]
fn voices_in_lanes_play_what_they_play_alone() {
    let rate = SampleRate(48_000);
    let materials: Vec<PreparedMaterial> = builtin()
        .materials
        .iter()
        .map(|m| PreparedMaterial::prepare(m, rate, &VoiceConfig::default()).unwrap())
        .collect();
    for mut lanes in [VoiceLanes::new(), VoiceLanes::baseline()] {
        let mut rng = SplitMix64::new(7);
        let mut alone: Vec<Voice> = (0..LANE_WIDTH)
            .map(|c| {
                let mut v = Voice::new();
                v.load(&materials[(c * 3) % materials.len()], DriveKind::Impulse);
                v
            })
            .collect();
        // Out of phase: each voice has run a different number of samples before.
        for (c, v) in alone.iter_mut().enumerate() {
            let warm = vec![0.1f32; 9 * c + 1];
            let mut out = vec![0.0f32; warm.len()];
            v.process(&warm, &mut out);
        }
        let mut laned = alone.clone();
        let mut resets_alone = 0;
        let mut resets_laned = 0;
        for block in 0..400 {
            let n = 1 + (rng.uniform() * 130.0) as usize;
            let inputs: Vec<Vec<f32>> = (0..LANE_WIDTH)
                .map(|c| {
                    (0..n)
                        .map(|i| {
                            if block == 123 && c == 5 && i == n / 2 {
                                f32::NAN
                            } else if rng.uniform() < 0.01 {
                                (rng.uniform() * 2.0) as f32
                            } else {
                                0.0
                            }
                        })
                        .collect()
                })
                .collect();
            if rng.uniform() < 0.1 {
                let c = (rng.uniform() * LANE_WIDTH as f64) as usize;
                alone[c].perturb(&mut SplitMix64::new(block), 0.05);
                laned[c].perturb(&mut SplitMix64::new(block), 0.05);
            }
            let skip = (rng.uniform() < 0.2).then(|| (rng.uniform() * LANE_WIDTH as f64) as usize);
            // At times a single voice: it runs alone, and must go on where the lanes left it.
            let only = (rng.uniform() < 0.1).then(|| (rng.uniform() * LANE_WIDTH as f64) as usize);
            let runs = |c: usize| Some(c) != skip && only.is_none_or(|o| o == c);
            let mut want = vec![vec![0.0f32; n]; LANE_WIDTH];
            for (c, v) in alone.iter_mut().enumerate() {
                if runs(c) {
                    resets_alone += v.process(&inputs[c], &mut want[c]);
                }
            }
            let mut got = vec![vec![0.0f32; n]; LANE_WIDTH];
            let mut args: [Option<Lane<'_>>; LANE_WIDTH] = Default::default();
            for (((arg, v), input), output) in args
                .iter_mut()
                .zip(laned.iter_mut())
                .zip(&inputs)
                .zip(got.iter_mut())
                .enumerate()
                .filter(|(c, _)| runs(*c))
                .map(|(_, x)| x)
            {
                *arg = Some(Lane {
                    voice: v,
                    input,
                    output,
                });
            }
            resets_laned += lanes.process(&mut args);
            for c in 0..LANE_WIDTH {
                for (i, (w, g)) in want[c].iter().zip(&got[c]).enumerate() {
                    assert!(
                        w.to_bits() == g.to_bits() || (*w == 0.0 && *g == 0.0),
                        "block {block}, lane {c}, sample {i}: {w} alone, {g} in lanes"
                    );
                }
            }
        }
        assert_eq!(resets_alone, 1);
        assert_eq!(resets_laned, 1);
    }
}
