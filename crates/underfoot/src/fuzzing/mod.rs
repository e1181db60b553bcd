//! Fuzz targets: one per parser of outside input, shared by the cargo-fuzz crate
//! (`fuzz/`, libFuzzer, run by `scripts/fuzz`) and the stable property tests (`tests/fuzz.rs`), so that both run
//! the same bodies.
//!
//! Not part of the API: no stability promise, hidden from the docs.
//!
//! A target takes arbitrary bytes and hands them to a parser the way the program does
//! with a file or a datagram (through the from-bytes or from-string entry point, never the
//! file system). A bad input must come back as an error; a panic is a finding. Where a
//! parse succeeds, the target also checks what the rest of the program relies on: a
//! library, track or calibration written back out reads back in, and a decoded event or
//! frame is within the ranges the decoder promises. Hangs and allocations are watched by
//! the harness (libFuzzer's `-timeout`/`-rss_limit_mb`, or the timing and the counting
//! allocator of the stable tests).
//!
//! Each target also has seeds: small valid inputs of its format, made here (a WAV, a
//! gait's force track, a fitted sensor calibration, ...) or taken from the crate (the
//! built-in library, the example interface file), which the harnesses mutate.
//!
//! # Adding a target
//!
//! Write `fn run_NAME(data: &[u8])` and `fn seeds_NAME() -> Vec<Vec<u8>>` in the file of
//! its parser family (below) and add an entry to [`TARGETS`]; then add
//! `fuzz/fuzz_targets/NAME.rs` (a copy of any other target with the name changed) and its
//! `[[bin]]` in `fuzz/Cargo.toml`. The stable tests
//! pick it up from [`TARGETS`] by themselves.
//!
//! | file | targets |
//! |---|---|
//! | `documents.rs` | `library_json`, `compensation_json` |
//! | `sensors.rs` | `sensor_csv`, `calibration_json` |
//! | `recordings.rs` | `audio`, `recording_csv` |
//! | `force.rs` | `force_track`, `gait_spec` |
//! | `settings.rs` | `interface_toml`, `cli_specs` |
//! | `wire.rs` | `osc`, `serial` |

mod documents;
mod force;
mod recordings;
mod sensors;
mod settings;
mod wire;

/// A fuzz target: its name (the cargo-fuzz binary's), its body, and its seeds.
#[derive(Clone, Copy)]
pub struct Target {
    /// The name, as `fuzz/fuzz_targets/<name>.rs` and in `scripts/fuzz`.
    pub name: &'static str,
    /// The body: parses `data`; panics only on a bug.
    pub run: fn(&[u8]),
    /// Small valid inputs to mutate.
    pub seeds: fn() -> Vec<Vec<u8>>,
}

/// Every target. A new one is an entry here (see the [module docs](self#adding-a-target)).
pub const TARGETS: &[Target] = &[
    Target {
        name: "library_json",
        run: documents::run_library_json,
        seeds: documents::seeds_library_json,
    },
    Target {
        name: "audio",
        run: recordings::run_audio,
        seeds: recordings::seeds_audio,
    },
    Target {
        name: "recording_csv",
        run: recordings::run_recording_csv,
        seeds: recordings::seeds_recording_csv,
    },
    Target {
        name: "force_track",
        run: force::run_force_track,
        seeds: force::seeds_force_track,
    },
    Target {
        name: "gait_spec",
        run: force::run_gait_spec,
        seeds: force::seeds_gait_spec,
    },
    Target {
        name: "interface_toml",
        run: settings::run_interface_toml,
        seeds: settings::seeds_interface_toml,
    },
    Target {
        name: "sensor_csv",
        run: sensors::run_sensor_csv,
        seeds: sensors::seeds_sensor_csv,
    },
    Target {
        name: "calibration_json",
        run: sensors::run_calibration_json,
        seeds: sensors::seeds_calibration_json,
    },
    Target {
        name: "compensation_json",
        run: documents::run_compensation_json,
        seeds: documents::seeds_compensation_json,
    },
    #[cfg(feature = "osc")]
    Target {
        name: "osc",
        run: wire::run_osc,
        seeds: wire::seeds_osc,
    },
    Target {
        name: "cli_specs",
        run: settings::run_cli_specs,
        seeds: settings::seeds_cli_specs,
    },
    #[cfg(feature = "serial")]
    Target {
        name: "serial",
        run: wire::run_serial,
        seeds: wire::seeds_serial,
    },
];

/// The target named `name`.
#[must_use]
pub fn target(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

// Text formats are read with `read_to_string`, which refuses bytes that are not UTF-8;
// the lossy form still lets the fuzzer reach the parser with every other byte it tries.
fn text(data: &[u8]) -> std::borrow::Cow<'_, str> {
    String::from_utf8_lossy(data)
}
