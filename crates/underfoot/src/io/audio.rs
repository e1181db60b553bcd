//! Vibration to an audio device through cpal (ALSA; JACK with the `jack` feature).
//!
//! [`AudioOutput::start`] opens a device, picks a stream configuration and calls a render
//! callback from the device's audio thread until [`AudioOutput::stop`]. The callback has
//! the engine's signature, `FnMut(&mut [f32], usize)`: interleaved output (frames x
//! channels) and the channel count. It must fill the whole slice and never allocate,
//! lock or block; it may be called with fewer frames than the device buffer (see below).
//!
//! # Choosing the stream
//!
//! The device is `AudioConfig::device`, matched in this order against the host's output
//! devices: the exact device id (`null`, `hw:CARD=1,DEV=0`), the id in ALSA's short form
//! (`hw:1` means `hw:CARD=1,DEV=0`), the exact description, then the first id or
//! description that contains it (case-insensitive). [`list_devices`] shows the
//! candidates.
//!
//! Among the device's configurations with the requested channels and rate, 32-bit float
//! is preferred; otherwise the best remaining PCM format, ranked by resolution. A
//! requested buffer size must lie in the device's range; without one the host's default
//! is used. Anything the device cannot do is an [`IoError::Unsupported`] that lists what
//! it can do.
//!
//! For a device that does not take `f32`, the callback renders into a scratch buffer
//! allocated at start-up, and the samples are converted (clamped to full scale for
//! integer formats). The scratch is sized
//! from the buffer size (requested, or the device's maximum capped at
//! [`MAX_SCRATCH_FRAMES`]); a larger device buffer is rendered in several whole-frame
//! chunks rather than allocating on the audio thread.
//!
//! [`AudioInput::start`] is the same for capture: the device is matched among the host's
//! input devices and configured by the same rules, and `on_input(samples, channels)` gets
//! interleaved `f32` (converted from the device's format through a scratch buffer
//! allocated at start-up, like the output's).
//!
//! # Measuring through the sound card
//!
//! [`AudioLoop`] is a sweep [`Device`]: each [`Device::play`] opens the input (the
//! accelerometer, one channel recorded) and then the output (the actuator, the excitation
//! on one channel, the others silent), plays silence for [`LoopConfig::lead_in`], then the
//! excitation, records `excitation.len()` samples plus [`LoopConfig::tail`], and stops both
//! streams (the lead-in is also the time to patch ports, on JACK). Nothing on the audio threads locks or allocates: the output reads the
//! excitation from a shared slice at its own position, the input pushes the recorded
//! channel into an `rtrb` ring, and the calling thread drains the ring every few ms.
//!
//! The recording is aligned to playback by a count: the input counts the frames it has
//! delivered, and the output's first callback of the excitation reads that count. The
//! recording starts at that input frame, so it lags playback by the path's latency (output
//! plus input buffering and converters), about a buffer plus the hardware latency, which
//! the sweep's window absorbs (it keeps 50 ms before time zero and 250 ms after). Within
//! one JACK graph with the output patched to the input, the lag is zero: the output client
//! runs before the input client in the same cycle.
//!
//! Failures are [`CompensationError::Device`] with the reason: a stream that cannot be
//! opened (no such device, a rate the device or the JACK server does not run at, whose
//! message lists what it offers), an input and output at different rates, a stream the
//! host reports errors on, no input within the lead-in plus [`LOOP_TIMEOUT_MARGIN`], or a
//! recording not complete within the excitation's length plus the tail plus that margin.
//! An xrun while recording leaves a gap that shifts the rest of the recording, so such a
//! recording is thrown away and the excitation played again in the same streams, up to
//! [`LoopConfig::attempts`] times; when every attempt had xruns, that is the error.
//! [`AudioLoop::last_report`] says how many attempts it took.
//!
//! # What it measured
//!
//! The audio thread records into atomics (no locks), read by [`AudioOutput::stats`]:
//! callbacks, frames, the largest buffer, late callbacks (more than 1.5 buffer durations
//! after the previous one, on the host's clock), host errors, and the output latency:
//! the host's playback instant minus its callback instant, as the median of the last
//! [`LATENCY_WINDOW`] callbacks.
//!
//! # JACK
//!
//! cpal's JACK host does not start a server: one must be running before [`list_devices`]
//! or [`AudioOutput::start`] (otherwise there is no output device). The rate and buffer
//! size are the server's; a request for anything else is refused with the server's
//! values. Without a sound card, the dummy back-end is paced like a device
//! (`.ci/audio-setup` starts it):
//!
//! ```text
//! jackd --realtime -d dummy -r 48000 -p 64 &       # where SCHED_FIFO is allowed
//! jackd --no-realtime -d dummy -r 48000 -p 64 &    # otherwise
//! ```
//!
//! Real-time scheduling decides whether the pace holds on a busy machine: on 2 cores with
//! four busy processes, a `--no-realtime` server delivered 0.85x real time with ~80 xruns
//! a second, a `--realtime` one 1.00x with one or two. Root in this project's container may use
//! it; `chrt -f 10 true` tells. The dummy back-end reserves no sound card, so `JACK_NO_AUDIO_RESERVATION` is not
//! needed. Xruns are counted in [`StreamStats::xruns`], apart from real errors.

use std::fmt;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use cpal::traits::{DeviceTrait, HostTrait, StreamTrait};
use cpal::{
    BufferSize, FromSample, InputCallbackInfo, OutputCallbackInfo, SizedSample, StreamConfig,
    StreamInstant, SupportedBufferSize, SupportedStreamConfigRange,
};

use super::IoError;
use crate::compensation::CompensationError;
use crate::compensation::sweep::Device;
use crate::safety::{Limiter, LimiterReport};
use crate::units::{Decibels, SampleRate, Seconds};

/// The device's sample format, as cpal names it.
pub use cpal::SampleFormat;

/// The largest scratch buffer, in frames, allocated for a non-float device whose buffer
/// size was not requested. Bigger device buffers are rendered in chunks of this size.
pub const MAX_SCRATCH_FRAMES: u32 = 8192;

/// How many recent callbacks the latency median is taken over.
pub const LATENCY_WINDOW: usize = 64;

/// How often (in callbacks) the latency median is recomputed once the window is full.
const LATENCY_PUBLISH_EVERY: u64 = 16;

/// How long to wait for a host to build a stream. JACK builds on a helper thread and
/// gives up after this; ALSA uses it as its poll timeout to notice a stalled device.
const BUILD_TIMEOUT: Duration = Duration::from_secs(5);

/// Rates listed by [`list_devices`] when a device offers a continuous range.
const STANDARD_RATES: [u32; 11] = [
    8_000, 11_025, 16_000, 22_050, 32_000, 44_100, 48_000, 88_200, 96_000, 176_400, 192_000,
];

/// Which cpal host (audio system) to use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum AudioHost {
    /// The platform's default host (ALSA on Linux).
    #[default]
    Default,
    /// ALSA, Linux's kernel audio interface.
    Alsa,
    /// A running JACK server.
    #[cfg(feature = "jack")]
    Jack,
}

impl fmt::Display for AudioHost {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Default => "default",
            Self::Alsa => "ALSA",
            #[cfg(feature = "jack")]
            Self::Jack => "JACK",
        })
    }
}

impl FromStr for AudioHost {
    type Err = IoError;

    /// Parses `default`, `alsa` or `jack` (any case), for a `--host` flag.
    fn from_str(s: &str) -> Result<Self, IoError> {
        match s.to_ascii_lowercase().as_str() {
            "default" => Ok(Self::Default),
            "alsa" => Ok(Self::Alsa),
            #[cfg(feature = "jack")]
            "jack" => Ok(Self::Jack),
            #[cfg(not(feature = "jack"))]
            "jack" => Err(IoError::Unsupported {
                device: s.to_string(),
                reason: "this build has no JACK support (cargo feature `jack`)".into(),
            }),
            _ => Err(IoError::Unsupported {
                device: s.to_string(),
                reason: "unknown audio host; expected default, alsa or jack".into(),
            }),
        }
    }
}

/// What to open: host, device and stream format.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AudioConfig {
    /// The audio system.
    pub host: AudioHost,
    /// The device: an id, a description or a part of either (`"hw:1"`, `"null"`,
    /// `"default"`); `None` for the host's default output.
    pub device: Option<String>,
    /// Interleaved output channels.
    pub channels: u16,
    /// Sample rate; the device must support it (nothing is resampled here).
    pub rate: SampleRate,
    /// Frames per callback; `None` for the host's default.
    pub buffer_frames: Option<u32>,
}

impl Default for AudioConfig {
    /// Stereo at 48 kHz on the default device, default buffer size.
    fn default() -> Self {
        Self {
            host: AudioHost::Default,
            device: None,
            channels: 2,
            rate: SampleRate(48_000),
            buffer_frames: None,
        }
    }
}

/// One output device, for `--list-devices`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceInfo {
    /// The id to pass as [`AudioConfig::device`] (`"hw:CARD=0,DEV=0"`, `"null"`).
    pub name: String,
    /// What the host calls it (`"HDA Intel PCH, ALC892 Analog"`).
    pub description: String,
    /// The most output channels of any configuration.
    pub max_channels: u16,
    /// Rates it accepts: the standard rates inside its ranges, and any single-rate
    /// configuration (a JACK server's rate).
    pub rates: Vec<SampleRate>,
    /// Smallest and largest buffer in frames, if the host says.
    pub buffer_frames: Option<(u32, u32)>,
    /// Sample formats it offers.
    pub formats: Vec<SampleFormat>,
    /// Why its configurations could not be read (busy, no permission); the other fields
    /// are then empty.
    pub problem: Option<String>,
}

/// What a started stream got.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StreamInfo {
    /// The host that was used (never [`AudioHost::Default`]).
    pub host: AudioHost,
    /// The device id.
    pub device: String,
    /// Sample rate.
    pub rate: SampleRate,
    /// Interleaved channels, as passed to the render callback.
    pub channels: u16,
    /// Frames per callback as reported by the host, else as requested; `None` if neither.
    pub buffer_frames: Option<u32>,
    /// The device's sample format; anything but `F32` is converted from `f32`.
    pub sample_format: SampleFormat,
}

/// What the audio thread has seen so far.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StreamStats {
    /// Callbacks from the device.
    pub callbacks: u64,
    /// Frames rendered.
    pub frames: u64,
    /// The largest callback, in frames.
    pub max_callback_frames: u64,
    /// Host playback instant minus callback instant: the median over the last
    /// [`LATENCY_WINDOW`] callbacks, `None` until the host has given a usable timestamp.
    pub output_latency: Option<Seconds>,
    /// Callbacks that came more than 1.5 buffer durations after the previous one.
    pub late_callbacks: u64,
    /// Errors reported by the host other than xruns (device lost, backend errors).
    pub stream_errors: u64,
    /// Buffer under- or overruns reported by the host.
    pub xruns: u64,
}

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
            build_stream(device, chosen, shared, render)
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
    /// an output's (module documentation), among the host's input devices.
    ///
    /// # Errors
    /// As [`AudioOutput::start`].
    pub fn start(
        config: &AudioConfig,
        on_input: impl FnMut(&[f32], usize) + Send + 'static,
    ) -> Result<Self, IoError> {
        Running::start(config, Direction::Input, |device, chosen, shared| {
            build_input_stream(device, chosen, shared, on_input)
        })
        .map(Self)
    }

    /// What was opened.
    #[must_use]
    pub fn info(&self) -> &StreamInfo {
        &self.0.info
    }

    /// Counts so far, read without disturbing the audio thread. For an input,
    /// [`StreamStats::output_latency`] holds the capture latency: the callback instant
    /// minus the host's capture instant.
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

/// How long a loop waits for the first input beyond its lead-in, and for the rest of the
/// recording beyond the excitation and tail, before it gives up.
pub const LOOP_TIMEOUT_MARGIN: Seconds = Seconds(2.0);

/// How often the calling thread drains the recording while an [`AudioLoop`] runs.
const LOOP_POLL: Duration = Duration::from_millis(5);

/// [`LoopShared::start_frame`] before the excitation has started.
const NOT_STARTED: u64 = u64::MAX;

/// Settings of an [`AudioLoop`]: which output drives the actuator and which input reads
/// the accelerometer.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopConfig {
    /// The output stream; the excitation goes to `out_channel`, the others stay silent.
    pub output: AudioConfig,
    /// The output channel that drives the actuator (from 0).
    pub out_channel: u16,
    /// The input stream; only `in_channel` is recorded. Its rate must be the output's.
    pub input: AudioConfig,
    /// The input channel the accelerometer is on (from 0).
    pub in_channel: u16,
    /// Silence played after both streams run and before the excitation starts, for the
    /// devices (and any patching of ports) to settle.
    pub lead_in: Seconds,
    /// Recorded after the end of the excitation, so that the device's decay is kept.
    pub tail: Seconds,
    /// Playbacks tried, in the same streams, before giving up on recordings with xruns
    /// (an xrun leaves a gap that shifts the rest of the recording).
    pub attempts: u32,
    /// The ceiling of the hard limiter the excitation passes last, with the non-finite
    /// guard, as every output does ([`crate::safety`]; default 0 dB, full scale, which a
    /// valid sweep never reaches, so a measurement is untouched).
    pub ceiling: Decibels,
}

impl LoopConfig {
    /// Channel 0 of `output` to channel 0 of `input`, a 0.2 s lead-in, a 0.5 s tail and up
    /// to 3 attempts.
    #[must_use]
    pub fn new(output: AudioConfig, input: AudioConfig) -> Self {
        Self {
            output,
            out_channel: 0,
            input,
            in_channel: 0,
            lead_in: Seconds(0.2),
            tail: Seconds(0.5),
            attempts: 3,
            ceiling: Decibels(0.0),
        }
    }
}

/// What the last [`AudioLoop`] measurement ran on and saw.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopReport {
    /// The output stream.
    pub output: StreamInfo,
    /// The input stream.
    pub input: StreamInfo,
    /// The output's counts when it was stopped.
    pub output_stats: StreamStats,
    /// The input's counts when it was stopped.
    pub input_stats: StreamStats,
    /// Input frames captured before the output callback that began the excitation: the
    /// recording starts at this input frame.
    pub start_frame: u64,
    /// Frames returned (the excitation plus the tail).
    pub recorded_frames: usize,
    /// Playbacks it took to get one without xruns.
    pub attempts: u32,
}

/// Lock-free state shared by the two audio threads and the calling thread.
struct LoopShared {
    /// Raised by the calling thread to start an attempt (0 before the first): the output
    /// starts the excitation from its beginning at its next callback.
    attempt: AtomicU32,
    /// The input frame count the output read when it began the current attempt.
    start_frame: AtomicU64,
    /// Input frames delivered so far; counted before they are pushed, so that any frame
    /// the calling thread has popped lies below every later value.
    input_frames: AtomicU64,
    /// Input samples lost because the ring was full.
    dropped: AtomicU64,
    /// Excitation samples written to the output so far.
    played: AtomicUsize,
}

impl Default for LoopShared {
    fn default() -> Self {
        Self {
            attempt: AtomicU32::new(0),
            start_frame: AtomicU64::new(NOT_STARTED),
            input_frames: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            played: AtomicUsize::new(0),
        }
    }
}

/// A sweep [`Device`] made of a sound card's output (driving the actuator) and input
/// (reading the accelerometer): plays an excitation and records it, aligned to the start
/// of playback. See the module documentation.
#[derive(Debug)]
pub struct AudioLoop {
    cfg: LoopConfig,
    last: Option<LoopReport>,
}

impl AudioLoop {
    /// Checks the settings; nothing is opened until [`Device::play`].
    ///
    /// # Errors
    /// [`IoError::Unsupported`] when the input's rate differs from the output's, a channel
    /// lies outside its stream, the lead-in or tail is negative or not finite, or no
    /// attempt is allowed.
    pub fn new(cfg: LoopConfig) -> Result<Self, IoError> {
        let unsupported = |device: &AudioConfig, reason: String| IoError::Unsupported {
            device: device.device.clone().unwrap_or_else(|| "default".into()),
            reason,
        };
        if cfg.input.rate != cfg.output.rate {
            return Err(unsupported(
                &cfg.input,
                format!(
                    "the input runs at {} but the output at {}; a measurement needs one rate",
                    cfg.input.rate, cfg.output.rate
                ),
            ));
        }
        if cfg.out_channel >= cfg.output.channels {
            return Err(unsupported(
                &cfg.output,
                format!(
                    "output channel {} of a {} channel stream (channels count from 0)",
                    cfg.out_channel, cfg.output.channels
                ),
            ));
        }
        if cfg.in_channel >= cfg.input.channels {
            return Err(unsupported(
                &cfg.input,
                format!(
                    "input channel {} of a {} channel stream (channels count from 0)",
                    cfg.in_channel, cfg.input.channels
                ),
            ));
        }
        if cfg.attempts == 0 {
            return Err(unsupported(&cfg.output, "zero attempts".into()));
        }
        if !(cfg.ceiling.0.is_finite() && cfg.ceiling.0 <= 0.0) {
            return Err(unsupported(
                &cfg.output,
                format!(
                    "a ceiling of {}: need a finite level of at most 0 dB",
                    cfg.ceiling
                ),
            ));
        }
        for (name, t) in [("lead-in", cfg.lead_in), ("tail", cfg.tail)] {
            if !(t.0.is_finite() && t.0 >= 0.0) {
                return Err(unsupported(
                    &cfg.output,
                    format!("a {name} of {t}: need a finite duration of at least 0 s"),
                ));
            }
        }
        Ok(Self { cfg, last: None })
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &LoopConfig {
        &self.cfg
    }

    /// What the last successful measurement ran on, its start frame and its counts.
    #[must_use]
    pub fn last_report(&self) -> Option<&LoopReport> {
        self.last.as_ref()
    }

    /// Plays `excitation` and records, as [`Device::play`], with the reason of a failure
    /// as text.
    fn run(&mut self, excitation: &[f64]) -> Result<Vec<f64>, String> {
        let cfg = &self.cfg;
        let rate = cfg.output.rate;
        let needed = excitation.len() + rate.samples_in(cfg.tail);
        // Room for everything captured from the start of the input to the end of the
        // recording, so the ring cannot fill even if the calling thread stalls a while.
        let capacity =
            rate.samples_in(Seconds(cfg.lead_in.0 + 2.0 * LOOP_TIMEOUT_MARGIN.0)) + needed;

        let shared = Arc::new(LoopShared::default());
        let (mut producer, consumer) = rtrb::RingBuffer::<f32>::new(capacity);
        let in_channel = usize::from(cfg.in_channel);
        let input_side = Arc::clone(&shared);
        // The input starts first, so that it is counting frames before the output can
        // read the count.
        let input = AudioInput::start(&cfg.input, move |data: &[f32], channels: usize| {
            let frames = data.len() / channels;
            input_side
                .input_frames
                .fetch_add(frames as u64, Ordering::AcqRel);
            for frame in data.chunks_exact(channels) {
                let x = frame.get(in_channel).copied().unwrap_or(0.0);
                if producer.push(x).is_err() {
                    input_side.dropped.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
        .map_err(|e| format!("the input: {e}"))?;

        let program: Arc<[f32]> = excitation.iter().map(|&x| x as f32).collect();
        let out_channel = usize::from(cfg.out_channel);
        let output_side = Arc::clone(&shared);
        // Past the end until the first attempt: silence.
        let mut position = program.len();
        let mut seen_attempt = 0_u32;
        // The excitation leaves through the same last stage as the engine's output: the
        // non-finite guard and the ceiling (a sweep has no sensor input to watch; it ends
        // by itself, and the output is silence past it).
        let mut limiter = Limiter::new(cfg.ceiling, Seconds(0.05), rate);
        let mut report = LimiterReport::default();
        let output = AudioOutput::start(&cfg.output, move |out: &mut [f32], channels: usize| {
            out.fill(0.0);
            let attempt = output_side.attempt.load(Ordering::Acquire);
            if attempt != seen_attempt {
                seen_attempt = attempt;
                position = 0;
                let at = output_side.input_frames.load(Ordering::Acquire);
                output_side.start_frame.store(at, Ordering::Release);
            }
            for (frame, &x) in out
                .chunks_exact_mut(channels)
                .zip(program.get(position..).unwrap_or_default())
            {
                if let Some(sample) = frame.get_mut(out_channel) {
                    *sample = limiter.tick(x, &mut report);
                }
                position += 1;
            }
            output_side.played.store(position, Ordering::Release);
        })
        .map_err(|e| format!("the output: {e}"))?;

        let mut session = Session {
            shared: &shared,
            consumer,
            input: &input,
            output: &output,
            index: 0,
        };
        let result = session.measure(needed, cfg);
        let output_info = output.info().clone();
        let input_info = input.info().clone();
        let output_stats = output.stop();
        let input_stats = input.stop();
        let (recording, start_frame, attempts) = result?;
        self.last = Some(LoopReport {
            output: output_info,
            input: input_info,
            output_stats,
            input_stats,
            start_frame,
            recorded_frames: recording.len(),
            attempts,
        });
        Ok(recording)
    }
}

/// The calling thread's side of a running [`AudioLoop`].
struct Session<'a> {
    shared: &'a LoopShared,
    consumer: rtrb::Consumer<f32>,
    input: &'a AudioInput,
    output: &'a AudioOutput,
    /// The input frame the next popped sample is.
    index: u64,
}

impl Session<'_> {
    /// Waits for input, lets the lead-in pass, and records attempts until one has no
    /// xruns. Returns the recording, the input frame it starts at and the attempts made.
    fn measure(&mut self, needed: usize, cfg: &LoopConfig) -> Result<(Vec<f64>, u64, u32), String> {
        let lead_in = Duration::from_secs_f64(cfg.lead_in.0);
        let margin = Duration::from_secs_f64(LOOP_TIMEOUT_MARGIN.0);
        // Before the first attempt, everything popped lies before its start (see
        // `LoopShared::input_frames`), so it is dropped.
        let opened = Instant::now();
        loop {
            self.drain(None);
            self.check()?;
            let arrived = self.shared.input_frames.load(Ordering::Acquire) > 0;
            if arrived && opened.elapsed() >= lead_in {
                break;
            }
            if !arrived && opened.elapsed() >= lead_in + margin {
                return Err(format!(
                    "no input arrived from {} within {:.1} s of starting it",
                    describe(self.input.info()),
                    (lead_in + margin).as_secs_f64()
                ));
            }
            std::thread::sleep(LOOP_POLL);
        }

        let mut spoiled = Vec::new();
        for attempt in 1..=cfg.attempts {
            let xruns = || self.output.stats().xruns + self.input.stats().xruns;
            let before = xruns();
            let (recording, start) = self.attempt(attempt, needed, margin)?;
            let during = xruns() - before;
            if during == 0 {
                return Ok((recording, start, attempt));
            }
            spoiled.push(during.to_string());
        }
        Err(format!(
            "every attempt had xruns while recording ({} in the {} attempts), which leave \
             gaps in the recording; try a larger buffer or a less busy machine",
            spoiled.join(", "),
            cfg.attempts
        ))
    }

    /// One playback of the excitation: arms the output and collects `needed` frames from
    /// the input frame it started at.
    fn attempt(
        &mut self,
        attempt: u32,
        needed: usize,
        margin: Duration,
    ) -> Result<(Vec<f64>, u64), String> {
        let shared = self.shared;
        shared.start_frame.store(NOT_STARTED, Ordering::Release);
        shared.attempt.store(attempt, Ordering::Release);
        let armed = Instant::now();
        let rate = self.input.info().rate.hz();
        let deadline = Duration::from_secs_f64(needed as f64 / rate) + margin;
        // Frames popped from here on may lie at or after the start, which the output has
        // perhaps not published yet: all are kept until it has.
        let base = self.index;
        let mut captured: Vec<f32> = Vec::with_capacity(needed + self.consumer.slots());
        loop {
            self.drain(Some(&mut captured));
            self.check()?;
            let start = shared.start_frame.load(Ordering::Acquire);
            // Never below `base`: the output reads the count after it sees the attempt.
            let skip = usize::try_from(start.saturating_sub(base)).unwrap_or(usize::MAX);
            if start != NOT_STARTED && captured.len().saturating_sub(skip) >= needed {
                let recording = captured[skip..skip + needed]
                    .iter()
                    .map(|&x| f64::from(x))
                    .collect();
                return Ok((recording, start));
            }
            if armed.elapsed() >= deadline {
                let seconds = deadline.as_secs_f64();
                return Err(if start == NOT_STARTED {
                    format!(
                        "the output on {} never started the excitation within {seconds:.1} s \
                         (no callbacks from the host)",
                        describe(self.output.info())
                    )
                } else {
                    format!(
                        "input from {} stopped arriving: {} of {needed} samples recorded \
                         within {seconds:.1} s ({} excitation samples played)",
                        describe(self.input.info()),
                        captured.len().saturating_sub(skip),
                        shared.played.load(Ordering::Acquire),
                    )
                });
            }
            std::thread::sleep(LOOP_POLL);
        }
    }

    /// Pops everything the input has pushed, into `keep` if given.
    fn drain(&mut self, mut keep: Option<&mut Vec<f32>>) {
        while let Ok(x) = self.consumer.pop() {
            if let Some(keep) = keep.as_mut() {
                keep.push(x);
            }
            self.index += 1;
        }
    }

    /// A failed stream or lost input.
    fn check(&self) -> Result<(), String> {
        for (which, stream) in [
            ("output", (self.output.stats(), self.output.info())),
            ("input", (self.input.stats(), self.input.info())),
        ] {
            let (stats, info) = stream;
            if stats.stream_errors > 0 {
                return Err(format!(
                    "the {which} stream on {} failed ({} error(s) from the host)",
                    describe(info),
                    stats.stream_errors
                ));
            }
        }
        let dropped = self.shared.dropped.load(Ordering::Relaxed);
        if dropped > 0 {
            return Err(format!(
                "{dropped} input samples were lost (the recording was not drained in time)"
            ));
        }
        Ok(())
    }
}

fn describe(info: &StreamInfo) -> String {
    format!("{} device \"{}\"", info.host, info.device)
}

impl Device for AudioLoop {
    /// Opens both streams, plays `excitation` after the lead-in and returns the input
    /// from the output callback that began it, `excitation.len()` plus the tail long.
    /// Both streams are stopped before it returns, also on failure.
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        self.run(excitation)
            .map_err(|reason| CompensationError::Device { reason })
    }
}

/// Lists the output devices of `host` with what each offers.
///
/// A device whose configurations cannot be read (busy, no permission) is listed with
/// [`DeviceInfo::problem`] set rather than failing the whole list.
///
/// # Errors
/// [`IoError::Open`] if the host is unavailable or cannot enumerate its devices.
pub fn list_devices(host: AudioHost) -> Result<Vec<DeviceInfo>, IoError> {
    let (host, kind) = open_host(host)?;
    let devices = output_devices(&host).map_err(|e| IoError::Open {
        device: kind.to_string(),
        reason: format!("cannot list output devices: {e}"),
    })?;
    Ok(devices.iter().map(describe_device).collect())
}

/// The host's output devices. cpal's own filter keeps JACK's input device, whose
/// configurations it lists for both directions; its description knows better.
fn output_devices(host: &cpal::Host) -> Result<Vec<cpal::Device>, cpal::Error> {
    Ok(host.output_devices()?.filter(is_output).collect())
}

fn is_output(device: &cpal::Device) -> bool {
    device.supports_output()
        && !matches!(device.description(), Ok(d) if d.direction() == cpal::DeviceDirection::Input)
}

fn describe_device(device: &cpal::Device) -> DeviceInfo {
    let mut info = DeviceInfo {
        name: device_id(device),
        description: device_description(device),
        max_channels: 0,
        rates: Vec::new(),
        buffer_frames: None,
        formats: Vec::new(),
        problem: None,
    };
    let ranges: Vec<SupportedStreamConfigRange> = match device.supported_output_configs() {
        Ok(r) => r.filter(|r| !r.sample_format().is_dsd()).collect(),
        Err(e) => {
            info.problem = Some(e.to_string());
            return info;
        }
    };
    info.max_channels = ranges.iter().map(|r| r.channels()).max().unwrap_or(0);
    let mut rates: Vec<u32> = STANDARD_RATES
        .into_iter()
        .filter(|&rate| ranges.iter().any(|r| r.contains_rate(rate)))
        .chain(
            ranges
                .iter()
                .filter(|r| r.min_sample_rate() == r.max_sample_rate())
                .map(|r| r.min_sample_rate()),
        )
        .collect();
    rates.sort_unstable();
    rates.dedup();
    info.rates = rates.into_iter().map(SampleRate).collect();
    info.buffer_frames = ranges
        .iter()
        .filter_map(|r| match *r.buffer_size() {
            SupportedBufferSize::Range { min, max } => Some((min, max)),
            SupportedBufferSize::Unknown => None,
        })
        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)));
    for r in &ranges {
        if !info.formats.contains(&r.sample_format()) {
            info.formats.push(r.sample_format());
        }
    }
    info
}

/// Resolves the host; `Default` becomes the concrete host so that [`StreamInfo`] says
/// what was used.
fn open_host(kind: AudioHost) -> Result<(cpal::Host, AudioHost), IoError> {
    let (id, kind) = match kind {
        // cpal::default_host() panics when ALSA cannot be initialised; going through the
        // id gives an error instead. Without the pipewire/pulseaudio features (not
        // enabled here) ALSA is exactly what default_host() would pick on Linux.
        AudioHost::Default | AudioHost::Alsa => (alsa_host_id()?, AudioHost::Alsa),
        #[cfg(feature = "jack")]
        AudioHost::Jack => (cpal::HostId::Jack, AudioHost::Jack),
    };
    let host = cpal::host_from_id(id).map_err(|e| IoError::Open {
        device: kind.to_string(),
        reason: format!("audio host unavailable: {e}"),
    })?;
    Ok((host, kind))
}

fn alsa_host_id() -> Result<cpal::HostId, IoError> {
    cpal::HostId::from_str("alsa").map_err(|_| IoError::Open {
        device: AudioHost::Alsa.to_string(),
        reason: "ALSA is not available on this platform".into(),
    })
}

fn device_id(device: &cpal::Device) -> String {
    match device.id() {
        Ok(id) => id.id().to_string(),
        Err(_) => device_description(device),
    }
}

fn device_description(device: &cpal::Device) -> String {
    device
        .description()
        .map(|d| d.name().to_string())
        .unwrap_or_default()
}

/// Which way a stream carries audio; device matching and configuration take it so that
/// inputs and outputs are chosen by the same rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    Output,
    Input,
}

impl fmt::Display for Direction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Output => "output",
            Self::Input => "input",
        })
    }
}

/// The host's devices in `direction`.
fn devices_in(host: &cpal::Host, direction: Direction) -> Result<Vec<cpal::Device>, cpal::Error> {
    match direction {
        Direction::Output => output_devices(host),
        Direction::Input => Ok(host
            .input_devices()?
            .filter(|d| goes(d, Direction::Input))
            .collect()),
    }
}

/// Whether `device` carries audio in `direction`. cpal lists JACK's synthetic devices
/// under both directions; their description says which one each really is.
fn goes(device: &cpal::Device, direction: Direction) -> bool {
    match direction {
        Direction::Output => is_output(device),
        Direction::Input => {
            device.supports_input()
                && !matches!(device.description(), Ok(d) if d.direction() == cpal::DeviceDirection::Output)
        }
    }
}

fn default_device(host: &cpal::Host, direction: Direction) -> Option<cpal::Device> {
    match direction {
        Direction::Output => host.default_output_device(),
        Direction::Input => host.default_input_device(),
    }
}

fn find_device(
    host: &cpal::Host,
    kind: AudioHost,
    wanted: Option<&str>,
    direction: Direction,
) -> Result<cpal::Device, IoError> {
    let no_device = |reason: String| IoError::Open {
        device: match wanted {
            Some(w) => format!("{kind} device \"{w}\""),
            None => format!("{kind} default {direction} device"),
        },
        reason,
    };
    let server_hint = match kind {
        #[cfg(feature = "jack")]
        AudioHost::Jack => " (is a JACK server running? cpal does not start one)",
        _ => "",
    };
    let Some(wanted) = wanted else {
        return default_device(host, direction)
            .ok_or_else(|| no_device(format!("the host has no {direction} device{server_hint}")));
    };

    let devices = devices_in(host, direction)
        .map_err(|e| no_device(format!("cannot list {direction} devices: {e}")))?;
    let ids: Vec<String> = devices.iter().map(device_id).collect();
    let descriptions: Vec<String> = devices.iter().map(device_description).collect();

    if let Some(i) = ids.iter().position(|id| id == wanted) {
        return Ok(devices[i].clone());
    }
    // ALSA's "default" is not always among the enumerated devices, but always opens.
    if let Some(device) = default_device(host, direction)
        && device_id(&device) == wanted
    {
        return Ok(device);
    }
    // ALSA ids are canonicalised by the host ("hw:1" -> "hw:CARD=1,DEV=0").
    if let Some(device) = host.device_by_id(&cpal::DeviceId::new(host.id(), wanted))
        && goes(&device, direction)
    {
        return Ok(device);
    }
    if let Some(i) = descriptions
        .iter()
        .position(|d| d.eq_ignore_ascii_case(wanted))
    {
        return Ok(devices[i].clone());
    }
    let needle = wanted.to_lowercase();
    if let Some(i) = (0..devices.len()).find(|&i| {
        ids[i].to_lowercase().contains(&needle) || descriptions[i].to_lowercase().contains(&needle)
    }) {
        return Ok(devices[i].clone());
    }
    let available = if ids.is_empty() {
        format!("the host has no {direction} device{server_hint}")
    } else {
        format!("no such {direction} device; available: {}", ids.join(", "))
    };
    Err(no_device(available))
}

/// A device found and configured for one direction, not yet streaming.
struct Opened {
    device: cpal::Device,
    host_kind: AudioHost,
    name: String,
    label: String,
    chosen: Chosen,
}

fn open_device(config: &AudioConfig, direction: Direction) -> Result<Opened, IoError> {
    let (host, host_kind) = open_host(config.host)?;
    let device = find_device(&host, host_kind, config.device.as_deref(), direction)?;
    let name = device_id(&device);
    let label = format!("{host_kind} device \"{name}\"");
    let chosen = choose_config(&device, &label, config, direction)?;
    Ok(Opened {
        device,
        host_kind,
        name,
        label,
        chosen,
    })
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

/// The configuration picked for a device.
struct Chosen {
    stream: StreamConfig,
    format: SampleFormat,
    /// Frames of `f32` scratch for converting formats.
    scratch_frames: usize,
}

fn choose_config(
    device: &cpal::Device,
    label: &str,
    config: &AudioConfig,
    direction: Direction,
) -> Result<Chosen, IoError> {
    let unsupported = |reason: String| IoError::Unsupported {
        device: label.to_string(),
        reason,
    };
    if config.channels == 0 {
        return Err(unsupported("zero channels requested".into()));
    }
    if config.rate.0 == 0 {
        return Err(unsupported("a sample rate of 0 Hz requested".into()));
    }
    if config.buffer_frames == Some(0) {
        return Err(unsupported("a buffer of 0 frames requested".into()));
    }

    let cannot_read = |e: cpal::Error| IoError::Open {
        device: label.to_string(),
        reason: format!("cannot read its {direction} configurations: {e}"),
    };
    let ranges: Vec<SupportedStreamConfigRange> = match direction {
        Direction::Output => device
            .supported_output_configs()
            .map_err(cannot_read)?
            .collect(),
        Direction::Input => device
            .supported_input_configs()
            .map_err(cannot_read)?
            .collect(),
    };
    let ranges: Vec<SupportedStreamConfigRange> = ranges
        .into_iter()
        .filter(|r| format_rank(r.sample_format()).is_some())
        .collect();
    if ranges.is_empty() {
        return Err(unsupported(format!(
            "it offers no PCM {direction} configuration"
        )));
    }

    let with_channels: Vec<&SupportedStreamConfigRange> = ranges
        .iter()
        .filter(|r| r.channels() == config.channels)
        .collect();
    if with_channels.is_empty() {
        let offered: Vec<u32> = ranges.iter().map(|r| u32::from(r.channels())).collect();
        return Err(unsupported(format!(
            "{} channels not supported; it offers {} channels",
            config.channels,
            spans(offered)
        )));
    }
    let with_rate: Vec<&SupportedStreamConfigRange> = with_channels
        .iter()
        .copied()
        .filter(|r| r.contains_rate(config.rate.0))
        .collect();
    if with_rate.is_empty() {
        return Err(unsupported(format!(
            "{} not supported with {} channels; it offers {}",
            config.rate,
            config.channels,
            rate_spans(&with_channels)
        )));
    }
    let fits_buffer =
        |r: &&SupportedStreamConfigRange| match (config.buffer_frames, r.buffer_size()) {
            (None, _) | (Some(_), SupportedBufferSize::Unknown) => true,
            (Some(n), &SupportedBufferSize::Range { min, max }) => (min..=max).contains(&n),
        };
    let Some(best) = with_rate
        .iter()
        .copied()
        .filter(fits_buffer)
        .min_by_key(|r| format_rank(r.sample_format()))
    else {
        let offered: Vec<String> = with_rate
            .iter()
            .filter_map(|r| match *r.buffer_size() {
                SupportedBufferSize::Range { min, max } if min == max => Some(format!("{min}")),
                SupportedBufferSize::Range { min, max } => Some(format!("{min}-{max}")),
                SupportedBufferSize::Unknown => None,
            })
            .collect();
        return Err(unsupported(format!(
            "a buffer of {} frames not supported at {} with {} channels; it offers {} frames",
            config.buffer_frames.unwrap_or(0),
            config.rate,
            config.channels,
            dedup_join(offered)
        )));
    };

    let buffer_size = match config.buffer_frames {
        Some(n) => BufferSize::Fixed(n),
        None => BufferSize::Default,
    };
    let scratch_frames = match (config.buffer_frames, best.buffer_size()) {
        (Some(n), _) => n,
        (None, &SupportedBufferSize::Range { max, .. }) => max.min(MAX_SCRATCH_FRAMES),
        (None, SupportedBufferSize::Unknown) => MAX_SCRATCH_FRAMES,
    };
    Ok(Chosen {
        stream: StreamConfig {
            channels: config.channels,
            sample_rate: config.rate.0,
            buffer_size,
        },
        format: best.sample_format(),
        scratch_frames: usize::try_from(scratch_frames.max(1)).unwrap_or(1),
    })
}

/// Preference among PCM formats, best first; `None` for formats that cannot carry PCM.
fn format_rank(format: SampleFormat) -> Option<u8> {
    use SampleFormat as F;
    let rank = match format {
        F::F32 => 0,
        F::F64 => 1,
        F::I32 => 2,
        F::U32 => 3,
        F::I24 => 4,
        F::U24 => 5,
        F::I16 => 6,
        F::U16 => 7,
        F::I64 => 8,
        F::U64 => 9,
        F::I8 => 10,
        F::U8 => 11,
        _ => return None,
    };
    Some(rank)
}

/// `[1, 2, 3, 6]` -> `"1-3, 6"`.
fn spans(mut values: Vec<u32>) -> String {
    values.sort_unstable();
    values.dedup();
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < values.len() {
        let mut j = i;
        while j + 1 < values.len() && values[j + 1] == values[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            values[i].to_string()
        } else {
            format!("{}-{}", values[i], values[j])
        });
        i = j + 1;
    }
    out.join(", ")
}

fn rate_spans(ranges: &[&SupportedStreamConfigRange]) -> String {
    let items: Vec<String> = ranges
        .iter()
        .map(|r| {
            let (lo, hi) = (r.min_sample_rate(), r.max_sample_rate());
            if lo == hi {
                format!("{lo} Hz")
            } else {
                format!("{lo}-{hi} Hz")
            }
        })
        .collect();
    dedup_join(items)
}

fn dedup_join(mut items: Vec<String>) -> String {
    items.sort();
    items.dedup();
    if items.is_empty() {
        "no size the host will say".into()
    } else {
        items.join(", ")
    }
}

fn build_stream(
    device: &cpal::Device,
    chosen: &Chosen,
    shared: Arc<Shared>,
    render: impl FnMut(&mut [f32], usize) + Send + 'static,
) -> Result<cpal::Stream, cpal::Error> {
    use SampleFormat as F;
    let args = (device, chosen, shared, render);
    match chosen.format {
        F::F32 => build_f32(args),
        F::F64 => build_converted::<f64, _>(args),
        F::I32 => build_converted::<i32, _>(args),
        F::U32 => build_converted::<u32, _>(args),
        F::I24 => build_converted::<cpal::I24, _>(args),
        F::U24 => build_converted::<cpal::U24, _>(args),
        F::I16 => build_converted::<i16, _>(args),
        F::U16 => build_converted::<u16, _>(args),
        F::I64 => build_converted::<i64, _>(args),
        F::U64 => build_converted::<u64, _>(args),
        F::I8 => build_converted::<i8, _>(args),
        F::U8 => build_converted::<u8, _>(args),
        // choose_config only picks formats that format_rank accepts.
        other => Err(cpal::Error::with_message(
            cpal::ErrorKind::UnsupportedConfig,
            format!("sample format {other} cannot carry PCM"),
        )),
    }
}

type BuildArgs<'a, R> = (&'a cpal::Device, &'a Chosen, Arc<Shared>, R);

fn error_counter(shared: Arc<Shared>) -> impl FnMut(cpal::Error) + Send + 'static {
    move |e: cpal::Error| {
        let counter = if e.kind() == cpal::ErrorKind::Xrun {
            &shared.xruns
        } else {
            &shared.stream_errors
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

fn build_f32<R>(
    (device, chosen, shared, mut render): BuildArgs<'_, R>,
) -> Result<cpal::Stream, cpal::Error>
where
    R: FnMut(&mut [f32], usize) + Send + 'static,
{
    let channels = usize::from(chosen.stream.channels);
    let mut meter = Meter::new(Arc::clone(&shared), chosen.stream.sample_rate);
    device.build_output_stream(
        chosen.stream,
        move |data: &mut [f32], info: &OutputCallbackInfo| {
            meter.record(data.len() / channels, info);
            render(data, channels);
        },
        error_counter(shared),
        Some(BUILD_TIMEOUT),
    )
}

fn build_converted<T, R>(
    (device, chosen, shared, mut render): BuildArgs<'_, R>,
) -> Result<cpal::Stream, cpal::Error>
where
    T: SizedSample + FromSample<f32> + Send + 'static,
    R: FnMut(&mut [f32], usize) + Send + 'static,
{
    let channels = usize::from(chosen.stream.channels);
    let mut scratch = vec![0.0_f32; chosen.scratch_frames * channels];
    let mut meter = Meter::new(Arc::clone(&shared), chosen.stream.sample_rate);
    device.build_output_stream(
        chosen.stream,
        move |data: &mut [T], info: &OutputCallbackInfo| {
            meter.record(data.len() / channels, info);
            render_converted(data, &mut scratch, channels, &mut render);
        },
        error_counter(shared),
        Some(BUILD_TIMEOUT),
    )
}

/// Renders `out` through the `f32` scratch buffer, in whole-frame chunks when `out` is
/// larger than the scratch. `scratch.len()` is a non-zero multiple of `channels`.
fn render_converted<T, R>(out: &mut [T], scratch: &mut [f32], channels: usize, render: &mut R)
where
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

fn build_input_stream(
    device: &cpal::Device,
    chosen: &Chosen,
    shared: Arc<Shared>,
    on_input: impl FnMut(&[f32], usize) + Send + 'static,
) -> Result<cpal::Stream, cpal::Error> {
    use SampleFormat as F;
    let args = (device, chosen, shared, on_input);
    match chosen.format {
        F::F32 => build_input_f32(args),
        F::F64 => build_input_converted::<f64, _>(args),
        F::I32 => build_input_converted::<i32, _>(args),
        F::U32 => build_input_converted::<u32, _>(args),
        F::I24 => build_input_converted::<cpal::I24, _>(args),
        F::U24 => build_input_converted::<cpal::U24, _>(args),
        F::I16 => build_input_converted::<i16, _>(args),
        F::U16 => build_input_converted::<u16, _>(args),
        F::I64 => build_input_converted::<i64, _>(args),
        F::U64 => build_input_converted::<u64, _>(args),
        F::I8 => build_input_converted::<i8, _>(args),
        F::U8 => build_input_converted::<u8, _>(args),
        other => Err(cpal::Error::with_message(
            cpal::ErrorKind::UnsupportedConfig,
            format!("sample format {other} cannot carry PCM"),
        )),
    }
}

fn build_input_f32<R>(
    (device, chosen, shared, mut on_input): BuildArgs<'_, R>,
) -> Result<cpal::Stream, cpal::Error>
where
    R: FnMut(&[f32], usize) + Send + 'static,
{
    let channels = usize::from(chosen.stream.channels);
    let mut meter = Meter::new(Arc::clone(&shared), chosen.stream.sample_rate);
    device.build_input_stream(
        chosen.stream,
        move |data: &[f32], info: &InputCallbackInfo| {
            meter.record_input(data.len() / channels, info);
            on_input(data, channels);
        },
        error_counter(shared),
        Some(BUILD_TIMEOUT),
    )
}

fn build_input_converted<T, R>(
    (device, chosen, shared, mut on_input): BuildArgs<'_, R>,
) -> Result<cpal::Stream, cpal::Error>
where
    T: SizedSample + Send + 'static,
    f32: FromSample<T>,
    R: FnMut(&[f32], usize) + Send + 'static,
{
    let channels = usize::from(chosen.stream.channels);
    let mut scratch = vec![0.0_f32; chosen.scratch_frames * channels];
    let mut meter = Meter::new(Arc::clone(&shared), chosen.stream.sample_rate);
    device.build_input_stream(
        chosen.stream,
        move |data: &[T], info: &InputCallbackInfo| {
            meter.record_input(data.len() / channels, info);
            deliver_converted(data, &mut scratch, channels, &mut on_input);
        },
        error_counter(shared),
        Some(BUILD_TIMEOUT),
    )
}

/// Converts `captured` to `f32` through the scratch buffer and delivers it, in
/// whole-frame chunks when it is larger than the scratch (no allocation on the audio
/// thread). `scratch.len()` is a non-zero multiple of `channels`.
fn deliver_converted<T, R>(captured: &[T], scratch: &mut [f32], channels: usize, on_input: &mut R)
where
    T: SizedSample,
    f32: FromSample<T>,
    R: FnMut(&[f32], usize),
{
    for block in captured.chunks(scratch.len()) {
        let samples = &mut scratch[..block.len()];
        for (s, &x) in samples.iter_mut().zip(block) {
            *s = <f32 as cpal::Sample>::from_sample(x);
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
fn to_device<T: SizedSample + FromSample<f32>>(x: f32) -> T {
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

/// Counters shared between the audio thread and [`AudioOutput`].
struct Shared {
    callbacks: AtomicU64,
    frames: AtomicU64,
    max_callback_frames: AtomicU64,
    latency_nanos: AtomicU64,
    late_callbacks: AtomicU64,
    stream_errors: AtomicU64,
    xruns: AtomicU64,
}

/// `latency_nanos` before the host has given a usable timestamp.
const NO_LATENCY: u64 = u64::MAX;

impl Default for Shared {
    fn default() -> Self {
        Self {
            callbacks: AtomicU64::new(0),
            frames: AtomicU64::new(0),
            max_callback_frames: AtomicU64::new(0),
            latency_nanos: AtomicU64::new(NO_LATENCY),
            late_callbacks: AtomicU64::new(0),
            stream_errors: AtomicU64::new(0),
            xruns: AtomicU64::new(0),
        }
    }
}

impl Shared {
    fn snapshot(&self) -> StreamStats {
        let latency = self.latency_nanos.load(Ordering::Relaxed);
        StreamStats {
            callbacks: self.callbacks.load(Ordering::Relaxed),
            frames: self.frames.load(Ordering::Relaxed),
            max_callback_frames: self.max_callback_frames.load(Ordering::Relaxed),
            output_latency: (latency != NO_LATENCY).then_some(Seconds(latency as f64 * 1e-9)),
            late_callbacks: self.late_callbacks.load(Ordering::Relaxed),
            stream_errors: self.stream_errors.load(Ordering::Relaxed),
            xruns: self.xruns.load(Ordering::Relaxed),
        }
    }
}

/// The audio thread's side of [`Shared`]: timing state that only it touches, so it
/// needs no synchronisation, plus fixed arrays for the latency median.
struct Meter {
    shared: Arc<Shared>,
    rate: f64,
    previous: Option<(StreamInstant, usize)>,
    latencies: [u64; LATENCY_WINDOW],
    sorted: [u64; LATENCY_WINDOW],
    filled: usize,
    next: usize,
    measured: u64,
}

impl Meter {
    fn new(shared: Arc<Shared>, rate: u32) -> Self {
        Self {
            shared,
            rate: f64::from(rate),
            previous: None,
            latencies: [0; LATENCY_WINDOW],
            sorted: [0; LATENCY_WINDOW],
            filled: 0,
            next: 0,
            measured: 0,
        }
    }

    fn record(&mut self, frames: usize, info: &OutputCallbackInfo) {
        let timestamp = info.timestamp();
        // A host without a playback estimate gives an instant before the callback.
        let latency = timestamp
            .playback
            .checked_duration_since(timestamp.callback);
        self.record_at(frames, timestamp.callback, latency);
    }

    fn record_input(&mut self, frames: usize, info: &InputCallbackInfo) {
        let timestamp = info.timestamp();
        let latency = timestamp.callback.checked_duration_since(timestamp.capture);
        self.record_at(frames, timestamp.callback, latency);
    }

    fn record_at(&mut self, frames: usize, callback: StreamInstant, latency: Option<Duration>) {
        let s = &self.shared;
        let frames_u64 = frames as u64;
        s.callbacks.fetch_add(1, Ordering::Relaxed);
        s.frames.fetch_add(frames_u64, Ordering::Relaxed);
        s.max_callback_frames
            .fetch_max(frames_u64, Ordering::Relaxed);

        if let Some((instant, previous_frames)) = self.previous
            && let Some(interval) = callback.checked_duration_since(instant)
        {
            let budget = previous_frames as f64 / self.rate;
            if interval.as_secs_f64() > 1.5 * budget {
                s.late_callbacks.fetch_add(1, Ordering::Relaxed);
            }
        }
        self.previous = Some((callback, frames));

        if let Some(latency) = latency {
            self.push_latency(u64::try_from(latency.as_nanos()).unwrap_or(NO_LATENCY - 1));
        }
    }

    fn push_latency(&mut self, nanos: u64) {
        self.latencies[self.next] = nanos;
        self.next = (self.next + 1) % LATENCY_WINDOW;
        self.filled = (self.filled + 1).min(LATENCY_WINDOW);
        self.measured += 1;
        // Sorting 64 numbers is cheap, but there is no need to do it every callback once
        // the window is full; early on it is done every time so that short runs report.
        if self.filled < LATENCY_WINDOW || self.measured % LATENCY_PUBLISH_EVERY == 0 {
            let window = &mut self.sorted[..self.filled];
            window.copy_from_slice(&self.latencies[..self.filled]);
            window.sort_unstable();
            let median = window[window.len() / 2];
            self.shared
                .latency_nanos
                .store(median.min(NO_LATENCY - 1), Ordering::Relaxed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use cpal::OutputStreamTimestamp;

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
        let ceiling = crate::units::Decibels(-6.0).to_amplitude() as f32;
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
        let latency = stats.output_latency.expect("latency");
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
        let latency = shared.snapshot().output_latency.expect("latency");
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
}
