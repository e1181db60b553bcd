//! The exported C header, compiled with the system C compiler and run against the Rust
//! cascades and excitation generator, for every built-in material.
//!
//! The compiler is `$CC` or `cc`; without one the test is skipped with a message, unless
//! `UNDERFOOT_REQUIRE_CC=1` (CI sets it).

use std::path::Path;
use std::process::Command;

use underfoot::excitation::clock::nominal_speeds;
use underfoot::excitation::{Generator, MAX_DRAWS, Tables};
use underfoot::export::{self, ExportConfig, c};
use underfoot::material::builtin::builtin;
use underfoot::numeric::dtft;
use underfoot::safety::{Limiter, LimiterReport};
use underfoot::signal::fixed::{
    F32State, Q15State, Q31State, f32_cascade, q15_cascade, q31_cascade, to_q15, to_q31,
};
use underfoot::signal::noise::SplitMix64;
use underfoot::units::{Decibels, SampleRate, Seconds};

const DRIVER: &str = r#"
#define UNDERFOOT_IMPLEMENTATION
#include "materials.h"
#include <stdio.h>
#include <stdlib.h>

/* driver NAME N IN OUT CEILING_BITS RELEASE_BITS: IN holds n f32, n int16, n int32;
 * OUT gets the f32, Q15 and Q31 cascades' outputs, the limited f32 output, and the Q15
 * cascade's output times the material's fixed-point gain. */
int main(int argc, char **argv) {
    const uf_material *m;
    FILE *in, *out;
    long n, i;
    float *xf, *yf, *yl;
    int16_t *x15;
    int32_t *y15, *x31, *y31, *g15;
    uf_f32_state sf[UF_MAX_SECTIONS], bf[UF_MAX_SECTIONS];
    uf_q15_state s15[UF_MAX_SECTIONS], b15[UF_MAX_SECTIONS];
    uf_q31_state s31[UF_MAX_SECTIONS], b31[UF_MAX_SECTIONS];
    float blockf[7];
    int32_t block15[7], block31[7];
    uf_limiter lim;
    union { uint32_t u; float f; } ceiling, release;
    if (argc != 7) return 2;
    m = uf_find(argv[1]);
    if (m == 0 || m->sections > UF_MAX_SECTIONS) return 3;
    n = atol(argv[2]);
    ceiling.u = (uint32_t)strtoul(argv[5], 0, 10);
    release.u = (uint32_t)strtoul(argv[6], 0, 10);
    xf = malloc(sizeof(float) * (size_t)n); yf = malloc(sizeof(float) * (size_t)n);
    yl = malloc(sizeof(float) * (size_t)n);
    x15 = malloc(sizeof(int16_t) * (size_t)n); y15 = malloc(sizeof(int32_t) * (size_t)n);
    x31 = malloc(sizeof(int32_t) * (size_t)n); y31 = malloc(sizeof(int32_t) * (size_t)n);
    g15 = malloc(sizeof(int32_t) * (size_t)n);
    if (!xf || !yf || !yl || !x15 || !y15 || !x31 || !y31 || !g15) return 4;
    in = fopen(argv[3], "rb");
    if (in == 0) return 5;
    if (fread(xf, sizeof(float), (size_t)n, in) != (size_t)n) return 6;
    if (fread(x15, sizeof(int16_t), (size_t)n, in) != (size_t)n) return 6;
    if (fread(x31, sizeof(int32_t), (size_t)n, in) != (size_t)n) return 6;
    fclose(in);
    uf_f32_reset(sf, m->sections);
    uf_q15_reset(s15, m->sections);
    uf_q31_reset(s31, m->sections);
    uf_limiter_init(&lim, ceiling.f, release.f);
    for (i = 0; i < n; ++i) {
        yf[i] = uf_f32_cascade(m->f32, sf, m->sections, xf[i]);
        yl[i] = uf_limiter_tick(&lim, yf[i] * m->gain);
        y15[i] = m->q15 ? uf_q15_cascade(m->q15, s15, m->sections, x15[i]) : 0;
        y31[i] = m->q31 ? uf_q31_cascade(m->q31, s31, m->sections, x31[i]) : 0;
        g15[i] = uf_q31_gain(m, y15[i]);
    }
    /* The block functions, in blocks of 7 (one short at the end): the same bits. */
    uf_f32_reset(bf, m->sections);
    uf_q15_reset(b15, m->sections);
    uf_q31_reset(b31, m->sections);
    for (i = 0; i < n; i += 7) {
        unsigned len = (unsigned)(n - i < 7 ? n - i : 7), k;
        uf_f32_cascade_block(m->f32, bf, m->sections, xf + i, blockf, len);
        if (m->q15) uf_q15_cascade_block(m->q15, b15, m->sections, x15 + i, block15, len);
        if (m->q31) uf_q31_cascade_block(m->q31, b31, m->sections, x31 + i, block31, len);
        for (k = 0; k < len; ++k) {
            if (blockf[k] != yf[i + k] && !(blockf[k] != blockf[k] && yf[i + k] != yf[i + k])) return 8;
            if (m->q15 && block15[k] != y15[i + k]) return 8;
            if (m->q31 && block31[k] != y31[i + k]) return 8;
        }
    }
    out = fopen(argv[4], "wb");
    if (out == 0) return 7;
    fwrite(yf, sizeof(float), (size_t)n, out);
    fwrite(y15, sizeof(int32_t), (size_t)n, out);
    fwrite(y31, sizeof(int32_t), (size_t)n, out);
    fwrite(yl, sizeof(float), (size_t)n, out);
    fwrite(g15, sizeof(int32_t), (size_t)n, out);
    fclose(out);
    free(xf); free(yf); free(yl); free(x15); free(y15); free(x31); free(y31); free(g15);
    return 0;
}
"#;

const EXCITATION_DRIVER: &str = r#"
#define UNDERFOOT_IMPLEMENTATION
#include "materials.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void act(uf_excitation_state *st, const uf_material *m, unsigned char action, float intensity) {
    if (action == 1) uf_exc_strike(st, m, intensity);
    else if (action == 2) uf_exc_step(st, m, intensity);
    else if (action == 3) uf_exc_stop(st);
}

/* exc NAME N SEED IN OUT: IN holds n actions (uint8, before the sample: 0 none, 1 strike,
 * 2 step, 3 stop), n intensities and n clock speeds (float); OUT gets per sample the
 * excitation (float), the micro-impacts so far (uint64) and whether a step plays
 * (uint8). The block form, in place, in blocks of up to 7 cut at every action, must give
 * the same bits and end in the same state (exit 8 otherwise). */
int main(int argc, char **argv) {
    const uf_material *m;
    FILE *in, *out;
    long n, i, k, end;
    uint64_t seed, *events;
    unsigned char *action, *active;
    float *intensity, *speed, *y, block[7];
    uf_excitation_state st, bst;
    if (argc != 6) return 2;
    m = uf_find(argv[1]);
    if (m == 0 || m->excitation == 0) return 3;
    n = atol(argv[2]);
    seed = (uint64_t)strtoull(argv[3], 0, 10);
    action = malloc((size_t)n); active = malloc((size_t)n);
    intensity = malloc(sizeof(float) * (size_t)n); speed = malloc(sizeof(float) * (size_t)n);
    y = malloc(sizeof(float) * (size_t)n); events = malloc(sizeof(uint64_t) * (size_t)n);
    if (!action || !active || !intensity || !speed || !y || !events) return 4;
    in = fopen(argv[4], "rb");
    if (in == 0) return 5;
    if (fread(action, 1, (size_t)n, in) != (size_t)n) return 6;
    if (fread(intensity, sizeof(float), (size_t)n, in) != (size_t)n) return 6;
    if (fread(speed, sizeof(float), (size_t)n, in) != (size_t)n) return 6;
    fclose(in);
    uf_exc_init(&st, seed);
    for (i = 0; i < n; ++i) {
        act(&st, m, action[i], intensity[i]);
        y[i] = uf_exc_next(&st, m, speed[i]);
        events[i] = st.events;
        active[i] = st.active;
    }
    uf_exc_init(&bst, seed);
    for (i = 0; i < n; i = end) {
        act(&bst, m, action[i], intensity[i]);
        for (end = i + 1; end < n && end < i + 7 && action[end] == 0; ++end) {}
        for (k = i; k < end; ++k) block[k - i] = speed[k];
        uf_exc_block(&bst, m, block, block, (unsigned)(end - i));
        if (memcmp(block, y + i, sizeof(float) * (size_t)(end - i)) != 0) return 8;
        if (bst.events != events[end - 1]) return 8;
    }
    if (bst.rng != st.rng || bst.pos != st.pos || bst.step != st.step || bst.events != st.events
        || bst.gain != st.gain || bst.active != st.active || bst.heel_due != st.heel_due
        || bst.free_running != st.free_running) return 8;
    out = fopen(argv[5], "wb");
    if (out == 0) return 7;
    fwrite(y, sizeof(float), (size_t)n, out);
    fwrite(events, sizeof(uint64_t), (size_t)n, out);
    fwrite(active, 1, (size_t)n, out);
    fclose(out);
    free(action); free(active); free(intensity); free(speed); free(y); free(events);
    return 0;
}
"#;

fn compiler() -> Option<String> {
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".to_string());
    let found = Command::new(&cc)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if found {
        return Some(cc);
    }
    assert!(
        std::env::var("UNDERFOOT_REQUIRE_CC").as_deref() != Ok("1"),
        "UNDERFOOT_REQUIRE_CC=1 but no C compiler ({cc}) was found"
    );
    eprintln!(
        "firmware: no C compiler ({cc}) found; skipping (set CC, or UNDERFOOT_REQUIRE_CC=1 to fail)"
    );
    None
}

/// The excitation driver, compiled against `header`.
fn compile_excitation(cc: &str, dir: &Path, header: &str) -> std::path::PathBuf {
    std::fs::write(dir.join("materials.h"), header).unwrap();
    std::fs::write(dir.join("exc.c"), EXCITATION_DRIVER).unwrap();
    let exe = dir.join("exc");
    c99(cc, &dir.join("exc.c"), &exe, &["-O2"]);
    exe
}

fn compile(cc: &str, dir: &Path, header: &str) -> std::path::PathBuf {
    std::fs::write(dir.join("materials.h"), header).unwrap();
    std::fs::write(dir.join("driver.c"), DRIVER).unwrap();
    // The header on its own, without the implementation, must compile cleanly too.
    std::fs::write(
        dir.join("plain.c"),
        "#include \"materials.h\"\nint main(void) { return UF_MATERIAL_COUNT == 0; }\n",
    )
    .unwrap();
    let exe = dir.join("driver");
    c99(cc, &dir.join("driver.c"), &exe, &["-O2"]);
    c99(cc, &dir.join("plain.c"), &dir.join("plain"), &["-O2"]);
    exe
}

/// Compiles `src` to `out` as strict C99 with every warning an error, plus `flags`.
fn c99(cc: &str, src: &Path, out: &Path, flags: &[&str]) {
    let result = Command::new(cc)
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"])
        .args(flags)
        .arg("-o")
        .arg(out)
        .arg(src)
        .output()
        .unwrap();
    assert!(
        result.status.success(),
        "{cc} {}: {}",
        src.display(),
        String::from_utf8_lossy(&result.stderr)
    );
}

struct Outputs {
    f32: Vec<f32>,
    /// The Q15 cascade's output: Q31.
    q15: Vec<i32>,
    q31: Vec<i32>,
    limited: Vec<f32>,
    /// The Q15 cascade's output times the fixed-point gain.
    gained: Vec<i32>,
}

fn run(exe: &Path, dir: &Path, name: &str, x: &[f64], ceiling: f32, release: f32) -> Outputs {
    let n = x.len();
    let mut bytes = Vec::new();
    for v in x {
        bytes.extend((*v as f32).to_ne_bytes());
    }
    for v in x {
        bytes.extend(to_q15(*v as f32).to_ne_bytes());
    }
    for v in x {
        bytes.extend(to_q31(*v).to_ne_bytes());
    }
    let (input, output) = (dir.join("in.bin"), dir.join("out.bin"));
    std::fs::write(&input, bytes).unwrap();
    let status = Command::new(exe)
        .arg(name)
        .arg(n.to_string())
        .arg(&input)
        .arg(&output)
        .arg(ceiling.to_bits().to_string())
        .arg(release.to_bits().to_string())
        .status()
        .unwrap();
    assert!(status.success(), "driver on {name}: {status}");
    let out = std::fs::read(&output).unwrap();
    assert_eq!(out.len(), n * 20);
    let (f, rest) = out.split_at(4 * n);
    let (q15, rest) = rest.split_at(4 * n);
    let (q31, rest) = rest.split_at(4 * n);
    let (limited, gained) = rest.split_at(4 * n);
    Outputs {
        f32: f
            .chunks(4)
            .map(|c| f32::from_ne_bytes(c.try_into().unwrap()))
            .collect(),
        q15: q15
            .chunks(4)
            .map(|c| i32::from_ne_bytes(c.try_into().unwrap()))
            .collect(),
        q31: q31
            .chunks(4)
            .map(|c| i32::from_ne_bytes(c.try_into().unwrap()))
            .collect(),
        limited: limited
            .chunks(4)
            .map(|c| f32::from_ne_bytes(c.try_into().unwrap()))
            .collect(),
        gained: gained
            .chunks(4)
            .map(|c| i32::from_ne_bytes(c.try_into().unwrap()))
            .collect(),
    }
}

/// A drive-like input: a heel strike's force derivative (a raised-cosine pulse and its
/// rebound) with a little sensor noise, seeded; peak about 0.9.
fn drive(n: usize, seed: u64) -> Vec<f64> {
    let mut g = SplitMix64::new(seed);
    (0..n)
        .map(|i| {
            let t = i as f64 / 60.0;
            let pulse = if t < 2.0 {
                (std::f64::consts::PI * t).sin() * 0.85
            } else {
                0.0
            };
            pulse + 0.02 * g.symmetric()
        })
        .collect()
}

#[test]
#[ignore = "slow tier: compiles C"]
fn exported_c_matches_rust_for_every_builtin_material() {
    let Some(cc) = compiler() else { return };
    let library = builtin();
    // The default export (f32, Q15 and Q31) must pass its own check for every material.
    let exported = export::export_library(library, "built-in", &[], &ExportConfig::default())
        .expect("the built-in library exports with the default settings");
    assert!(exported.materials.iter().all(|m| m.with_q15 && m.with_q31));
    // Without Q15, Q31 is the same.
    let q31_only = ExportConfig {
        q15: false,
        ..ExportConfig::default()
    };
    let strict = export::export_library(library, "built-in", &[], &q31_only).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let exe = compile(&cc, dir.path(), &c::header(&exported));

    let rate = SampleRate(2000);
    // -20 dB: its nearest f32 is above it, so the C limiter, given the largest f32 not
    // above (`ceiling_amplitude`), must hold every sample under the exact ceiling.
    let ceiling = Decibels(-20.0);
    let release_time = Seconds(0.05);
    let release = (1.0 - (-1.0 / (release_time.0 * rate.hz())).exp()) as f32;

    for (m, strict_m) in exported.materials.iter().zip(&strict.materials) {
        assert_eq!(
            m.q31, strict_m.q31,
            "{}: Q31 does not depend on Q15",
            m.name
        );
        let n = m.impulse_samples;
        let mut impulse = vec![0.0; n];
        impulse[0] = 1.0;
        // The quietest level the export is checked at.
        let mut quiet = vec![0.0; n];
        quiet[0] = QUIET.to_amplitude();
        let mut quiet_drive = drive(n, 11);
        quiet_drive
            .iter_mut()
            .for_each(|v| *v *= QUIET.to_amplitude());
        for (what, x) in [
            ("impulse", impulse),
            ("drive", drive(n, 7)),
            ("-30 dBFS impulse", quiet),
            ("-30 dBFS drive", quiet_drive),
        ] {
            let got = run(
                &exe,
                dir.path(),
                &m.name,
                &x,
                underfoot::safety::ceiling_amplitude(ceiling),
                release,
            );
            // Rust, the same loops.
            let mut s15 = vec![Q15State::default(); m.q15.len()];
            let mut s31 = vec![Q31State::default(); m.q31.len()];
            let mut sf = vec![F32State::default(); m.f32.len()];
            let mut limiter = Limiter::new(ceiling, release_time, rate);
            let mut report = LimiterReport::default();
            let mut max_f32_err = 0.0f32;
            for (i, &xi) in x.iter().enumerate() {
                let y15 = q15_cascade(&m.q15, &mut s15, to_q15(xi as f32));
                let y31 = q31_cascade(&m.q31, &mut s31, to_q31(xi));
                let yf = f32_cascade(&m.f32, &mut sf, xi as f32);
                let yl = limiter.tick(got.f32[i] * m.gain as f32, &mut report);
                assert_eq!(got.q15[i], y15, "{} {what}: Q15 sample {i}", m.name);
                assert_eq!(got.q31[i], y31, "{} {what}: Q31 sample {i}", m.name);
                assert_eq!(got.limited[i], yl, "{} {what}: limiter sample {i}", m.name);
                assert!(f64::from(got.limited[i].abs()) <= ceiling.to_amplitude());
                // The fixed-point gain: the float gain within 2^-15 relative, plus the
                // shift's rounding (one unit, towards minus infinity).
                let want = f64::from(y15) * m.gain;
                let err = (f64::from(got.gained[i]) - want).abs();
                assert!(
                    want.abs() >= f64::from(i32::MAX) || err <= want.abs() * 2f64.powi(-15) + 1.0,
                    "{} {what}: gain sample {i}: {} for {want}",
                    m.name,
                    got.gained[i]
                );
                max_f32_err = max_f32_err.max((got.f32[i] - yf).abs());
            }
            let peak = got.f32.iter().fold(0.0f32, |p, v| p.max(v.abs()));
            assert!(
                max_f32_err <= 1e-5 * peak.max(1e-3),
                "{} {what}: f32 differs by {max_f32_err} (peak {peak})",
                m.name
            );
            if !what.ends_with("impulse") {
                continue;
            }
            // The C impulse responses against the f64 model over the band.
            let model = library.get(&m.name).unwrap();
            let reference = export_reference(m);
            let grid = model.band_hz.log_grid(256);
            let worst = |ir: Vec<f64>| {
                grid.iter()
                    .map(|&f| {
                        let w = model.sample_rate.omega(f);
                        (20.0 * (dtft(&ir, w).norm() / reference.response(w).norm()).log10()).abs()
                    })
                    .fold(0.0, f64::max)
            };
            // Each divided by the impulse actually fed.
            let (x15, x31) = (to_q15(x[0] as f32), to_q31(x[0]));
            let q31_db = worst(
                got.q31
                    .iter()
                    .map(|&v| f64::from(v) / f64::from(x31))
                    .collect(),
            );
            let q15_db = worst(
                got.q15
                    .iter()
                    .map(|&v| f64::from(v) / (f64::from(x15) * 65536.0))
                    .collect(),
            );
            let f32_db = worst(got.f32.iter().map(|&v| f64::from(v) / x[0]).collect());
            eprintln!(
                "{:<8} {what}: C impulse response vs f64 over the band: f32 {f32_db:.5} dB, Q15 {q15_db:.3} dB, Q31 {q31_db:.5} dB",
                m.name
            );
            assert!(q31_db <= 0.5, "{}: Q31 {q31_db} dB", m.name);
            assert!(f32_db <= 0.5, "{}: f32 {f32_db} dB", m.name);
            assert!(q15_db <= 0.5, "{}: Q15 {q15_db} dB", m.name);
        }
    }
}

/// The quietest level the export checks by default.
const QUIET: Decibels = Decibels(-30.0);

/// The float model the export is checked against: the scaled f64 sections.
fn export_reference(m: &export::Exported) -> underfoot::signal::Sos {
    underfoot::signal::Sos::new(m.sections.clone())
}

/// What happens before a sample of a scripted excitation (the driver's codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Act {
    None = 0,
    Strike = 1,
    Step = 2,
    Stop = 3,
}

/// A scripted input for the excitation: per sample, what happens before it and the
/// clock's speed at it.
#[derive(Default)]
struct Script {
    action: Vec<Act>,
    intensity: Vec<f32>,
    speed: Vec<f32>,
}

impl Script {
    /// `act` (of `intensity`) before the first of `speeds`.
    fn then(&mut self, act: Act, intensity: f32, speeds: &[f32]) -> &mut Self {
        assert!(!speeds.is_empty());
        for (k, &v) in speeds.iter().enumerate() {
            self.action.push(if k == 0 { act } else { Act::None });
            self.intensity.push(if k == 0 { intensity } else { 0.0 });
            self.speed.push(v);
        }
        self
    }
}

/// Every path of the generator at `rate`: the nominal walker's clock, a foot standing
/// still, speeds that count as 0 (NaN, negative, infinite) and the smallest that do not,
/// a ramp restruck mid-train, refused intensities, several draws a sample and more than
/// the cap, a clock thrown past the end of any profile, a free-running step, a stop and a
/// strike at once, and a tail for the cascades to ring out.
fn excitation_script(rate: SampleRate) -> Script {
    let nominal = nominal_speeds(rate);
    let ramp: Vec<f32> = (0..300u16).map(|k| f32::from(k) / 100.0).collect();
    let mut s = Script::default();
    s.then(Act::None, 0.0, &[1.0; 5])
        .then(Act::Strike, 1.0, &nominal)
        .then(Act::None, 0.0, &[1.0; 40])
        .then(Act::Stop, 0.0, &[1.0; 10])
        .then(Act::Strike, 0.7, &[0.0; 40])
        .then(
            Act::None,
            0.0,
            &[
                f32::NAN,
                -f32::NAN,
                -1.0,
                f32::INFINITY,
                f32::NEG_INFINITY,
                -0.0,
                f32::from_bits(1),
                f32::MIN_POSITIVE,
                1e-30,
            ],
        )
        .then(Act::None, 0.0, &ramp[..150])
        .then(Act::Strike, 1.3, &ramp[150..])
        .then(Act::None, 0.0, &[1.0; 400])
        .then(Act::Strike, 0.0, &[1.0])
        .then(Act::Strike, -1.0, &[1.0])
        .then(Act::Strike, f32::NAN, &[1.0])
        .then(Act::Step, f32::INFINITY, &[1.0])
        .then(Act::None, 0.0, &[1.0; 200])
        .then(Act::Strike, 1.0, &[50.0; 6])
        .then(Act::Strike, 1.0, &[1e5, 1.0])
        .then(Act::Strike, 1.0, &[1.0, f32::MAX, 1.0, 1.0])
        .then(Act::Step, 0.5, &[0.0; 300])
        .then(Act::None, 0.0, &[f32::NAN; 5])
        .then(Act::Strike, 0.0, &[0.0])
        .then(Act::None, 0.0, &[0.0; 800])
        .then(Act::Strike, 0.9, &nominal[..300])
        .then(Act::Stop, 0.0, &[1.0])
        .then(Act::Strike, 0.9, &nominal)
        .then(Act::Strike, 2.0, &nominal)
        .then(Act::None, 0.0, &[0.0; 1000]);
    s
}

/// A generator's output over a script.
#[derive(Debug, PartialEq)]
struct Excitation {
    y: Vec<f32>,
    /// Micro-impacts so far, after each sample.
    events: Vec<u64>,
    active: Vec<bool>,
}

fn rust_excitation(tables: &Tables, seed: u64, script: &Script) -> Excitation {
    let mut g = Generator::new(seed);
    let mut out = Excitation {
        y: Vec::new(),
        events: Vec::new(),
        active: Vec::new(),
    };
    for ((&act, &intensity), &speed) in script
        .action
        .iter()
        .zip(&script.intensity)
        .zip(&script.speed)
    {
        match act {
            Act::Strike => g.strike(tables, intensity),
            Act::Step => g.step(tables, intensity),
            Act::Stop => g.stop(),
            Act::None => {}
        }
        out.y.push(g.next(tables, speed));
        out.events.push(g.events());
        out.active.push(g.is_active());
    }
    out
}

/// The C generator over `script`, in single calls (the driver checks its blocks).
fn c_excitation(exe: &Path, dir: &Path, name: &str, seed: u64, script: &Script) -> Excitation {
    let n = script.speed.len();
    let mut bytes: Vec<u8> = script.action.iter().map(|&a| a as u8).collect();
    for v in &script.intensity {
        bytes.extend(v.to_ne_bytes());
    }
    for v in &script.speed {
        bytes.extend(v.to_ne_bytes());
    }
    let (input, output) = (dir.join("exc-in.bin"), dir.join("exc-out.bin"));
    std::fs::write(&input, bytes).unwrap();
    let status = Command::new(exe)
        .arg(name)
        .arg(n.to_string())
        .arg(seed.to_string())
        .arg(&input)
        .arg(&output)
        .status()
        .unwrap();
    assert!(status.success(), "excitation driver on {name}: {status}");
    let out = std::fs::read(&output).unwrap();
    assert_eq!(out.len(), n * 13);
    let (y, rest) = out.split_at(4 * n);
    let (events, active) = rest.split_at(8 * n);
    Excitation {
        y: y.chunks(4)
            .map(|c| f32::from_ne_bytes(c.try_into().unwrap()))
            .collect(),
        events: events
            .chunks(8)
            .map(|c| u64::from_ne_bytes(c.try_into().unwrap()))
            .collect(),
        active: active.iter().map(|&a| a != 0).collect(),
    }
}

/// A channel's seed: all 64 bits used.
fn seed(k: usize) -> u64 {
    0xC0FF_EE00_0000_0001u64.wrapping_mul(k as u64 + 1)
}

/// The exported generator is the Rust one in C: for every built-in material, the same seed
/// and the same calls (every path of [`excitation_script`]) give the same bits at every
/// sample, the same micro-impacts and the same end of each step, in single calls and (the
/// driver checks) in blocks.
#[test]
#[ignore = "slow tier: compiles C"]
fn exported_c_excitation_is_bit_identical_with_the_rust_generator() {
    let Some(cc) = compiler() else { return };
    let library = builtin();
    let exported =
        export::export_library(library, "built-in", &[], &ExportConfig::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let exe = compile_excitation(&cc, dir.path(), &c::header(&exported));
    let mut capped = false;
    for (k, m) in exported.materials.iter().enumerate() {
        let model = library.get(&m.name).unwrap();
        let tables = Tables::new(&model.excitation_or_heel(), model.sample_rate).unwrap();
        assert_eq!(m.excitation, tables, "{}: the tables exported", m.name);
        let script = excitation_script(model.sample_rate);
        let want = rust_excitation(&tables, seed(k), &script);
        let got = c_excitation(&exe, dir.path(), &m.name, seed(k), &script);
        for i in 0..script.speed.len() {
            assert_eq!(
                (got.y[i].to_bits(), got.events[i], got.active[i]),
                (want.y[i].to_bits(), want.events[i], want.active[i]),
                "{} sample {i}: C {} Rust {} (speed {}, {:?})",
                m.name,
                got.y[i],
                want.y[i],
                script.speed[i],
                script.action[i]
            );
        }
        // The script reached what it is there for.
        let total = *want.events.last().unwrap();
        let most = want.events.windows(2).map(|w| w[1] - w[0]).max().unwrap();
        let sounding = want.y.iter().filter(|y| **y != 0.0).count();
        eprintln!(
            "{:<8} {} samples, {total} micro-impacts (at most {most} a sample), {sounding} non-zero",
            m.name,
            want.y.len()
        );
        if tables.bins() > 0 {
            assert!(total > 0, "{}: no micro-impact", m.name);
            capped |= most == u64::from(MAX_DRAWS);
        } else {
            // The heels alone: one for each of the script's 10 steps that are played.
            assert_eq!((total, sounding), (0, 10), "{}", m.name);
        }
    }
    assert!(capped, "no material reached the cap of draws a sample");
}

/// The worst deviation (dB) over the model's band of `y`'s power spectrum from
/// `reference`'s, each summed over 4 stretches of the signal: a train's spectrum has
/// near-zeros at random frequencies, where a single DFT would weigh the rounding noise
/// instead of the filter.
fn band_deviation(y: &[f64], reference: &[f64], model: &underfoot::material::MaterialModel) -> f64 {
    let stretch = y.len().div_ceil(4);
    model
        .band_hz
        .log_grid(256)
        .iter()
        .map(|&f| {
            let w = model.sample_rate.omega(f);
            let power = |x: &[f64]| {
                x.chunks(stretch)
                    .map(|c| dtft(c, w).norm_sqr())
                    .sum::<f64>()
            };
            let d = (10.0 * (power(y) / power(reference)).log10()).abs();
            if d.is_nan() { f64::INFINITY } else { d }
        })
        .fold(0.0, f64::max)
}

/// The excitation through the exported cascades, in C: the float cascade gives the Rust
/// `f32` cascade's bits, Q15 and Q31 the Rust loops', and over the band each stays within
/// 0.5 dB of the float (f64) model fed the same excitation (rounded to its input format),
/// for every built-in material, loud (peaks at -12 to -6 dBFS) and 24 dB quieter.
#[test]
#[ignore = "slow tier: compiles C"]
fn excitation_through_the_exported_cascades_stays_within_half_a_db() {
    let Some(cc) = compiler() else { return };
    let library = builtin();
    let exported =
        export::export_library(library, "built-in", &[], &ExportConfig::default()).unwrap();
    let header = c::header(&exported);
    let dir = tempfile::tempdir().unwrap();
    let generator = compile_excitation(&cc, dir.path(), &header);
    let cascades = compile(&cc, dir.path(), &header);
    let full_scale = 2f64.powi(31);
    for (k, m) in exported.materials.iter().enumerate() {
        let model = library.get(&m.name).unwrap();
        let script = excitation_script(model.sample_rate);
        let e = c_excitation(&generator, dir.path(), &m.name, seed(k), &script);
        let peak = e.y.iter().fold(0.0f32, |p, v| p.max(v.abs()));
        assert!(peak > 0.0, "{}", m.name);
        // Powers of two, so that the float cascade gets the excitation's bits, scaled.
        let loud = 2f64.powi(-(f64::from(peak) / 0.5).log2().ceil() as i32);
        for (level, scale) in [("loud", loud), ("quiet", loud / 16.0)] {
            let x: Vec<f64> = e.y.iter().map(|&v| f64::from(v) * scale).collect();
            let got = run(&cascades, dir.path(), &m.name, &x, 0.5, 0.01);
            let mut sf = vec![F32State::default(); m.f32.len()];
            let mut s15 = vec![Q15State::default(); m.q15.len()];
            let mut s31 = vec![Q31State::default(); m.q31.len()];
            for (i, &xi) in x.iter().enumerate() {
                let yf = f32_cascade(&m.f32, &mut sf, xi as f32);
                assert_eq!(
                    got.f32[i].to_bits(),
                    yf.to_bits(),
                    "{} {level}: f32 sample {i}",
                    m.name
                );
                assert_eq!(
                    got.q15[i],
                    q15_cascade(&m.q15, &mut s15, to_q15(xi as f32)),
                    "{} {level}: Q15 sample {i}",
                    m.name
                );
                assert_eq!(
                    got.q31[i],
                    q31_cascade(&m.q31, &mut s31, to_q31(xi)),
                    "{} {level}: Q31 sample {i}",
                    m.name
                );
            }
            // Against the model fed what each format was fed.
            let reference = export_reference(m);
            let filtered = |input: Vec<f64>| {
                let mut y = input;
                reference.filter_in_place(&mut y);
                y
            };
            let to_f64 = |v: &[i32]| {
                v.iter()
                    .map(|&v| f64::from(v) / full_scale)
                    .collect::<Vec<_>>()
            };
            let f32_db = band_deviation(
                &got.f32.iter().map(|&v| f64::from(v)).collect::<Vec<_>>(),
                &filtered(x.iter().map(|&v| f64::from(v as f32)).collect()),
                model,
            );
            let q15_db = band_deviation(
                &to_f64(&got.q15),
                &filtered(
                    x.iter()
                        .map(|&v| f64::from(to_q15(v as f32)) / 32768.0)
                        .collect(),
                ),
                model,
            );
            let q31_db = band_deviation(
                &to_f64(&got.q31),
                &filtered(
                    x.iter()
                        .map(|&v| f64::from(to_q31(v)) / full_scale)
                        .collect(),
                ),
                model,
            );
            eprintln!(
                "{:<8} excitation ({level}, x{scale}) through C vs f64 over the band: f32 {f32_db:.5} dB, Q15 {q15_db:.3} dB, Q31 {q31_db:.5} dB",
                m.name
            );
            assert!(f32_db <= 0.5, "{} {level}: f32 {f32_db} dB", m.name);
            assert!(q15_db <= 0.5, "{} {level}: Q15 {q15_db} dB", m.name);
            assert!(q31_db <= 0.5, "{} {level}: Q31 {q31_db} dB", m.name);
        }
    }
}

#[test]
fn header_is_deterministic_and_names_the_library() {
    let library = builtin();
    let names = vec!["gravel".to_string()];
    let a = export::export_library(library, "built-in", &names, &ExportConfig::default()).unwrap();
    let b = export::export_library(library, "built-in", &names, &ExportConfig::default()).unwrap();
    let (ha, hb) = (c::header(&a), c::header(&b));
    assert_eq!(ha, hb);
    assert!(ha.contains(&a.library_sha256) && a.library_sha256.len() == 64);
    assert!(ha.contains("gravel") && !ha.contains("\"sand\""));
    assert!(ha.contains(env!("CARGO_PKG_VERSION")));
}

/// A small library: one hand-built resonant material, enough to cover every part of the
/// header (float, Q15 and Q31 tables, scaling, a short excitation, the implementation).
fn small_library() -> underfoot::material::Library {
    use underfoot::material::{FilterCoefficients, FitRecord, Library, MaterialModel};
    use underfoot::signal::{Biquad, Sos};
    use underfoot::units::{Band, Hz};
    let rate = SampleRate(2000);
    let band = Band::new(20.0, 900.0);
    let sos = Sos::new(vec![
        Biquad {
            b: [0.1, 0.0, -0.1],
            a: [1.0, -1.6, 0.81],
        },
        Biquad {
            b: [1.0, -1.2, 0.5],
            a: [1.0, -1.9, 0.95],
        },
    ]);
    let grid: Vec<f64> = band.log_grid(24).iter().map(|f| f.0).collect();
    let mag: Vec<f64> = grid
        .iter()
        .map(|&f| sos.response(rate.omega(Hz(f))).norm())
        .collect();
    let mut library = Library::new();
    library.upsert(MaterialModel {
        name: "test-tile".to_string(),
        sample_rate: rate,
        band_hz: band,
        order: sos.order(),
        filter: FilterCoefficients::from_sos(&sos),
        fit: FitRecord {
            grid_hz: grid,
            measured: mag.clone(),
            model: mag,
            nrmse: 0.0,
            lsd_db: 0.0,
            method: "hand-built".to_string(),
            poor_fit: false,
            strikes: 1,
            fit_seconds: 0.0,
            longest_decay: underfoot::units::Seconds(0.5),
            worst: None,
        },
        sources: Vec::new(),
        physical: None,
        // Half the energy in the heel, the rest in four bins of 2 micro-impacts each.
        excitation: Some(underfoot::excitation::ExcitationModel {
            heel: 0.5,
            bin_s: 0.005,
            rate_hz: vec![400.0; 4],
            energy: vec![0.125; 4],
            duration_spread: 0.1,
            amplitude_shape: 2.0,
            perturbation_db: 0.0,
        }),
        time: None,
        level_db: 0.0,
    });
    library
}

#[test]
fn header_of_a_small_library_matches_its_golden_file() {
    // To accept a deliberate change:
    // UNDERFOOT_BLESS=1 cargo test -p underfoot --test library firmware::
    let golden = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/small_materials.h");
    let exported = export::export_library(
        &small_library(),
        "small test library",
        &[],
        &ExportConfig::default(),
    )
    .expect("the small library passes in Q15 and Q31");
    let header = c::header(&exported);
    if std::env::var("UNDERFOOT_BLESS").as_deref() == Ok("1") {
        std::fs::create_dir_all(golden.parent().unwrap()).unwrap();
        std::fs::write(&golden, &header).unwrap();
    }
    let expected =
        std::fs::read_to_string(&golden).expect("golden header (UNDERFOOT_BLESS=1 writes it)");
    assert_eq!(
        header, expected,
        "the header changed; UNDERFOOT_BLESS=1 to accept"
    );
}

/// The symbols of a linked program (`nm`), or `None` without `nm`.
fn symbols(program: &Path) -> Option<Vec<String>> {
    let out = Command::new("nm").arg(program).output().ok()?;
    assert!(out.status.success(), "nm {}", program.display());
    Some(
        String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| l.split_whitespace().last().map(str::to_owned))
            .collect(),
    )
}

/// Unused materials and formats cost no flash: a program that plays one material in Q15,
/// built as the header says (`UF_NO_INDEX`, `UF_NO_F32`, `UF_NO_Q31`, per-section
/// objects, `--gc-sections`), keeps that material's Q15 table and nothing of the other
/// materials, formats or the index; the same program through `uf_find` keeps every
/// material (so the check can tell).
#[test]
#[ignore = "slow tier: compiles C"]
fn a_firmware_links_only_the_material_and_format_it_plays() {
    let Some(cc) = compiler() else { return };
    let exported =
        export::export_library(builtin(), "built-in", &[], &ExportConfig::default()).unwrap();
    assert!(exported.materials.len() >= 3);
    let header = c::header(&exported);
    let id = header
        .lines()
        .filter_map(|l| l.strip_prefix("extern const uf_material "))
        .nth(1)
        .and_then(|l| l.split(';').next())
        .expect("a second material's object")
        .to_owned();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("materials.h"), &header).unwrap();
    // `excitation`: the cascade's drive is the material's excitation, not an impulse.
    let play = |name: &str, defines: &str, material: &str, excitation: bool| {
        let src = dir.path().join(format!("{name}.c"));
        let drive = if excitation {
            "uf_excitation_state e;\n\
             float v[8] = {1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f};\n\
             unsigned i;\n\
             uf_exc_init(&e, 1);\n\
             uf_exc_strike(&e, m, 1.0f);\n\
             uf_exc_block(&e, m, v, v, 8);\n\
             for (i = 0; i < 8; ++i) x[i] = (int16_t)(v[i] * 8192.0f);\n"
        } else {
            ""
        };
        std::fs::write(
            &src,
            format!(
                "{defines}#define UNDERFOOT_IMPLEMENTATION\n#include \"materials.h\"\n\
                 int main(void) {{\n\
                 const uf_material *m = {material};\n\
                 uf_q15_state s[UF_MAX_SECTIONS];\n\
                 int16_t x[8] = {{1000}};\n\
                 int32_t y[8];\n\
                 if (m == 0) return 1;\n\
                 {{\n{drive}}}\n\
                 uf_q15_reset(s, m->sections);\n\
                 uf_q15_cascade_block(m->q15, s, m->sections, x, y, 8);\n\
                 return (int)(uf_q31_clamp(uf_q31_gain(m, y[7]), 1 << 30) & 1);\n}}\n"
            ),
        )
        .unwrap();
        let exe = dir.path().join(name);
        c99(
            &cc,
            &src,
            &exe,
            &[
                "-Os",
                "-ffunction-sections",
                "-fdata-sections",
                "-Wl,--gc-sections",
            ],
        );
        exe
    };
    let lean = play(
        "lean",
        "#define UF_NO_INDEX\n#define UF_NO_F32\n#define UF_NO_Q31\n#define UF_NO_EXCITATION\n",
        &format!("&{id}"),
        false,
    );
    let Some(kept) = symbols(&lean) else {
        assert!(
            std::env::var("UNDERFOOT_REQUIRE_CC").as_deref() != Ok("1"),
            "UNDERFOOT_REQUIRE_CC=1 but there is no nm"
        );
        eprintln!("firmware: no nm; skipping the link check");
        return;
    };
    let tables = |syms: &[String]| -> Vec<String> {
        syms.iter()
            .filter(|s| {
                s.starts_with("uf_m") && s.as_bytes().get(4).is_some_and(u8::is_ascii_digit)
            })
            .cloned()
            .collect()
    };
    let lean_tables = tables(&kept);
    eprintln!("one material, Q15 only: {lean_tables:?}");
    assert!(
        lean_tables.contains(&format!("{id}_q15")),
        "{id}_q15 missing from {lean_tables:?}"
    );
    assert!(
        lean_tables
            .iter()
            .all(|s| s == &id || s == &format!("{id}_q15")),
        "other tables linked: {lean_tables:?}"
    );
    for gone in [
        "uf_materials",
        "uf_find",
        "uf_f32_cascade",
        "uf_q31_cascade",
    ] {
        assert!(!kept.iter().any(|s| s == gone), "{gone} linked");
    }
    let excitation = |syms: &[String]| -> Vec<String> {
        syms.iter()
            .filter(|s| s.starts_with("uf_exc_") || s.contains("_exc"))
            .cloned()
            .collect()
    };
    assert_eq!(excitation(&kept), Vec::<String>::new(), "UF_NO_EXCITATION");
    // Playing the excitation too links that material's excitation tables and the two
    // shared tables it uses, and nothing of the other materials'.
    let played = play(
        "excitation",
        "#define UF_NO_INDEX\n#define UF_NO_F32\n#define UF_NO_Q31\n",
        &format!("&{id}"),
        true,
    );
    let kept = symbols(&played).unwrap();
    let own = tables(&kept);
    eprintln!(
        "one material, its excitation and Q15: {own:?} {:?}",
        excitation(&kept)
    );
    let allowed =
        ["", "_q15", "_exc", "_exc_threshold", "_exc_amplitude"].map(|s| format!("{id}{s}"));
    assert!(
        own.iter().all(|s| allowed.contains(s)),
        "other tables linked: {own:?}"
    );
    for needed in ["_q15", "_exc_threshold", "_exc_amplitude"] {
        assert!(
            own.contains(&format!("{id}{needed}")),
            "{id}{needed} missing from {own:?}"
        );
    }
    for shared in ["uf_exc_steps_", "uf_exc_quantiles_"] {
        let n = kept.iter().filter(|s| s.starts_with(shared)).count();
        assert_eq!(n, 1, "{shared}*: {:?}", excitation(&kept));
    }
    // Through the index, every material's tables stay.
    let full = play("full", "", "uf_find(\"gravel\")", false);
    let all = tables(&symbols(&full).unwrap());
    assert!(
        all.len() >= 3 * exported.materials.len(),
        "the index should keep every table: {all:?}"
    );
}
