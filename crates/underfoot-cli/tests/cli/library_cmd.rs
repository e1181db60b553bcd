//! `underfoot library`: list, show, remove, on library files the tests write and on the built-in library; broken files refused and left as they were.

use std::fs;

use underfoot::material::{FilterCoefficients, Library, MaterialModel};
use underfoot::signal::{Biquad, Sos};

use crate::common::{assert_error, assert_ok, library, model, run, s, stdout, write_library};

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
    let v4 = library(&["gravel"])
        .to_json()
        .replace("underfoot.library/3", "underfoot.library/4");
    let cases: [(&str, String, &[&str]); 3] = [
        (
            "malformed",
            "{\n  \"format\": \"underfoot.library/3\",\n  \"materials\": [\n".into(),
            &["line", "column"],
        ),
        (
            "unknown version",
            v4,
            &["\"underfoot.library/4\"", "underfoot.library/3"],
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

/// `library show` on a fitted material (issue 31): the poles from the lowest frequency
/// up, and the fit's computing time on a line of its own, not beside the strikes as if it
/// were the recordings' length.
#[test]
fn show_sorts_the_poles_and_says_what_its_time_is() {
    let o = run(&["library", "show", "gravel"]);
    assert_ok(&o);
    let out = stdout(&o);
    let freqs: Vec<f64> = out
        .lines()
        .skip_while(|l| !l.contains("poles"))
        .skip(1)
        .filter_map(|l| {
            l.trim()
                .strip_suffix(" Hz")?
                .split_whitespace()
                .nth(1)?
                .parse()
                .ok()
        })
        .collect();
    assert_eq!(freqs.len(), 8, "{out}");
    assert!(freqs.windows(2).all(|w| w[0] <= w[1]), "{freqs:?}");
    let evidence = out.lines().find(|l| l.contains("evidence")).unwrap();
    assert_eq!(evidence.trim(), "evidence     3 strikes", "{out}");
    assert!(out.contains("fit time "), "{out}");
}
