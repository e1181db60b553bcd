//! What the audio thread has seen, recorded without locks.
//!
//! The audio thread records into atomics, read by
//! [`AudioOutput::stats`](super::AudioOutput::stats) and
//! [`AudioInput::stats`](super::AudioInput::stats): callbacks, frames, the largest buffer,
//! late callbacks (more than 1.5 buffer durations after the previous one, on the host's
//! clock), host errors, xruns, and the latency: for an output, the host's playback instant
//! minus its callback instant; for an input, the callback instant minus the host's capture
//! instant; as the median of the last [`LATENCY_WINDOW`] callbacks.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use cpal::{InputCallbackInfo, OutputCallbackInfo, StreamInstant};

use crate::units::Seconds;

/// How many recent callbacks the latency median is taken over.
pub const LATENCY_WINDOW: usize = 64;

/// How often (in callbacks) the latency median is recomputed once the window is full.
const LATENCY_PUBLISH_EVERY: u64 = 16;

/// What the audio thread has seen so far.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StreamStats {
    /// Callbacks from the device.
    pub callbacks: u64,
    /// Frames rendered.
    pub frames: u64,
    /// The largest callback, in frames.
    pub max_callback_frames: u64,
    /// The stream's latency, the median over the last [`LATENCY_WINDOW`] callbacks: for
    /// an output, the host's playback instant minus the callback instant; for an input,
    /// the callback instant minus the host's capture instant. `None` until the host has
    /// given a usable timestamp.
    pub latency: Option<Seconds>,
    /// Callbacks that came more than 1.5 buffer durations after the previous one.
    pub late_callbacks: u64,
    /// Errors reported by the host other than xruns (device lost, backend errors).
    pub stream_errors: u64,
    /// Buffer under- or overruns reported by the host.
    pub xruns: u64,
}

/// Counters shared between the audio thread and the stream's owner.
pub(super) struct Shared {
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
    pub(super) fn snapshot(&self) -> StreamStats {
        let latency = self.latency_nanos.load(Ordering::Relaxed);
        StreamStats {
            callbacks: self.callbacks.load(Ordering::Relaxed),
            frames: self.frames.load(Ordering::Relaxed),
            max_callback_frames: self.max_callback_frames.load(Ordering::Relaxed),
            latency: (latency != NO_LATENCY).then_some(Seconds(latency as f64 * 1e-9)),
            late_callbacks: self.late_callbacks.load(Ordering::Relaxed),
            stream_errors: self.stream_errors.load(Ordering::Relaxed),
            xruns: self.xruns.load(Ordering::Relaxed),
        }
    }
}

/// The host's error callback: counts xruns apart from real errors.
pub(super) fn error_counter(shared: Arc<Shared>) -> impl FnMut(cpal::Error) + Send + 'static {
    move |e: cpal::Error| {
        let counter = if e.kind() == cpal::ErrorKind::Xrun {
            &shared.xruns
        } else {
            &shared.stream_errors
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// The audio thread's side of [`Shared`]: timing state that only it touches, so it
/// needs no synchronisation, plus fixed arrays for the latency median.
pub(super) struct Meter {
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
    pub(super) fn new(shared: Arc<Shared>, rate: u32) -> Self {
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

    pub(super) fn record(&mut self, frames: usize, info: &OutputCallbackInfo) {
        let timestamp = info.timestamp();
        // A host without a playback estimate gives an instant before the callback.
        let latency = timestamp
            .playback
            .checked_duration_since(timestamp.callback);
        self.record_at(frames, timestamp.callback, latency);
    }

    pub(super) fn record_input(&mut self, frames: usize, info: &InputCallbackInfo) {
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
        if self.filled < LATENCY_WINDOW || self.measured.is_multiple_of(LATENCY_PUBLISH_EVERY) {
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
