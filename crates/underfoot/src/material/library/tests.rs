use super::*;
use crate::atomic_file::OutputFile;
use crate::document::{Document, FileError, TAG_PREFIX};
use crate::material::{FilterCoefficients, FitRecord, SourceFile};
use crate::signal::{Biquad, Sos};
use crate::units::{Band, SampleRate};
use std::fs;
use std::path::Path;

/// A valid model: one resonant section whose fit record is its own response.
fn model(name: &str) -> MaterialModel {
    let rate = SampleRate(2000);
    let band = Band::new(20.0, 900.0);
    let sos = Sos::new(vec![Biquad {
        b: [0.1, 0.0, -0.1],
        a: [1.0, -1.6, 0.81],
    }]);
    let grid: Vec<f64> = band.log_grid(16).iter().map(|f| f.0).collect();
    let mag: Vec<f64> = grid
        .iter()
        .map(|&f| sos.response(rate.omega(crate::units::Hz(f))).norm())
        .collect();
    MaterialModel {
        name: name.to_string(),
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
            method: "hand".to_string(),
            poor_fit: false,
            strikes: 3,
            fit_seconds: 0.5,
            longest_decay: crate::units::Seconds(0.5),
            worst: None,
        },
        sources: vec![SourceFile {
            file: "a.wav".to_string(),
            sha256: "ab".repeat(32),
        }],
        physical: None,
        excitation: None,
        time: None,
        level_db: 0.0,
    }
}

fn library(names: &[&str]) -> Library {
    Library {
        format: FORMAT.to_string(),
        materials: names.iter().map(|n| model(n)).collect(),
    }
}

fn invalid_reason(m: MaterialModel) -> String {
    let lib = Library {
        format: FORMAT.to_string(),
        materials: vec![m],
    };
    match Library::from_json(&lib.to_json(), "test.json") {
        Err(LibraryError::Invalid { origin, reason, .. }) => {
            assert_eq!(origin, "test.json");
            reason
        }
        other => panic!("expected Invalid, got {other:?}"),
    }
}

#[test]
fn round_trips_through_json() {
    let lib = library(&["gravel", "snow"]);
    let back = Library::from_json(&lib.to_json(), "mem").expect("valid");
    assert_eq!(back, lib);
    assert_eq!(back.names(), ["gravel", "snow"]);
    assert!(Library::new().validate().is_ok());
}

#[test]
fn json_syntax_error_gives_line_and_column() {
    let text = "{\n  \"format\": \"underfoot.library/1\",\n  \"materials\": [,]\n}";
    match Library::from_json(text, "bad.json") {
        Err(e @ LibraryError::Json { line: 3, .. }) => {
            let msg = e.to_string();
            assert!(msg.starts_with("bad.json:"), "{msg}");
            assert!(msg.contains("line 3, column"), "{msg}");
        }
        other => panic!("expected Json at line 3, got {other:?}"),
    }
}

#[test]
fn wrong_shape_is_a_json_error() {
    let text = r#"{"format": "underfoot.library/1", "materials": [{"name": "x"}]}"#;
    match Library::from_json(text, "o") {
        Err(LibraryError::Json { message, .. }) => assert!(message.contains("missing field")),
        other => panic!("expected Json, got {other:?}"),
    }
}

/// `model` with its section's poles moved to radius `r` (same angle), record updated.
fn ringing(name: &str, r: f64) -> MaterialModel {
    let mut m = model(name);
    let w: f64 = 0.3;
    let sos = Sos::new(vec![Biquad {
        b: [0.1, 0.0, -0.1],
        a: [1.0, -2.0 * r * w.cos(), r * r],
    }]);
    m.filter = FilterCoefficients::from_sos(&sos);
    m.fit.model = m
        .fit
        .grid_hz
        .iter()
        .map(|&f| {
            sos.response(m.sample_rate.omega(crate::units::Hz(f)))
                .norm()
        })
        .collect();
    m.fit.measured = m.fit.model.clone();
    m
}

/// A pole that rings longer than the stored limit is refused on load, naming the
/// section, the decay and the limit.
#[test]
fn a_pole_beyond_the_decay_limit_is_refused() {
    let slow = ringing("slow", 0.999_99); // 50 s at 2 kHz
    let reason = invalid_reason(slow);
    assert!(
        reason.contains("filter.sos[0]") && reason.contains("longest_decay_s = 0.5"),
        "{reason}"
    );
    // Just inside it is fine.
    let rho = crate::fit::decay_radius(SampleRate(2000), crate::units::Seconds(0.5));
    let lib = Library {
        format: FORMAT.to_string(),
        materials: vec![ringing("edge", rho * (1.0 - 1e-12))],
    };
    Library::from_json(&lib.to_json(), "edge").unwrap();
}

/// A format-1 file is read as what it played: its slow pole pulled in to the 0.5 s
/// radius, the record recomputed for that filter, and written back as format 2.
#[test]
fn format_1_is_upgraded_to_what_the_voice_played() {
    let old = Library {
        format: FORMAT_1.to_string(),
        materials: vec![ringing("old", 0.999_99), model("fine")],
    };
    let mut value: serde_json::Value = serde_json::from_str(&old.to_json()).unwrap();
    value["format"] = FORMAT_1.into();
    for m in value["materials"].as_array_mut().unwrap() {
        m["fit"].as_object_mut().unwrap().remove("longest_decay_s");
    }
    let text = value.to_string();
    assert!(!text.contains("longest_decay_s"), "{text}");
    let lib = Library::from_json(&text, "old.json").unwrap();
    assert_eq!(lib.format, FORMAT);
    let m = lib.get("old").unwrap();
    let rho = crate::fit::decay_radius(SampleRate(2000), crate::units::Seconds(0.5));
    let radius = m.sos().unwrap().poles()[0].norm();
    assert!((radius - rho).abs() < 1e-12, "{radius} vs {rho}");
    assert!(m.fit.lsd_db > 0.0 && m.fit.method.contains("format 1"));
    let sos = m.sos().unwrap();
    for (f, v) in m.fit.grid_hz.iter().zip(&m.fit.model) {
        let now = sos
            .response(m.sample_rate.omega(crate::units::Hz(*f)))
            .norm();
        assert!((now / v - 1.0).abs() < 1e-12);
    }
    // The model that was inside the limit is untouched.
    assert_eq!(lib.get("fine").unwrap(), &model("fine"));
    assert!(lib.to_json().contains(FORMAT));
}

/// The upgrade does not repair a format-1 file: an unstable filter is still refused.
#[test]
fn format_1_with_an_unstable_filter_is_still_refused() {
    let old = Library {
        format: FORMAT_1.to_string(),
        materials: vec![ringing("bad", 1.01)],
    };
    let mut value: serde_json::Value = serde_json::from_str(&old.to_json()).unwrap();
    value["format"] = FORMAT_1.into();
    value["materials"][0]["fit"]
        .as_object_mut()
        .unwrap()
        .remove("longest_decay_s");
    let e = Library::from_json(&value.to_string(), "old.json").expect_err("unstable");
    assert!(e.to_string().contains("unstable"), "{e}");
}

#[test]
fn unknown_or_missing_format_is_reported_with_supported_versions() {
    let v4 = r#"{"format": "underfoot.library/4", "materials": [{"whatever": 1}]}"#;
    let e = Library::from_json(v4, "new.json").expect_err("v4");
    assert!(
        matches!(&e, LibraryError::UnknownFormat { found: Some(f), .. } if f == "underfoot.library/4")
    );
    let msg = e.to_string();
    assert!(
        msg.contains("underfoot.library/4") && msg.contains(FORMAT),
        "{msg}"
    );

    let none = Library::from_json(r#"{"materials": []}"#, "o").expect_err("no tag");
    assert!(matches!(
        none,
        LibraryError::UnknownFormat { found: None, .. }
    ));
    let num = Library::from_json(r#"{"format": 1, "materials": []}"#, "o").expect_err("num");
    assert!(matches!(num, LibraryError::UnknownFormat { found: Some(f), .. } if f == "1"));
    let arr = Library::from_json("[]", "o").expect_err("array");
    assert!(matches!(
        arr,
        LibraryError::UnknownFormat { found: None, .. }
    ));
}

#[test]
fn invalid_names_are_rejected() {
    assert!(invalid_reason(model("")).contains("name is empty"));
    assert!(invalid_reason(model("a b")).contains("name contains ' '"));
    assert!(invalid_reason(model("grès")).contains("name contains 'è'"));
    assert!(invalid_reason(model(&"g".repeat(65))).contains("more than 64"));
    let lib = library(&["a", "b", "a"]);
    match Library::from_json(&lib.to_json(), "o") {
        Err(LibraryError::Invalid {
            material, reason, ..
        }) => {
            assert_eq!(material, "a");
            assert!(
                reason.contains("duplicate") && reason.contains("materials[0]"),
                "{reason}"
            );
        }
        other => panic!("expected duplicate, got {other:?}"),
    }
}

#[test]
fn rate_and_band_are_checked() {
    let mut m = model("m");
    m.sample_rate = SampleRate(0);
    assert!(invalid_reason(m).contains("sample_rate is 0"));
    let mut m = model("m");
    m.band_hz = Band::new(20.0, 1000.0);
    assert!(invalid_reason(m).contains("band_hz"));
    let mut m = model("m");
    m.band_hz = Band::new(500.0, 100.0);
    assert!(invalid_reason(m).contains("band_hz"));
}

#[test]
fn malformed_sections_are_rejected() {
    let mut m = model("m");
    m.filter.sos.clear();
    assert!(invalid_reason(m).contains("no sections"));
    let mut m = model("m");
    m.filter.sos[0][3] = 0.0;
    assert!(invalid_reason(m).contains("a0 = 0"));
    // NaN cannot be written as JSON, so check the in-memory path too.
    let mut m = model("m");
    m.filter.sos[0][1] = f64::NAN;
    let r = validate_model(&m).expect_err("nan").to_string();
    assert!(r.contains("filter.sos[0][1] is not finite"), "{r}");
    let lib = Library {
        format: FORMAT.to_string(),
        materials: vec![m],
    };
    assert!(matches!(lib.validate(), Err(LibraryError::Invalid { .. })));
}

#[test]
fn unstable_section_is_rejected() {
    let mut m = model("m");
    // Poles at radius sqrt(1.0201) = 1.01: just outside the unit circle.
    let sos = Sos::new(vec![Biquad {
        b: [0.1, 0.0, -0.1],
        a: [1.0, -1.6, 1.0201],
    }]);
    m.filter = FilterCoefficients::from_sos(&sos);
    let r = invalid_reason(m);
    assert!(r.contains("unstable") && r.contains("1.01"), "{r}");
    // On the circle is unstable too.
    let mut m = model("m");
    m.filter.sos[0][5] = 1.0;
    m.filter.a[2] = 1.0;
    assert!(invalid_reason(m).contains("unstable"));
}

#[test]
fn order_must_match_sections() {
    let mut m = model("m");
    m.order = 4;
    let r = invalid_reason(m);
    assert!(r.contains("order is 4") && r.contains("2 poles"), "{r}");
}

#[test]
fn expanded_coefficients_must_match_sections() {
    let mut m = model("m");
    m.filter.a[1] *= 1.0 + 1e-6;
    assert!(invalid_reason(m).contains("filter.a[1]"));
    let mut m = model("m");
    m.filter.b.push(0.0);
    assert!(invalid_reason(m).contains("filter.b has 4 coefficients"));
    // Rounding noise well inside the tolerance is accepted.
    let mut m = model("m");
    m.filter.a[1] *= 1.0 + 1e-12;
    assert!(validate_model(&m).is_ok());
}

#[test]
fn fit_record_is_checked() {
    let mut m = model("m");
    m.fit.model.pop();
    assert!(invalid_reason(m).contains("fit arrays differ in length"));
    let mut m = model("m");
    m.fit.grid_hz.swap(0, 1);
    assert!(invalid_reason(m).contains("not increasing"));
    let mut m = model("m");
    m.fit.measured[2] = -1.0;
    assert!(invalid_reason(m).contains("fit.measured[2]"));
    let mut m = model("m");
    m.fit.lsd_db = f64::INFINITY;
    assert!(
        validate_model(&m)
            .expect_err("inf")
            .to_string()
            .contains("fit.lsd_db")
    );
    let mut m = model("m");
    m.fit.nrmse = -0.1;
    assert!(invalid_reason(m).contains("fit.nrmse"));
    let mut m = model("m");
    m.sources[0].sha256 = "XYZ".to_string();
    assert!(invalid_reason(m).contains("sources[0].sha256"));
}

#[test]
fn upsert_replaces_in_place_and_get_remove_report_missing_names() {
    let mut lib = library(&["a", "b", "c"]);
    let mut b2 = model("b");
    b2.fit.strikes = 99;
    let old = lib.upsert(b2).expect("replaced");
    assert_eq!(old.fit.strikes, 3);
    assert_eq!(lib.names(), ["a", "b", "c"]);
    assert_eq!(lib.get("b").expect("b").fit.strikes, 99);
    assert!(lib.upsert(model("d")).is_none());
    assert_eq!(lib.names(), ["a", "b", "c", "d"]);

    assert_eq!(lib.remove("a").expect("a").name, "a");
    match lib.remove("a") {
        Err(e @ LibraryError::NotFound { .. }) => {
            let LibraryError::NotFound {
                ref name,
                ref available,
            } = e
            else {
                unreachable!()
            };
            assert_eq!(name, "a");
            assert_eq!(available, &["b", "c", "d"]);
            assert!(e.to_string().contains("available: b, c, d"));
        }
        other => panic!("expected NotFound, got {other:?}"),
    }
    let mut many = Library::new();
    for i in 0..30 {
        many.upsert(model(&format!("m{i}")));
    }
    let text = many.get("x").expect_err("not there").to_string();
    assert!(
        text.contains("m0, m1,") && text.contains("m23 and 6 more") && !text.contains("m24"),
        "{text}"
    );
    let empty = Library::new();
    assert!(
        empty
            .get("x")
            .expect_err("empty")
            .to_string()
            .contains("library is empty")
    );
}

fn dir_entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn save_and_load_round_trip_without_leftovers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("lib.json");
    let lib = library(&["gravel"]);
    lib.save(&path).expect("save");
    assert_eq!(Library::load(&path).expect("load"), lib);
    // Overwrite an existing file.
    let lib2 = library(&["gravel", "sand"]);
    lib2.save(&path).expect("save again");
    assert_eq!(Library::load(&path).expect("load"), lib2);
    assert_eq!(dir_entries(dir.path()), ["lib.json"]);
}

#[test]
fn saving_an_invalid_library_leaves_the_old_file_untouched() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("lib.json");
    library(&["gravel"]).save(&path).expect("save");
    let before = fs::read(&path).expect("read");

    let mut bad = library(&["gravel"]);
    bad.materials[0].filter.sos[0][5] = 1.5;
    let e = bad.save(&path).expect_err("unstable");
    assert!(matches!(e, LibraryError::Invalid { .. }));
    assert!(e.to_string().contains("library to be saved to"), "{e}");
    assert_eq!(fs::read(&path).expect("read"), before);
    assert_eq!(dir_entries(dir.path()), ["lib.json"]);
}

#[test]
fn failed_write_leaves_target_and_no_temp_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The target is a non-empty directory: renaming a file over it must fail, after
    // the temporary file has been written.
    let target = dir.path().join("lib.json");
    fs::create_dir(&target).expect("mkdir");
    fs::write(target.join("keep"), b"x").expect("write");
    match library(&["a"]).save(&target) {
        // The output policy refuses a directory before anything is written.
        Err(LibraryError::File(FileError { path, action, .. })) => {
            assert_eq!(path, target);
            assert_eq!(action, crate::atomic_file::REFUSED);
        }
        other => panic!("expected Io, got {other:?}"),
    }
    assert_eq!(dir_entries(dir.path()), ["lib.json"]);
    assert_eq!(fs::read(target.join("keep")).expect("kept"), b"x");
}

#[test]
fn concurrent_edits_all_land() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("lib.json");
    let names = ["a", "b", "c", "d", "e", "f"];
    std::thread::scope(|s| {
        for name in names {
            let path = &path;
            s.spawn(move || {
                let out = OutputFile::check(path, &[]).expect("check");
                let model = library(&[name]).materials.remove(0);
                Library::edit(&out, true, |lib| {
                    // Widen the window between the read and the write.
                    std::thread::sleep(std::time::Duration::from_millis(20));
                    Ok(lib.upsert(model))
                })
                .expect("edit");
            });
        }
    });
    let mut got = Library::load(&path).expect("load").names().join(",");
    got = got
        .split(',')
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect::<Vec<_>>()
        .join(",");
    assert_eq!(got, names.join(","));
    // Without create, a missing library is an error and nothing is written.
    let missing = OutputFile::check(&dir.path().join("none.json"), &[]).expect("check");
    assert!(Library::edit(&missing, false, |_| Ok(())).is_err());
    assert!(!dir.path().join("none.json").exists());
}

#[test]
fn load_reports_io_and_load_or_new_accepts_only_a_missing_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let missing = dir.path().join("none.json");
    match Library::load(&missing) {
        Err(e @ LibraryError::File(_)) => {
            assert!(e.to_string().contains("none.json"), "{e}");
        }
        other => panic!("expected Io, got {other:?}"),
    }
    assert_eq!(
        Library::load_or_new(&missing).expect("empty"),
        Library::new()
    );

    let broken = dir.path().join("broken.json");
    fs::write(&broken, "{").expect("write");
    assert!(matches!(
        Library::load_or_new(&broken),
        Err(LibraryError::Json { .. })
    ));
    // A directory exists but is not a readable file.
    assert!(matches!(
        Library::load_or_new(dir.path()),
        Err(LibraryError::File(_))
    ));
}

/// The tag the document layer writes is the one this module names.
#[test]
fn the_document_tag_is_the_library_format() {
    assert_eq!(crate::document::tag::<Library>(), FORMAT);
    assert_eq!(
        format!("{TAG_PREFIX}{}/{}", Library::KIND, Library::OLDEST),
        FORMAT_1
    );
}
