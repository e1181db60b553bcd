//! `underfoot render`: force (a generated walk, a CSV track) to a WAV file of vibration.

use std::fs;

use crate::common::{assert_error, assert_ok, read_wav, run, s, stderr, stdout};

#[test]
#[ignore = "slow tier: long renders"]
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

/// The ceiling holds in the WAV the CLI writes, measured in exact arithmetic: at -4 dB the
/// nearest `f32` (0.63095737) is above 10^(-4/20) (0.630957344...), and a limiter held to it
/// let 262 samples of this render through over the ceiling.
#[test]
fn no_written_sample_exceeds_the_ceiling_in_exact_arithmetic() {
    let dir = tempfile::tempdir().expect("tempdir");
    for db in ["-4", "-5", "-20", "-0.0001"] {
        let out = dir.path().join(format!("c{db}.wav"));
        let o = run(&[
            "render",
            "--material",
            "gravel",
            "--gait",
            "steps=6",
            "--gain-db",
            "40",
            &format!("--ceiling-db={db}"),
            "--out",
            s(&out),
        ]);
        assert_ok(&o);
        let (_, y) = read_wav(&out);
        let exact = 10f64.powf(db.parse::<f64>().unwrap() / 20.0);
        let over = y.iter().filter(|v| f64::from(v.abs()) > exact).count();
        let peak = y.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        assert_eq!(over, 0, "{db} dB: peak {peak} against {exact}");
        // Limited hard, so the peak sits at the ceiling, not merely under it.
        assert!(f64::from(peak) > exact * 0.999_999, "{db} dB: peak {peak}");
    }
}

/// A negative number is a value, refused for what it is (it was "unexpected argument
/// '-1'"), and a negative gain needs no `=`.
#[test]
fn a_negative_number_is_read_as_a_value() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("t.wav");
    let o = run(&[
        "render",
        "--material",
        "hard",
        "--gait",
        "steps=2",
        "--tail",
        "-1",
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("tail \"-1\": expected seconds from 0 to 60"),
        "{e}"
    );
    assert!(!e.contains("unexpected argument"), "{e}");
    assert_ok(&run(&[
        "render",
        "--material",
        "hard",
        "--gait",
        "steps=2",
        "--gain-db",
        "-20",
        "--out",
        s(&out),
    ]));
}

/// The step threshold is a flag: above every step's force no strike is found, and the
/// warning names the threshold and the flag; at a reachable one every step strikes.
#[test]
fn the_step_threshold_is_a_flag() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("t.wav");
    let render = |threshold: &str| {
        run(&[
            "render",
            "--material",
            "hard",
            "--gait",
            "steps=4,channels=1",
            "--step-threshold",
            threshold,
            "--out",
            s(&out),
        ])
    };
    let o = render("2000");
    assert_ok(&o);
    assert!(stdout(&o).contains(" 0 strike(s)"), "{}", stdout(&o));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("never rose through 2000 N") && e.contains("--step-threshold"),
        "{e}"
    );
    let o = render("300");
    assert_ok(&o);
    assert!(stdout(&o).contains(" 4 strike(s)"), "{}", stdout(&o));
    let o = render("0");
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("from 1 to 5000"));
}

/// The limiter's warning says how far over the ceiling the loudest moment went and the
/// gain that fits; rendered at that gain, nothing is limited. `run` warns the same way.
#[test]
fn the_limiter_warning_gives_the_gain_that_fits() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("loud.wav");
    let render = |gain: &str| {
        let o = crate::common::run(&[
            "render",
            "--material",
            "snow",
            "--gait",
            "steps=6",
            "--gain-db",
            gain,
            "--out",
            crate::common::s(&out),
        ]);
        crate::common::assert_ok(&o);
        crate::common::stderr(&o)
    };
    let err = render("20");
    assert!(err.contains("dB over the ceiling (-6.0 dBFS)"), "{err}");
    let fits = err
        .split("--gain-db ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .unwrap_or_else(|| panic!("{err}"))
        .to_owned();
    let over: f64 = err
        .split("went ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        over > 3.0 && (20.0 - over - fits.parse::<f64>().unwrap()).abs() < 0.11,
        "{err}"
    );
    let quiet = render(&fits);
    assert!(!quiet.contains("limiter"), "at --gain-db {fits}: {quiet}");
    let o = crate::common::run(&[
        "run",
        "--material",
        "snow",
        "--input",
        "gait:steps=2,lead_in=0.1,tail=0.1",
        "--output",
        "null",
        "--gain-db",
        "20",
    ]);
    crate::common::assert_ok(&o);
    assert!(
        crate::common::stderr(&o).contains("dB over the ceiling"),
        "{}",
        crate::common::stderr(&o)
    );
}

/// An old spelling (issue 31's renames) still works for one release, with a warning that
/// names the new one: `render --rate` is `--audio-rate`.
#[test]
fn an_old_flag_spelling_works_with_a_warning_naming_the_new_one() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("old.wav");
    let o = run(&[
        "render",
        "--material",
        "gravel",
        "--gait",
        "steps=2",
        "--rate",
        "8000",
        "--out",
        s(&out),
    ]);
    assert_ok(&o);
    assert!(
        stderr(&o).contains("`render --rate` is now `--audio-rate`"),
        "{}",
        stderr(&o)
    );
    let (spec, _) = read_wav(&out);
    assert_eq!(spec.sample_rate, 8000);
}

#[test]
fn render_prepares_only_the_materials_it_plays() {
    // Issue 30 item 6: render prepared every material of the library (30 ms each, a
    // minute for 2,000) before playing one. A material that cannot be prepared for a
    // physical render (it has no physical model) shows it: render fails on it only if
    // it prepares it.
    let dir = tempfile::tempdir().unwrap();
    let mut lib = underfoot::material::builtin::builtin().clone();
    lib.upsert(crate::common::model("no-physical", 3));
    let path = dir.path().join("lib.json");
    fs::write(&path, lib.to_json()).unwrap();
    let out = dir.path().join("gravel.wav");
    let render = |material: &str, model: &str| {
        run(&[
            "render",
            "--library",
            s(&path),
            "--material",
            material,
            "--model",
            model,
            "--gait",
            "steps=2",
            "--out",
            s(&out),
        ])
    };
    assert_ok(&render("gravel", "physical"));
    // Asked for, it is refused by name; a name the library lacks is refused with the
    // library's names.
    assert!(
        assert_error(&render("no-physical", "physical"))
            .contains("\"no-physical\" has no physical model")
    );
    let o = render("nope", "iir");
    let text = assert_error(&o);
    assert!(
        text.contains("no material named \"nope\"") && text.contains("gravel"),
        "{text}"
    );
}
