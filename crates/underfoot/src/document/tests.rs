use serde::{Deserialize, Serialize};

use super::*;

#[derive(Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Gauge {
    name: String,
    newtons: f64,
}

#[derive(Debug, thiserror::Error)]
#[error("newtons is {0}, expected a finite value")]
struct NotFinite(f64);

impl Document for Gauge {
    const KIND: &'static str = "gauge";
    const VERSION: u32 = 3;
    const OLDEST: u32 = 2;
    const LEGACY_KIND: Option<&'static str> = Some("old-gauge");
    const DESCRIPTION: &'static str = "test gauge";
    type Invalid = NotFinite;

    fn validate(&self) -> Result<(), NotFinite> {
        if self.newtons.is_finite() {
            Ok(())
        } else {
            Err(NotFinite(self.newtons))
        }
    }

    fn upgrade(mut self, from: u32) -> Result<Self, NotFinite> {
        assert_eq!(from, 2);
        self.newtons *= 1000.0; // version 2 stored kN
        Ok(self)
    }
}

fn gauge() -> Gauge {
    Gauge {
        name: "heel".into(),
        newtons: 700.0,
    }
}

#[test]
fn round_trip_puts_the_tag_first() {
    let json = to_json(&gauge(), "mem").unwrap();
    assert!(json.starts_with("{\n  \"format\": \"underfoot.gauge/3\",\n  \"name\""));
    assert!(json.ends_with("}\n"));
    assert_eq!(from_json::<Gauge>(&json, "mem").unwrap(), gauge());
}

#[test]
fn an_older_version_is_upgraded() {
    let g: Gauge = from_json(
        r#"{"format": "underfoot.gauge/2", "name": "heel", "newtons": 0.7}"#,
        "m",
    )
    .unwrap();
    assert_eq!(g, gauge());
}

#[test]
fn a_legacy_header_still_loads() {
    let g: Gauge = from_json(
        r#"{"kind": "old-gauge", "version": 3, "name": "heel", "newtons": 700.0}"#,
        "m",
    )
    .unwrap();
    assert_eq!(g, gauge());
}

#[test]
fn headers_are_checked_before_the_body() {
    let cases = [
        (
            r#"{"name": 1}"#,
            "no \"format\" tag (is this an underfoot test gauge file?)",
        ),
        (r#"[1, 2]"#, "no \"format\" tag"),
        (
            r#"{"format": "underfoot.library/2", "materials": []}"#,
            "a file of format \"underfoot.library/2\", expected \"underfoot.gauge/3\"",
        ),
        (r#"{"format": 7}"#, "a file of format \"7\""),
        (
            r#"{"format": "underfoot.gauge/4", "x": 1}"#,
            "test gauge format version 4 is not supported; this version of underfoot reads versions 2 to 3",
        ),
        (
            r#"{"format": "underfoot.gauge/1"}"#,
            "version 1 is not supported",
        ),
        (
            r#"{"format": "underfoot.gauge/x"}"#,
            "version x is not supported",
        ),
        (
            r#"{"kind": "frequency-response", "version": 1}"#,
            "a file of format \"frequency-response\"",
        ),
        (
            r#"{"kind": "old-gauge"}"#,
            "version missing is not supported",
        ),
        (
            r#"{"kind": "old-gauge", "version": 9}"#,
            "version 9 is not supported",
        ),
    ];
    for (text, expected) in cases {
        let e = from_json::<Gauge>(text, "f.json").unwrap_err().to_string();
        assert!(e.starts_with("f.json: "), "{e}");
        assert!(e.contains(expected), "{text}: {e}");
    }
}

#[test]
fn bodies_are_checked_after_the_header() {
    let e =
        from_json::<Gauge>("{\"format\": \"underfoot.gauge/3\",\n \"name\": 3}", "f").unwrap_err();
    assert!(matches!(e, DocumentError::Json { line: 2, .. }), "{e}");
    assert!(
        e.to_string()
            .contains("not a valid test gauge file at line 2"),
        "{e}"
    );
    let e = from_json::<Gauge>("{\"format\": \"underfoot.gauge/3\"", "f").unwrap_err();
    assert!(matches!(e, DocumentError::Json { .. }), "{e}");
    // A field outside the body's shape is refused, and the tag is not one.
    let e = from_json::<Gauge>(
        r#"{"format": "underfoot.gauge/3", "name": "a", "newtons": 1, "kind": "x"}"#,
        "f",
    )
    .unwrap_err();
    assert!(e.to_string().contains("unknown field `kind`"), "{e}");
}

#[test]
fn validation_runs_on_load_and_before_save() {
    let e = from_json::<Gauge>(
        r#"{"format": "underfoot.gauge/3", "name": "a", "newtons": 1e999}"#,
        "f",
    );
    // 1e999 is not JSON serde accepts as finite; a NaN cannot be written in JSON at all,
    // so validation is reached through an upgrade that overflows.
    assert!(e.is_err());
    let e = from_json::<Gauge>(
        r#"{"format": "underfoot.gauge/2", "name": "a", "newtons": 1e306}"#,
        "f",
    )
    .unwrap_err();
    assert_eq!(e.to_string(), "f: newtons is inf, expected a finite value");
    assert!(e.reason().unwrap().downcast_ref::<NotFinite>().is_some());

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.json");
    std::fs::write(&path, "kept").unwrap();
    let bad = Gauge {
        name: "a".into(),
        newtons: f64::NAN,
    };
    assert!(matches!(
        save(&path, &bad),
        Err(DocumentError::Invalid { .. })
    ));
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "kept");
}

#[test]
fn files_round_trip_and_name_their_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.json");
    save(&path, &gauge()).unwrap();
    assert_eq!(load::<Gauge>(&path).unwrap(), gauge());

    let missing = dir.path().join("missing.json");
    let e = load::<Gauge>(&missing).unwrap_err();
    let DocumentError::File(file) = &e else {
        panic!("{e}")
    };
    assert_eq!(file.path, missing);
    assert_eq!(file.source.kind(), std::io::ErrorKind::NotFound);

    let e = save(dir.path(), &gauge()).unwrap_err();
    assert!(
        matches!(&e, DocumentError::File(f) if f.is_refusal()),
        "{e}"
    );
}
