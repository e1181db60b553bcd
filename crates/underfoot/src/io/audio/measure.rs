//! Measuring through the sound card: [`AudioLoop`], a sweep [`Device`] made of an
//! output that drives the actuator and an input that reads the accelerometer.
//!
//! Each [`Device::play`] opens the input (the accelerometer, one channel recorded) and
//! then the output (the actuator, the excitation on one channel, the others silent),
//! plays silence for [`LoopConfig::lead_in`], then the excitation, records
//! `excitation.len()` samples plus [`LoopConfig::tail`], and stops both streams (the
//! lead-in is also the time to patch ports, on JACK). Nothing on the audio threads locks
//! or allocates: the output reads the excitation from a shared slice at its own position,
//! the input pushes the recorded channel into an `rtrb` ring, and the calling thread
//! drains the ring every few ms.
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

use std::sync::Arc;
use std::sync::atomic::{AtomicU32, AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use super::{AudioConfig, AudioInput, AudioOutput, StreamInfo, StreamStats};
use crate::compensation::CompensationError;
use crate::compensation::sweep::Device;
use crate::io::IoError;
use crate::safety::{Limiter, LimiterReport};
use crate::units::{Decibels, Seconds};

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
                    "output channel {} of a {} channel stream (channels count from 1)",
                    u32::from(cfg.out_channel) + 1,
                    cfg.output.channels
                ),
            ));
        }
        if cfg.in_channel >= cfg.input.channels {
            return Err(unsupported(
                &cfg.input,
                format!(
                    "input channel {} of a {} channel stream (channels count from 1)",
                    u32::from(cfg.in_channel) + 1,
                    cfg.input.channels
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
