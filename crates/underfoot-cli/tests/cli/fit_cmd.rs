//! `underfoot fit`: recordings the tests make (and the shared ones) in, a material in the library out; every bad input refused before the library is touched.

use std::fs;
use std::path::{Path, PathBuf};

use underfoot::material::Library;

use crate::common::{
    assert_error, assert_ok, footsteps_dir, run, s, stderr, stdout, write_library,
};

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
        let o = run(&["fit", "--name", "sand", "--library", s(&lib), s(file)]);
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
        "--name",
        "sand",
        "--library",
        s(&broken),
        s(&missing),
    ]));
    assert!(e.contains(s(&broken)) && !e.contains("missing.wav"), "{e}");
    assert_eq!(fs::read_to_string(&broken).expect("read"), "{ not json");

    let bad_runs: [(&[&str], &str); 4] = [
        (&["--name", "a b"], "--name"),
        (&["--name", "sand", "--plot", "p.jpg"], ".svg or .png"),
        (
            &["--name", "sand", "--analysis-rate", "1000"],
            "does not fit",
        ),
        (
            &["--name", "sand", "--report", "/nonexistent/dir/r.json"],
            "does not exist",
        ),
    ];
    for (extra, expected) in bad_runs {
        let mut args = vec!["fit", "--library", s(&lib)];
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
        let mut args = vec!["fit", "--name", "sand", "--library", s(&lib)];
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
    // Finite, but its energy is not: it was "-inf dB above its noise, inf dB short".
    let huge: String = (0..2000)
        .map(|i| {
            let v = if i == 900 {
                1e308
            } else {
                f64::from(i % 7) * 0.1
            };
            format!("{i},{v:e}\n")
        })
        .collect();
    fs::write(p("huge.csv"), format!("t,accel\n{huge}")).expect("write");

    let cases: [(&str, &[&str], &str); 9] = [
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
        (
            "huge.csv",
            &["--csv-column", "accel", "--csv-rate", "1000"],
            "sample 900 is 1e308, beyond",
        ),
    ];
    for (name, extra, fault) in cases {
        let file = p(name);
        let mut args = vec!["fit", "--name", "sand", "--library", s(&lib)];
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
        "--name",
        "x",
        "--library",
        s(&lib),
        "--analysis-rate",
        "1000",
        s(&wav),
    ]);
    let e = assert_error(&o);
    assert!(e.contains("does not fit"), "{e}");
    assert_eq!(fs::read(&lib).expect("read"), before);

    // The lowest band the parser allows designs its conditioning filter too (it was "band
    // 0.05-0.30000000000000004 Hz does not fit"): what fails is the recording, said so.
    let o = run(&[
        "fit",
        "--name",
        "x",
        "--library",
        s(&lib),
        "--band",
        "0.1:0.2",
        s(&wav),
    ]);
    let e = assert_error(&o);
    assert!(!e.contains("does not fit") && !e.contains("0000000"), "{e}");
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
        "--name",
        "synthetic",
        "--library",
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
        "--name",
        "synthetic",
        "--library",
        s(&lib),
        "--order",
        "4",
        s(&wav),
    ]));
    let library = Library::load(&lib).expect("library");
    assert_eq!(library.names(), vec!["gravel", "synthetic"]);
    assert_eq!(library.get("synthetic").expect("model").order, 4);
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
            "--name",
            "bad",
            "--library",
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
        "--name",
        "rough",
        "--library",
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
#[ignore = "slow tier: real recordings"]
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
    let mut args = vec!["fit", "--name", "gravel", "--library", s(&lib)];
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
        // In time: the left-out recording's steps and the other two's model rendered.
        let recorded = h["recorded"]["duration_ms"].as_f64().expect("recorded D90");
        let rendered = h["rendered"]["steps"]["duration_ms"]
            .as_f64()
            .expect("rendered D90");
        assert!(recorded > 0.0 && rendered > 0.0, "{h}");
        assert!(
            (rendered / recorded).log2().abs() < 2.0,
            "a model fitted on the other gravel recordings rings {rendered:.0} ms against \
             {recorded:.0} ms: {h}"
        );
    }
    // The whole material's steps in time, both models.
    let time = &r["materials"][0]["time"];
    let recorded = time["recorded"]["duration_ms"].as_f64().expect("D90");
    assert!(recorded > 100.0, "gravel steps last hundreds of ms: {time}");
    for model in ["iir", "physical"] {
        let steps = &time[model]["steps"];
        assert_eq!(steps["steps"].as_u64(), Some(48), "{model}: {time}");
        assert!(steps["events"].as_f64().expect("events") > 10.0, "{time}");
    }
    assert!(out.contains("in time"), "{out}");
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
        "--name",
        "gravel1",
        "--library",
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

/// A set of recordings that mixes materials fits its mean spectrum well: only leaving
/// each recording out shows it, and `fit` says so without `--report`, naming the odd
/// recording. A material's own takes raise no warning.
#[test]
#[ignore = "slow tier: real recordings"]
fn fit_names_the_recording_that_does_not_belong() {
    let Some(data) = footsteps_dir() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("lab.json");
    let files = |m: &str| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(data.join(m))
            .unwrap()
            .flatten()
            .map(|e| e.path().display().to_string())
            .collect();
        v.sort();
        v
    };
    for (name, set, odd) in [
        (
            "gravel-glass",
            [files("gravel"), files("glass")].concat(),
            Some("default_glass_footstep.ogg"),
        ),
        (
            "snow-metal",
            [files("snow"), files("metal")[1..].to_vec()].concat(),
            Some("default_metal_footstep.2.ogg"),
        ),
        ("gravel", files("gravel"), None),
        ("snow", files("snow"), None),
    ] {
        let mut args = vec!["fit", "--name", name, "--library", s(&out)];
        args.extend(set.iter().map(String::as_str));
        let o = run(&args);
        assert_ok(&o);
        let err = stderr(&o);
        match odd {
            Some(file) => assert!(err.contains(&format!("{file} stands out")), "{name}: {err}"),
            None => assert!(!err.contains("stands out"), "{name}: {err}"),
        }
    }
}

/// Issue 30 item 6: a 30-minute recording (44.1 kHz, 900 strikes) is fitted within
/// 300 MB; the whole file in memory took 7.7 GB. The child's peak resident memory is
/// its `VmHWM`, polled until it exits (Linux only).
#[cfg(target_os = "linux")]
#[test]
#[ignore = "slow tier: a 30-minute recording"]
fn a_thirty_minute_recording_is_fitted_within_300_mb() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("half-hour.wav");
    let rate = 44_100u32;
    let fs = f64::from(rate);
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut rng = underfoot::signal::noise::SplitMix64::new(0x5eed);
    let mut w = hound::WavWriter::create(&wav, spec).unwrap();
    let period = 2 * rate as usize;
    let ring = (0.3 * fs) as usize;
    let mut gain = 0.4;
    for n in 0..1800 * rate as usize {
        let k = n % period;
        if k == 0 {
            gain = 0.3 + 0.2 * rng.uniform();
        }
        let mut x = 2e-4 * (rng.uniform() - 0.5);
        if k < ring {
            let t = k as f64 / fs;
            x += gain
                * (-t / 0.04).exp()
                * ((std::f64::consts::TAU * 120.0 * t).sin() + 0.2 * (rng.uniform() - 0.5));
        }
        w.write_sample((x * 32767.0).round() as i16).unwrap();
    }
    w.finalize().unwrap();

    let lib = dir.path().join("lib.json");
    let mut child = std::process::Command::new(crate::common::bin())
        .args(["fit", "--name", "walk", "--library", s(&lib), s(&wav)])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let status = format!("/proc/{}/status", child.id());
    let mut peak_kb = 0u64;
    let done = loop {
        if let Ok(text) = fs::read_to_string(&status)
            && let Some(kb) = text
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        {
            peak_kb = peak_kb.max(kb);
        }
        if let Some(done) = child.try_wait().unwrap() {
            break done;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(done.success(), "{err}");
    eprintln!("a 30-minute recording: peak {} MB", peak_kb / 1024);
    assert!(peak_kb > 0 && peak_kb < 300 * 1024, "peak {peak_kb} kB");
    assert!(
        err.contains("read as 256 excerpts (of 900) around its 900 strikes"),
        "{err}"
    );
    let lib = Library::load(&lib).unwrap();
    let m = lib.get("walk").unwrap();
    assert_eq!(m.sources.len(), 1);
    assert!(m.fit.strikes >= 200, "{}", m.fit.strikes);
}
