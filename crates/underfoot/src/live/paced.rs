//! The paced pseudo-device: the engine at real-time pace without a sound card.
//!
//! A `wav:` or `null` output has no device whose callback asks for buffers, so a thread
//! stands in for one: it renders one buffer of `block` frames per buffer period,
//! `block / rate` seconds, into a WAV file or nowhere. Like a device's, its frame clock
//! keeps time with the wall clock: after a wake-up that comes more than a buffer late,
//! the buffers it missed are rendered back to back instead of being dropped from the
//! timeline, so that frames keep wall-clock time. A stall of over a second (a suspended
//! process) restarts the clock instead, rather than render a burst of catch-up buffers.
//! Each late wake-up is counted.
//!
//! [`PacedDevice::render`] is the pseudo-device's callback: like a device's, it renders
//! into a buffer allocated once, at [`PacedDevice::new`], and never allocates, locks or
//! panics (`tests/realtime.rs` checks it). The WAV file, when there is one, is written
//! from the same thread, as [`WavSink`] allows (see [`crate::io::wav`], *Live
//! recordings*).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use crate::engine::Engine;
use crate::io::IoError;
use crate::io::wav::{WavSink, WavSummary};
use crate::units::SampleRate;

use super::record::OutputTap;

/// The engine, a buffer of one period, its clock, and where the buffers go.
pub struct PacedDevice {
    engine: Engine,
    sink: Option<WavSink>,
    /// A session record's copy of every buffer.
    record: Option<OutputTap>,
    channels: usize,
    buffer: Vec<f32>,
    period: Duration,
    /// When the next buffer is due.
    next: Instant,
    blocks: u64,
    late: u64,
    /// The same count, for other threads to read while the device runs.
    late_shared: Arc<AtomicU64>,
}

impl std::fmt::Debug for PacedDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PacedDevice")
            .field("sink", &self.sink)
            .field("channels", &self.channels)
            .field("period", &self.period)
            .field("blocks", &self.blocks)
            .field("late", &self.late)
            .finish_non_exhaustive()
    }
}

/// What a paced output did.
#[derive(Debug, Clone, PartialEq)]
pub struct PacedReport {
    /// Buffers rendered.
    pub blocks: u64,
    /// Wake-ups more than a buffer late.
    pub late: u64,
    /// The WAV file written, and what it holds; `None` for `null`.
    pub wav: Option<(PathBuf, WavSummary)>,
}

impl PacedDevice {
    /// A device of `channels` channels at `rate` that renders `block` frames (at least 1)
    /// per period into `sink`, or nowhere; its clock starts now, and again when
    /// [`run`](Self::run) starts.
    #[must_use]
    pub fn new(
        engine: Engine,
        sink: Option<WavSink>,
        channels: usize,
        rate: SampleRate,
        block: usize,
    ) -> Self {
        let block = block.max(1);
        Self {
            engine,
            sink,
            record: None,
            channels,
            buffer: vec![0.0; block * channels],
            period: Duration::from_secs_f64(block as f64 / rate.hz()),
            next: Instant::now(),
            blocks: 0,
            late: 0,
            late_shared: Arc::new(AtomicU64::new(0)),
        }
    }

    /// The device, with every buffer copied to a session's record too.
    #[must_use]
    pub fn with_record(mut self, tap: OutputTap) -> Self {
        self.record = Some(tap);
        self
    }

    /// The count of late wake-ups, readable from another thread while the device runs.
    #[must_use]
    pub fn late_counter(&self) -> Arc<AtomicU64> {
        Arc::clone(&self.late_shared)
    }

    fn count_late(&mut self) {
        self.late += 1;
        self.late_shared.fetch_add(1, Ordering::Relaxed);
    }

    /// Renders the next buffer into the sink, if any, and advances the clock by one
    /// period; returns how long to wait before the next buffer is due (zero when the
    /// device is behind and must catch up). Allocates nothing.
    ///
    /// # Errors
    /// Writing to the WAV file failed.
    pub fn render(&mut self) -> Result<Duration, IoError> {
        self.engine.process(&mut self.buffer, self.channels);
        if let Some(record) = &mut self.record {
            record.push(&self.buffer, self.channels);
        }
        if let Some(sink) = &mut self.sink {
            sink.write_interleaved(&self.buffer)?;
        }
        self.blocks += 1;
        self.next += self.period;
        let now = Instant::now();
        if self.next > now {
            return Ok(self.next - now);
        }
        let behind = now - self.next;
        if behind > Duration::from_secs(1) {
            // Stalled for over a second (a suspended process): start the clock afresh
            // rather than render a burst of catch-up buffers.
            self.count_late();
            self.next = now;
        } else if behind > self.period {
            // Behind by more than a buffer: render the missed ones back to back, as a
            // device's clock would have played them, so frames keep wall-clock time.
            self.count_late();
        }
        Ok(Duration::ZERO)
    }

    /// Renders one buffer per period until `stop` is set, then finishes the WAV file.
    ///
    /// # Errors
    /// Writing or finishing the WAV file failed.
    pub fn run(mut self, stop: &AtomicBool) -> Result<PacedReport, IoError> {
        self.next = Instant::now();
        while !stop.load(Ordering::SeqCst) {
            let wait = self.render()?;
            if !wait.is_zero() {
                thread::sleep(wait);
            }
        }
        self.finish()
    }

    /// Finishes the WAV file, if any, and says what was done.
    ///
    /// # Errors
    /// Finishing the WAV file failed.
    pub fn finish(self) -> Result<PacedReport, IoError> {
        let wav = match self.sink {
            Some(sink) => {
                let path = sink.path().to_path_buf();
                Some((path, sink.finish()?))
            }
            None => None,
        };
        Ok(PacedReport {
            blocks: self.blocks,
            late: self.late,
            wav,
        })
    }
}
