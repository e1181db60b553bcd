//! Reading recordings: WAV/FLAC/Ogg/CSV decoding against known content, every kind of bad
//! file, and onset detection on real footsteps.

use crate::common;

use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use underfoot::recording::strikes::{OnsetConfig, find_onsets};
use underfoot::recording::{CsvSpec, MIN_DURATION, Recording, RecordingError, read, read_bytes};
use underfoot::signal::noise::SplitMix64;
use underfoot::units::SampleRate;

fn hex_sha256(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Writes interleaved 16-bit samples as a WAV file.
fn write_wav_i16(path: &Path, rate: u32, channels: u16, interleaved: &[i16]) {
    let spec = hound::WavSpec {
        channels,
        sample_rate: rate,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut w = hound::WavWriter::create(path, spec).unwrap();
    for &s in interleaved {
        w.write_sample(s).unwrap();
    }
    w.finalize().unwrap();
}

/// Writes interleaved 32-bit float samples as a WAV file.
fn write_wav_f32(path: &Path, rate: u32, channels: u16, interleaved: &[f32]) {
    let spec = hound::WavSpec {
        channels,
        sample_rate: rate,
        bits_per_sample: 32,
        sample_format: hound::SampleFormat::Float,
    };
    let mut w = hound::WavWriter::create(path, spec).unwrap();
    for &s in interleaved {
        w.write_sample(s).unwrap();
    }
    w.finalize().unwrap();
}

/// A deterministic test signal: two incommensurate tones plus seeded noise, in [-0.9, 0.9].
fn test_signal(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = SplitMix64::new(seed);
    (0..n)
        .map(|i| {
            let t = i as f64;
            0.5 * (0.031 * t).sin() + 0.3 * (0.0071 * t + 1.0).cos() + 0.1 * (rng.uniform() - 0.5)
        })
        .collect()
}

fn to_i16(x: &[f64]) -> Vec<i16> {
    x.iter().map(|v| (v * 32767.0).round() as i16).collect()
}

fn expect_err(r: Result<Recording, RecordingError>, file: &str) -> RecordingError {
    let e = match r {
        Ok(rec) => panic!(
            "{file}: expected an error, decoded {} samples",
            rec.samples.len()
        ),
        Err(e) => e,
    };
    let msg = e.to_string();
    assert!(msg.contains(file), "message does not name {file}: {msg}");
    e
}

// ---------------------------------------------------------------- WAV

#[test]
fn wav_16bit_mono_is_scaled_to_full_scale_at_several_rates() {
    let dir = tempfile::tempdir().unwrap();
    for (k, rate) in [8000u32, 22_050, 44_100, 48_000].into_iter().enumerate() {
        let n = rate as usize / 5;
        let mut pcm = to_i16(&test_signal(n, k as u64));
        // Both extremes of the format, to pin the scale: -32768 is exactly -1.
        pcm[10] = i16::MIN;
        pcm[11] = i16::MAX;
        let path = dir.path().join(format!("mono_{rate}.wav"));
        write_wav_i16(&path, rate, 1, &pcm);
        let rec = read(&path, None).unwrap();
        assert_eq!(rec.rate, SampleRate(rate));
        assert_eq!(rec.name, format!("mono_{rate}.wav"));
        assert_eq!(rec.samples.len(), n);
        for (i, (&got, &p)) in rec.samples.iter().zip(&pcm).enumerate() {
            assert_eq!(got, f64::from(p) / 32768.0, "sample {i} at {rate} Hz");
        }
        assert_eq!(rec.samples[10], -1.0);
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(rec.sha256, hex_sha256(&bytes));
        assert!(
            rec.sha256.len() == 64
                && rec
                    .sha256
                    .chars()
                    .all(|c| matches!(c, '0'..='9' | 'a'..='f'))
        );
    }
}

#[test]
fn wav_16bit_stereo_is_averaged_to_mono() {
    let dir = tempfile::tempdir().unwrap();
    let n = 4410;
    let left = to_i16(&test_signal(n, 1));
    let right = to_i16(
        &test_signal(n, 2)
            .iter()
            .map(|v| -0.5 * v)
            .collect::<Vec<_>>(),
    );
    let interleaved: Vec<i16> = left
        .iter()
        .zip(&right)
        .flat_map(|(&l, &r)| [l, r])
        .collect();
    let path = dir.path().join("stereo.wav");
    write_wav_i16(&path, 44_100, 2, &interleaved);
    let rec = read(&path, None).unwrap();
    assert_eq!(rec.samples.len(), n);
    for i in 0..n {
        let want = (f64::from(left[i]) / 32768.0 + f64::from(right[i]) / 32768.0) / 2.0;
        assert!(
            (rec.samples[i] - want).abs() < 1e-15,
            "frame {i}: {} vs {want}",
            rec.samples[i]
        );
    }
}

#[test]
fn wav_24bit_is_scaled_by_two_to_the_23() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s24.wav");
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: 16_000,
        bits_per_sample: 24,
        sample_format: hound::SampleFormat::Int,
    };
    let pcm: Vec<i32> = test_signal(1600, 9)
        .iter()
        .map(|v| (v * 8_388_607.0).round() as i32)
        .collect();
    let mut w = hound::WavWriter::create(&path, spec).unwrap();
    for &s in &pcm {
        w.write_sample(s).unwrap();
    }
    w.finalize().unwrap();
    let rec = read(&path, None).unwrap();
    assert_eq!(rec.samples.len(), pcm.len());
    for (&got, &p) in rec.samples.iter().zip(&pcm) {
        assert_eq!(got, f64::from(p) / 8_388_608.0);
    }
}

#[test]
fn float_wav_mono_and_stereo_keep_their_values() {
    let dir = tempfile::tempdir().unwrap();
    for rate in [2000u32, 11_025, 96_000] {
        let n = rate as usize / 10;
        let x: Vec<f32> = test_signal(n, u64::from(rate))
            .iter()
            .map(|&v| v as f32)
            .collect();
        let mono = dir.path().join(format!("f_{rate}.wav"));
        write_wav_f32(&mono, rate, 1, &x);
        let rec = read(&mono, None).unwrap();
        assert_eq!(rec.rate, SampleRate(rate));
        assert_eq!(
            rec.samples,
            x.iter().map(|&v| f64::from(v)).collect::<Vec<_>>()
        );

        let y: Vec<f32> = x.iter().rev().map(|v| 0.25 * v).collect();
        let interleaved: Vec<f32> = x.iter().zip(&y).flat_map(|(&a, &b)| [a, b]).collect();
        let stereo = dir.path().join(format!("f2_{rate}.wav"));
        write_wav_f32(&stereo, rate, 2, &interleaved);
        let rec = read(&stereo, None).unwrap();
        assert_eq!(rec.samples.len(), n);
        for i in 0..n {
            let want = (f64::from(x[i]) + f64::from(y[i])) / 2.0;
            assert!((rec.samples[i] - want).abs() < 1e-15);
        }
    }
}

#[test]
fn read_bytes_matches_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("same.wav");
    write_wav_i16(&path, 8000, 1, &to_i16(&test_signal(800, 3)));
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(
        read_bytes("same.wav", &bytes, None).unwrap(),
        read(&path, None).unwrap()
    );
}

#[test]
fn format_is_probed_not_taken_from_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("really_a_wav.flac");
    let pcm = to_i16(&test_signal(800, 4));
    write_wav_i16(&path, 8000, 1, &pcm);
    assert_eq!(read(&path, None).unwrap().samples.len(), 800);
}

// ---------------------------------------------------------------- FLAC

/// MSB-first bit writer for the FLAC test encoder.
struct Bits {
    bytes: Vec<u8>,
    nbits: usize,
}

impl Bits {
    fn new() -> Self {
        Self {
            bytes: Vec::new(),
            nbits: 0,
        }
    }
    fn put(&mut self, value: u64, width: usize) {
        for k in (0..width).rev() {
            if self.nbits.is_multiple_of(8) {
                self.bytes.push(0);
            }
            if (value >> k) & 1 == 1 {
                let last = self.bytes.len() - 1;
                self.bytes[last] |= 0x80 >> (self.nbits % 8);
            }
            self.nbits += 1;
        }
    }
}

/// CRC-8 of FLAC frame headers: polynomial x^8 + x^2 + x + 1, initial 0.
fn crc8(data: &[u8]) -> u8 {
    data.iter().fold(0u8, |mut crc, &b| {
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

/// CRC-16 of FLAC frames: polynomial x^16 + x^15 + x^2 + 1, initial 0.
fn crc16(data: &[u8]) -> u16 {
    data.iter().fold(0u16, |mut crc, &b| {
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

/// A minimal FLAC encoder written from the format specification (RFC 9639): 16-bit
/// samples, fixed 1024-sample blocks, independent channels, VERBATIM subframes. Enough to
/// give the decoder a file whose every sample is known.
fn encode_flac(rate: u32, channels: &[Vec<i16>]) -> Vec<u8> {
    const BLOCK: usize = 1024;
    let n = channels[0].len();
    let mut out = b"fLaC".to_vec();
    let mut info = Bits::new();
    info.put(1, 1); // last metadata block
    info.put(0, 7); // STREAMINFO
    info.put(34, 24);
    info.put(BLOCK as u64, 16);
    info.put(BLOCK as u64, 16);
    info.put(0, 24); // min frame size unknown
    info.put(0, 24); // max frame size unknown
    info.put(u64::from(rate), 20);
    info.put(channels.len() as u64 - 1, 3);
    info.put(15, 5); // 16 bits per sample
    info.put(n as u64, 36);
    info.put(0, 64); // MD5 unknown
    info.put(0, 64);
    out.extend(info.bytes);
    for (frame_no, start) in (0..n).step_by(BLOCK).enumerate() {
        let len = BLOCK.min(n - start);
        let mut f = Bits::new();
        f.put(0b11_1111_1111_1110, 14); // sync
        f.put(0, 1);
        f.put(0, 1); // fixed block size
        f.put(0b0111, 4); // block size - 1 in 16 bits after the header
        f.put(0, 4); // rate from STREAMINFO
        f.put(channels.len() as u64 - 1, 4); // independent channels
        f.put(0b100, 3); // 16 bits per sample
        f.put(0, 1);
        assert!(frame_no < 128, "one-byte UTF-8 frame number");
        f.put(frame_no as u64, 8);
        f.put(len as u64 - 1, 16);
        let c8 = crc8(&f.bytes);
        f.put(u64::from(c8), 8);
        for ch in channels {
            f.put(0, 1);
            f.put(0b000001, 6); // VERBATIM
            f.put(0, 1); // no wasted bits
            for &s in &ch[start..start + len] {
                f.put(u64::from(s as u16), 16);
            }
        }
        // Byte-aligned already (16-bit samples, 8-bit subframe headers).
        let c16 = crc16(&f.bytes);
        f.put(u64::from(c16), 16);
        out.extend(f.bytes);
    }
    out
}

#[test]
fn flac_decodes_to_the_samples_encoded() {
    let n = 5000;
    let left = to_i16(&test_signal(n, 11));
    let right = to_i16(&test_signal(n, 12));
    let mono = encode_flac(16_000, std::slice::from_ref(&left));
    let rec = read_bytes("mono.flac", &mono, None).unwrap();
    assert_eq!(rec.rate, SampleRate(16_000));
    assert_eq!(
        rec.samples,
        left.iter()
            .map(|&s| f64::from(s) / 32768.0)
            .collect::<Vec<_>>()
    );

    let stereo = encode_flac(44_100, &[left.clone(), right.clone()]);
    let rec = read_bytes("stereo.flac", &stereo, None).unwrap();
    assert_eq!(rec.samples.len(), n);
    for i in 0..n {
        let want = (f64::from(left[i]) + f64::from(right[i])) / 65536.0;
        assert!((rec.samples[i] - want).abs() < 1e-15);
    }
}

#[test]
fn flac_cut_short_is_corrupt() {
    let x = to_i16(&test_signal(8000, 13));
    let bytes = encode_flac(16_000, &[x]);
    let cut = &bytes[..bytes.len() * 2 / 3];
    let e = expect_err(read_bytes("cut.flac", cut, None), "cut.flac");
    assert!(matches!(e, RecordingError::Corrupt { .. }), "{e:?}");
}

// ---------------------------------------------------------------- CSV

fn spec(column: &str, rate: u32) -> CsvSpec {
    CsvSpec {
        column: column.into(),
        rate: SampleRate(rate),
    }
}

#[test]
fn csv_column_by_name_and_by_index() {
    let x = test_signal(200, 5);
    let mut with_header = String::from("time, accel_x ,accel_z\n");
    let mut no_header = String::new();
    for (i, v) in x.iter().enumerate() {
        with_header.push_str(&format!("{},{},{v:e}\n", i, -v));
        no_header.push_str(&format!("{i},{},{v:e}\n", -v));
    }
    let by_name = read_bytes(
        "log.csv",
        with_header.as_bytes(),
        Some(&spec("accel_z", 1000)),
    )
    .unwrap();
    assert_eq!(by_name.samples, x);
    assert_eq!(by_name.rate, SampleRate(1000));
    // The header is trimmed, so " accel_x " is found by name.
    let x_col = read_bytes(
        "log.csv",
        with_header.as_bytes(),
        Some(&spec("accel_x", 1000)),
    )
    .unwrap();
    assert_eq!(x_col.samples, x.iter().map(|v| -v).collect::<Vec<_>>());
    // Index into a file with a header that lacks the name: the header row is skipped.
    let by_index = read_bytes("log.csv", with_header.as_bytes(), Some(&spec("2", 500))).unwrap();
    assert_eq!(by_index.samples, x);
    assert_eq!(by_index.rate, SampleRate(500));
    // Index into a file with no header: the first row is data.
    let headless = read_bytes("raw.CSV", no_header.as_bytes(), Some(&spec("2", 1000))).unwrap();
    assert_eq!(headless.samples, x);
}

#[test]
fn csv_read_from_disk_names_file_and_hashes_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("logger.csv");
    let body: String = test_signal(100, 6)
        .iter()
        .map(|v| format!("{v}\n"))
        .collect();
    std::fs::write(&path, &body).unwrap();
    let rec = read(&path, Some(&spec("0", 1000))).unwrap();
    assert_eq!(rec.name, "logger.csv");
    assert_eq!(rec.samples.len(), 100);
    assert_eq!(rec.sha256, hex_sha256(body.as_bytes()));
}

#[test]
fn csv_errors_name_the_file_and_line() {
    let s = spec("a", 1000);
    let good: String = (0..100)
        .map(|i| format!("{},{}\n", i, f64::from(i).sin()))
        .collect();

    let e = expect_err(read_bytes("needs.csv", good.as_bytes(), None), "needs.csv");
    assert!(matches!(e, RecordingError::CsvNeedsSpec { .. }), "{e:?}");

    let e = expect_err(
        read_bytes("zero.csv", good.as_bytes(), Some(&spec("1", 0))),
        "zero.csv",
    );
    assert!(matches!(e, RecordingError::InvalidRate { .. }), "{e:?}");

    let mut bad_cell = format!("t,a\n{good}");
    bad_cell = bad_cell.replacen("\n5,", "\n5,oops", 1);
    // Line 1 is the header, sample i is on line i + 2; the replaced row is sample 5.
    let e = expect_err(
        read_bytes("cell.csv", bad_cell.as_bytes(), Some(&s)),
        "cell.csv",
    );
    assert!(
        matches!(
            e,
            RecordingError::Csv {
                line: 7,
                column: Some(1),
                ..
            }
        ),
        "{e:?}"
    );
    assert!(e.to_string().contains("line 7"), "{e}");

    let nan_body: String = (0..100)
        .map(|i| {
            if i == 42 {
                format!("{i},NaN\n")
            } else {
                format!("{i},{}\n", f64::from(i).cos())
            }
        })
        .collect();
    let e = expect_err(
        read_bytes("nan.csv", nan_body.as_bytes(), Some(&spec("1", 1000))),
        "nan.csv",
    );
    assert!(
        matches!(e, RecordingError::NonFinite { index: 42, .. }),
        "{e:?}"
    );

    let inf_body = nan_body.replace("NaN", "-inf");
    let e = expect_err(
        read_bytes("inf.csv", inf_body.as_bytes(), Some(&spec("1", 1000))),
        "inf.csv",
    );
    assert!(
        matches!(e, RecordingError::NonFinite { index: 42, .. }),
        "{e:?}"
    );

    let ragged = format!("t,a\n{}", good.replacen("\n9,", "\n9,1,", 1));
    let e = expect_err(
        read_bytes("ragged.csv", ragged.as_bytes(), Some(&s)),
        "ragged.csv",
    );
    assert!(matches!(e, RecordingError::Csv { line: 11, .. }), "{e:?}");

    let e = expect_err(
        read_bytes("name.csv", format!("t,b\n{good}").as_bytes(), Some(&s)),
        "name.csv",
    );
    assert!(matches!(e, RecordingError::Csv { line: 1, .. }), "{e:?}");
    assert!(e.to_string().contains("'a'"), "{e}");

    let e = expect_err(
        read_bytes("index.csv", good.as_bytes(), Some(&spec("5", 1000))),
        "index.csv",
    );
    assert!(
        matches!(
            e,
            RecordingError::Csv {
                line: 1,
                column: Some(5),
                ..
            }
        ),
        "{e:?}"
    );

    let e = expect_err(read_bytes("hdr.csv", b"t,a\n", Some(&s)), "hdr.csv");
    assert!(matches!(e, RecordingError::Empty { .. }), "{e:?}");

    let flat: String = (0..100).map(|i| format!("{i},512\n")).collect();
    let e = expect_err(
        read_bytes("flat.csv", flat.as_bytes(), Some(&spec("1", 1000))),
        "flat.csv",
    );
    assert!(matches!(e, RecordingError::Silent { .. }), "{e:?}");

    let short: String = (0..49)
        .map(|i| format!("{}\n", f64::from(i).sin()))
        .collect();
    let e = expect_err(
        read_bytes("short.csv", short.as_bytes(), Some(&spec("0", 1000))),
        "short.csv",
    );
    assert!(
        matches!(e, RecordingError::TooShort { samples: 49, .. }),
        "{e:?}"
    );
}

// ---------------------------------------------------------------- bad audio files

#[test]
fn missing_file_is_io_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nowhere.wav");
    let e = expect_err(read(&path, None), "nowhere.wav");
    assert!(matches!(e, RecordingError::File(_)), "{e:?}");
    assert_eq!(e.file(), path.as_path());
}

#[test]
fn garbage_bytes_are_corrupt_whatever_the_extension() {
    let mut rng = SplitMix64::new(77);
    let garbage: Vec<u8> = (0..20_000).map(|_| rng.next_u64() as u8).collect();
    let dir = tempfile::tempdir().unwrap();
    for name in ["noise.wav", "noise.ogg", "noise.flac", "noise"] {
        let path = dir.path().join(name);
        std::fs::write(&path, &garbage).unwrap();
        let e = expect_err(read(&path, None), name);
        assert!(matches!(e, RecordingError::Corrupt { .. }), "{name}: {e:?}");
    }
    let e = expect_err(read_bytes("nothing.wav", &[], None), "nothing.wav");
    assert!(matches!(e, RecordingError::Corrupt { .. }), "{e:?}");
}

#[test]
fn wav_truncated_mid_data_is_corrupt() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("full.wav");
    write_wav_i16(&path, 8000, 1, &to_i16(&test_signal(8000, 21)));
    let bytes = std::fs::read(&path).unwrap();
    for cut in [bytes.len() / 2, bytes.len() / 2 + 1, bytes.len() - 1] {
        let e = expect_err(read_bytes("cut.wav", &bytes[..cut], None), "cut.wav");
        assert!(
            matches!(e, RecordingError::Corrupt { .. }),
            "cut at {cut}: {e:?}"
        );
    }
}

#[test]
fn header_only_wav_is_empty() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("header_only.wav");
    write_wav_i16(&path, 8000, 1, &[]);
    let e = expect_err(read(&path, None), "header_only.wav");
    assert!(matches!(e, RecordingError::Empty { .. }), "{e:?}");
}

#[test]
fn float_wav_with_nan_reports_its_index() {
    let dir = tempfile::tempdir().unwrap();
    let mut x: Vec<f32> = test_signal(4000, 22).iter().map(|&v| v as f32).collect();
    x[1234] = f32::NAN;
    let path = dir.path().join("nan.wav");
    write_wav_f32(&path, 8000, 1, &x);
    let e = expect_err(read(&path, None), "nan.wav");
    assert!(
        matches!(e, RecordingError::NonFinite { index: 1234, .. }),
        "{e:?}"
    );

    // In stereo the index is the frame's.
    let mut st: Vec<f32> = x
        .iter()
        .map(|v| if v.is_nan() { 0.1 } else { *v })
        .collect();
    st = st.iter().flat_map(|&v| [v, -v]).collect();
    st[2 * 777 + 1] = f32::INFINITY;
    let path = dir.path().join("inf_stereo.wav");
    write_wav_f32(&path, 8000, 2, &st);
    let e = expect_err(read(&path, None), "inf_stereo.wav");
    assert!(
        matches!(e, RecordingError::NonFinite { index: 777, .. }),
        "{e:?}"
    );
}

#[test]
fn silent_and_short_wavs_are_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zeros.wav");
    write_wav_i16(&path, 8000, 2, &[0; 16_000]);
    let e = expect_err(read(&path, None), "zeros.wav");
    assert!(matches!(e, RecordingError::Silent { .. }), "{e:?}");

    let path = dir.path().join("dc.wav");
    write_wav_f32(&path, 8000, 1, &[0.25; 8000]);
    let e = expect_err(read(&path, None), "dc.wav");
    assert!(matches!(e, RecordingError::Silent { .. }), "{e:?}");

    // One sample under the minimum at 8 kHz.
    let min = SampleRate(8000).samples_in(MIN_DURATION);
    let path = dir.path().join("short.wav");
    write_wav_i16(&path, 8000, 1, &to_i16(&test_signal(min - 1, 23)));
    let e = expect_err(read(&path, None), "short.wav");
    assert!(matches!(e, RecordingError::TooShort { .. }), "{e:?}");
    let path = dir.path().join("just_long_enough.wav");
    write_wav_i16(&path, 8000, 1, &to_i16(&test_signal(min, 23)));
    assert!(read(&path, None).is_ok());
}

#[test]
fn wav_declaring_zero_hz_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rate.wav");
    write_wav_i16(&path, 8000, 1, &to_i16(&test_signal(800, 24)));
    let mut bytes = std::fs::read(&path).unwrap();
    // Canonical 44-byte header: the sample rate is the u32 at offset 24.
    assert_eq!(&bytes[24..28], &8000u32.to_le_bytes());
    bytes[24..28].copy_from_slice(&0u32.to_le_bytes());
    let e = expect_err(read_bytes("rate0.wav", &bytes, None), "rate0.wav");
    assert!(matches!(e, RecordingError::InvalidRate { .. }), "{e:?}");
}

// ---------------------------------------------------------------- real recordings

#[test]
#[ignore = "slow tier: real recordings"]
fn real_footsteps_decode_and_each_has_an_onset() {
    let Some(dir) = common::footsteps_dir() else {
        return;
    };
    let files = footstep_files(&dir);
    assert!(
        files.len() >= 10,
        "expected the footstep set, found {files:?}"
    );
    for path in &files {
        let rec = read(path, None).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            [22_050, 44_100, 48_000].contains(&rec.rate.0),
            "{}: unexpected rate {}",
            rec.name,
            rec.rate
        );
        assert_eq!(rec.name, path.file_name().unwrap().to_string_lossy());
        assert_eq!(rec.sha256, hex_sha256(&std::fs::read(path).unwrap()));
        let peak = rec.samples.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(peak > 0.01 && peak < 1.5, "{}: peak {peak}", rec.name);
        let onsets = find_onsets(&rec.samples, rec.rate, &OnsetConfig::default());
        assert!(!onsets.is_empty(), "{}: no onset found", rec.name);
        assert!(onsets.iter().all(|&o| o < rec.samples.len()));
    }
}

#[test]
#[ignore = "slow tier: real recordings"]
fn real_ogg_cut_short_errors_or_decodes_shorter_never_panics() {
    let Some(dir) = common::footsteps_dir() else {
        return;
    };
    for path in footstep_files(&dir) {
        let bytes = std::fs::read(&path).unwrap();
        let full = read_bytes("whole.ogg", &bytes, None).unwrap();
        for frac in [0.5, 0.3, 0.9] {
            let cut = &bytes[..(bytes.len() as f64 * frac) as usize];
            match read_bytes("half.ogg", cut, None) {
                Ok(rec) => {
                    assert!(rec.samples.len() < full.samples.len(), "{}", path.display());
                    // A clean shorter decode is a prefix of the full one.
                    let n = rec.samples.len();
                    let err = rec
                        .samples
                        .iter()
                        .zip(&full.samples[..n])
                        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                    assert!(err < 1e-6, "{}: prefix differs by {err}", path.display());
                }
                Err(e) => assert!(e.to_string().contains("half.ogg"), "{e}"),
            }
        }
    }
}

#[test]
fn data_dir_lookup_is_absent_or_a_directory() {
    if let Some(dir) = common::footsteps_dir() {
        assert!(PathBuf::from(&dir).is_dir());
    }
}

/// Every `*.ogg` file one level down in `dir` (one folder per material), sorted.
fn footstep_files(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = common::footsteps_by_material(dir)
        .into_iter()
        .flat_map(|(_, files)| files)
        .collect();
    files.sort();
    files
}
