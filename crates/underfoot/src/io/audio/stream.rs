//! Running streams: [`AudioOutput`] and [`AudioInput`], built for the device's sample
//! format.
//!
//! For a device that does not take `f32`, the callback renders into a scratch buffer
//! allocated at start-up, and the samples are converted (clamped to full scale for
//! integer formats). The scratch is sized from the buffer size (requested, or the
//! device's maximum capped at [`MAX_SCRATCH_FRAMES`](super::MAX_SCRATCH_FRAMES)); a larger device buffer is
//! rendered in several whole-frame chunks rather than allocating on the audio thread. An
//! input converts the other way, through a scratch buffer sized the same way.
//!
//! One dispatch on the sample format serves both directions: each direction says how to
//! build a stream of `f32` and of any other sample type, and the format picks the type.

use std::fmt;
use std::sync::Arc;
use std::time::Duration;

use cpal::traits::{DeviceTrait, StreamTrait};
use cpal::{FromSample, InputCallbackInfo, OutputCallbackInfo, SizedSample};

use super::choose::Chosen;
use super::discovery::{Opened, open_device};
use super::meter::{Meter, Shared, StreamStats, error_counter};
use super::{AudioConfig, Direction, SampleFormat, StreamInfo};
use crate::io::IoError;

/// How long to wait for a host to build a stream. JACK builds on a helper thread and
/// gives up after this; ALSA uses it as its poll timeout to notice a stalled device.
const BUILD_TIMEOUT: Duration = Duration::from_secs(5);

/// A running output stream. Dropping it stops the stream as [`AudioOutput::stop`] does.
pub struct AudioOutput(Running);

impl fmt::Debug for AudioOutput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("AudioOutput")
            .field("info", &self.0.info)
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

impl AudioOutput {
    /// Opens the device in `config` and starts calling `render` from its audio thread.
    ///
    /// `render(buffer, channels)` must fill all of `buffer` (interleaved, a whole number of
    /// frames) without allocating, locking or blocking.
    ///
    /// # Errors
    /// - [`IoError::Open`]: the host is unavailable, no device matches (the message lists
    ///   the devices), or the stream could not be built or started.
    /// - [`IoError::Unsupported`]: zero channels, rate or buffer size, or a combination
    ///   the device does not offer (the message lists what it offers).
    pub fn start(
        config: &AudioConfig,
        render: impl FnMut(&mut [f32], usize) + Send + 'static,
    ) -> Result<Self, IoError> {
        Running::start(config, Direction::Output, |device, chosen, shared| {
            build_for_format(
                chosen.format,
                Output {
                    parts: Parts {
                        device,
                        chosen,
                        shared,
                    },
                    render,
                },
            )
        })
        .map(Self)
    }

    /// What was opened.
    #[must_use]
    pub fn info(&self) -> &StreamInfo {
        &self.0.info
    }

    /// Counts so far, read without disturbing the audio thread.
    #[must_use]
    pub fn stats(&self) -> StreamStats {
        self.0.shared.snapshot()
    }

    /// Stops the stream, waits for the audio thread to let go of the callback, and
    /// returns the final counts.
    pub fn stop(self) -> StreamStats {
        self.0.stop()
    }
}

/// A running input stream. Dropping it stops the stream as [`AudioInput::stop`] does.
pub struct AudioInput(Running);

impl fmt::Debug for AudioInput {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("AudioInput")
            .field("info", &self.0.info)
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

impl AudioInput {
    /// Opens the input device in `config` and hands each buffer it captures to
    /// `on_input` on its audio thread.
    ///
    /// `on_input(samples, channels)` gets interleaved `f32` (frames x channels), converted
    /// from the device's format (integers scaled to ±1); it must not allocate, lock or
    /// block. The device is matched, and its configuration chosen, by the same rules as
    /// an output's ([`discovery`](super::discovery), [`choose`](super::choose)), among
    /// the host's input devices.
    ///
    /// # Errors
    /// As [`AudioOutput::start`].
    pub fn start(
        config: &AudioConfig,
        on_input: impl FnMut(&[f32], usize) + Send + 'static,
    ) -> Result<Self, IoError> {
        Running::start(config, Direction::Input, |device, chosen, shared| {
            build_for_format(
                chosen.format,
                Input {
                    parts: Parts {
                        device,
                        chosen,
                        shared,
                    },
                    on_input,
                },
            )
        })
        .map(Self)
    }

    /// What was opened.
    #[must_use]
    pub fn info(&self) -> &StreamInfo {
        &self.0.info
    }

    /// Counts so far, read without disturbing the audio thread. For an input,
    /// [`StreamStats::latency`] holds the capture latency: the callback instant minus the
    /// host's capture instant.
    #[must_use]
    pub fn stats(&self) -> StreamStats {
        self.0.shared.snapshot()
    }

    /// Stops the stream, waits for the audio thread to let go of the callback, and
    /// returns the final counts.
    pub fn stop(self) -> StreamStats {
        self.0.stop()
    }
}

/// A started stream of either direction, with what its audio thread records.
struct Running {
    stream: cpal::Stream,
    info: StreamInfo,
    shared: Arc<Shared>,
}

impl Running {
    /// Opens the device for `direction`, builds its stream with `build` (which gets the
    /// counters the audio thread records into) and starts it.
    fn start(
        config: &AudioConfig,
        direction: Direction,
        build: impl FnOnce(&cpal::Device, &Chosen, Arc<Shared>) -> Result<cpal::Stream, cpal::Error>,
    ) -> Result<Self, IoError> {
        let opened = open_device(config, direction)?;
        let shared = Arc::new(Shared::default());
        let stream = build(&opened.device, &opened.chosen, Arc::clone(&shared)).map_err(|e| {
            IoError::Open {
                device: opened.label.clone(),
                reason: format!(
                    "cannot build a {} channel, {}, {} {direction} stream: {e}",
                    opened.chosen.stream.channels, config.rate, opened.chosen.format
                ),
            }
        })?;
        let info = play_stream(&stream, &opened, config)?;
        Ok(Self {
            stream,
            info,
            shared,
        })
    }

    fn stop(self) -> StreamStats {
        // Pausing first makes the host output silence rather than cut off mid-buffer on
        // hosts that keep running until the stream is torn down. Failure to pause changes
        // nothing: dropping the stream stops it anyway.
        let _ = self.stream.pause();
        drop(self.stream);
        self.shared.snapshot()
    }
}

/// Starts a built stream and describes it.
fn play_stream(
    stream: &cpal::Stream,
    opened: &Opened,
    config: &AudioConfig,
) -> Result<StreamInfo, IoError> {
    stream.play().map_err(|e| IoError::Open {
        device: opened.label.clone(),
        reason: format!("cannot start the stream: {e}"),
    })?;
    let buffer_frames = stream
        .buffer_size()
        .ok()
        .filter(|&n| n > 0)
        .or(config.buffer_frames);
    Ok(StreamInfo {
        host: opened.host_kind,
        device: opened.name.clone(),
        rate: config.rate,
        channels: config.channels,
        buffer_frames,
        sample_format: opened.chosen.format,
    })
}

/// A device sample type other than `f32`: converted to it on output, from it on input.
trait DeviceSample: SizedSample + FromSample<f32> + Send + 'static {
    /// The sample as `f32` (integers scaled to ±1).
    fn to_f32(self) -> f32;
}

impl<T> DeviceSample for T
where
    T: SizedSample + FromSample<f32> + Send + 'static,
    f32: FromSample<T>,
{
    fn to_f32(self) -> f32 {
        <f32 as cpal::Sample>::from_sample(self)
    }
}

/// How one direction builds its stream, for `f32` and for any other sample type;
/// [`build_for_format`] picks which from the device's format.
trait Build: Sized {
    /// The device takes `f32`: the callback sees the device's buffer itself.
    fn float(self) -> Result<cpal::Stream, cpal::Error>;
    /// The device takes `T`: converted through an `f32` scratch buffer.
    fn converted<T: DeviceSample>(self) -> Result<cpal::Stream, cpal::Error>;
}

/// Builds the stream for the sample type of `format`.
fn build_for_format(format: SampleFormat, build: impl Build) -> Result<cpal::Stream, cpal::Error> {
    use SampleFormat as F;
    match format {
        F::F32 => build.float(),
        F::F64 => build.converted::<f64>(),
        F::I32 => build.converted::<i32>(),
        F::U32 => build.converted::<u32>(),
        F::I24 => build.converted::<cpal::I24>(),
        F::U24 => build.converted::<cpal::U24>(),
        F::I16 => build.converted::<i16>(),
        F::U16 => build.converted::<u16>(),
        F::I64 => build.converted::<i64>(),
        F::U64 => build.converted::<u64>(),
        F::I8 => build.converted::<i8>(),
        F::U8 => build.converted::<u8>(),
        // choose_config only picks formats that format_rank accepts.
        other => Err(cpal::Error::with_message(
            cpal::ErrorKind::UnsupportedConfig,
            format!("sample format {other} cannot carry PCM"),
        )),
    }
}

/// What every stream is built from.
struct Parts<'a> {
    device: &'a cpal::Device,
    chosen: &'a Chosen,
    shared: Arc<Shared>,
}

impl Parts<'_> {
    fn channels(&self) -> usize {
        usize::from(self.chosen.stream.channels)
    }

    fn meter(&self) -> Meter {
        Meter::new(Arc::clone(&self.shared), self.chosen.stream.sample_rate)
    }

    /// Scratch for converting one device buffer (or a chunk of one), allocated now.
    fn scratch(&self) -> Vec<f32> {
        vec![0.0_f32; self.chosen.scratch_frames * self.channels()]
    }
}

/// An output stream calling `render`.
struct Output<'a, R> {
    parts: Parts<'a>,
    render: R,
}

impl<R: FnMut(&mut [f32], usize) + Send + 'static> Build for Output<'_, R> {
    fn float(self) -> Result<cpal::Stream, cpal::Error> {
        let Self { parts, mut render } = self;
        let channels = parts.channels();
        let mut meter = parts.meter();
        parts.device.build_output_stream(
            parts.chosen.stream,
            move |data: &mut [f32], info: &OutputCallbackInfo| {
                meter.record(data.len() / channels, info);
                render(data, channels);
            },
            error_counter(parts.shared),
            Some(BUILD_TIMEOUT),
        )
    }

    fn converted<T: DeviceSample>(self) -> Result<cpal::Stream, cpal::Error> {
        let Self { parts, mut render } = self;
        let channels = parts.channels();
        let mut scratch = parts.scratch();
        let mut meter = parts.meter();
        parts.device.build_output_stream(
            parts.chosen.stream,
            move |data: &mut [T], info: &OutputCallbackInfo| {
                meter.record(data.len() / channels, info);
                render_converted(data, &mut scratch, channels, &mut render);
            },
            error_counter(parts.shared),
            Some(BUILD_TIMEOUT),
        )
    }
}

/// An input stream calling `on_input`.
struct Input<'a, R> {
    parts: Parts<'a>,
    on_input: R,
}

impl<R: FnMut(&[f32], usize) + Send + 'static> Build for Input<'_, R> {
    fn float(self) -> Result<cpal::Stream, cpal::Error> {
        let Self {
            parts,
            mut on_input,
        } = self;
        let channels = parts.channels();
        let mut meter = parts.meter();
        parts.device.build_input_stream(
            parts.chosen.stream,
            move |data: &[f32], info: &InputCallbackInfo| {
                meter.record_input(data.len() / channels, info);
                on_input(data, channels);
            },
            error_counter(parts.shared),
            Some(BUILD_TIMEOUT),
        )
    }

    fn converted<T: DeviceSample>(self) -> Result<cpal::Stream, cpal::Error> {
        let Self {
            parts,
            mut on_input,
        } = self;
        let channels = parts.channels();
        let mut scratch = parts.scratch();
        let mut meter = parts.meter();
        parts.device.build_input_stream(
            parts.chosen.stream,
            move |data: &[T], info: &InputCallbackInfo| {
                meter.record_input(data.len() / channels, info);
                deliver_converted(data, &mut scratch, channels, &mut on_input);
            },
            error_counter(parts.shared),
            Some(BUILD_TIMEOUT),
        )
    }
}

/// Renders `out` through the `f32` scratch buffer, in whole-frame chunks when `out` is
/// larger than the scratch. `scratch.len()` is a non-zero multiple of `channels`.
pub(super) fn render_converted<T, R>(
    out: &mut [T],
    scratch: &mut [f32],
    channels: usize,
    render: &mut R,
) where
    T: SizedSample + FromSample<f32>,
    R: FnMut(&mut [f32], usize),
{
    for block in out.chunks_mut(scratch.len()) {
        let samples = &mut scratch[..block.len()];
        render(samples, channels);
        for (o, &x) in block.iter_mut().zip(samples.iter()) {
            *o = to_device(x);
        }
    }
}

/// Converts `captured` to `f32` through the scratch buffer and delivers it, in
/// whole-frame chunks when it is larger than the scratch (no allocation on the audio
/// thread). `scratch.len()` is a non-zero multiple of `channels`.
fn deliver_converted<T, R>(captured: &[T], scratch: &mut [f32], channels: usize, on_input: &mut R)
where
    T: DeviceSample,
    R: FnMut(&[f32], usize),
{
    for block in captured.chunks(scratch.len()) {
        let samples = &mut scratch[..block.len()];
        for (s, &x) in samples.iter_mut().zip(block) {
            *s = x.to_f32();
        }
        on_input(samples, channels);
    }
}

/// One sample to the device format. Integer formats get the sample already on their
/// grid: [`quantize`](crate::safety::quantize)d (truncated towards zero, so never past
/// the limiter's ceiling, whatever rounding the format conversion does) to the format's
/// bits, at most 24 (what an `f32` holds exactly), and back to the exact `f32` of that
/// code, which the conversion then only scales. That also keeps full scale inside the
/// container (+1.0 would overflow a 24-bit one into a negative full-scale value). NaN
/// becomes silence.
pub(super) fn to_device<T: SizedSample + FromSample<f32>>(x: f32) -> T {
    if T::FORMAT.is_float() {
        T::from_sample(x)
    } else if x.is_nan() {
        T::EQUILIBRIUM
    } else {
        let bits = T::FORMAT.bits_per_sample().clamp(2, 24);
        let full = (1u32 << (bits - 1)) as f32;
        T::from_sample(crate::safety::quantize(x, bits) as f32 / full)
    }
}
