//! What the tests of the binary share: the binary, a run of it, its output as text, and
//! the library files, recordings and failures several commands' tests need.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use underfoot::material::{FilterCoefficients, FitRecord, Library, MaterialModel, SourceFile};
use underfoot::signal::{Biquad, Sos};
use underfoot::units::{Band, Hz, SampleRate};

/// The binary under test; `UNDERFOOT_TEST_BIN` points these tests at another build
/// (e.g. main's, to see each of them fail there).
pub fn bin() -> PathBuf {
    std::env::var_os("UNDERFOOT_TEST_BIN").map_or_else(
        || PathBuf::from(env!("CARGO_BIN_EXE_underfoot")),
        PathBuf::from,
    )
}

/// Runs the binary with `args` to completion. The fit plot looks for fonts; an empty
/// `UNDERFOOT_FONT` keeps the tests independent of the machine's fonts.
pub fn run(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .env("UNDERFOOT_FONT", "")
        .output()
        .expect("run underfoot")
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Asserts that the run succeeded, showing its status and output if not.
pub fn assert_ok(o: &Output) {
    assert!(
        o.status.success(),
        "exit {:?}\nstdout: {}\nstderr: {}",
        o.status.code(),
        stdout(o),
        stderr(o)
    );
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// A valid model: one resonant section (poles at radius 0.9) whose fit record is its own
/// response, so the library accepts it exactly as a fit would have written it.
pub fn model(name: &str, strikes: usize) -> MaterialModel {
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
        excitation: None,
        time: None,
        level_db: 0.0,
    }
}

pub fn library(names: &[&str]) -> Library {
    let mut lib = Library::new();
    for (i, n) in names.iter().enumerate() {
        lib.upsert(model(n, 10 + i));
    }
    lib
}

pub fn write_library(dir: &Path, names: &[&str]) -> PathBuf {
    let path = dir.join("lib.json");
    fs::write(&path, library(names).to_json()).expect("write library");
    path
}

/// Asserts a failure with status 1 (an error, not a usage mistake) and returns stderr.
pub fn assert_error(o: &Output) -> String {
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

pub fn read_wav(path: &Path) -> (hound::WavSpec, Vec<f32>) {
    let mut r = hound::WavReader::open(path).expect("open wav");
    let spec = r.spec();
    let samples = r.samples::<f32>().map(|s| s.expect("sample")).collect();
    (spec, samples)
}

/// The shared footstep recordings, or `None` (with a note) when they are absent and
/// `UNDERFOOT_REQUIRE_DATA` is not `1`.
pub fn footsteps_dir() -> Option<PathBuf> {
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

/// The events of the session record in `folder` once the session has ended (its
/// manifest says why), waiting up to 10 s for the end.
#[cfg_attr(
    not(feature = "panel"),
    expect(dead_code, reason = "the panel's tests read the records")
)]
pub fn ended_record_events(folder: &Path) -> Vec<serde_json::Value> {
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while !fs::read_to_string(folder.join("manifest.json")).is_ok_and(|m| m.contains("\"reason\""))
    {
        assert!(
            std::time::Instant::now() < deadline,
            "the record in {} never ended",
            folder.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    fs::read_to_string(folder.join("events.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}
