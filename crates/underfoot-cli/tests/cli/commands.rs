//! End-to-end tests of the `underfoot` binary on library files written by the tests.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::{assert_ok, run, s, stderr, stdout};
use underfoot::material::{FilterCoefficients, FitRecord, Library, MaterialModel, SourceFile};
use underfoot::signal::{Biquad, Sos};
use underfoot::units::{Band, Hz, SampleRate};

/// A valid model: one resonant section (poles at radius 0.9) whose fit record is its own
/// response, so the library accepts it exactly as a fit would have written it.
fn model(name: &str, strikes: usize) -> MaterialModel {
    let rate = SampleRate(2000);
    let band = Band::new(20.0, 900.0);
    let sos = Sos::new(vec![Biquad {
        b: [0.1, 0.0, -0.1],
        a: [1.0, -1.6, 0.81],
    }]);
    let grid: Vec<f64> = band.log_grid(24).iter().map(|f| f.0).collect();
    let mag: Vec<f64> = grid
        .iter()
        .map(|&f| sos.response(rate.omega(Hz(f))).norm())
        .collect();
    MaterialModel {
        name: name.to_string(),
        sample_rate: rate,
        band_hz: band,
        order: sos.order(),
        filter: FilterCoefficients::from_sos(&sos),
        fit: FitRecord {
            grid_hz: grid,
            measured: mag.iter().map(|m| m * 1.05).collect(),
            model: mag,
            nrmse: 0.0488,
            lsd_db: 0.42,
            method: "hand-built".to_string(),
            poor_fit: false,
            strikes,
            fit_seconds: 1.5,
            longest_decay: underfoot::units::Seconds(0.5),
            worst: None,
        },
        sources: vec![SourceFile {
            file: format!("{name}.wav"),
            sha256: "0f".repeat(32),
        }],
        physical: None,
    }
}

fn library(names: &[&str]) -> Library {
    let mut lib = Library::new();
    for (i, n) in names.iter().enumerate() {
        lib.upsert(model(n, 10 + i));
    }
    lib
}

fn write_library(dir: &Path, names: &[&str]) -> PathBuf {
    let path = dir.join("lib.json");
    fs::write(&path, library(names).to_json()).expect("write library");
    path
}

/// Asserts a failure with status 1 (an error, not a usage mistake) and returns stderr.
fn assert_error(o: &Output) -> String {
    assert_eq!(
        o.status.code(),
        Some(1),
        "stdout: {}\nstderr: {}",
        stdout(o),
        stderr(o)
    );
    let e = stderr(o);
    assert!(e.starts_with("underfoot: error: "), "{e}");
    e
}

#[test]
fn list_prints_a_table_of_the_library() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = write_library(dir.path(), &["gravel", "snow"]);
    let o = run(&["library", "list", "--library", s(&lib)]);
    assert_ok(&o);
    let out = stdout(&o);
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 4, "{out}");
    for col in [
        "name", "rate Hz", "band Hz", "order", "NRMSE", "LSD dB", "strikes",
    ] {
        assert!(lines[0].contains(col), "missing column {col}: {out}");
    }
    let gravel: Vec<&str> = lines[2].split_whitespace().collect();
    assert_eq!(
        gravel,
        ["gravel", "2000", "20-900", "2", "0.0488", "0.42", "10"]
    );
    assert!(lines[3].starts_with("snow"));
}

#[test]
fn list_and_show_json_parse() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = write_library(dir.path(), &["gravel", "snow"]);

    let o = run(&["library", "list", "--library", s(&lib), "--json"]);
    assert_ok(&o);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).expect("list --json is JSON");
    let rows = v.as_array().expect("array");
    assert_eq!(rows.len(), 2);
    assert_eq!(rows[1]["name"], "snow");
    assert_eq!(rows[1]["order"], 2);
    assert_eq!(rows[1]["strikes"], 11);
    assert_eq!(rows[0]["band_hz"], serde_json::json!([20.0, 900.0]));

    let o = run(&["library", "show", "snow", "--library", s(&lib), "--json"]);
    assert_ok(&o);
    let m: MaterialModel = serde_json::from_str(&stdout(&o)).expect("show --json is a model");
    assert_eq!(m, model("snow", 11));
}

#[test]
fn show_describes_fit_and_poles() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = write_library(dir.path(), &["gravel"]);
    let o = run(&["library", "show", "gravel", "--library", s(&lib)]);
    assert_ok(&o);
    let out = stdout(&o);
    assert!(out.contains("NRMSE 0.0488, LSD 0.42 dB"), "{out}");
    assert!(out.contains("gravel.wav"), "{out}");
    // 1 - 1.6 z^-1 + 0.81 z^-2: radius 0.9 at acos(0.8/0.9) * 2000 / 2pi = 151.5 Hz.
    assert!(out.contains("0.900000  151.5 Hz"), "{out}");
}

#[test]
fn remove_deletes_and_saves() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = write_library(dir.path(), &["gravel", "sand", "snow"]);
    let o = run(&["library", "remove", "sand", "--library", s(&lib)]);
    assert_ok(&o);
    assert!(stdout(&o).contains("2 materials left"));
    let after = Library::load(&lib).expect("still a valid library");
    assert_eq!(after.names(), ["gravel", "snow"]);
    let entries: Vec<_> = fs::read_dir(dir.path()).expect("dir").collect();
    assert_eq!(entries.len(), 1, "no temporary files left behind");
}

#[test]
fn remove_or_show_of_unknown_name_fails_cleanly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = write_library(dir.path(), &["gravel", "snow"]);
    let before = fs::read(&lib).expect("read");
    for cmd in ["remove", "show"] {
        let e = assert_error(&run(&["library", cmd, "ice", "--library", s(&lib)]));
        assert!(
            e.contains(s(&lib)) && e.contains("\"ice\"") && e.contains("available: gravel, snow"),
            "{e}"
        );
    }
    assert_eq!(fs::read(&lib).expect("read"), before);
}

#[test]
fn broken_libraries_fail_with_a_clear_message_and_stay_unchanged() {
    let unstable = {
        let mut lib = library(&["gravel", "ice"]);
        // Poles at radius sqrt(1.0201) = 1.01, with b/a kept consistent so that only
        // stability is wrong.
        let sos = Sos::new(vec![Biquad {
            b: [0.1, 0.0, -0.1],
            a: [1.0, -1.6, 1.0201],
        }]);
        lib.materials[1].filter = FilterCoefficients::from_sos(&sos);
        lib.to_json()
    };
    let v3 = library(&["gravel"])
        .to_json()
        .replace("underfoot.library/2", "underfoot.library/3");
    let cases: [(&str, String, &[&str]); 3] = [
        (
            "malformed",
            "{\n  \"format\": \"underfoot.library/2\",\n  \"materials\": [\n".into(),
            &["line", "column"],
        ),
        (
            "unknown version",
            v3,
            &["\"underfoot.library/3\"", "underfoot.library/2"],
        ),
        ("unstable", unstable, &["\"ice\"", "unstable", "1.01"]),
    ];
    for (what, text, expected) in cases {
        let dir = tempfile::tempdir().expect("tempdir");
        let lib = dir.path().join("lib.json");
        fs::write(&lib, &text).expect("write");
        for args in [
            vec!["library", "list", "--library", s(&lib)],
            vec!["library", "show", "gravel", "--library", s(&lib)],
            vec!["library", "remove", "gravel", "--library", s(&lib)],
            vec!["demo", "--library", s(&lib), "--out-dir", s(dir.path())],
        ] {
            let e = assert_error(&run(&args));
            assert!(
                e.contains(s(&lib)),
                "{what}: {args:?}: error must name the file: {e}"
            );
            for word in expected {
                assert!(
                    e.contains(word),
                    "{what}: {args:?}: expected {word:?} in {e}"
                );
            }
            assert_eq!(
                fs::read_to_string(&lib).expect("read"),
                text,
                "{what}: {args:?} changed the file"
            );
        }
        let entries: Vec<_> = fs::read_dir(dir.path()).expect("dir").collect();
        assert_eq!(entries.len(), 1, "{what}: nothing else written");
    }
}

#[test]
fn builtin_library_lists_and_flags_conflict() {
    assert_ok(&run(&["library", "list"]));
    let o = run(&["library", "list", "--builtin", "--json"]);
    assert_ok(&o);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).expect("json");
    assert!(v.is_array());
    // Usage mistakes are clap's: status 2.
    let o = run(&["library", "list", "--builtin", "--library", "x.json"]);
    assert_eq!(o.status.code(), Some(2));
    let o = run(&["library", "list", "--library", "/nonexistent/dir/lib.json"]);
    assert!(assert_error(&o).contains("/nonexistent/dir/lib.json"));
}

#[test]
fn demo_prints_fit_table_and_writes_spectra() {
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = write_library(dir.path(), &["gravel", "concrete", "snow"]);
    let out_dir = dir.path().join("out");
    let o = run(&["demo", "--library", s(&lib), "--out-dir", s(&out_dir)]);
    assert_ok(&o);
    let out = stdout(&o);
    let row: Vec<&str> = out
        .lines()
        .find(|l| l.starts_with("concrete"))
        .expect("row")
        .split_whitespace()
        .collect();
    assert_eq!(row, ["concrete", "2", "0.0488", "0.42"]);
    let svg = fs::read_to_string(out_dir.join("spectra.svg")).expect("spectra.svg");
    for name in ["gravel", "concrete", "snow"] {
        assert!(
            svg.contains(&format!(">\n{name}: order 2")),
            "panel for {name}"
        );
    }
    // Curves are the polylines with many points; axes, ticks and legend have two.
    let curves = svg
        .lines()
        .filter(|l| l.starts_with("<polyline") && l.matches(',').count() >= 24);
    assert_eq!(curves.count(), 6, "measured and model per panel");
}

/// A library file the `fit` tests expect to find unchanged.
fn existing_library(dir: &Path) -> (PathBuf, Vec<u8>) {
    let lib = write_library(dir, &["gravel"]);
    let bytes = fs::read(&lib).expect("read");
    (lib, bytes)
}

#[test]
fn fit_of_missing_or_garbage_recording_fails_and_keeps_library() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, before) = existing_library(dir.path());
    let missing = dir.path().join("missing.wav");
    let garbage = dir.path().join("garbage.wav");
    fs::write(
        &garbage,
        b"RIFF\x10\x00\x00\x00WAVEthis is not audio at all",
    )
    .expect("write");
    for file in [&missing, &garbage] {
        let o = run(&["fit", "--material", "sand", "--out", s(&lib), s(file)]);
        let e = assert_error(&o);
        assert!(
            e.contains(s(file)),
            "error must name {}: {e}",
            file.display()
        );
        assert_eq!(fs::read(&lib).expect("read"), before);
    }
    let entries: Vec<_> = fs::read_dir(dir.path()).expect("dir").collect();
    assert_eq!(entries.len(), 2, "only the library and garbage.wav");
}

#[test]
fn fit_checks_its_arguments_and_out_library_before_reading() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, before) = existing_library(dir.path());
    let missing = dir.path().join("missing.wav");

    // A broken --out library fails before any recording is looked at.
    let broken = dir.path().join("broken.json");
    fs::write(&broken, "{ not json").expect("write");
    let e = assert_error(&run(&[
        "fit",
        "--material",
        "sand",
        "--out",
        s(&broken),
        s(&missing),
    ]));
    assert!(e.contains(s(&broken)) && !e.contains("missing.wav"), "{e}");
    assert_eq!(fs::read_to_string(&broken).expect("read"), "{ not json");

    let bad_runs: [(&[&str], &str); 4] = [
        (&["--material", "a b"], "--material"),
        (&["--material", "sand", "--plot", "p.jpg"], ".svg or .png"),
        (&["--material", "sand", "--rate", "1000"], "does not fit"),
        (
            &["--material", "sand", "--report", "/nonexistent/dir/r.json"],
            "does not exist",
        ),
    ];
    for (extra, expected) in bad_runs {
        let mut args = vec!["fit", "--out", s(&lib)];
        args.extend_from_slice(extra);
        args.push(s(&missing));
        let e = assert_error(&run(&args));
        assert!(
            e.contains(expected) && !e.contains("missing.wav"),
            "{extra:?}: {e}"
        );
        assert_eq!(fs::read(&lib).expect("read"), before);
    }
    // Usage errors: conflicting options, and CSV options that need each other.
    for extra in [
        &["--order", "4", "--max-order", "8"][..],
        &["--csv-column", "z"][..],
    ] {
        let mut args = vec!["fit", "--material", "sand", "--out", s(&lib)];
        args.extend_from_slice(extra);
        args.push(s(&missing));
        assert_eq!(run(&args).status.code(), Some(2), "{extra:?}");
    }
}

fn write_wav_i16(path: &Path, rate: u32, samples: &[f64]) {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut w = hound::WavWriter::create(path, spec).expect("create wav");
    for &x in samples {
        w.write_sample((x * 32767.0).round() as i16).expect("write");
    }
    w.finalize().expect("finalize");
}

fn write_wav_f32(path: &Path, rate: u32, samples: &[f32]) {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate,
        bits_per_sample: 32,
        sample_format: hound::SampleFormat::Float,
    };
    let mut w = hound::WavWriter::create(path, spec).expect("create wav");
    for &x in samples {
        w.write_sample(x).expect("write");
    }
    w.finalize().expect("finalize");
}

/// Three seeded strikes through a known resonance (80 Hz, then 300 Hz), 8 kHz, 2 s.
fn strikes(rate: u32) -> Vec<f64> {
    let mut rng = underfoot::signal::noise::SplitMix64::new(0x9e37_79b9);
    let mut noise = move || rng.uniform() - 0.5;
    let fs = f64::from(rate);
    let mut x: Vec<f64> = (0..2 * rate as usize).map(|_| 1e-4 * noise()).collect();
    for onset in [0.2, 0.8, 1.4] {
        let start = (onset * fs) as usize;
        for n in 0..(0.4 * fs) as usize {
            let t = n as f64 / fs;
            let env = (-t / 0.04).exp();
            x[start + n] += 0.5
                * env
                * ((std::f64::consts::TAU * 80.0 * t).sin()
                    + 0.5 * (std::f64::consts::TAU * 300.0 * t).sin()
                    + 0.05 * noise());
        }
    }
    x
}

/// Every kind of bad recording: a clear message naming the file and the fault, a
/// non-zero exit, and the existing library byte-for-byte as it was.
#[test]
fn fit_of_each_bad_recording_kind_fails_clearly_and_keeps_library() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, before) = existing_library(dir.path());
    let p = |n: &str| dir.path().join(n);

    fs::write(p("empty.wav"), b"").expect("write");
    write_wav_i16(&p("header-only.wav"), 8000, &[]);
    write_wav_i16(&p("silent.wav"), 8000, &vec![0.0; 8000]);
    write_wav_i16(&p("short.wav"), 8000, &strikes(8000)[1600..1700]);
    let mut nan: Vec<f32> = strikes(8000).iter().map(|&v| v as f32).collect();
    nan[5000] = f32::NAN;
    write_wav_f32(&p("nan.wav"), 8000, &nan);
    write_wav_i16(&p("whole.wav"), 8000, &strikes(8000));
    let whole = fs::read(p("whole.wav")).expect("read");
    fs::write(p("truncated.wav"), &whole[..whole.len() / 2]).expect("write");
    fs::remove_file(p("whole.wav")).expect("rm");
    fs::write(p("garbage.ogg"), b"OggS\x00\x02 definitely not vorbis").expect("write");
    fs::write(p("nan.csv"), "t,accel\n0,0.1\n1,nan\n2,0.3\n").expect("write");

    let cases: [(&str, &[&str], &str); 8] = [
        ("empty.wav", &[], "corrupt"),
        ("header-only.wav", &[], "no samples"),
        ("silent.wav", &[], "silent"),
        ("short.wav", &[], "shorter than"),
        ("nan.wav", &[], "not a finite number"),
        ("truncated.wav", &[], "corrupt"),
        ("garbage.ogg", &[], "corrupt"),
        (
            "nan.csv",
            &["--csv-column", "accel", "--csv-rate", "1000"],
            "not a finite number",
        ),
    ];
    for (name, extra, fault) in cases {
        let file = p(name);
        let mut args = vec!["fit", "--material", "sand", "--out", s(&lib)];
        args.extend_from_slice(extra);
        args.push(s(&file));
        let e = assert_error(&run(&args));
        assert!(e.contains(name), "{name}: error must name the file: {e}");
        assert!(e.contains(fault), "{name}: error must say {fault:?}: {e}");
        assert_eq!(
            fs::read(&lib).expect("read"),
            before,
            "{name}: library changed"
        );
    }
}

/// A recording whose content cannot be fitted as asked (band above the analysis Nyquist)
/// fails before anything is written.
#[test]
fn fit_with_band_beyond_rate_fails_and_keeps_library() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, before) = existing_library(dir.path());
    let wav = dir.path().join("steps.wav");
    write_wav_i16(&wav, 8000, &strikes(8000));
    let o = run(&[
        "fit",
        "--material",
        "x",
        "--out",
        s(&lib),
        "--rate",
        "1000",
        s(&wav),
    ]);
    let e = assert_error(&o);
    assert!(e.contains("does not fit"), "{e}");
    assert_eq!(fs::read(&lib).expect("read"), before);
}

/// The whole path on a recording the test makes: the model lands in the library next to
/// what was there, the report and plot are written, and its spectrum peaks where the
/// recording's resonance is.
#[test]
fn fit_adds_a_material_writes_report_and_plot() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, _) = existing_library(dir.path());
    let wav = dir.path().join("steps.wav");
    write_wav_i16(&wav, 8000, &strikes(8000));
    let report = dir.path().join("report.json");
    let plot = dir.path().join("fit.svg");
    let o = run(&[
        "fit",
        "--material",
        "synthetic",
        "--out",
        s(&lib),
        "--report",
        s(&report),
        "--plot",
        s(&plot),
        s(&wav),
    ]);
    assert_ok(&o);
    assert!(stdout(&o).contains("synthetic: order"), "{}", stdout(&o));

    let library = Library::load(&lib).expect("library");
    assert_eq!(library.names(), vec!["gravel", "synthetic"]);
    let m = library.get("synthetic").expect("model");
    assert_eq!(m.fit.strikes, 3, "three strikes in the recording");
    assert!(m.fit.lsd_db <= 1.0, "LSD {}", m.fit.lsd_db);
    let peak = m
        .fit
        .grid_hz
        .iter()
        .zip(&m.fit.model)
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(f, _)| *f)
        .expect("grid");
    assert!(
        (70.0..92.0).contains(&peak),
        "model peak at {peak} Hz, resonance at 80 Hz"
    );
    assert_eq!(m.sources[0].file, "steps.wav");

    let r: serde_json::Value =
        serde_json::from_slice(&fs::read(&report).expect("report")).expect("json");
    let entry = &r["materials"][0];
    assert_eq!(entry["name"], "synthetic");
    for key in ["order", "nrmse", "lsd_db", "fit_seconds"] {
        assert!(entry[key].is_number(), "report lacks {key}: {r}");
    }
    let svg = fs::read_to_string(&plot).expect("plot");
    assert!(
        svg.starts_with("<svg") && svg.contains("polyline"),
        "not a plot"
    );

    // Fitting again replaces, keeps one entry.
    assert_ok(&run(&[
        "fit",
        "--material",
        "synthetic",
        "--out",
        s(&lib),
        "--order",
        "4",
        s(&wav),
    ]));
    let library = Library::load(&lib).expect("library");
    assert_eq!(library.names(), vec!["gravel", "synthetic"]);
    assert_eq!(library.get("synthetic").expect("model").order, 4);
}

fn read_wav(path: &Path) -> (hound::WavSpec, Vec<f32>) {
    let mut r = hound::WavReader::open(path).expect("open wav");
    let spec = r.spec();
    let samples = r.samples::<f32>().map(|s| s.expect("sample")).collect();
    (spec, samples)
}

/// The acceptance test of the demo: every material's stretch of `walk.wav`, analysed
/// with the fitting pipeline, matches that material's measured response within 2 dB.
#[test]
fn demo_walks_across_every_builtin_material_and_each_stretch_matches_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = run(&["demo", "--out-dir", s(dir.path())]);
    assert_ok(&o);
    let (spec, samples) = read_wav(&dir.path().join("walk.wav"));
    assert_eq!((spec.channels, spec.sample_rate), (1, 48_000));
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(dir.path().join("walk.json")).unwrap()).unwrap();
    let gain = underfoot::units::Decibels(report["gain_db"].as_f64().unwrap());
    let segments = report["segments"].as_array().unwrap();
    let lib = underfoot::material::builtin::builtin();
    assert_eq!(segments.len(), lib.materials.len());
    assert_eq!(report["limited_samples"], 0);
    let rate = SampleRate(48_000);
    for seg in segments {
        let name = seg["material"].as_str().unwrap();
        let a = rate.samples_in(underfoot::units::Seconds(seg["start_s"].as_f64().unwrap()));
        let b = rate.samples_in(underfoot::units::Seconds(seg["end_s"].as_f64().unwrap()));
        let lsd = underfoot::material::evaluate::segment_lsd(
            &samples[a..b.min(samples.len())],
            rate,
            lib.get(name).unwrap(),
            gain,
        )
        .unwrap();
        assert!(lsd < 2.0, "{name}: {lsd:.2} dB");
    }
    for file in ["walk.svg", "spectra.svg", "walk-force.csv"] {
        assert!(
            fs::metadata(dir.path().join(file)).unwrap().len() > 1000,
            "{file}"
        );
    }
    assert!(stdout(&o).contains("LSD dB"));
}

#[test]
fn render_of_a_generated_walk_is_reproducible_and_carries_the_force() {
    let dir = tempfile::tempdir().expect("tempdir");
    let render = |out: &str, seed: &str| {
        run(&[
            "render",
            "--material",
            "snow",
            "--gait",
            "steps=3,channels=1",
            "--out",
            s(&dir.path().join(out)),
            "--seed",
            seed,
            "--force-out",
            s(&dir.path().join(format!("force-{out}"))),
            "--gain-db",
            "-20",
            "--save-force",
            s(&dir.path().join("steps.csv")),
        ])
    };
    assert_ok(&render("a.wav", "1"));
    assert_ok(&render("b.wav", "1"));
    let o = render("c.wav", "2");
    assert_ok(&o);
    assert!(stdout(&o).contains("3 strike(s)"), "{}", stdout(&o));
    let (spec, a) = read_wav(&dir.path().join("a.wav"));
    assert_eq!(spec.channels, 1, "the drive only: force has its own file");
    let (_, force) = read_wav(&dir.path().join("force-a.wav"));
    let (_, b) = read_wav(&dir.path().join("b.wav"));
    let (_, c) = read_wav(&dir.path().join("c.wav"));
    assert_eq!(a, b, "same seed, same output");
    assert_ne!(a, c, "another seed perturbs the steps differently");
    // The force channel peaks near 1.15 body weights of 70 kg, in kN.
    let force_peak = force.iter().fold(0.0f32, |m, v| m.max(*v));
    assert!((0.7..0.95).contains(&force_peak), "{force_peak}");
    // The saved track renders to the same vibration.
    let o = run(&[
        "render",
        "--material",
        "snow",
        "--force",
        s(&dir.path().join("steps.csv")),
        "--out",
        s(&dir.path().join("d.wav")),
        "--seed",
        "1",
        "--gain-db",
        "-20",
    ]);
    assert_ok(&o);
    let (_, d) = read_wav(&dir.path().join("d.wav"));
    let vib = a;
    assert_eq!(vib.len(), d.len());
    let diff = vib
        .iter()
        .zip(&d)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max);
    assert!(diff < 1e-6, "{diff}");
}

#[test]
fn render_of_a_bad_force_track_fails_and_keeps_the_old_wav() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out.wav");
    fs::write(&out, b"previous render").unwrap();
    for (name, text) in [
        ("empty.csv", ""),
        ("nan.csv", "time_s,force\n0,0\n0.01,nan\n"),
        ("backwards.csv", "time_s,force\n0,0\n0.02,10\n0.01,20\n"),
        ("ragged.csv", "time_s,left.heel,left.toe\n0,0,0\n0.01,5\n"),
    ] {
        let csv = dir.path().join(name);
        fs::write(&csv, text).unwrap();
        let o = run(&[
            "render",
            "--material",
            "gravel",
            "--force",
            s(&csv),
            "--out",
            s(&out),
        ]);
        let e = assert_error(&o);
        assert!(e.contains(name), "{name}: {e}");
        assert_eq!(fs::read(&out).unwrap(), b"previous render");
    }
    let o = run(&[
        "render",
        "--material",
        "granite",
        "--gait",
        "steps=1",
        "--out",
        s(&out),
    ]);
    assert!(assert_error(&o).contains("granite"));
    let o = run(&[
        "render",
        "--material",
        "gravel",
        "--gait",
        "steps=1,speed=3",
        "--out",
        s(&out),
    ]);
    assert!(assert_error(&o).contains("speed"));
    assert_eq!(fs::read(&out).unwrap(), b"previous render");
}

#[test]
fn run_plays_a_walk_live_into_a_paced_wav() {
    let dir = tempfile::tempdir().expect("tempdir");
    let wav = dir.path().join("live.wav");
    let started = std::time::Instant::now();
    let o = run(&[
        "run",
        "--material",
        "wood",
        "--input",
        "gait:steps=2,channels=1,lead_in=0.2,tail=0.2",
        "--output",
        &format!("wav:{}", s(&wav)),
        "--gain-db",
        "-20",
    ]);
    assert_ok(&o);
    let took = started.elapsed().as_secs_f64();
    assert!(stdout(&o).contains("2 strike(s)"), "{}", stdout(&o));
    // Real-time pace: the walk lasts about 1.4 s, plus a second to ring out.
    assert!(took > 2.0, "{took} s");
    let (_, samples) = read_wav(&wav);
    assert!(samples.iter().any(|v| v.abs() > 1e-4));
    assert!(samples.iter().all(|v| v.abs() <= 0.5012));
}

#[test]
fn run_rejects_bad_inputs_and_outputs_clearly() {
    // A malformed spec is a usage error (status 2), refused while parsing (issue 14).
    let o = run(&["run", "--input", "tcp:1234", "--output", "null"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("unknown kind"));
    let o = run(&[
        "run",
        "--input",
        "replay:/nonexistent.csv",
        "--output",
        "null",
    ]);
    assert!(assert_error(&o).contains("/nonexistent.csv"));
    let o = run(&["run", "--input", "gait:steps=1", "--output", "speaker"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("speaker"));
    let o = run(&[
        "run",
        "--input",
        "serial:/dev/does-not-exist",
        "--output",
        "null",
    ]);
    assert!(assert_error(&o).contains("/dev/does-not-exist"));
}

/// The shared footstep recordings, or `None` (with a note) when they are absent and
/// `UNDERFOOT_REQUIRE_DATA` is not `1`.
fn footsteps_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/footsteps");
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var("UNDERFOOT_REQUIRE_DATA")
            .ok()
            .is_none_or(|v| v != "1"),
        "UNDERFOOT_REQUIRE_DATA=1 but the footstep recordings are not at {}",
        dir.display()
    );
    eprintln!(
        "note: skipping: footstep recordings not found at {}",
        dir.display()
    );
    None
}

#[test]
fn compare_prints_table_one_for_the_papers_five_materials() {
    let Some(data) = footsteps_dir() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let json = dir.path().join("table.json");
    let plots = dir.path().join("fig4");
    // The paper's broken stone, concrete, sand, earth and snow.
    let pairs: Vec<String> = ["gravel", "hard", "sand", "dirt", "snow"]
        .iter()
        .map(|m| format!("{m}={}", data.join(m).display()))
        .collect();
    let mut args = vec![
        "compare",
        "--json",
        json.to_str().unwrap(),
        "--plot",
        plots.to_str().unwrap(),
    ];
    args.extend(pairs.iter().map(String::as_str));
    let o = run(&args);
    assert_ok(&o);
    let table = stdout(&o);
    eprintln!("{table}");
    assert_eq!(table.lines().count(), 6, "a header and five rows:\n{table}");
    let parsed: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&json).expect("json written")).expect("json");
    let rows = parsed["materials"].as_array().expect("materials");
    assert_eq!(rows.len(), 5);
    for row in rows {
        let name = row["name"].as_str().expect("name");
        for model in ["iir", "physical"] {
            let nrmse = row[model]["nrmse"].as_f64().expect("nrmse");
            let lsd = row[model]["lsd_db"].as_f64().expect("lsd_db");
            assert!(nrmse.is_finite() && nrmse >= 0.0, "{name} {model}");
            assert!(
                table.contains(&format!("{lsd:.2}")),
                "{name} {model} in the table"
            );
        }
        // The fitted filter is the closer of the two, as in the paper; both are close.
        assert!(row["iir"]["lsd_db"].as_f64().unwrap() <= 1.0, "{name}");
        assert!(row["physical"]["lsd_db"].as_f64().unwrap() <= 3.0, "{name}");
        let svg = fs::read_to_string(plots.join(format!("{name}.svg"))).expect("plot");
        assert!(
            svg.contains("physical") && svg.contains("IIR"),
            "{name}: legend"
        );
    }
    // A folder without recordings is an error that names it.
    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    let arg = format!("x={}", empty.display());
    let err = assert_error(&run(&["compare", &arg]));
    assert!(err.contains("holds no recording"), "{err}");
}

/// `fit` and `compare` on the same recordings print the same figures for the same
/// metric, and `compare`'s held-out figure is named apart from the calibration's.
#[test]
fn fit_and_compare_agree_on_the_same_recordings() {
    let Some(data) = footsteps_dir() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, report, json) = (
        dir.path().join("lib.json"),
        dir.path().join("report.json"),
        dir.path().join("table.json"),
    );
    let folder = data.join("gravel");
    let mut files: Vec<PathBuf> = fs::read_dir(&folder)
        .expect("gravel folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "ogg"))
        .collect();
    files.sort();
    let mut args = vec![
        "fit".to_string(),
        "--material".into(),
        "gravel".into(),
        "--out".into(),
        lib.display().to_string(),
        "--report".into(),
        report.display().to_string(),
    ];
    args.extend(files.iter().map(|f| f.display().to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let fitted = run(&args);
    assert_ok(&fitted);
    let pair = format!("gravel={}", folder.display());
    let compared = run(&["compare", "--json", s(&json), &pair]);
    assert_ok(&compared);

    let read = |p: &Path| -> serde_json::Value {
        serde_json::from_slice(&fs::read(p).expect("written")).expect("json")
    };
    let (r, t) = (read(&report), read(&json));
    let (fit, cmp) = (&r["materials"][0], &t["materials"][0]);
    for (a, b) in [
        (&fit["lsd_db"], &cmp["iir"]["lsd_db"]),
        (&fit["nrmse"], &cmp["iir"]["nrmse"]),
        (&fit["physical"]["lsd_db"], &cmp["physical"]["lsd_db"]),
        (&fit["physical"]["nrmse"], &cmp["physical"]["nrmse"]),
    ] {
        let (a, b) = (
            a.as_f64().expect("fit figure"),
            b.as_f64().expect("compare figure"),
        );
        assert_eq!(a, b, "fit {fit}\ncompare {cmp}");
    }
    // And as printed.
    let lsd = fit["physical"]["lsd_db"].as_f64().expect("physical LSD");
    let printed = format!("LSD {lsd:.2} dB (calibration render)");
    assert!(stdout(&fitted).contains(&printed), "{}", stdout(&fitted));
    assert!(stdout(&compared).contains(&format!("{lsd:.2}")));
    let held_out = cmp["physical"]["held_out_lsd_db"]
        .as_f64()
        .expect("held-out");
    assert!(held_out.is_finite() && held_out <= 3.0, "{held_out}");
    assert!(stdout(&compared).contains("held-out"));
}

/// The README's compensation session on the simulated tile: measure, equalize, fit a
/// user, tabulate users, and render through the compensation.
#[test]
fn a_compensation_session_on_the_simulated_tile() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    let unloaded = p("tile-unloaded.json");
    let o = run(&["calibrate", "sweep", "--out", s(&unloaded)]);
    assert_ok(&o);
    assert!(stdout(&o).contains("2.83 dB from flat"), "{}", stdout(&o));

    let eq = p("tile-eq.json");
    let plot = p("eq.svg");
    let o = run(&[
        "calibrate",
        "equalize",
        "--device",
        s(&unloaded),
        "--passes",
        "3",
        "--out",
        s(&eq),
        "--plot",
        s(&plot),
    ]);
    assert_ok(&o);
    // Pass 3's RMS deviation, from the table: below the paper's 0.28 dB.
    let last = stdout(&o)
        .lines()
        .find(|l| l.trim_start().starts_with("3 "))
        .map(|l| l.split_whitespace().nth(1).unwrap().parse::<f64>().unwrap())
        .expect("a row for pass 3");
    assert!(last < 0.28, "{}", stdout(&o));
    assert!(fs::metadata(&plot).unwrap().len() > 1000);

    // Two users stand on the tile; their limb models go into a table.
    let table = p("users.json");
    for (name, load) in [("anna", "table1"), ("bob", "0.0055,2.5e6,1200")] {
        let sweep = p(&format!("{name}-sweep.json"));
        assert_ok(&run(&[
            "calibrate",
            "sweep",
            "--load",
            load,
            "--eq",
            s(&eq),
            "--out",
            s(&sweep),
        ]));
        let limb = p(&format!("{name}.json"));
        let o = run(&[
            "calibrate",
            "limb",
            "--sweeps",
            s(&sweep),
            "--out",
            s(&limb),
        ]);
        assert_ok(&o);
        assert!(stdout(&o).contains("b3/k3"), "{}", stdout(&o));
        assert_ok(&run(&[
            "eq-table",
            "add",
            "--user",
            s(&limb),
            "--table",
            s(&table),
            "--eq",
            s(&eq),
        ]));
    }
    let o = run(&["eq-table", "show", "--table", s(&table)]);
    assert_ok(&o);
    assert!(stdout(&o).contains("anna") && stdout(&o).contains("bob"));

    // Rendering through the equalizer and Anna's limb filter, and through the table.
    for extra in [
        vec!["--user", s(&p("anna.json"))],
        vec!["--eq-table", s(&table), "--user", "0.0045,4e6,1800"],
    ] {
        let wav = p("walk.wav");
        let mut args = vec![
            "render",
            "--material",
            "snow",
            "--gait",
            "steps=2",
            "--out",
            s(&wav),
            "--eq",
            s(&eq),
        ];
        args.extend(extra);
        assert_ok(&run(&args));
        assert!(fs::metadata(&wav).unwrap().len() > 1000);
    }

    // Another command's file, a missing file and a newer version are clean errors, and a
    // failed run leaves the files alone.
    let before = fs::read(&eq).unwrap();
    let err = assert_error(&run(&[
        "calibrate",
        "equalize",
        "--device",
        s(&eq),
        "--out",
        s(&eq),
    ]));
    assert!(err.contains("format \"underfoot.equalizer/1\""), "{err}");
    assert_eq!(fs::read(&eq).unwrap(), before);
    let newer = p("newer.json");
    fs::write(
        &newer,
        fs::read_to_string(&unloaded)
            .unwrap()
            .replace("frequency-response/1", "frequency-response/2"),
    )
    .unwrap();
    let err = assert_error(&run(&[
        "calibrate",
        "limb",
        "--sweeps",
        s(&newer),
        "--out",
        s(&p("x.json")),
    ]));
    assert!(err.contains("version 2"), "{err}");
    assert_error(&run(&[
        "render",
        "--material",
        "snow",
        "--gait",
        "steps=2",
        "--out",
        s(&p("w.wav")),
        "--eq",
        s(&p("missing.json")),
    ]));
}

/// `--device audio` in a build without the `audio` feature says so, rather than treating
/// `audio` as a file name.
#[cfg(not(feature = "audio"))]
#[test]
fn calibrate_on_a_sound_card_needs_the_audio_feature() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("tile.json");
    let o = run(&[
        "calibrate",
        "sweep",
        "--device",
        "audio",
        "--output-device",
        "hw:1",
        "--out",
        s(&out),
    ]);
    let message = assert_error(&o);
    assert!(message.contains("no audio support"), "{message}");
    assert!(message.contains("hw:1"), "{message}");
    assert!(!out.exists());
}

#[test]
fn calibrate_sensors_fits_saves_and_reports_residuals() {
    let dir = tempfile::tempdir().unwrap();
    let readings = dir.path().join("scale.csv");
    let mut csv = String::from("# lab scale session\nsensor,raw,load_n\n");
    for i in 0..30 {
        let load = 30.0 * f64::from(i);
        for (name, r0) in [("heel", 200.0), ("toe", 150.0)] {
            let raw = r0 + (load / 0.0119_f64).powf(1.0 / 1.4);
            csv.push_str(&format!("{name},{raw:.1},{load}\n"));
        }
    }
    fs::write(&readings, csv).unwrap();
    let out = dir.path().join("sensors.json");
    for kind in ["power", "piecewise"] {
        let o = run(&[
            "calibrate",
            "sensors",
            "--readings",
            s(&readings),
            "--out",
            s(&out),
            "--kind",
            kind,
        ]);
        assert_ok(&o);
        let text = stdout(&o);
        assert!(
            text.contains("heel") && text.contains("toe") && text.contains("rms N"),
            "{text}"
        );
        let cal = underfoot::force::calibration::SensorCalibration::load(&out).unwrap();
        assert_eq!(cal.sensors.len(), 2);
    }

    fs::write(&readings, "sensor,raw,load_n\nheel,200,0\nheel,oops,10\n").unwrap();
    let message = assert_error(&run(&[
        "calibrate",
        "sensors",
        "--readings",
        s(&readings),
        "--out",
        s(&out),
    ]));
    assert!(
        message.contains("scale.csv") && message.contains("line 3"),
        "{message}"
    );
}

/// The commented example interface configurations, at the workspace root.
fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

/// The first number before `what` in `text`, e.g. "12 strike(s)".
fn count_before(text: &str, what: &str) -> u64 {
    let at = text
        .find(what)
        .unwrap_or_else(|| panic!("{what:?} not in {text}"));
    let digits: String = text[..at]
        .trim_end()
        .chars()
        .rev()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.chars().rev().collect::<String>().parse().unwrap()
}

#[test]
fn run_interface_plays_the_simulated_foot_and_drives_its_servos() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The example, with a shorter walk.
    let text = fs::read_to_string(example("prosthetic.toml")).unwrap();
    let short = text.replace("gait = \"steps=4,", "gait = \"steps=2,");
    assert_ne!(short, text, "the example's walk changed: update this test");
    let config = dir.path().join("prosthetic.toml");
    fs::write(&config, short).unwrap();
    let wav = dir.path().join("interface.wav");
    let o = run(&[
        "run",
        "--interface",
        s(&config),
        "--material",
        "gravel",
        "--output",
        &format!("wav:{}", s(&wav)),
        "--seconds",
        "20",
    ]);
    assert_ok(&o);
    let out = stdout(&o);
    // Two steps on each of the four discs.
    assert_eq!(count_before(&out, "strike(s)"), 8, "{out}");
    let sent = count_before(&out, "servo frame(s) sent");
    let received = count_before(&out, "servo frame(s) received");
    assert!(sent > 20, "{out}");
    assert!(received > 0 && received <= sent, "{out}");
    assert_eq!(
        count_before(&out, "insole frame(s),"),
        count_before(&out, "insole frame(s) sent")
    );
    assert_eq!(count_before(&out, "rejected ("), 0, "{out}");
    // After the walk the servos are back at rest (1100, 1100 and the reversed 1900 µs).
    assert!(out.contains("servos at [1100, 1100, 1900] µs"), "{out}");
    let (spec, samples) = read_wav(&wav);
    assert_eq!(spec.channels, 4);
    assert!(samples.iter().any(|v| v.abs() > 1e-4));
}

#[test]
fn run_interface_refuses_a_broken_config_clearly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = fs::read_to_string(example("prosthetic.toml")).unwrap();
    let config = dir.path().join("broken.toml");
    // A reversed range on the second servo.
    let broken = text.replacen("range_us = [1000, 2000]", "range_us = [2000, 1000]", 2);
    let broken = broken.replacen("range_us = [2000, 1000]", "range_us = [1000, 2000]", 1);
    fs::write(&config, &broken).unwrap();
    let o = run(&["run", "--interface", s(&config), "--output", "null"]);
    let err = assert_error(&o);
    assert!(err.contains("broken.toml"), "{err}");
    assert!(err.contains("servo[1].range_us"), "{err}");
    // A misspelt key, with its line.
    let line = text
        .lines()
        .position(|l| l.starts_with("dead_band_us"))
        .unwrap()
        + 1;
    fs::write(&config, text.replacen("dead_band_us", "deadband_us", 1)).unwrap();
    let err = assert_error(&run(&[
        "run",
        "--interface",
        s(&config),
        "--output",
        "null",
    ]));
    assert!(err.contains(&format!("broken.toml:{line}")), "{err}");
    assert!(err.contains("deadband_us"), "{err}");
    // A missing file.
    let err = assert_error(&run(&[
        "run",
        "--interface",
        "/nonexistent/prosthetic.toml",
        "--output",
        "null",
    ]));
    assert!(err.contains("/nonexistent/prosthetic.toml"), "{err}");
    // A calibration file that is not one.
    let cal = dir.path().join("sensors.json");
    fs::write(&cal, "{\"kind\": \"something else\"}").unwrap();
    let err = assert_error(&run(&[
        "run",
        "--input",
        "serial:/dev/does-not-exist",
        "--sensors",
        s(&cal),
        "--output",
        "null",
    ]));
    assert!(err.contains("sensors.json"), "{err}");
}

#[test]
fn export_writes_a_c_header_and_refuses_what_fails_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let lib = write_library(dir.path(), &["tile", "board"]);
    let out = dir.path().join("materials.h");
    let o = run(&[
        "export",
        "--format",
        "c",
        "--out",
        s(&out),
        "--library",
        s(&lib),
        "--materials",
        "board",
    ]);
    assert_ok(&o);
    let table = stdout(&o);
    assert!(
        table.contains("board") && !table.contains("tile"),
        "{table}"
    );
    let header = fs::read_to_string(&out).unwrap();
    assert!(header.contains("#define UF_MATERIAL_COUNT 1u"));
    assert!(header.contains("\"board\"") && header.contains("uf_q31_cascade"));
    // Both fixed-point formats by default; `--fixed` picks.
    assert!(header.contains("uf_m0_board_q15[") && header.contains("uf_m0_board_q31["));
    let only = dir.path().join("q31.h");
    assert_ok(&run(&[
        "export",
        "--out",
        s(&only),
        "--library",
        s(&lib),
        "--materials",
        "board",
        "--fixed",
        "q31",
    ]));
    let q31_only = fs::read_to_string(&only).unwrap();
    assert!(!q31_only.contains("uf_m0_board_q15[") && q31_only.contains("uf_m0_board_q31["));

    // An unknown material, and a tolerance no quantised filter meets: status 1, named.
    let e = assert_error(&run(&[
        "export",
        "--out",
        s(&out),
        "--library",
        s(&lib),
        "--materials",
        "lava",
    ]));
    assert!(e.contains("lava"), "{e}");
    let e = assert_error(&run(&[
        "export",
        "--out",
        s(&out),
        "--library",
        s(&lib),
        "--fixed",
        "q15",
        "--tolerance-db",
        "1e-9",
    ]));
    assert!(e.contains("Q15") && e.contains(" Hz"), "{e}");
    // The failed export left the earlier header in place.
    assert_eq!(fs::read_to_string(&out).unwrap(), header);
}

/// The four meaningless fits: a 1 Hz WAV, a WAV of nothing but +-1 LSB, a CSV
/// logged at 1000 Hz fitted over the default 20-900 Hz band, and a fit of order 1 to a
/// recording with two resonances. Each is refused with a message that says why and what to
/// do, exits 1, and writes nothing: the library byte for byte as it was, no report.
#[test]
fn fit_refuses_meaningless_models_and_keeps_library() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, before) = existing_library(dir.path());
    let p = |n: &str| dir.path().join(n);

    let mut rng = underfoot::signal::noise::SplitMix64::new(0x51);
    let one_hz: Vec<f64> = (0..20).map(|_| 0.5 * rng.symmetric()).collect();
    write_wav_i16(&p("one-hz.wav"), 1, &one_hz);
    let lsb: Vec<f64> = (0..16000)
        .map(|_| ((rng.uniform() * 3.0).floor() - 1.0) / 32767.0)
        .collect();
    write_wav_i16(&p("lsb.wav"), 8000, &lsb);
    let logged: String = strikes(1000)
        .iter()
        .enumerate()
        .map(|(i, v)| format!("{i},{v}\n"))
        .collect();
    fs::write(p("log.csv"), format!("t,accel\n{logged}")).expect("write");
    write_wav_i16(&p("steps.wav"), 8000, &strikes(8000));

    let report = p("report.json");
    let cases: [(&str, &[&str], &[&str]); 4] = [
        (
            "one-hz.wav",
            &[],
            &["1 Hz", "too low a sample rate", "100 Hz"],
        ),
        (
            "lsb.wav",
            &[],
            &["no heel strike stands clearly above the noise", "dB short"],
        ),
        (
            "log.csv",
            &["--csv-column", "accel", "--csv-rate", "1000"],
            &["above the Nyquist frequency", "1000 Hz", "--band 20:450"],
        ),
        (
            "steps.wav",
            &["--order", "1"],
            &["too far from the measured response", "--accept-poor-fit"],
        ),
    ];
    for (name, extra, expected) in cases {
        let mut args = vec![
            "fit",
            "--material",
            "bad",
            "--out",
            s(&lib),
            "--report",
            s(&report),
        ];
        args.extend_from_slice(extra);
        let file = p(name);
        args.push(s(&file));
        let e = assert_error(&run(&args));
        if name != "steps.wav" {
            assert!(e.contains(name), "{name}: error must name the file: {e}");
        }
        for x in expected {
            assert!(e.contains(x), "{name}: error must say {x:?}: {e}");
        }
        assert_eq!(
            fs::read(&lib).expect("read"),
            before,
            "{name}: library changed"
        );
        assert!(!report.exists(), "{name}: report written");
    }
}

/// `--accept-poor-fit` keeps the order-1 fit, warns, and marks it in the library, where
/// `library list` and `show` (text and JSON) say so; a good fit is not marked.
#[test]
fn accept_poor_fit_keeps_it_marked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, _) = existing_library(dir.path());
    let wav = dir.path().join("steps.wav");
    write_wav_i16(&wav, 8000, &strikes(8000));
    let o = run(&[
        "fit",
        "--material",
        "rough",
        "--out",
        s(&lib),
        "--order",
        "1",
        "--accept-poor-fit",
        s(&wav),
    ]);
    assert_ok(&o);
    assert!(
        stderr(&o).contains("warning: \"rough\" is a poor fit"),
        "{}",
        stderr(&o)
    );
    let library = Library::load(&lib).expect("library");
    assert!(library.get("rough").expect("kept").fit.poor_fit);
    assert!(!library.get("gravel").expect("kept").fit.poor_fit);

    let list = stdout(&run(&["library", "list", "--library", s(&lib)]));
    let rough = list
        .lines()
        .find(|l| l.starts_with("rough"))
        .expect("listed");
    assert!(rough.contains("POOR"), "{list}");
    assert!(
        !list
            .lines()
            .any(|l| l.starts_with("gravel") && l.contains("POOR"))
    );
    assert!(list.contains("--accept-poor-fit"), "{list}");
    let json: serde_json::Value = serde_json::from_str(&stdout(&run(&[
        "library",
        "list",
        "--library",
        s(&lib),
        "--json",
    ])))
    .expect("json");
    assert_eq!(json[1]["name"], "rough");
    assert_eq!(json[1]["poor_fit"], true);
    assert_eq!(json[0]["poor_fit"], false);
    let show = stdout(&run(&["library", "show", "rough", "--library", s(&lib)]));
    assert!(show.contains("POOR FIT"), "{show}");
}

/// `fit --report` on gravel's three recordings prints the leave-one-recording-out table
/// and writes it into the report; with one recording it says why there is none.
#[test]
fn fit_report_gives_leave_one_out_on_gravel() {
    let Some(data) = footsteps_dir() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let lib = dir.path().join("lib.json");
    let report = dir.path().join("report.json");
    let gravel: Vec<String> = (1..=3)
        .map(|i| {
            data.join(format!("gravel/default_gravel_footstep.{i}.ogg"))
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let mut args = vec!["fit", "--material", "gravel", "--out", s(&lib)];
    args.extend(["--report", s(&report)]);
    args.extend(gravel.iter().map(String::as_str));
    let o = run(&args);
    assert_ok(&o);
    let out = stdout(&o);
    assert!(out.contains("leave one recording out"), "{out}");
    for i in 1..=3 {
        assert!(
            out.lines()
                .any(|l| l.starts_with(&format!("default_gravel_footstep.{i}.ogg"))),
            "{out}"
        );
    }
    assert!(out.lines().any(|l| l.starts_with("mean")), "{out}");
    let r: serde_json::Value =
        serde_json::from_slice(&fs::read(&report).expect("report")).expect("json");
    let loo = &r["materials"][0]["leave_one_out"];
    let held = loo["held_out"].as_array().expect("held out");
    assert_eq!(held.len(), 3);
    for h in held {
        let lsd = h["lsd_db"].as_f64().expect("number");
        assert!(lsd > 0.0 && lsd < 10.0, "{h}");
    }
    let mean = loo["mean_lsd_db"].as_f64().expect("mean");
    let in_sample = loo["mean_in_sample_lsd_db"].as_f64().expect("mean");
    assert!(in_sample <= mean, "{loo}");
    assert_eq!(
        r["materials"][0]["strike_to_noise_db"]
            .as_array()
            .expect("figures")
            .len(),
        3
    );

    let o = run(&[
        "fit",
        "--material",
        "gravel1",
        "--out",
        s(&lib),
        "--report",
        s(&report),
        &gravel[0],
    ]);
    assert_ok(&o);
    assert!(stdout(&o).contains("not possible"), "{}", stdout(&o));
    let r: serde_json::Value =
        serde_json::from_slice(&fs::read(&report).expect("report")).expect("json");
    assert!(r["materials"][0]["leave_one_out"].is_null());
}
