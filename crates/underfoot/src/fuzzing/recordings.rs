//! Recordings: audio decoding (WAV, FLAC, Ogg Vorbis by content) and the fit's CSV
//! reader (data-logger recordings).

use crate::recording::{CsvSpec, read_bytes};
use crate::units::SampleRate;

// ---- audio decoding (WAV, FLAC, Ogg Vorbis by content) ----

pub(super) fn run_audio(data: &[u8]) {
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

pub(super) fn seeds_audio() -> Vec<Vec<u8>> {
    let x = strikes(2000, 2000);
    vec![
        wav_bytes(2000, 1, 16, &x),
        wav_bytes(2000, 1, 24, &x[..600]),
        wav_bytes(2000, 3, 32, &x[..600]),
        flac_bytes(2000, &x),
    ]
}

// ---- the fit's CSV reader (data-logger recordings) ----

pub(super) fn run_recording_csv(data: &[u8]) {
    for column in ["1", "force"] {
        let spec = CsvSpec {
            column: column.to_owned(),
            rate: SampleRate(1000),
        };
        let _ = read_bytes("fuzz.csv", data, Some(&spec));
    }
}

pub(super) fn seeds_recording_csv() -> Vec<Vec<u8>> {
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
