//! Settings: the interface configuration (TOML) and the command line's spec strings.

use std::path::Path;

use super::sensors::seeds_calibration_json;
use super::text;
use crate::force::calibration::SensorCalibration;
use crate::interface::config::InterfaceConfig;
use crate::io::spec::{self, InputSpec, OutputSpec};
use crate::units::SampleRate;

// ---- the interface configuration (TOML) ----

pub(super) fn run_interface_toml(data: &[u8]) {
    // A calibration file it names reads as the seed calibration, so that the fuzzer gets
    // past that key to the sensors that use it.
    let calibration = seeds_calibration_json().remove(0);
    let _ = InterfaceConfig::parse(&text(data), Path::new("fuzz.toml"), |name| {
        SensorCalibration::from_json_str(&String::from_utf8_lossy(&calibration), name)
    });
}

pub(super) fn seeds_interface_toml() -> Vec<Vec<u8>> {
    let example = include_str!("../../../../examples/prosthetic.toml");
    let calibrated = example.replace(
        "# calibration = \"sensors.json\"",
        "calibration = \"sensors.json\"",
    );
    vec![example.as_bytes().to_vec(), calibrated.into_bytes()]
}

// ---- the command line's spec strings (`--input`, `--output`, `@SPEED`, `--duration`, `--band`) ----

/// The first byte picks the parser, the rest is the text: one target for every spec string
/// the command line hands to [`crate::io::spec`], so that the fuzzer's corpus mixes them.
pub(super) fn run_cli_specs(data: &[u8]) {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let s = text(rest);
    match which % 6 {
        0 => {
            if let Ok(InputSpec::Replay { speed, .. }) = InputSpec::parse(&s) {
                assert!(
                    (spec::MIN_SPEED..=spec::MAX_SPEED).contains(&speed),
                    "{speed}"
                );
            }
        }
        1 => {
            let _ = OutputSpec::parse(&s);
        }
        2 => {
            if let Ok(band) = spec::parse_band(&s) {
                assert!(
                    band.fits(SampleRate(250_000)),
                    "{s:?} gave a band the fit refuses: {band:?}"
                );
            }
        }
        3 => {
            if let Ok(v) = spec::parse_speed(&s) {
                assert!(v.is_finite() && v > 0.0, "{v}");
            }
        }
        4 => {
            if let Ok(d) = spec::parse_session_duration(&s) {
                assert!(
                    d.0.is_finite() && (0.0..=spec::MAX_SESSION.0).contains(&d.0),
                    "{d:?}"
                );
                // What `run` makes of it must not overflow.
                let _ = std::time::Duration::from_secs_f64(d.0);
            }
        }
        _ => {
            if let Ok(r) = spec::parse_rate(&s, "--rate", 1, 768_000) {
                assert!((1..=768_000).contains(&r.0));
            }
        }
    }
}

pub(super) fn seeds_cli_specs() -> Vec<Vec<u8>> {
    [
        (0u8, "replay:steps.csv@2"),
        (0, "gait:steps=4,channels=1"),
        (0, "serial:/dev/ttyACM0"),
        (0, "osc:127.0.0.1:9000"),
        (1, "wav:out.wav"),
        (1, "audio:hw:0"),
        (1, "null"),
        (2, "20:900"),
        (2, "40,1024"),
        (3, "0.5"),
        (4, "600"),
        (5, "48000"),
    ]
    .into_iter()
    .map(|(which, s)| {
        let mut v = vec![which];
        v.extend_from_slice(s.as_bytes());
        v
    })
    .collect()
}
