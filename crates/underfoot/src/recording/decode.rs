//! Decoding WAV, FLAC and Ogg Vorbis through symphonia, mixed down to mono.
//!
//! The container is chosen by probing the content; the file extension is only a hint, so a
//! FLAC file named `.wav` still decodes, and garbage named `.wav` is reported as corrupt.
//!
//! Decoding is all-or-nothing. Symphonia's decoders allow skipping a bad packet and going
//! on, which suits a media player but not a measurement: a hole in a recording shifts
//! every later strike and smears its spectrum. So any demuxer or decoder error, a stream
//! that ends before the frame count its header promises, or a change of sample rate or
//! channel count part-way is reported as [`RecordingError::Corrupt`] (or
//! [`RecordingError::InvalidRate`]) rather than returning what was decoded so far.
//! A stream whose header carries no frame count (e.g. an Ogg file cut short, whose last
//! complete page then looks like the end) cannot be told from a shorter recording and
//! decodes cleanly to what is there.
//!
//! Samples are converted by symphonia to `f64`: integer PCM divided by `2^(bits-1)`, so
//! full scale is `[-1, 1)`; float PCM passes unchanged (NaN included, which the caller
//! rejects). Channels are averaged with equal weight, `m[n] = (1/C) sum_c x_c[n]`, which
//! keeps a signal present identically on all channels at its level.

use super::RecordingError;
use crate::limits::MAX_RECORDING_FRAMES;
use crate::units::SampleRate;
use std::io::Cursor;
use std::path::Path;
use symphonia::core::codecs::audio::AudioDecoderOptions;
use symphonia::core::errors::Error as SymError;
use symphonia::core::formats::probe::Hint;
use symphonia::core::formats::{FormatOptions, TrackType};
use symphonia::core::io::{MediaSource, MediaSourceStream, MediaSourceStreamOptions};
use symphonia::core::meta::MetadataOptions;

/// The most channels a WAV header may declare. Symphonia computes the block size as a
/// `u16` product of channels and bytes per sample, which overflows (a panic in a debug
/// build) for a header declaring tens of thousands of channels; a footstep recording has
/// a few.
pub(crate) const MAX_WAV_CHANNELS: u16 = 64;

/// Decodes an audio file held in memory to mono samples and its sample rate.
///
/// `file` names the file in errors; its extension is passed to the probe as a hint.
///
/// Headers are checked here for what the decoder library is known to mishandle (see
/// [`wav_header_fault`]); a panic inside it on anything else is still reported as a
/// corrupt file rather than ending the program.
pub(crate) fn decode_audio(
    file: &Path,
    bytes: &[u8],
) -> Result<(SampleRate, Vec<f64>), RecordingError> {
    if let Some(fault) = wav_header_fault(bytes) {
        return Err(RecordingError::Corrupt {
            file: file.to_path_buf(),
            reason: fault,
        });
    }
    let mut sink = Collect::default();
    let rate = decode_source(file, Box::new(Cursor::new(bytes)), &mut sink)?;
    Ok((rate, sink.samples))
}

/// Where decoded audio goes, a packet's frames at a time, mixed to mono.
pub(crate) trait Sink {
    /// Before the first frames: how many the header promises, when it says.
    fn begin(&mut self, _promised_frames: Option<u64>) {}
    /// The next frames, at `rate` (as the packet says; 0 is refused after the last).
    fn push(&mut self, rate: SampleRate, mono: &[f64]);
}

/// A sink that keeps every frame.
#[derive(Default)]
pub(crate) struct Collect {
    pub(crate) samples: Vec<f64>,
}

impl Sink for Collect {
    fn begin(&mut self, promised_frames: Option<u64>) {
        // Sized from the header when it gives a length (bounded above by the frame cap,
        // checked before): growing by doubling would hold up to twice the recording.
        self.samples
            .reserve(promised_frames.map_or(0, |n| n as usize));
    }

    fn push(&mut self, _rate: SampleRate, mono: &[f64]) {
        self.samples.extend_from_slice(mono);
    }
}

/// Decodes `source` into `sink`, returning the rate. The headers must have been checked
/// ([`wav_header_fault`], [`riff_fault_at`]).
///
/// A panic inside the decoder library is reported as a corrupt file rather than ending
/// the program.
pub(crate) fn decode_source(
    file: &Path,
    source: Box<dyn MediaSource + '_>,
    sink: &mut dyn Sink,
) -> Result<SampleRate, RecordingError> {
    let run = std::panic::AssertUnwindSafe(|| decode_with_symphonia(file, source, sink));
    std::panic::catch_unwind(run).unwrap_or_else(|_| {
        Err(RecordingError::Corrupt {
            file: file.to_path_buf(),
            reason: "the audio decoder failed on this file (a fault in the decoder library)".into(),
        })
    })
}

/// What is wrong with a RIFF/WAVE header that the decoder library does not check before
/// using it: a `fmt ` chunk (any of them) declaring no channels or more than
/// [`MAX_WAV_CHANNELS`].
/// `None` for anything else, including files that are not WAV.
///
/// The probe looks for a format's marker past the start of the file too (it skips junk
/// before a stream), so every `RIFF....WAVE` in the bytes is checked, not only one at
/// offset 0.
fn wav_header_fault(bytes: &[u8]) -> Option<String> {
    let at = |from: usize, len: usize| {
        from.checked_add(len)
            .and_then(|end| bytes.get(from..end))
            .map(<[u8]>::to_vec)
    };
    riff_starts(bytes, 0)
        .into_iter()
        .find_map(|start| riff_fault_at(&at, start))
}

/// Where `RIFF....WAVE` begins in `bytes`, which start at offset `base` of the file.
pub(crate) fn riff_starts(bytes: &[u8], base: usize) -> Vec<usize> {
    bytes
        .windows(12)
        .enumerate()
        .filter(|(_, w)| &w[..4] == b"RIFF" && &w[8..] == b"WAVE")
        .map(|(i, _)| base + i)
        .collect()
}

/// [`wav_header_fault`] for a RIFF/WAVE header at offset `start` of a file that
/// `read(at, len)` reads (`None` past its end).
///
/// The chunks are walked the ways a decoder may walk them: by each chunk's declared size
/// (padded to even), and, after a `fmt ` chunk with an extension, by the extension's own
/// size (`cbSize`), which symphonia follows even where it disagrees with the chunk's size
/// (found by libFuzzer). Every chunk start reachable either way is looked at once.
pub(crate) fn riff_fault_at(
    read: &dyn Fn(usize, usize) -> Option<Vec<u8>>,
    start: usize,
) -> Option<String> {
    let mut pending = vec![start + 12];
    let mut seen = std::collections::HashSet::new();
    while let Some(at) = pending.pop() {
        if !seen.insert(at) {
            continue;
        }
        let Some(header) = read(at, 8) else {
            continue;
        };
        let size = u32::from_le_bytes([header[4], header[5], header[6], header[7]]) as usize;
        let body = at + 8;
        if &header[..4] == b"fmt " {
            if let Some(c) = read(body + 2, 2) {
                let channels = u16::from_le_bytes([c[0], c[1]]);
                if channels == 0 || channels > MAX_WAV_CHANNELS {
                    return Some(format!(
                        "the WAV header declares {channels} channels (1 to {MAX_WAV_CHANNELS})"
                    ));
                }
            }
            // Not the end: the decoder reads every `fmt ` chunk, and a later one is the
            // format it keeps (found by libFuzzer).
            if let Some(c) = read(body + 16, 2) {
                let extension = usize::from(u16::from_le_bytes([c[0], c[1]]));
                pending.push(body + 18 + extension);
            }
        }
        // Chunks are padded to an even length.
        if let Some(next) = body.checked_add(size).and_then(|n| n.checked_add(size & 1)) {
            pending.push(next);
        }
    }
    None
}

fn decode_with_symphonia(
    file: &Path,
    source: Box<dyn MediaSource + '_>,
    sink: &mut dyn Sink,
) -> Result<SampleRate, RecordingError> {
    let corrupt = |reason: String| RecordingError::Corrupt {
        file: file.to_path_buf(),
        reason,
    };

    let mss = MediaSourceStream::new(source, MediaSourceStreamOptions::default());
    let mut hint = Hint::new();
    if let Some(ext) = file.extension().and_then(|e| e.to_str()) {
        hint.with_extension(ext);
    }
    let mut format = symphonia::default::get_probe()
        .probe(
            &hint,
            mss,
            FormatOptions::default(),
            MetadataOptions::default(),
        )
        .map_err(|e| match e {
            // The Ogg reader looks for the last page while probing, so a cut file fails here.
            SymError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
                corrupt("truncated: the file ends part-way through its data".into())
            }
            e => corrupt(format!("not a recognisable WAV, FLAC or Ogg file ({e})")),
        })?;

    let track = format
        .default_track(TrackType::Audio)
        .ok_or_else(|| corrupt("no audio track".into()))?;
    let track_id = track.id;
    let promised_frames = track.num_frames;
    let params = track
        .codec_params
        .as_ref()
        .and_then(|p| p.audio())
        .ok_or_else(|| corrupt("the audio track has no codec parameters".into()))?
        .clone();
    let too_long = || RecordingError::TooLong {
        file: file.to_path_buf(),
        limit: format!("{MAX_RECORDING_FRAMES} frames (30 minutes at 48 kHz)"),
    };
    if promised_frames.is_some_and(|n| n > MAX_RECORDING_FRAMES as u64) {
        return Err(too_long());
    }
    let mut rate = params.sample_rate;
    if rate == Some(0) {
        return Err(invalid_rate(file, "the header says 0 Hz".into()));
    }
    let mut decoder = symphonia::default::get_codecs()
        .make_audio_decoder(&params, &AudioDecoderOptions::default())
        .map_err(|e| corrupt(format!("no decoder for this codec ({e})")))?;

    sink.begin(promised_frames);
    let mut frames = 0usize;
    let mut mono: Vec<f64> = Vec::new();
    let mut channels: Option<usize> = None;
    let mut interleaved: Vec<f64> = Vec::new();
    let mut packet_index = 0usize;
    loop {
        let packet = match format.next_packet() {
            Ok(Some(p)) => p,
            Ok(None) => break,
            Err(SymError::ResetRequired) => {
                return Err(corrupt(
                    "the stream changes its tracks part-way (chained stream), not supported".into(),
                ));
            }
            Err(e) => {
                return Err(corrupt(format!(
                    "demuxing failed after {frames} frames, truncated or damaged ({e})"
                )));
            }
        };
        if packet.track_id != track_id {
            continue;
        }
        let buf = decoder
            .decode(&packet)
            .map_err(|e| corrupt(format!("packet {packet_index} could not be decoded ({e})")))?;
        packet_index += 1;
        if buf.frames() == 0 {
            continue;
        }
        let spec = buf.spec();
        match rate {
            None => rate = Some(spec.rate()),
            Some(r) if r != spec.rate() => {
                return Err(invalid_rate(
                    file,
                    format!("changes from {r} Hz to {} Hz part-way", spec.rate()),
                ));
            }
            Some(_) => {}
        }
        let c = spec.channels().count();
        if c == 0 {
            return Err(corrupt("a decoded packet has no channels".into()));
        }
        match channels {
            None => channels = Some(c),
            Some(prev) if prev != c => {
                return Err(corrupt(format!(
                    "channel count changes from {prev} to {c} part-way"
                )));
            }
            Some(_) => {}
        }
        if frames + buf.frames() > MAX_RECORDING_FRAMES {
            return Err(too_long());
        }
        buf.copy_to_vec_interleaved(&mut interleaved);
        let inv = 1.0 / c as f64;
        mono.clear();
        mono.extend(
            interleaved
                .chunks_exact(c)
                .map(|frame| frame.iter().sum::<f64>() * inv),
        );
        frames += mono.len();
        sink.push(SampleRate(spec.rate()), &mono);
    }

    if let Some(n) = promised_frames.filter(|&n| (frames as u64) < n) {
        return Err(corrupt(format!(
            "truncated: the header promises {n} frames but only {frames} could be decoded"
        )));
    }
    if frames == 0 {
        return Err(RecordingError::Empty {
            file: file.to_path_buf(),
        });
    }
    let rate = match rate {
        Some(0) => return Err(invalid_rate(file, "the stream says 0 Hz".into())),
        Some(r) => r,
        None => return Err(invalid_rate(file, "the stream gives no sample rate".into())),
    };
    Ok(SampleRate(rate))
}

fn invalid_rate(file: &Path, reason: String) -> RecordingError {
    RecordingError::InvalidRate {
        file: file.to_path_buf(),
        reason,
    }
}
