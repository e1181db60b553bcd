//! Output safety through the binary (issue 14): `render` never quantises past the
//! ceiling, and with limb compensation (`--user`) the file is silent within 100 ms of the
//! last force reading.

use crate::common::{assert_ok, run, s};
use std::path::Path;

fn codes(path: &Path) -> (hound::WavSpec, Vec<i32>) {
    let mut r = hound::WavReader::open(path).expect("open wav");
    let spec = r.spec();
    let v = r.samples::<i32>().map(|x| x.expect("sample")).collect();
    (spec, v)
}

#[test]
fn render_in_integer_formats_never_writes_a_code_past_the_ceiling() {
    let dir = tempfile::tempdir().expect("tempdir");
    // -6 dB: 16422.9 codes in 16 bits; rounded, the loudest sample was 16423.
    let ceiling = 10f64.powf(-6.0 / 20.0);
    for (format, full) in [("i16", 32_768.0), ("i24", 8_388_608.0)] {
        let out = dir.path().join(format!("{format}.wav"));
        assert_ok(&run(&[
            "render",
            "--material",
            "metal",
            "--gait",
            "steps=2,channels=1",
            "--gain-db",
            "30",
            "--sample-format",
            format,
            "--out",
            s(&out),
        ]));
        let (_, v) = codes(&out);
        let peak = v.iter().map(|c| c.unsigned_abs()).max().unwrap_or(0);
        let limit = ceiling * full;
        eprintln!("{format}: loudest code {peak}, ceiling {limit:.2}");
        assert!(
            f64::from(peak) <= limit,
            "{format}: code {peak} against a ceiling of {limit:.1}"
        );
        // The limiter was working: the output reaches the ceiling's last code.
        assert_eq!(f64::from(peak), limit.floor(), "{format}");
    }
}

#[test]
fn render_with_user_compensation_is_silent_within_100_ms_of_the_last_reading() {
    let dir = tempfile::tempdir().expect("tempdir");
    for (model, drive) in [("iir", "force"), ("physical", "force-rate")] {
        let out = dir.path().join(format!("{model}.wav"));
        let csv = dir.path().join(format!("{model}.csv"));
        assert_ok(&run(&[
            "render",
            "--material",
            "gravel",
            "--model",
            model,
            "--drive",
            drive,
            "--gait",
            "steps=2,channels=1",
            "--user",
            "table1",
            "--gain-db",
            "12",
            "--tail",
            "1",
            "--save-force",
            s(&csv),
            "--out",
            s(&out),
        ]));
        let text = std::fs::read_to_string(&csv).expect("force csv");
        let last_time: f64 = text
            .lines()
            .rfind(|l| !l.trim().is_empty())
            .and_then(|l| l.split(',').next())
            .and_then(|t| t.trim().parse().ok())
            .expect("last row's time");
        let mut r = hound::WavReader::open(&out).expect("open wav");
        let rate = f64::from(r.spec().sample_rate);
        let v: Vec<f32> = r.samples::<f32>().map(|x| x.expect("sample")).collect();
        assert!(v.iter().any(|x| x.abs() > 1e-4), "{model}: sound");
        let last_loud = v.iter().rposition(|x| *x != 0.0).unwrap_or(0);
        let after = last_loud as f64 / rate - last_time;
        eprintln!(
            "{model}: last non-zero sample {:.1} ms after the last reading",
            after * 1000.0
        );
        assert!(
            after < 0.1,
            "{model}: the last non-zero sample is {:.1} ms after the last reading",
            after * 1000.0
        );
    }
}
