//! Long recordings are read as excerpts around their strikes (`recording::excerpts`),
//! and analyse as the whole file does: the same strikes, the same measured response,
//! whether the file was read whole or cut.

use std::path::Path;

use underfoot::analysis::{AnalysisConfig, measure};
use underfoot::recording::excerpts::{LONG_FRAMES, MAX_EXCERPTS};
use underfoot::recording::strikes::{OnsetConfig, find_onsets};
use underfoot::recording::{Recording, RecordingError, by_file, read, read_for_analysis};
use underfoot::units::{Hz, SampleRate};

use crate::common::footsteps_dir;

/// A seeded uniform number in [-1, 1).
fn noise(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    (*state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// Writes `x` as a 16-bit mono WAV.
fn write_wav(path: &Path, rate: u32, x: &[f64]) {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut w = hound::WavWriter::create(path, spec).unwrap();
    for &v in x {
        w.write_sample((v * 32767.0).round().clamp(-32768.0, 32767.0) as i16)
            .unwrap();
    }
    w.finalize().unwrap();
}

/// A walk: a strike (a ringing burst, each a little different) every `period` seconds
/// over quiet noise, `seconds` long.
fn walk(rate: u32, seconds: f64, period: f64, seed: u64) -> (Vec<f64>, Vec<usize>) {
    let fs = f64::from(rate);
    let n = (seconds * fs) as usize;
    let mut state = seed;
    let mut x: Vec<f64> = (0..n).map(|_| 1e-4 * noise(&mut state)).collect();
    let mut onsets = Vec::new();
    let mut t = 0.4;
    while t + period < seconds {
        let at = (t * fs) as usize;
        onsets.push(at);
        let f = 180.0 + 40.0 * noise(&mut state);
        let gain = 0.3 * (1.0 + 0.2 * noise(&mut state));
        for k in 0..(0.3 * fs) as usize {
            let tt = k as f64 / fs;
            x[at + k] += gain
                * (-tt / 0.03).exp()
                * ((2.0 * std::f64::consts::PI * f * tt).sin() + 0.3 * noise(&mut state));
        }
        t += period;
    }
    (x, onsets)
}

#[test]
fn a_long_recording_is_read_as_one_excerpt_per_strike_each_around_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("walk.wav");
    let rate = 16_000;
    let (x, onsets) = walk(rate, 150.0, 0.7, 7);
    assert!(x.len() > LONG_FRAMES && onsets.len() < MAX_EXCERPTS);
    write_wav(&path, rate, &x);

    let excerpts = read_for_analysis(&path, None).unwrap();
    let whole = read(&path, None).unwrap();
    // Strikes 0.7 s apart share excerpts of at most 4 s.
    assert!(excerpts.len() >= onsets.len() / 5 && excerpts.len() < onsets.len());
    assert_eq!(by_file(&excerpts), vec![0..excerpts.len()]);
    let fs = SampleRate(rate);
    let mut found_all = Vec::new();
    let mut end = 0;
    for r in &excerpts {
        let e = r.excerpt.expect("an excerpt");
        assert_eq!((r.name.as_str(), r.rate), ("walk.wav", fs));
        assert_eq!(r.sha256, whole.sha256);
        assert_eq!(
            (e.file_frames, e.strikes),
            (whole.samples.len(), onsets.len())
        );
        assert!(r.samples.len() <= (4.3 * f64::from(rate)) as usize);
        // The samples are the file's, in order, none twice.
        assert!(e.start >= end);
        end = e.start + r.samples.len();
        assert_eq!(r.samples, whole.samples[e.start..end]);
        found_all.extend(
            find_onsets(&r.samples, fs, &OnsetConfig::default())
                .into_iter()
                .map(|k| k + e.start),
        );
    }
    // Every strike is in an excerpt, with quiet before it and its ring after it, and
    // is found there where it is.
    assert_eq!(found_all.len(), onsets.len(), "{found_all:?}");
    for (&got, &onset) in found_all.iter().zip(&onsets) {
        assert!(got + 16 >= onset && got <= onset + 16, "{got} vs {onset}");
    }

    // The same input cut differently: excerpts and the whole file measure alike.
    let cfg = AnalysisConfig::default();
    let cut = measure(&excerpts, &cfg).unwrap();
    let full = measure(std::slice::from_ref(&whole), &cfg).unwrap();
    assert_eq!(cut.strikes.len(), full.strikes.len());
    let worst = worst_db(&cut, &full, &cfg);
    assert!(worst < 0.05, "excerpts vs whole: {worst} dB");
}

#[test]
fn a_short_recording_is_read_whole_exactly_as_read_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("short.wav");
    let (x, _) = walk(16_000, 20.0, 0.7, 3);
    write_wav(&path, 16_000, &x);
    let got = read_for_analysis(&path, None).unwrap();
    assert_eq!(got, vec![read(&path, None).unwrap()]);
}

#[test]
fn many_strikes_keep_an_even_spread_of_them() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.wav");
    let rate = 8_000;
    // 400 strikes, each an excerpt of its own: more than are kept.
    let (x, onsets) = walk(rate, 400.0 * 1.1 + 1.0, 1.1, 11);
    assert!(onsets.len() > MAX_EXCERPTS);
    write_wav(&path, rate, &x);
    let excerpts = read_for_analysis(&path, None).unwrap();
    assert_eq!(excerpts.len(), MAX_EXCERPTS);
    let e = excerpts[0].excerpt.unwrap();
    assert_eq!(
        (e.kept, e.cut, e.strikes),
        (MAX_EXCERPTS, onsets.len(), onsets.len())
    );
    // From the first strike to near the last, in order.
    let last = excerpts.last().unwrap().excerpt.unwrap().start;
    assert!(
        e.start < onsets[1] && last > onsets[onsets.len() - 3],
        "{last}"
    );
    assert!(
        excerpts
            .windows(2)
            .all(|w| w[0].excerpt.unwrap().start < w[1].excerpt.unwrap().start)
    );
}

#[test]
fn a_long_recording_is_checked_as_any_other() {
    let dir = tempfile::tempdir().unwrap();
    let rate = 16_000;
    let (mut x, _) = walk(rate, 150.0, 0.7, 5);
    // Clipped far past full scale is not a recording problem for a WAV; silence is.
    x.iter_mut().for_each(|v| *v = 0.0);
    let path = dir.path().join("silent.wav");
    write_wav(&path, rate, &x);
    let e = read_for_analysis(&path, None).unwrap_err();
    assert!(matches!(e, RecordingError::Silent { .. }), "{e:?}");
    assert!(e.to_string().contains("silent.wav"), "{e}");
}

/// The largest difference (dB) between two measured responses over the band.
fn worst_db(
    a: &underfoot::analysis::MeasuredResponse,
    b: &underfoot::analysis::MeasuredResponse,
    cfg: &AnalysisConfig,
) -> f64 {
    cfg.band
        .log_grid(96)
        .iter()
        .map(|&f: &Hz| (20.0 * (a.at(f) / b.at(f)).log10()).abs())
        .fold(0.0, f64::max)
}

#[test]
#[ignore = "slow tier: real recordings"]
fn a_walk_of_the_shared_gravel_measures_as_its_clips_do() {
    // The real clips, each repeated with quiet between them into a walk longer than
    // LONG_FRAMES: its excerpts must measure as the clips read whole do.
    let Some(dir) = footsteps_dir() else {
        return;
    };
    let clips: Vec<Recording> = ["1", "2", "3"]
        .iter()
        .map(|k| {
            read(
                &dir.join(format!("gravel/default_gravel_footstep.{k}.ogg")),
                None,
            )
            .unwrap()
        })
        .collect();
    let rate = clips[0].rate;
    assert!(clips.iter().all(|c| c.rate == rate));
    let gap = rate.samples_in(underfoot::units::Seconds(1.0));
    let mut state = 99u64;
    let mut x = Vec::new();
    while x.len() <= LONG_FRAMES + rate.0 as usize {
        for c in &clips {
            x.extend((0..gap).map(|_| 2e-5 * noise(&mut state)));
            x.extend(&c.samples);
        }
    }
    x.extend((0..gap).map(|_| 2e-5 * noise(&mut state)));
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("gravel-walk.wav");
    write_wav(&path, rate.0, &x);
    let excerpts = read_for_analysis(&path, None).unwrap();
    assert!(excerpts[0].excerpt.is_some());
    let cfg = AnalysisConfig::default();
    let cut = measure(&excerpts, &cfg).unwrap();
    let whole = measure(&[read(&path, None).unwrap()], &cfg).unwrap();
    let clips_alone = measure(&clips, &cfg).unwrap();
    assert_eq!(cut.strikes.len(), whole.strikes.len());
    let vs_whole = worst_db(&cut, &whole, &cfg);
    let vs_clips = worst_db(&cut, &clips_alone, &cfg);
    eprintln!(
        "gravel walk ({} strikes in {} excerpts): excerpts vs whole file {vs_whole:.3} dB, \
         vs the clips {vs_clips:.3} dB",
        cut.strikes.len(),
        excerpts.len()
    );
    assert!(vs_whole < 0.1, "{vs_whole}");
    assert!(vs_clips < 0.5, "{vs_clips}");
}

#[test]
fn a_bad_wav_header_is_found_across_the_streaming_reads_chunks() {
    // The streaming reader scans the file in 1 MiB chunks for the headers a decoder's
    // probe may find anywhere; one that straddles two chunks is found as the in-memory
    // reader finds it.
    let mut bytes = vec![0u8; (1 << 20) - 6];
    bytes.extend_from_slice(b"RIFF");
    bytes.extend_from_slice(&100u32.to_le_bytes());
    bytes.extend_from_slice(b"WAVEfmt ");
    bytes.extend_from_slice(&16u32.to_le_bytes());
    bytes.extend_from_slice(&1u16.to_le_bytes()); // PCM
    bytes.extend_from_slice(&0u16.to_le_bytes()); // no channels
    bytes.extend_from_slice(&[0; 64]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("hidden.wav");
    std::fs::write(&path, &bytes).unwrap();
    let streamed = read_for_analysis(&path, None).unwrap_err();
    let whole = read(&path, None).unwrap_err();
    assert!(
        streamed.to_string().contains("declares 0 channels"),
        "{streamed}"
    );
    assert_eq!(streamed.to_string(), whole.to_string());
}
