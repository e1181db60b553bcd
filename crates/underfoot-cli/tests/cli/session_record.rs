//! A recorded session, from outside: `run --record DIR` driven as a lab drives it (a
//! walk, markers typed on standard input every 5 s), its folder read back with the
//! tests' own readers (not the library's), and compared with what the session said, with
//! the walk it was given, and with an offline `render` of the force it recorded. Then a
//! session killed with SIGKILL, whose folder `session show` must still read.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{assert_ok, bin, run, s, stderr, stdout};

const RATE: f64 = 48_000.0;

fn json_lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{l}: {e}")))
        .collect()
}

/// The rows of a CSV file after its header (and comment lines).
fn csv_rows(path: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect()
}

fn mono(path: &Path) -> Vec<f32> {
    let mut r = hound::WavReader::open(path).unwrap();
    assert_eq!(r.spec().channels, 1);
    r.samples::<f32>().map(Result::unwrap).collect()
}

fn peak_db(x: &[f32]) -> f64 {
    20.0 * f64::from(x.iter().fold(0.0f32, |p, v| p.max(v.abs()))).log10()
}

/// The issue's acceptance: 60 s of walking with a marker every 5 s.
#[test]
#[ignore = "slow tier: a minute in real time"]
fn a_minute_recorded_with_markers_holds_every_reading_strike_and_marker() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("p07-session");
    let mut child = Command::new(bin())
        .args([
            "run",
            "--input",
            "gait:steps=200,channels=1",
            "--output",
            "null",
            "--material",
            "gravel",
            "--duration",
            "60",
            "--record",
            s(&folder),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let started = Instant::now();
    let mut sent = 0;
    for trial in 1..=11u32 {
        std::thread::sleep(
            (started + Duration::from_secs(5 * u64::from(trial)))
                .saturating_duration_since(Instant::now()),
        );
        writeln!(
            stdin,
            r#"{{"text": "trial {trial} starts", "trial": {trial}, "participant": "P07", "condition": "gravel"}}"#
        )
        .unwrap();
        sent += 1;
    }
    let out = child.wait_with_output().unwrap();
    assert_ok(&out);
    let report = stdout(&out);

    // Every strike the engine counted is in the list.
    let strikes = csv_rows(&folder.join("strikes.csv"));
    let counted: usize = report
        .split(" strike(s)")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{report}"));
    assert_eq!(strikes.len(), counted, "{report}");
    assert!(counted >= 50, "{counted} strikes in a minute: {report}");

    // Every reading: 500 a second from the first to the last, none missing or doubled,
    // and the walk's own readings.
    let force = csv_rows(&folder.join("force.csv"));
    let first: f64 = force[0][0].parse().unwrap();
    let last: f64 = force[force.len() - 1][0].parse().unwrap();
    assert!(last - first > 59.0, "{first} to {last}");
    let expected = ((last - first) * 500.0).round() as usize + 1;
    assert!(
        force.len().abs_diff(expected) <= 1,
        "{} rows for {expected}",
        force.len()
    );
    for w in force.windows(2) {
        let dt = w[1][0].parse::<f64>().unwrap() - w[0][0].parse::<f64>().unwrap();
        assert!(
            (dt - 0.002).abs() < 1e-9,
            "a gap of {dt} s at {:?}",
            w[1][0]
        );
    }

    // The markers, in order, 5 s apart, with their fields.
    let events = json_lines(&folder.join("events.jsonl"));
    let markers: Vec<_> = events.iter().filter(|e| e["kind"] == "marker").collect();
    assert_eq!(markers.len(), sent);
    for (i, m) in markers.iter().enumerate() {
        assert_eq!(m["trial"], i + 1);
        assert_eq!(m["participant"], "P07");
        assert_eq!(m["condition"], "gravel");
    }
    // Sent 5 s apart (the session's clock starts after the process has prepared its
    // materials, so the spacing is what is checked).
    let times: Vec<f64> = markers.iter().map(|m| m["t"].as_f64().unwrap()).collect();
    for w in times.windows(2) {
        assert!((w[1] - w[0] - 5.0).abs() < 0.3, "markers at {times:?}");
    }
    let frames: Vec<u64> = markers
        .iter()
        .map(|m| m["frame"].as_u64().unwrap())
        .collect();
    assert!(frames.windows(2).all(|w| w[1] > w[0]), "{frames:?}");
    assert_eq!(events.last().unwrap()["reason"], "duration");

    // The output equals an offline render of the recorded force, step by step: the
    // live output is the offline one shifted by the sensor clock's anchor.
    let offline = dir.path().join("offline.wav");
    assert_ok(&run(&[
        "render",
        "--force",
        s(&folder.join("force.csv")),
        "--material",
        "gravel",
        "--out",
        s(&offline),
    ]));
    let offline = mono(&offline);
    let live = mono(&folder.join("output.wav"));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("manifest.json")).unwrap())
            .unwrap();
    let anchor = &manifest["ended"]["sensor_clock"];
    let shift = anchor["frame"].as_i64().unwrap()
        - (anchor["time_s"].as_f64().unwrap() * RATE).round() as i64
        + (first * RATE).round() as i64;
    let window = (0.35 * RATE) as usize;
    let mut compared = 0;
    let mut worst = 0.0f64;
    for row in &strikes {
        let frame: usize = row[1].parse().unwrap();
        let at = frame as i64 - shift;
        // The last step may be cut by the duration, or not rendered offline yet.
        if frame + window > live.len() || at < 0 || at as usize + window > offline.len() {
            continue;
        }
        let a = peak_db(&live[frame..frame + window]);
        let b = peak_db(&offline[at as usize..at as usize + window]);
        assert!(
            (a - b).abs() <= 0.5,
            "the step at frame {frame}: live {a:.2} dB, offline {b:.2} dB"
        );
        worst = worst.max((a - b).abs());
        compared += 1;
    }
    eprintln!(
        "recorded output against an offline render of the recorded force: {compared} steps, \
         worst peak difference {worst:.3} dB"
    );
    assert!(
        compared + 2 >= strikes.len(),
        "{compared} of {} steps compared",
        strikes.len()
    );

    // `session show` reads it and counts the steps of each trial.
    let shown = run(&["session", "show", s(&folder)]);
    assert_ok(&shown);
    let text = stdout(&shown);
    assert!(text.contains(&format!("strikes: {counted}")), "{text}");
    assert!(text.contains("markers: 11"), "{text}");
    assert!(text.contains("steps per trial: trial 1:"), "{text}");
    assert!(text.contains("ended after"), "{text}");
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn a_session_killed_mid_walk_leaves_a_record_that_reads() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("killed");
    let mut child = Command::new(bin())
        .args([
            "run",
            "--input",
            "gait:steps=20,channels=1",
            "--output",
            "null",
            "--record",
            s(&folder),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    // The 4 s count from the session's start (its manifest), not the process's: a loaded
    // machine takes a second or more to prepare the materials.
    let deadline = Instant::now() + Duration::from_secs(30);
    while !folder.join("manifest.json").exists() {
        assert!(Instant::now() < deadline, "the session never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(1500));
    writeln!(stdin, "before the kill").unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    // SIGKILL: nothing of the process runs after it.
    child.kill().unwrap();
    child.wait().unwrap();
    drop(stdin);

    let shown = run(&["session", "show", s(&folder)]);
    assert_ok(&shown);
    let text = stdout(&shown);
    assert!(text.contains("did NOT finish"), "{text}");
    assert!(text.contains("before the kill"), "{text}");
    // At most the last second lost: force up to 2.5 s of the 4 s walked (the walk's
    // sensor time starts with the session), output at least 2.5 s.
    let force = csv_rows(&folder.join("force.csv"));
    let last: f64 = force.iter().rfind(|r| r.len() == 3).unwrap()[0]
        .parse()
        .unwrap();
    assert!(last > 2.5, "the force log ends at {last} s of 4");
    let wav = std::fs::read_dir(&folder)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().contains("output.partial-"))
        .expect("the partial output");
    let seconds = mono(&wav).len() as f64 / RATE;
    assert!(seconds > 2.5, "{seconds} s of output");
    let plot = dir.path().join("timeline.svg");
    assert_ok(&run(&["session", "show", s(&folder), "--plot", s(&plot)]));
    assert!(std::fs::metadata(&plot).unwrap().len() > 1000);
}

#[test]
fn a_record_goes_only_into_a_new_or_empty_folder() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("consent.pdf"), "signed").unwrap();
    let out = run(&[
        "run",
        "--input",
        "gait:steps=1",
        "--output",
        "null",
        "--record",
        s(dir.path()),
    ]);
    assert!(!out.status.success());
    assert!(stderr(&out).contains("not empty"), "{}", stderr(&out));
    assert_eq!(
        std::fs::read_to_string(dir.path().join("consent.pdf")).unwrap(),
        "signed"
    );
    // Not a record: said, not a panic.
    let shown = run(&["session", "show", s(dir.path())]);
    assert!(!shown.status.success());
    assert!(
        stderr(&shown).contains("not a session record"),
        "{}",
        stderr(&shown)
    );
}

/// A record is bounded: at `--record-max-mb` the force, status and output stop, an event
/// says so, and the session and its strikes go on.
#[test]
#[ignore = "slow tier: paced in real time"]
fn a_record_stops_growing_at_its_bound_and_the_session_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("bounded");
    // Two channels of 32-bit output at 48 kHz: 384 kB a second, 1 MiB in under 3 s.
    let o = run(&[
        "run",
        "--input",
        "gait:steps=8,channels=2,lead_in=0.2",
        "--output",
        "null",
        "--record",
        s(&folder),
        "--record-max-mb",
        "1",
    ]);
    assert_ok(&o);
    let report = stdout(&o);
    assert!(report.contains("it reached --record-max-mb"), "{report}");
    let total: u64 = std::fs::read_dir(&folder)
        .unwrap()
        .flatten()
        .map(|e| e.metadata().unwrap().len())
        .sum();
    // The bound, plus what is never cut: the manifest, the strikes, the events and the
    // WAV header.
    assert!(total <= (1 << 20) + 16 * 1024, "{total} bytes");
    let events = json_lines(&folder.join("events.jsonl"));
    assert!(
        events.iter().any(|e| e["kind"] == "record_full"),
        "{events:?}"
    );
    // Every strike the engine counted is still listed.
    let strikes = csv_rows(&folder.join("strikes.csv")).len();
    let counted: usize = report
        .split(" strike(s)")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert_eq!(strikes, counted, "{report}");
    let shown = run(&["session", "show", s(&folder)]);
    assert_ok(&shown);
    assert!(
        stdout(&shown).contains("reached its bound"),
        "{}",
        stdout(&shown)
    );
}
