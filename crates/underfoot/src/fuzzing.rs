//! Fuzz targets: one per parser of outside input, shared by the cargo-fuzz crate
//! (`fuzz/`, nightly) and the stable property tests (`tests/fuzz.rs`), so that both run
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
//! Write `fn run_NAME(data: &[u8])` and `fn seeds_NAME() -> Vec<Vec<u8>>` below and add
//! an entry to [`TARGETS`]; then add `fuzz/fuzz_targets/NAME.rs` (a copy of any other
//! target with the name changed) and its `[[bin]]` in `fuzz/Cargo.toml`. The stable tests
//! pick it up from [`TARGETS`] by themselves.

use std::path::Path;

use crate::compensation::files::{EqualizerFile, LimbFile, ResponseFile};
use crate::compensation::table::{UserEntry, UserTable};
use crate::document;
use crate::force::calibration::{
    CurveKind, FILE_KIND, SensorCalibration, fit_sensor, session_from_csv_str,
};
use crate::force::gait::{GaitConfig, generate};
use crate::force::track::ForceTrack;
use crate::interface::config::InterfaceConfig;
use crate::io::spec::{self, InputSpec, OutputSpec};
use crate::material::Library;
use crate::recording::{CsvSpec, read_bytes};
use crate::units::{Band, SampleRate};

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
        run: run_library_json,
        seeds: seeds_library_json,
    },
    Target {
        name: "audio",
        run: run_audio,
        seeds: seeds_audio,
    },
    Target {
        name: "recording_csv",
        run: run_recording_csv,
        seeds: seeds_recording_csv,
    },
    Target {
        name: "force_track",
        run: run_force_track,
        seeds: seeds_force_track,
    },
    Target {
        name: "gait_spec",
        run: run_gait_spec,
        seeds: seeds_gait_spec,
    },
    Target {
        name: "interface_toml",
        run: run_interface_toml,
        seeds: seeds_interface_toml,
    },
    Target {
        name: "sensor_csv",
        run: run_sensor_csv,
        seeds: seeds_sensor_csv,
    },
    Target {
        name: "calibration_json",
        run: run_calibration_json,
        seeds: seeds_calibration_json,
    },
    Target {
        name: "compensation_json",
        run: run_compensation_json,
        seeds: seeds_compensation_json,
    },
    #[cfg(feature = "osc")]
    Target {
        name: "osc",
        run: run_osc,
        seeds: seeds_osc,
    },
    #[cfg(feature = "serial")]
    Target {
        name: "cli_specs",
        run: run_cli_specs,
        seeds: seeds_cli_specs,
    },
    Target {
        name: "serial",
        run: run_serial,
        seeds: seeds_serial,
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

// ---- material library (JSON) ----

fn run_library_json(data: &[u8]) {
    let Ok(library) = Library::from_json(&text(data), "fuzz") else {
        return;
    };
    // What loaded is playable: every filter is stable, and the library saves and reloads.
    for name in library.names() {
        let model = library.get(name).expect("a listed name is in the library");
        if let Some(sos) = model.sos() {
            assert!(sos.is_stable(), "{name}: a loaded filter is unstable");
        }
    }
    let again = Library::from_json(&library.to_json(), "fuzz, saved");
    assert!(again.is_ok(), "a loaded library does not reload: {again:?}");
}

fn seeds_library_json() -> Vec<Vec<u8>> {
    vec![
        include_bytes!("material/builtin.json").to_vec(),
        Library::new().to_json().into_bytes(),
    ]
}

// ---- audio decoding (WAV, FLAC, Ogg Vorbis by content) ----

fn run_audio(data: &[u8]) {
    // No extension: the decoder goes by content alone, as for a file named oddly.
    let _ = read_bytes("fuzz", data, None);
}

/// A RIFF/WAVE file: `format` 1 (integer PCM) or 3 (float), mono, `bits` per sample.
fn wav_bytes(rate: u32, format: u16, bits: u16, samples: &[f64]) -> Vec<u8> {
    let bytes_per = usize::from(bits / 8);
    let data_len = samples.len() * bytes_per;
    let mut out = Vec::with_capacity(44 + data_len);
    let u32_of = |n: usize| u32::try_from(n).expect("a seed is small");
    out.extend_from_slice(b"RIFF");
    out.extend_from_slice(&u32_of(36 + data_len).to_le_bytes());
    out.extend_from_slice(b"WAVEfmt ");
    out.extend_from_slice(&16u32.to_le_bytes());
    out.extend_from_slice(&format.to_le_bytes());
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&rate.to_le_bytes());
    out.extend_from_slice(&(rate * u32::from(bits / 8)).to_le_bytes());
    out.extend_from_slice(&(bits / 8).to_le_bytes());
    out.extend_from_slice(&bits.to_le_bytes());
    out.extend_from_slice(b"data");
    out.extend_from_slice(&u32_of(data_len).to_le_bytes());
    for &s in samples {
        match (format, bits) {
            (3, 32) => out.extend_from_slice(&(s as f32).to_le_bytes()),
            (1, 24) => out.extend_from_slice(&((s * 8_388_607.0) as i32).to_le_bytes()[..3]),
            _ => out.extend_from_slice(&((s * 32_767.0) as i16).to_le_bytes()),
        }
    }
    out
}

/// A FLAC file: mono, 16 bits, blocks of 256 samples stored verbatim, with the frame
/// checksums a decoder verifies (CRC-8 of each frame header, CRC-16 of each frame).
fn flac_bytes(rate: u32, samples: &[f64]) -> Vec<u8> {
    fn crc8(bytes: &[u8]) -> u8 {
        bytes.iter().fold(0u8, |mut crc, &b| {
            crc ^= b;
            for _ in 0..8 {
                crc = if crc & 0x80 != 0 {
                    (crc << 1) ^ 0x07
                } else {
                    crc << 1
                };
            }
            crc
        })
    }
    fn crc16(bytes: &[u8]) -> u16 {
        bytes.iter().fold(0u16, |mut crc, &b| {
            crc ^= u16::from(b) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ 0x8005
                } else {
                    crc << 1
                };
            }
            crc
        })
    }
    const BLOCK: usize = 256;
    let samples = &samples[..samples.len() / BLOCK * BLOCK];
    let mut out = b"fLaC".to_vec();
    // STREAMINFO, the last metadata block: 34 bytes.
    out.extend_from_slice(&[0x80, 0, 0, 34]);
    out.extend_from_slice(&(BLOCK as u16).to_be_bytes());
    out.extend_from_slice(&(BLOCK as u16).to_be_bytes());
    out.extend_from_slice(&[0; 6]); // frame sizes unknown
    // Rate (20 bits), channels - 1 = 0 (3 bits), bits - 1 = 15 (5 bits), samples (36 bits).
    let packed = (u64::from(rate) << 44) | (15 << 36) | samples.len() as u64;
    out.extend_from_slice(&packed.to_be_bytes());
    out.extend_from_slice(&[0; 16]); // no MD5
    for (n, block) in samples.chunks(BLOCK).enumerate() {
        let start = out.len();
        // Sync, fixed blocks; 256 samples, the stream's rate; mono, 16 bits; frame number.
        out.extend_from_slice(&[0xFF, 0xF8, 0x80, 0x08]);
        out.push(u8::try_from(n).expect("a seed has few frames"));
        out.push(crc8(&out[start..]));
        out.push(0x02); // a verbatim subframe
        for &v in block {
            out.extend_from_slice(&((v * 32_767.0) as i16).to_be_bytes());
        }
        let crc = crc16(&out[start..]);
        out.extend_from_slice(&crc.to_be_bytes());
    }
    out
}

/// Two decaying 120 Hz strikes over a faint hiss: a recording the checks accept.
fn strikes(rate: u32, len: usize) -> Vec<f64> {
    let mut noise = crate::signal::noise::SplitMix64::new(7);
    let mut x: Vec<f64> = (0..len).map(|_| 1e-3 * noise.symmetric()).collect();
    for onset in [len / 8, len / 2] {
        for (n, v) in x[onset..].iter_mut().enumerate() {
            let t = n as f64 / f64::from(rate);
            *v += 0.5 * (-t / 0.05).exp() * (std::f64::consts::TAU * 120.0 * t).sin();
        }
    }
    x
}

fn seeds_audio() -> Vec<Vec<u8>> {
    let x = strikes(2000, 2000);
    vec![
        wav_bytes(2000, 1, 16, &x),
        wav_bytes(2000, 1, 24, &x[..600]),
        wav_bytes(2000, 3, 32, &x[..600]),
        flac_bytes(2000, &x),
    ]
}

// ---- the fit's CSV reader (data-logger recordings) ----

fn run_recording_csv(data: &[u8]) {
    for column in ["1", "force"] {
        let spec = CsvSpec {
            column: column.to_owned(),
            rate: SampleRate(1000),
        };
        let _ = read_bytes("fuzz.csv", data, Some(&spec));
    }
}

fn seeds_recording_csv() -> Vec<Vec<u8>> {
    let x = strikes(1000, 800);
    let mut with_header = String::from("# logger export\ntime_s,force\n");
    let mut bare = String::new();
    for (i, v) in x.iter().enumerate() {
        let t = i as f64 / 1000.0;
        with_header.push_str(&format!("{t},{v}\n"));
        bare.push_str(&format!("{t}, {v}\n"));
    }
    vec![with_header.into_bytes(), bare.into_bytes()]
}

// ---- force tracks (CSV) ----

fn run_force_track(data: &[u8]) {
    let Ok(track) = ForceTrack::from_csv_str(&text(data), "fuzz") else {
        return;
    };
    let _ = (track.duration(), track.channel_count(), track.sensor_rate());
    let again = ForceTrack::from_csv_str(&track.to_csv(), "fuzz, written");
    assert!(again.is_ok(), "a parsed track does not reparse: {again:?}");
}

fn seeds_force_track() -> Vec<Vec<u8>> {
    [
        "steps=1,rate=100",
        "steps=2,channels=2,rate=60,lead_in=0.1,tail=0.1",
    ]
    .into_iter()
    .map(|spec| {
        let config = GaitConfig::from_spec(spec).expect("a valid seed spec");
        let gait = generate(&config).expect("a short walk");
        gait.track.to_csv().into_bytes()
    })
    .collect()
}

// ---- gait specs (`--gait`, `--input gait:`) ----

/// Walks longer than this many rows are not generated by the target: their cost is the
/// size of what was asked for (bounded by [`crate::force::gait::MAX_ROWS`] at parse time),
/// not a parser's.
const GAIT_ROWS_GENERATED: f64 = 20_000.0;

fn run_gait_spec(data: &[u8]) {
    let Ok(config) = GaitConfig::from_spec(&text(data)) else {
        return;
    };
    let seconds =
        config.lead_in.0 + config.tail.0 + (2.0 * config.steps as f64 + 3.0) * 1.5 / config.cadence;
    if seconds * config.sensor_rate <= GAIT_ROWS_GENERATED {
        let gait = generate(&config);
        assert!(gait.is_ok(), "a parsed spec does not generate: {gait:?}");
    }
}

fn seeds_gait_spec() -> Vec<Vec<u8>> {
    [
        "",
        "steps=2",
        "steps=12,cadence=1.8,weight=70",
        "steps=3,channels=2,variation=0.1,rate=200,seed=7,stance=0.6,lead_in=0.5,tail=0.5",
    ]
    .into_iter()
    .map(|s| s.as_bytes().to_vec())
    .collect()
}

// ---- the interface configuration (TOML) ----

fn run_interface_toml(data: &[u8]) {
    // A calibration file it names reads as the seed calibration, so that the fuzzer gets
    // past that key to the sensors that use it.
    let calibration = seeds_calibration_json().remove(0);
    let _ = InterfaceConfig::parse(&text(data), Path::new("fuzz.toml"), |name| {
        SensorCalibration::from_json_str(&String::from_utf8_lossy(&calibration), name)
    });
}

fn seeds_interface_toml() -> Vec<Vec<u8>> {
    let example = include_str!("../../../examples/prosthetic.toml");
    let calibrated = example.replace(
        "# calibration = \"sensors.json\"",
        "calibration = \"sensors.json\"",
    );
    vec![example.as_bytes().to_vec(), calibrated.into_bytes()]
}

// ---- sensor calibration: the readings CSV, and the fitted curves (JSON) ----

fn run_sensor_csv(data: &[u8]) {
    let Ok(sensors) = session_from_csv_str(&text(data), "fuzz") else {
        return;
    };
    // `calibrate sensors` fits each sensor next: the fit must end on anything parsed.
    for sensor in sensors.iter().take(4) {
        for kind in [CurveKind::Power, CurveKind::Piecewise] {
            let _ = fit_sensor(&sensor.name, &sensor.samples, kind);
        }
    }
}

fn seeds_sensor_csv() -> Vec<Vec<u8>> {
    let mut csv = String::from("sensor,raw,load_n\n");
    for (name, r0) in [("left.heel", 200.0), ("left.toe", 150.0)] {
        for i in 0..10 {
            let load = 50.0 * f64::from(i);
            // The FSR's law inverted: raw = r0 + (F / a)^(1/b).
            let raw = r0 + (load / 0.012_f64).powf(1.0 / 1.4);
            csv.push_str(&format!("{name},{raw:.1},{load}\n"));
        }
    }
    vec![csv.into_bytes()]
}

fn run_calibration_json(data: &[u8]) {
    let Ok(calibration) = SensorCalibration::from_json_str(&text(data), "fuzz") else {
        return;
    };
    let again = SensorCalibration::from_json_str(&calibration.to_json(), "fuzz, saved");
    assert!(
        again.is_ok(),
        "a loaded calibration does not reload: {again:?}"
    );
}

fn seeds_calibration_json() -> Vec<Vec<u8>> {
    let documented = format!(
        "{{\"kind\": \"{FILE_KIND}\", \"version\": 1,\n \"sensors\": [{{\"name\": \"heel\", \
         \"model\": {{\"power\": {{\"a\": 0.012, \"b\": 1.4, \"r0\": 200.0}}}},\n \
         \"raw_range\": [190.0, 3500.0], \"drift\": 0.0}}]}}\n"
    );
    vec![documented.into_bytes()]
}

// ---- compensation files: response, equalizer, limb model, user table (JSON) ----

fn run_compensation_json(data: &[u8]) {
    let text = text(data);
    let origin = "fuzz.json";
    let _ = document::from_json::<ResponseFile>(&text, origin).map(|r| r.response());
    let _ = document::from_json::<EqualizerFile>(&text, origin);
    let _ = document::from_json::<LimbFile>(&text, origin);
    if let Ok(table) = document::from_json::<UserTable>(&text, origin) {
        if let Some(first) = table.entries.first() {
            let _ = table.interpolate(&first.params);
        }
    }
}

fn seeds_compensation_json() -> Vec<Vec<u8>> {
    use crate::compensation::equalizer::{EqualizerConfig, Realisation, SpectralWeights};
    use crate::compensation::limb::{LimbModel, LimbParams};
    use crate::compensation::sweep::FrequencyResponse;
    use crate::units::Hz;
    use num_complex::Complex64;

    let rate = SampleRate(8000);
    let band = Band::new(40.0, 1024.0);
    let response = FrequencyResponse {
        freqs: vec![Hz(40.0), Hz(100.0), Hz(1000.0)],
        response: vec![
            Complex64::new(1.0, 0.0),
            Complex64::new(0.0, 2.0),
            Complex64::new(-0.5, 0.0),
        ],
    };
    let weights =
        SpectralWeights::flat(EqualizerConfig::default(), rate).expect("the default config");
    let limb = LimbModel::new(LimbParams::TABLE1_MEAN, 0.5, 1.0).expect("Table 1's mean");
    let grid = band.log_grid(8);
    let table = UserTable {
        entries: vec![UserEntry {
            name: "a".into(),
            params: LimbParams::TABLE1_MEAN,
            weights_db: (0..grid.len()).map(|i| i as f64 * 0.5).collect(),
        }],
        freqs: grid,
    };
    let json = |v: Result<String, document::DocumentError>| v.expect("valid").into_bytes();
    let response = ResponseFile::new(&response, rate, band, 3, "seed");
    // A file of the first version, with `"kind"` and `"version"` instead of the tag, so
    // that the legacy header is explored too.
    let legacy = document::to_json(&response, "seed")
        .expect("valid")
        .replace(
            "\"format\": \"underfoot.frequency-response/1\"",
            "\"kind\": \"frequency-response\",\n  \"version\": 1",
        );
    vec![
        json(document::to_json(&response, "seed")),
        json(document::to_json(
            &EqualizerFile::new(weights, Realisation::LowDelay { taps: 64 }, vec![], "seed"),
            "seed",
        )),
        json(document::to_json(
            &LimbFile::new(limb, band, 0.3, "seed"),
            "seed",
        )),
        json(document::to_json(&table, "seed")),
        legacy.into_bytes(),
    ]
}

// ---- OSC datagrams ----

#[cfg(feature = "osc")]
fn run_osc(data: &[u8]) {
    use crate::engine::event::Event;
    use crate::io::osc::OscDecoder;
    let decoder = OscDecoder::new(vec!["gravel".into(), "sand".into()], 2)
        .expect("two channels and two materials");
    decoder.decode(data, &mut |event| match event {
        Ok(Event::Force { channel, .. }) => assert!(channel < 2, "force on channel {channel}"),
        Ok(Event::Step { channel, intensity }) => {
            assert!(channel < 2, "step on channel {channel}");
            assert!(intensity.is_finite(), "step intensity {intensity}");
        }
        Ok(Event::Material { channel, slot }) => {
            assert!(
                channel < 2 && slot < 2,
                "material {slot} on channel {channel}"
            );
        }
        _ => {}
    });
}

#[cfg(feature = "osc")]
fn seeds_osc() -> Vec<Vec<u8>> {
    use crate::io::osc::{FORCE_ADDRESS, MATERIAL_ADDRESS, STEP_ADDRESS};
    use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType, encoder};
    let message = |addr: &str, args: Vec<OscType>| {
        OscPacket::Message(OscMessage {
            addr: addr.to_owned(),
            args,
        })
    };
    let force = message(
        FORCE_ADDRESS,
        vec![OscType::Int(0), OscType::Float(300.0), OscType::Float(20.0)],
    );
    let step = message(STEP_ADDRESS, vec![OscType::Int(1), OscType::Float(0.8)]);
    let material = message(
        MATERIAL_ADDRESS,
        vec![OscType::Int(0), OscType::String("sand".into())],
    );
    let bundle = OscPacket::Bundle(OscBundle {
        timetag: OscTime::from((0, 1)),
        content: vec![force.clone(), step.clone(), material.clone()],
    });
    [force, step, material, bundle]
        .iter()
        .map(|p| encoder::encode(p).expect("a small packet encodes"))
        .collect()
}

// ---- serial frames (COBS, CRC-16) ----

#[cfg(feature = "serial")]
fn run_serial(data: &[u8]) {
    use crate::io::serial::{Frame, FrameDecoder, encode_frame, encode_servo_frame};
    let mut decoder = FrameDecoder::new();
    let mut frames = Vec::new();
    decoder.push(data, |f| frames.push(f));
    // A frame decoded is one that encodes back to itself.
    let mut bytes = Vec::new();
    for frame in &frames {
        match frame {
            Frame::Force(f) => encode_frame(f, &mut bytes),
            Frame::Servo(s) => encode_servo_frame(s, &mut bytes),
        }
    }
    let mut again = Vec::new();
    FrameDecoder::new().push(&bytes, |f| again.push(f));
    assert_eq!(frames, again, "decoded frames do not survive re-encoding");
}

#[cfg(feature = "serial")]
fn seeds_serial() -> Vec<Vec<u8>> {
    use crate::io::serial::{FrameData, ServoFrame, encode_frame, encode_servo_frame};
    let mut out = Vec::new();
    encode_frame(
        &FrameData::new(1, &[512, 0, 1023]).expect("three counts"),
        &mut out,
    );
    encode_servo_frame(
        &ServoFrame::new(2, &[1500, 1000]).expect("two targets"),
        &mut out,
    );
    encode_frame(&FrameData::new(3, &[7]).expect("one count"), &mut out);
    vec![out]
}

// ---- the command line's spec strings (`--input`, `--output`, `@SPEED`, `--duration`, `--band`) ----

/// The first byte picks the parser, the rest is the text: one target for every spec string
/// the command line hands to [`crate::io::spec`], so that the fuzzer's corpus mixes them.
fn run_cli_specs(data: &[u8]) {
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

fn seeds_cli_specs() -> Vec<Vec<u8>> {
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
