use std::sync::Arc;

use cpal::{
    OutputCallbackInfo, OutputStreamTimestamp, StreamInstant, SupportedBufferSize,
    SupportedStreamConfigRange,
};

use super::choose::{Refusal, choose_config, spans};
use super::meter::{Meter, Shared};
use super::stream::{render_converted, to_device};
use super::*;

fn info(callback_micros: u64, latency_micros: u64) -> OutputCallbackInfo {
    let callback = StreamInstant::from_micros(callback_micros);
    OutputCallbackInfo::new(OutputStreamTimestamp {
        callback,
        playback: StreamInstant::from_micros(callback_micros + latency_micros),
    })
}

#[test]
fn conversion_renders_large_buffers_in_whole_frame_chunks() {
    let channels = 2;
    let mut scratch = vec![0.0_f32; 3 * channels];
    let mut out = vec![0_i16; 8 * channels];
    let mut calls = Vec::new();
    let mut next = 0.0_f32;
    let mut render = |buf: &mut [f32], ch: usize| {
        calls.push((buf.len(), ch));
        for x in buf.iter_mut() {
            *x = next;
            next += 0.01;
        }
    };
    render_converted(&mut out, &mut scratch, channels, &mut render);
    assert_eq!(calls, vec![(6, 2), (6, 2), (4, 2)]);
    for (i, &o) in out.iter().enumerate() {
        let expected = (i as f32 * 0.01 * 32768.0) as i16;
        assert!((o - expected).abs() <= 1, "sample {i}: {o} vs {expected}");
    }
}

#[test]
fn integer_conversion_clamps_and_silences_nan() {
    assert_eq!(to_device::<i16>(2.0), i16::MAX);
    // The -6 dB ceiling is 16422.9 codes: rounded it was 16423, one above.
    let ceiling = crate::safety::ceiling_amplitude(crate::units::Decibels(-6.0));
    let c16 = f64::from(ceiling) * 32768.0;
    assert!(f64::from(to_device::<i16>(ceiling)) <= c16);
    assert!(f64::from(to_device::<i16>(-ceiling)) >= -c16);
    let c24 = f64::from(ceiling) * 8_388_608.0;
    assert!(f64::from(to_device::<cpal::I24>(ceiling).inner()) <= c24);
    assert!(f64::from(to_device::<i32>(ceiling)) <= f64::from(ceiling) * 2_147_483_648.0);
    assert!(i32::from(to_device::<u16>(ceiling)) - 32_768 <= c16 as i32);
    assert_eq!(to_device::<i16>(-2.0), i16::MIN);
    assert_eq!(to_device::<i16>(f32::NAN), 0);
    assert_eq!(to_device::<u16>(f32::NAN), 32_768);
    // Full scale must not wrap to negative in a 24-bit container.
    assert_eq!(to_device::<cpal::I24>(1.0).inner(), (1 << 23) - 1);
    assert_eq!(to_device::<cpal::I24>(-1.0).inner(), -(1 << 23));
    assert!(to_device::<i32>(1.0) > i32::MAX - 256);
    // Floats pass through untouched.
    assert_eq!(to_device::<f64>(1.5), 1.5);
}

#[test]
fn meter_counts_late_callbacks_and_reports_the_median_latency() {
    let shared = Arc::new(Shared::default());
    let mut meter = Meter::new(Arc::clone(&shared), 48_000);
    // 48 frames = 1 ms per buffer; late means more than 1.5 ms since the previous.
    let mut t = 0;
    for (step, latency) in [(0, 2_000), (1_000, 3_000), (1_400, 2_500), (1_600, 2_000)] {
        t += step;
        meter.record(48, &info(t, latency));
    }
    let stats = shared.snapshot();
    assert_eq!(stats.callbacks, 4);
    assert_eq!(stats.frames, 192);
    assert_eq!(stats.max_callback_frames, 48);
    assert_eq!(stats.late_callbacks, 1);
    // Sorted 2.0, 2.0, 2.5, 3.0 ms: the upper median.
    let latency = stats.latency.expect("latency");
    assert!((latency.0 - 2.5e-3).abs() < 1e-9, "{latency}");
}

#[test]
fn meter_keeps_only_the_recent_window() {
    let shared = Arc::new(Shared::default());
    let mut meter = Meter::new(Arc::clone(&shared), 48_000);
    for i in 0..(4 * LATENCY_WINDOW as u64) {
        let latency = if i < 2 * LATENCY_WINDOW as u64 {
            10_000
        } else {
            1_000
        };
        meter.record(48, &info(i * 1_000, latency));
    }
    let latency = shared.snapshot().latency.expect("latency");
    assert!((latency.0 - 1e-3).abs() < 1e-9, "{latency}");
    assert_eq!(shared.snapshot().late_callbacks, 0);
}

#[test]
fn spans_compress_runs() {
    assert_eq!(spans(vec![6, 1, 2, 3, 2]), "1-3, 6");
    assert_eq!(spans(vec![2]), "2");
}

#[test]
fn host_names_parse() {
    assert_eq!("ALSA".parse::<AudioHost>().ok(), Some(AudioHost::Alsa));
    assert_eq!(
        "default".parse::<AudioHost>().ok(),
        Some(AudioHost::Default)
    );
    assert!("pulse".parse::<AudioHost>().is_err());
}

/// A configuration range as a device lists it.
fn offer(
    channels: u16,
    rates: (u32, u32),
    buffer: Option<(u32, u32)>,
    format: SampleFormat,
) -> SupportedStreamConfigRange {
    let buffer = match buffer {
        Some((min, max)) => SupportedBufferSize::Range { min, max },
        None => SupportedBufferSize::Unknown,
    };
    SupportedStreamConfigRange::new(channels, rates.0, rates.1, buffer, format)
}

fn request(channels: u16, rate: u32, buffer_frames: Option<u32>) -> AudioConfig {
    AudioConfig {
        channels,
        rate: SampleRate(rate),
        buffer_frames,
        ..AudioConfig::default()
    }
}

/// A sound card: 16-bit and 32-bit integer stereo at 44.1 to 96 kHz, and float stereo
/// at 48 kHz only.
fn card() -> Vec<SupportedStreamConfigRange> {
    vec![
        offer(2, (44_100, 96_000), Some((64, 16_384)), SampleFormat::I16),
        offer(2, (44_100, 96_000), Some((64, 16_384)), SampleFormat::I32),
        offer(2, (48_000, 48_000), Some((128, 4096)), SampleFormat::F32),
        offer(4, (48_000, 48_000), None, SampleFormat::DsdU8),
    ]
}

#[test]
fn choice_prefers_float_then_resolution() {
    let chosen = choose_config(&card(), &request(2, 48_000, None), Direction::Output).unwrap();
    assert_eq!(chosen.format, SampleFormat::F32);
    assert_eq!(chosen.stream.channels, 2);
    assert_eq!(chosen.stream.sample_rate, 48_000);
    assert_eq!(chosen.stream.buffer_size, cpal::BufferSize::Default);
    // Without a requested buffer, the scratch covers the device's largest one.
    assert_eq!(chosen.scratch_frames, 4096);

    // Float is not offered at 96 kHz: 32-bit integers beat 16-bit ones.
    let chosen = choose_config(&card(), &request(2, 96_000, None), Direction::Output).unwrap();
    assert_eq!(chosen.format, SampleFormat::I32);
    assert_eq!(chosen.scratch_frames, MAX_SCRATCH_FRAMES as usize);

    // A buffer outside float's range picks the integer format that takes it.
    let chosen = choose_config(&card(), &request(2, 48_000, Some(8192)), Direction::Input).unwrap();
    assert_eq!(chosen.format, SampleFormat::I32);
    assert_eq!(chosen.stream.buffer_size, cpal::BufferSize::Fixed(8192));
    assert_eq!(chosen.scratch_frames, 8192);

    // A host that does not say its buffer sizes accepts any request.
    let jack = [offer(2, (48_000, 48_000), None, SampleFormat::F32)];
    let chosen = choose_config(&jack, &request(2, 48_000, Some(64)), Direction::Output).unwrap();
    assert_eq!(chosen.scratch_frames, 64);
    let chosen = choose_config(&jack, &request(2, 48_000, None), Direction::Output).unwrap();
    assert_eq!(chosen.scratch_frames, MAX_SCRATCH_FRAMES as usize);
}

#[test]
fn refusals_say_what_the_device_offers() {
    let refused = |config: AudioConfig| {
        choose_config(&card(), &config, Direction::Output)
            .unwrap_err()
            .to_string()
    };
    assert_eq!(refused(request(0, 48_000, None)), "zero channels requested");
    assert_eq!(
        refused(request(2, 0, None)),
        "a sample rate of 0 Hz requested"
    );
    assert_eq!(
        refused(request(2, 48_000, Some(0))),
        "a buffer of 0 frames requested"
    );
    // The DSD configuration is not PCM: its four channels are not offered.
    assert_eq!(
        refused(request(4, 48_000, None)),
        "4 channels not supported; it offers 2 channels"
    );
    assert_eq!(
        refused(request(2, 22_050, None)),
        "22050 Hz not supported with 2 channels; it offers 44100-96000 Hz, 48000 Hz"
    );
    assert_eq!(
        refused(request(2, 48_000, Some(32))),
        "a buffer of 32 frames not supported at 48000 Hz with 2 channels; it offers \
         128-4096, 64-16384 frames"
    );
    let dsd = [offer(2, (48_000, 48_000), None, SampleFormat::DsdU8)];
    assert_eq!(
        choose_config(&dsd, &request(2, 48_000, None), Direction::Input),
        Err(Refusal::NoPcm {
            direction: Direction::Input
        })
    );
    assert_eq!(
        choose_config(&dsd, &request(2, 48_000, None), Direction::Input)
            .unwrap_err()
            .to_string(),
        "it offers no PCM input configuration"
    );
    // A device whose ranges do not say their buffer sizes is refused without a list.
    let fixed = [offer(
        1,
        (48_000, 48_000),
        Some((256, 256)),
        SampleFormat::I16,
    )];
    assert_eq!(
        choose_config(&fixed, &request(1, 48_000, Some(64)), Direction::Output)
            .unwrap_err()
            .to_string(),
        "a buffer of 64 frames not supported at 48000 Hz with 1 channels; it offers 256 frames"
    );
}
