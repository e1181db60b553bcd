//! `underfoot run`: the live engine into a paced WAV file or nowhere, from a walk or a (simulated) prosthetic interface; bad inputs, outputs and configurations refused clearly.

use std::fs;
use std::path::PathBuf;

use crate::common::{assert_error, assert_ok, read_wav, run, s, stderr, stdout};

#[test]
#[ignore = "slow tier: paced in real time"]
fn run_plays_a_walk_live_into_a_paced_wav() {
    let dir = tempfile::tempdir().expect("tempdir");
    let wav = dir.path().join("live.wav");
    let started = std::time::Instant::now();
    let o = run(&[
        "run",
        "--material",
        "wood",
        "--input",
        "gait:steps=2,channels=1,lead_in=0.2,tail=0.2",
        "--output",
        &format!("wav:{}", s(&wav)),
        "--gain-db",
        "-20",
    ]);
    assert_ok(&o);
    let took = started.elapsed().as_secs_f64();
    assert!(stdout(&o).contains("2 strike(s)"), "{}", stdout(&o));
    // Real-time pace: the walk lasts about 1.4 s, plus a second to ring out.
    assert!(took > 2.0, "{took} s");
    let (_, samples) = read_wav(&wav);
    assert!(samples.iter().any(|v| v.abs() > 1e-4));
    assert!(samples.iter().all(|v| v.abs() <= 0.5012));
}

#[test]
fn run_rejects_bad_inputs_and_outputs_clearly() {
    // A malformed spec is a usage error (status 2), refused while parsing (issue 14).
    let o = run(&["run", "--input", "tcp:1234", "--output", "null"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("unknown kind"));
    let o = run(&[
        "run",
        "--input",
        "replay:/nonexistent.csv",
        "--output",
        "null",
    ]);
    assert!(assert_error(&o).contains("/nonexistent.csv"));
    let o = run(&["run", "--input", "gait:steps=1", "--output", "speaker"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("speaker"));
    let o = run(&[
        "run",
        "--input",
        "serial:/dev/does-not-exist",
        "--output",
        "null",
    ]);
    assert!(assert_error(&o).contains("/dev/does-not-exist"));
}

#[test]
fn adaptation_is_refused_clearly_where_it_cannot_run() {
    // Without an equalizer to adapt, or its options without --adapt: usage errors.
    let o = run(&["run", "--adapt", "--output", "null"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--eq"), "{}", stderr(&o));
    let o = run(&["run", "--adapt-input", "1", "--output", "null"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--adapt"), "{}", stderr(&o));

    // With one, on an output that is not a sound card: refused before anything plays,
    // and the adapted file is not written.
    let dir = tempfile::tempdir().expect("tempdir");
    let device = dir.path().join("tile.json");
    let eq = dir.path().join("eq.json");
    let adapted = dir.path().join("adapted.json");
    assert_ok(&run(&["calibrate", "sweep", "--out", s(&device)]));
    assert_ok(&run(&[
        "calibrate",
        "equalize",
        "--device-under-test",
        s(&device),
        "--passes",
        "1",
        "--out",
        s(&eq),
    ]));
    let o = run(&[
        "run",
        "--eq",
        s(&eq),
        "--adapt",
        "--adapt-out",
        s(&adapted),
        "--input",
        "gait:steps=1",
        "--output",
        "null",
    ]);
    let message = assert_error(&o);
    assert!(
        message.contains("adaptation needs an audio output"),
        "{message}"
    );
    assert!(!stdout(&o).contains("strike"), "it played: {}", stdout(&o));
    assert!(!adapted.exists());
    // The adapted file may not be the equalizer it starts from.
    let o = run(&[
        "run",
        "--eq",
        s(&eq),
        "--adapt",
        "--adapt-out",
        s(&eq),
        "--output",
        "audio",
    ]);
    assert_ne!(o.status.code(), Some(0));
    assert!(stderr(&o).contains(s(&eq)), "{}", stderr(&o));
}

/// The commented example interface configurations, at the workspace root.
fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
}

/// The first number before `what` in `text`, e.g. "12 strike(s)".
fn count_before(text: &str, what: &str) -> u64 {
    let at = text
        .find(what)
        .unwrap_or_else(|| panic!("{what:?} not in {text}"));
    let digits: String = text[..at]
        .trim_end()
        .chars()
        .rev()
        .take_while(char::is_ascii_digit)
        .collect();
    digits.chars().rev().collect::<String>().parse().unwrap()
}

#[test]
#[ignore = "slow tier: paced in real time"]
fn run_interface_plays_the_simulated_foot_and_drives_its_servos() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The example, with a shorter walk.
    let text = fs::read_to_string(example("prosthetic.toml")).unwrap();
    let short = text.replace("gait = \"steps=4,", "gait = \"steps=2,");
    assert_ne!(short, text, "the example's walk changed: update this test");
    let config = dir.path().join("prosthetic.toml");
    fs::write(&config, short).unwrap();
    let wav = dir.path().join("interface.wav");
    let o = run(&[
        "run",
        "--interface",
        s(&config),
        "--material",
        "gravel",
        "--output",
        &format!("wav:{}", s(&wav)),
        "--seconds",
        "20",
    ]);
    assert_ok(&o);
    let out = stdout(&o);
    // Two steps on each of the four discs.
    assert_eq!(count_before(&out, "strike(s)"), 8, "{out}");
    let sent = count_before(&out, "servo frame(s) sent");
    let received = count_before(&out, "servo frame(s) received");
    assert!(sent > 20, "{out}");
    assert!(received > 0 && received <= sent, "{out}");
    assert_eq!(
        count_before(&out, "insole frame(s),"),
        count_before(&out, "insole frame(s) sent")
    );
    assert_eq!(count_before(&out, "rejected ("), 0, "{out}");
    // After the walk the servos are back at rest (1100, 1100 and the reversed 1900 µs).
    assert!(out.contains("servos at [1100, 1100, 1900] µs"), "{out}");
    let (spec, samples) = read_wav(&wav);
    assert_eq!(spec.channels, 4);
    assert!(samples.iter().any(|v| v.abs() > 1e-4));
}

#[test]
fn run_interface_refuses_a_broken_config_clearly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let text = fs::read_to_string(example("prosthetic.toml")).unwrap();
    let config = dir.path().join("broken.toml");
    // A reversed range on the second servo.
    let broken = text.replacen("range_us = [1000, 2000]", "range_us = [2000, 1000]", 2);
    let broken = broken.replacen("range_us = [2000, 1000]", "range_us = [1000, 2000]", 1);
    fs::write(&config, &broken).unwrap();
    let o = run(&["run", "--interface", s(&config), "--output", "null"]);
    let err = assert_error(&o);
    assert!(err.contains("broken.toml"), "{err}");
    assert!(err.contains("servo[1].range_us"), "{err}");
    // A misspelt key, with its line.
    let line = text
        .lines()
        .position(|l| l.starts_with("dead_band_us"))
        .unwrap()
        + 1;
    fs::write(&config, text.replacen("dead_band_us", "deadband_us", 1)).unwrap();
    let err = assert_error(&run(&[
        "run",
        "--interface",
        s(&config),
        "--output",
        "null",
    ]));
    assert!(err.contains(&format!("broken.toml:{line}")), "{err}");
    assert!(err.contains("deadband_us"), "{err}");
    // A missing file.
    let err = assert_error(&run(&[
        "run",
        "--interface",
        "/nonexistent/prosthetic.toml",
        "--output",
        "null",
    ]));
    assert!(err.contains("/nonexistent/prosthetic.toml"), "{err}");
    // A calibration file that is not one.
    let cal = dir.path().join("sensors.json");
    fs::write(&cal, "{\"kind\": \"something else\"}").unwrap();
    let err = assert_error(&run(&[
        "run",
        "--input",
        "serial:/dev/does-not-exist",
        "--sensors",
        s(&cal),
        "--output",
        "null",
    ]));
    assert!(err.contains("sensors.json"), "{err}");
}

/// A bare `underfoot run` runs on the default build (issue 16): a generated walk, to the
/// sound card when the build has one, else to the paced null output, and it says which.
#[test]
#[ignore = "slow tier: paced in real time"]
fn a_bare_run_plays_a_generated_walk_and_says_what_it_chose() {
    let o = run(&["run"]);
    assert_ok(&o);
    let err = stderr(&o);
    assert!(
        err.contains("no --input: a generated walk (gait:steps=4)"),
        "{err}"
    );
    if cfg!(feature = "audio") {
        assert!(
            err.contains("no --output: the default audio device"),
            "{err}"
        );
    } else {
        assert!(err.contains("this build has no audio"), "{err}");
        assert!(err.contains("paced output null"), "{err}");
        // Four steps a foot, two feet.
        assert!(stdout(&o).contains("8 strike(s)"), "{}", stdout(&o));
    }
}

/// `--status-json -`: a line of JSON a second on standard output, before the summary,
/// that a script can parse; the counts only grow (issue 16).
#[test]
#[ignore = "slow tier: paced in real time"]
fn status_json_lines_parse_and_count_up() {
    let o = run(&[
        "run",
        "--input",
        "gait:steps=3,channels=1,lead_in=0.1,tail=0.1",
        "--output",
        "null",
        "--status-json",
        "-",
    ]);
    assert_ok(&o);
    let out = stdout(&o);
    let lines: Vec<serde_json::Value> = out
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    assert!(lines.len() >= 2, "{out}");
    for pair in lines.windows(2) {
        assert!(pair[1]["elapsed_s"].as_f64() > pair[0]["elapsed_s"].as_f64());
        assert!(pair[1]["strikes"].as_u64() >= pair[0]["strikes"].as_u64());
        assert!(pair[1]["input"]["events"].as_u64() > pair[0]["input"]["events"].as_u64());
    }
    let last = lines.last().unwrap();
    assert_eq!(last["channels"].as_array().unwrap().len(), 1);
    assert!(last["strikes"].as_u64().unwrap() >= 1, "{last}");
    // Not a terminal: no status block on stderr.
    assert!(!stderr(&o).contains('\x1b'), "{}", stderr(&o));
}

/// On a terminal, one status block redrawn in place (issue 16): run under a
/// pseudo-terminal (`script`), with standard input held open so that the session is not
/// stopped by an end of input.
#[test]
#[ignore = "slow tier: paced in real time"]
fn a_terminal_gets_a_status_block_redrawn_in_place() {
    let cmd = format!(
        "{} run --input gait:steps=2,channels=2,lead_in=0.1,tail=0.1 --output null",
        crate::common::bin().display()
    );
    let mut child = std::process::Command::new("script")
        .args(["-qec", &cmd, "/dev/null"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("`script` (util-linux) runs the command under a pseudo-terminal");
    // Kept open until the session has ended by itself.
    let stdin = child.stdin.take();
    let o = child.wait_with_output().expect("script ends");
    drop(stdin);
    assert!(o.status.success(), "{o:?}");
    let tty = String::from_utf8_lossy(&o.stdout);
    assert!(tty.contains("channel   force (N)   strikes"), "{tty}");
    // Redrawn: the cursor goes back up over the block (two header lines and a line per
    // channel) more than once.
    assert!(tty.matches("\x1b[5A").count() >= 2, "{tty}");
    assert!(tty.contains("4 strike(s)"), "{tty}");
}
