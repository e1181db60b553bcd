//! Lab Streaming Layer, from outside: a recorded walk published with `run --lsl`, received
//! on loopback by pylsl (PyPI's LSL client, with its own liblsl, which underfoot loads
//! too), every strike and marker counted and its timestamp checked against the session's
//! record. pylsl is installed from PyPI into `target/pylsl` on first use; without pip or
//! the network the test says so and skips, unless `UNDERFOOT_REQUIRE_LSL` is set (CI).

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::common::{assert_ok, bin, s};

/// Where pylsl is installed for the tests, once.
fn pylsl_site() -> Option<PathBuf> {
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target"),
        PathBuf::from,
    );
    let site = target.join("pylsl");
    if site.join("pylsl/lib/liblsl.so").exists() {
        return Some(site);
    }
    let installed = Command::new("python3")
        .args(["-m", "pip", "install", "-q", "--target"])
        .arg(&site)
        .arg("pylsl==1.18.6")
        .status()
        .is_ok_and(|s| s.success());
    let required = std::env::var_os("UNDERFOOT_REQUIRE_LSL").is_some();
    if installed && site.join("pylsl/lib/liblsl.so").exists() {
        Some(site)
    } else if required {
        panic!("UNDERFOOT_REQUIRE_LSL is set, and pylsl could not be installed from PyPI");
    } else {
        eprintln!("skipped: pylsl could not be installed (pip or the network is missing)");
        None
    }
}

/// LSL's configuration for the test: streams found on this machine only.
fn loopback_config(dir: &Path) -> PathBuf {
    let path = dir.join("lsl_api.cfg");
    std::fs::write(
        &path,
        "[ports]\nIPv6 = disable\n[multicast]\nResolveScope = machine\n[lab]\nKnownPeers = {127.0.0.1}\n",
    )
    .unwrap();
    path
}

/// One session published and received; the received samples and the record's folder,
/// or what each side said when the receiver found no streams.
fn exchange(
    site: &Path,
    dir: &Path,
    config: &Path,
    attempt: u32,
) -> Result<(serde_json::Value, PathBuf), String> {
    let folder = dir.join(format!("session-{attempt}"));
    let liblsl = site.join("pylsl/lib/liblsl.so");
    let mut session = Command::new(bin())
        .args([
            "run",
            "--input",
            "gait:steps=6,channels=1,lead_in=10",
            "--output",
            "null",
            "--record",
            s(&folder),
            "--lsl",
        ])
        .env("UNDERFOOT_LIBLSL", &liblsl)
        .env("LSLAPICFG", config)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut markers_in = session.stdin.take().unwrap();
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/cli/lsl_receive.py");
    let mut receiver = Command::new("python3")
        .arg(&script)
        .arg("20")
        .env("PYTHONPATH", site)
        .env("LSLAPICFG", config)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(receiver.stdout.take().unwrap()).lines();
    let ready = lines.next().and_then(Result::ok).unwrap_or_default();
    if ready != "READY" {
        // Say what each side said before failing: a resolution that fails on a loaded
        // machine and a session that did not start look alike from here.
        let _ = session.kill();
        let session = session.wait_with_output().unwrap();
        let receiver = receiver.wait_with_output().unwrap();
        return Err(format!(
            "the receiver did not find the streams ({ready:?})\nreceiver: {}\nsession: {}",
            String::from_utf8_lossy(&receiver.stderr),
            String::from_utf8_lossy(&session.stderr)
        ));
    }
    // The walk's first step comes after its 10 s lead-in: the inlets are open by then.
    for n in 1..=3 {
        writeln!(markers_in, r#"{{"text": "lsl marker {n}", "trial": {n}}}"#).unwrap();
        std::thread::sleep(Duration::from_millis(300));
    }
    let out = session.wait_with_output().unwrap();
    assert_ok(&out);
    let received: serde_json::Value =
        serde_json::from_str(&lines.next().and_then(Result::ok).unwrap_or_default())
            .expect("the receiver's JSON");
    assert!(receiver.wait().unwrap().success());
    Ok((received, folder))
}

#[test]
#[ignore = "slow tier: a session paced in real time, received over LSL"]
fn lsl_streams_carry_every_strike_and_marker_on_the_record_s_clock() {
    let Some(site) = pylsl_site() else { return };
    let dir = tempfile::tempdir().unwrap();
    let config = loopback_config(dir.path());
    let mut attempt = 1;
    let (received, folder) = loop {
        match exchange(&site, dir.path(), &config, attempt) {
            Ok(done) => break done,
            // LSL's discovery is UDP: on a loaded machine it has missed once in CI. A
            // second miss is a failure; the first is said, with both sides' output.
            Err(why) if attempt == 1 => {
                eprintln!("LSL attempt 1 failed, trying once more: {why}");
                attempt += 1;
            }
            Err(why) => panic!("{why}"),
        }
    };

    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("manifest.json")).unwrap())
            .unwrap();
    let started = manifest["started"]["monotonic_s"].as_f64().unwrap();
    let output = manifest["output_started_monotonic_s"].as_f64().unwrap();
    // Strikes: the same count, each at the record's output time on the same clock.
    let strikes: Vec<Vec<String>> = std::fs::read_to_string(folder.join("strikes.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    let got = received["underfoot strikes"].as_array().unwrap();
    assert_eq!(got.len(), strikes.len(), "{received}");
    assert_eq!(strikes.len(), 6);
    let mut worst = 0.0f64;
    for (row, sample) in strikes.iter().zip(got) {
        let time: f64 = row[0].parse().unwrap();
        let stamp = sample[1].as_f64().unwrap();
        worst = worst.max((stamp - (output + time)).abs());
        assert!(
            (stamp - (output + time)).abs() < 0.002,
            "strike at {time} s: LSL {stamp}, record {}",
            output + time
        );
        assert_eq!(sample[0]["frame"].as_u64().unwrap().to_string(), row[1]);
        assert_eq!(sample[0]["channel"].to_string(), row[2]);
    }
    // Markers: the same three, in order, at the record's times.
    let events: Vec<serde_json::Value> = std::fs::read_to_string(folder.join("events.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .filter(|e: &serde_json::Value| e["kind"] == "marker")
        .collect();
    let got = received["underfoot markers"].as_array().unwrap();
    assert_eq!(got.len(), 3, "{received}");
    assert_eq!(events.len(), 3);
    for (event, sample) in events.iter().zip(got) {
        assert_eq!(sample[0]["text"], event["text"]);
        assert_eq!(sample[0]["trial"], event["trial"]);
        let at = started + event["t"].as_f64().unwrap();
        let stamp = sample[1].as_f64().unwrap();
        worst = worst.max((stamp - at).abs());
        assert!(
            (stamp - at).abs() < 0.002,
            "marker: LSL {stamp}, record {at}"
        );
    }
    eprintln!(
        "LSL: {} strikes and 3 markers received, timestamps within {:.3} ms of the record's",
        strikes.len(),
        worst * 1e3
    );
}
