//! Live equals offline, end to end through the `underfoot` binary: the walk
//! (`gait:steps=6,channels=1` on gravel) played by `run` into a paced WAV at buffers of
//! 16, 64, 256 and 1024 frames, and to `null`, against `render` of the same walk.
//!
//! `run` reports its sensor clock's anchor ("t = T s at frame A"); the documented rule
//! puts a reading of sensor time `t` at frame `A + round((t - T) fs)`, and `render` at
//! `round(t fs)` (the walk starts at 0 s), so the live WAV is the offline one shifted by
//! `A - round(T fs)`. Each step's peak must be within 0.5 dB, its onset within one
//! sample of that, and its duration (D90) and micro-event count the same, measured by the
//! tests' own step analysis ([`crate::step_stats`]).

use crate::common::run;
use std::path::Path;
use std::process::Output;

const RATE: f64 = 48_000.0;
const WALK: &str = "steps=6,channels=1";

fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn read_wav(path: &Path) -> Vec<f32> {
    let mut r = hound::WavReader::open(path).expect("a WAV");
    assert_eq!(r.spec().channels, 1);
    r.samples::<f32>().map(|s| s.expect("a sample")).collect()
}

/// The number right after `key` in `text` (the report's "sensor clock: t = 0.000000 s at
/// frame 12345; late readings 0, resyncs 0" gives the anchor and the two counts).
fn number_after(text: &str, key: &str) -> f64 {
    let rest = &text[text
        .find(key)
        .unwrap_or_else(|| panic!("no {key:?} in {text}"))
        + key.len()..];
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .unwrap_or(rest.len());
    rest[..end]
        .parse()
        .unwrap_or_else(|_| panic!("{key:?} in {text}"))
}

/// Steps of a render (onset, peak in dBFS, D90 in ms, micro-events), measured as the
/// issue measures them.
fn steps(y: &[f32]) -> Vec<(usize, f64, f64, usize)> {
    let x: Vec<f64> = y.iter().map(|v| f64::from(*v)).collect();
    crate::step_stats::steps(&x, RATE as u32)
        .iter()
        .map(|s| (s.onset, 20.0 * s.peak.log10(), s.d90_ms, s.events))
        .collect()
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn run_plays_the_walk_as_render_does_for_buffers_16_to_1024() {
    let dir = tempfile::tempdir().expect("tempdir");
    let offline_path = dir.path().join("offline.wav");
    let offline_path_str = offline_path.to_str().unwrap().to_string();
    ok(&run(&[
        "render",
        "--material",
        "gravel",
        "--gait",
        WALK,
        "--out",
        &offline_path_str,
    ]));
    let offline = read_wav(&offline_path);
    let want = steps(&offline);
    assert_eq!(want.len(), 6, "{want:?}");

    // The four sessions at once: each is real time (about 5 s).
    let runs: Vec<_> = [16, 64, 256, 1024]
        .into_iter()
        .map(|buffer| {
            let path = dir.path().join(format!("live-{buffer}.wav"));
            let handle = std::thread::spawn({
                let path = path.clone();
                move || {
                    run(&[
                        "run",
                        "--material",
                        "gravel",
                        "--input",
                        &format!("gait:{WALK}"),
                        "--output",
                        &format!("wav:{}", path.to_str().unwrap()),
                        "--buffer",
                        &buffer.to_string(),
                        // Room for a loaded test machine's scheduling jitter.
                        "--sensor-latency",
                        "40",
                    ])
                }
            });
            (buffer, path, handle)
        })
        .collect();
    for (buffer, path, handle) in runs {
        let report = ok(&handle.join().expect("the run thread"));
        assert!(report.contains("6 strike(s)"), "{report}");
        let anchor_frame = number_after(&report, " s at frame ") as usize;
        let anchor_time = number_after(&report, "sensor clock: t = ");
        let late = number_after(&report, "late readings ");
        let resyncs = number_after(&report, "resyncs ");
        assert_eq!((late, resyncs), (0.0, 0.0), "buffer {buffer}: {report}");
        let shift = anchor_frame - (anchor_time * RATE).round() as usize;
        let live = read_wav(&path);
        let got = steps(&live);
        assert_eq!(got.len(), 6, "buffer {buffer}: {got:?}");
        for (k, (w, g)) in want.iter().zip(&got).enumerate() {
            assert!(
                (w.1 - g.1).abs() <= 0.5,
                "buffer {buffer}, step {k}: live {:.2} dBFS, offline {:.2}",
                g.1,
                w.1
            );
            assert!(
                (w.0 + shift).abs_diff(g.0) <= 1,
                "buffer {buffer}, step {k}: onset at {} live, {} offline + {shift}",
                g.0,
                w.0
            );
            assert!(
                (w.2 - g.2).abs() < 0.05 && w.3 == g.3,
                "buffer {buffer}, step {k}: D90 {:.1} ms and {} micro-events live, \
                 {:.1} ms and {} offline",
                g.2,
                g.3,
                w.2,
                w.3
            );
        }
        eprintln!(
            "buffer {buffer}: peaks offline {:?}, live {:?} dBFS",
            want.iter()
                .map(|s| format!("{:.2} ({:.0} ms, {})", s.1, s.2, s.3))
                .collect::<Vec<_>>(),
            got.iter()
                .map(|s| format!("{:.2} ({:.0} ms, {})", s.1, s.2, s.3))
                .collect::<Vec<_>>()
        );
    }
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn run_to_null_strikes_and_peaks_as_render_does() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("offline.wav");
    let offline = ok(&run(&[
        "render",
        "--material",
        "gravel",
        "--gait",
        WALK,
        "--out",
        out.to_str().unwrap(),
    ]));
    let live = ok(&run(&[
        "run",
        "--material",
        "gravel",
        "--input",
        &format!("gait:{WALK}"),
        "--output",
        "null",
        "--buffer",
        "64",
        "--sensor-latency",
        "40",
    ]));
    assert!(live.contains("6 strike(s)"), "{live}");
    assert!(live.contains("late readings 0, resyncs 0"), "{live}");
    let (a, b) = (
        number_after(&offline, "peak "),
        number_after(&live, "peak "),
    );
    assert!((a - b).abs() <= 0.5, "peak {b} dBFS live, {a} offline");
}
