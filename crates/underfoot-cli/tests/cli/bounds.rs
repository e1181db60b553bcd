//! Issue 14, "Time and numbers": nothing hangs, aborts or spins. Each test runs the binary
//! as a child with a deadline and kills it when the deadline passes, so a hang fails the
//! test instead of hanging CI; each checks that the command ends cleanly, with status 0, 1
//! (an error) or 2 (a usage error), never a panic (101) or an abort (134).
//!
//! `UNDERFOOT_TEST_BIN` runs them against another build (e.g. main's, to see them fail).

use crate::common::{assert_error, bin, run, s, stderr};
use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// How a run ended: its status code (None if killed at the deadline or by a signal) and
/// its stderr.
struct Ended {
    code: Option<i32>,
    stderr: String,
    took: Duration,
}

/// Runs the binary with `args` in `dir`, killing it after `deadline`.
fn run_within(dir: &Path, args: &[&str], deadline: Duration) -> Ended {
    let start = Instant::now();
    let mut child = Command::new(bin())
        .args(args)
        .current_dir(dir)
        .env("UNDERFOOT_FONT", "")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run underfoot");
    // Read stderr on a thread so that a chatty child cannot block on a full pipe.
    let mut pipe = child.stderr.take().expect("stderr");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = pipe.read_to_string(&mut s);
        s
    });
    let code = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status.code();
        }
        if start.elapsed() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Ended {
        code,
        stderr: reader.join().unwrap_or_default(),
        took: start.elapsed(),
    }
}

/// Asserts the run ended by itself with `code`, and returns stderr.
fn ended_with(e: &Ended, code: i32) -> &str {
    assert_eq!(
        e.code,
        Some(code),
        "ended with {:?} after {:?}; stderr:\n{}",
        e.code,
        e.took,
        e.stderr
    );
    &e.stderr
}

/// A generated walk's force track, with every time shifted by `offset` seconds.
fn walk_track(dir: &Path, name: &str, offset: f64) -> PathBuf {
    let base = dir.join("walk.csv");
    if !base.exists() {
        let e = run_within(
            dir,
            &[
                "render",
                "--material",
                "gravel",
                "--gait",
                "steps=2",
                "--out",
                "walk.wav",
                "--save-force",
                "walk.csv",
            ],
            Duration::from_secs(60),
        );
        ended_with(&e, 0);
    }
    let text = fs::read_to_string(&base).expect("read walk");
    let mut lines = text.lines();
    let mut out = String::from(lines.next().expect("header"));
    out.push('\n');
    for line in lines {
        let (t, rest) = line.split_once(',').expect("row");
        let t: f64 = t.parse().expect("time");
        out.push_str(&format!("{},{rest}\n", t + offset));
    }
    let path = dir.join(name);
    fs::write(&path, out).expect("write track");
    path
}

/// The frames of a float WAV file (channels interleaved) and its channel count.
fn wav_frames(path: &Path) -> (usize, u16) {
    let r = hound::WavReader::open(path).expect("open wav");
    (r.duration() as usize, r.spec().channels)
}

#[test]
fn a_track_on_a_loggers_clock_renders_from_its_first_reading() {
    // Main aborted with "memory allocation of 326400000192772 bytes failed".
    let dir = tempfile::tempdir().expect("tempdir");
    walk_track(dir.path(), "logger.csv", 1_700_000_000.0);
    let e = run_within(
        dir.path(),
        &[
            "render",
            "--material",
            "gravel",
            "--force",
            "logger.csv",
            "--out",
            "logger.wav",
        ],
        Duration::from_secs(60),
    );
    ended_with(&e, 0);
    // Same length and strikes as the walk at its own clock.
    let (frames, _) = wav_frames(&dir.path().join("logger.wav"));
    let (walk, _) = wav_frames(&dir.path().join("walk.wav"));
    assert!(frames.abs_diff(walk) <= 1, "{frames} vs {walk}");
    assert!(!e.stderr.contains("no heel strike"), "{}", e.stderr);
}

#[test]
fn a_last_row_far_out_is_refused_naming_its_line() {
    // Main silently rendered 1 s with 0 strikes (or aborted).
    let dir = tempfile::tempdir().expect("tempdir");
    let track = walk_track(dir.path(), "far.csv", 0.0);
    let text = fs::read_to_string(&track).expect("read");
    let rows = text.lines().count();
    fs::write(&track, format!("{text}1e300,0,0,0,0\n")).expect("append");
    let e = run_within(
        dir.path(),
        &[
            "render",
            "--material",
            "gravel",
            "--force",
            "far.csv",
            "--out",
            "far.wav",
        ],
        Duration::from_secs(60),
    );
    let err = ended_with(&e, 1);
    assert!(err.contains(&format!("line {}", rows + 1)), "{err}");
    assert!(err.contains("at most 10 s apart"), "{err}");
    assert!(err.len() < 400, "{err}");
    assert!(!dir.path().join("far.wav").exists());
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn a_replay_on_a_loggers_clock_plays_at_once_and_ends() {
    // Main waited 54 years for the first row.
    let dir = tempfile::tempdir().expect("tempdir");
    walk_track(dir.path(), "logger.csv", 1_700_000_000.0);
    let e = run_within(
        dir.path(),
        &[
            "run",
            "--material",
            "gravel",
            "--input",
            "replay:logger.csv@4",
            "--output",
            "null",
        ],
        Duration::from_secs(30),
    );
    ended_with(&e, 0);
    // A 3.8 s walk at 4x, plus a second to ring out.
    assert!(e.took < Duration::from_secs(15), "{:?}", e.took);
}

#[test]
fn durations_rates_and_counts_are_bounded_when_parsed() {
    // Main panicked after opening the device on `--duration inf` and `1e19`.
    let dir = tempfile::tempdir().expect("tempdir");
    let live = ["run", "--material", "gravel"];
    for (flag, value, named) in [
        ("--duration", "inf", "duration"),
        ("--duration", "1e19", "duration"),
        ("--duration", "NaN", "duration"),
        ("--buffer", "0", "buffer"),
        ("--buffer", "4000000000", "buffer"),
        ("--channels", "100000", "channels"),
        ("--sensor-latency", "inf", "sensor latency"),
        ("--input", "replay:x.csv@inf", "replay speed"),
        ("--input", "replay:x.csv@1e-300", "replay speed"),
        ("--input", "gait:steps=1e19", "steps"),
        ("--output", "wav:", "--output"),
    ] {
        let mut args = live.to_vec();
        if flag != "--input" {
            args.extend(["--input", "gait:steps=1"]);
        }
        if flag != "--output" {
            args.extend(["--output", "null"]);
        }
        args.extend([flag, value]);
        let e = run_within(dir.path(), &args, Duration::from_secs(20));
        let err = ended_with(&e, 2);
        assert!(
            err.contains(named) && err.contains(value),
            "{flag} {value}: {err}"
        );
    }
    for args in [
        &[
            "render",
            "--material",
            "gravel",
            "--gait",
            "steps=1",
            "--out",
            "o.wav",
            "--tail",
            "inf",
        ][..],
        &[
            "render",
            "--material",
            "gravel",
            "--gait",
            "steps=1",
            "--out",
            "o.wav",
            "--block",
            "0",
        ],
        &[
            "render",
            "--material",
            "gravel",
            "--gait",
            "steps=1",
            "--out",
            "o.wav",
            "--gain-db",
            "1e308",
        ],
        &[
            "calibrate",
            "sweep",
            "--out",
            "s.json",
            "--sweep-duration",
            "1e19",
        ],
        &[
            "calibrate",
            "sweep",
            "--out",
            "s.json",
            "--repeats",
            "100000000000",
        ],
        &[
            "calibrate",
            "sweep",
            "--out",
            "s.json",
            "--band",
            "1e-200,900",
        ],
        &[
            "calibrate",
            "sweep",
            "--out",
            "s.json",
            "--audio-rate",
            "4000000000",
        ],
    ] {
        let e = run_within(dir.path(), args, Duration::from_secs(20));
        ended_with(&e, 2);
    }
}

/// Three seeded decaying strikes at 8 kHz, 1.5 s, as a 16-bit WAV.
fn strikes_wav(path: &Path) {
    let rate = 8000u32;
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut w = hound::WavWriter::create(path, spec).expect("create wav");
    let mut seed = 0x9e37_79b9_u64;
    for n in 0..(3 * rate / 2) {
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        let noise = ((seed >> 33) as f64 / f64::from(1u32 << 31)) - 0.5;
        let t = f64::from(n % (rate / 2)) / f64::from(rate);
        let x = 0.5 * (-t / 0.04).exp() * (std::f64::consts::TAU * 120.0 * t).sin() + 1e-3 * noise;
        w.write_sample((x * 32767.0).round() as i16).expect("write");
    }
    w.finalize().expect("finalize");
}

#[test]
fn fit_bands_rates_and_endless_inputs_end_promptly() {
    let dir = tempfile::tempdir().expect("tempdir");
    strikes_wav(&dir.path().join("steps.wav"));
    let fit = ["fit", "--name", "x", "--library", "lib.json"];
    // Main spun forever inside the SVD on the first, and aborted on a 34 GB allocation on
    // the second.
    for (flag, value) in [
        ("--band", "1e-200:900"),
        ("--band", "20:1e300"),
        ("--analysis-rate", "4000000000"),
        ("--order", "100000"),
        ("--savgol", "1000000001:3"),
    ] {
        let mut args = fit.to_vec();
        args.extend([flag, value, "steps.wav"]);
        let e = run_within(dir.path(), &args, Duration::from_secs(30));
        let err = ended_with(&e, 2);
        assert!(err.contains(value), "{flag} {value}: {err}");
    }
    assert!(!dir.path().join("lib.json").exists());
    // Main grew until the kernel killed it.
    let mut args = fit.to_vec();
    args.push("/dev/zero");
    let e = run_within(dir.path(), &args, Duration::from_secs(30));
    let err = ended_with(&e, 1);
    assert!(
        err.contains("/dev/zero") && err.contains("too long"),
        "{err}"
    );
    // And a real fit still works.
    let mut args = fit.to_vec();
    args.push("steps.wav");
    let e = run_within(dir.path(), &args, Duration::from_secs(120));
    ended_with(&e, 0);
}

/// Errors echo what was typed, but not all of it (issue 16): a 100 kB material name or
/// spec comes back cut, with its length.
#[test]
fn errors_cut_what_they_echo() {
    let dir = tempfile::tempdir().expect("tempdir");
    let huge = "g".repeat(100_000);
    let out = dir.path().join("x.wav");
    let o = run(&[
        "render",
        "--material",
        &huge,
        "--gait",
        "steps=1",
        "--out",
        s(&out),
    ]);
    let e = assert_error(&o);
    assert!(e.len() < 1000, "{} bytes: {}", e.len(), &e[..200]);
    assert!(e.contains("characters)"), "{e}");
    assert!(!out.exists());
    // A usage error (clap's, status 2) too.
    let o = run(&[
        "run",
        "--input",
        &format!("gait:{huge}"),
        "--output",
        "null",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.len() < 1000, "{} bytes", e.len());
    assert!(e.contains("characters)"), "{e}");
}
