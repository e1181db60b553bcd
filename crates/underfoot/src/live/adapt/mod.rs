//! Online adaptation of the equalizer in a live session: the compensation paper's "adapt
//! the spectral weights while the user walks", from an accelerometer on an audio input.
//!
//! # The loop
//!
//! 1. The output's audio callback, after the engine has rendered (so after the
//!    equalizer, the limiter and every safety stage: the drive the actuator really got),
//!    copies the adapted channel's samples, each with the channel's force of that block
//!    ([`Telemetry::force`]), into a lock-free ring ([`DriveTap`]).
//! 2. An input stream's callback copies the accelerometer's channel into another ring.
//! 3. The session's thread, between polls of the force input, drains both rings
//!    ([`AdaptLoop::poll`]). The two streams count samples from their own starts and reach
//!    the session through different buffers: the sensor's sample `n + τ` is what the
//!    drive's sample `n` caused, for a lag `τ` that is the sum of both streams' buffering,
//!    their start-up offset and the plant's own delay. `τ` is estimated by the smoothed
//!    phase transform ([`crate::signal::delay`]) on windows of 2^16 samples (1.4 s at
//!    48 kHz) within ±[`AdaptSettings::max_delay`], and trusted when two windows in a row
//!    agree within [`LAG_TOLERANCE`] samples with a prominence of at least
//!    [`MIN_PROMINENCE`]. It is checked again every [`RECHECK`] seconds of drive; a
//!    stream that skipped samples (an xrun) moves it, and two agreeing estimates away
//!    from the old one re-align (counted in [`AdaptStatus::realignments`]).
//! 4. The aligned pairs go to the [`Adapter`] in blocks of [`BLOCK`] samples, each with
//!    the smallest force of its samples (a frame only counts when the foot was down for
//!    all of it). When the adapter moves the weights, they go to the engine through its
//!    command queue ([`Controller::set_equalizer_weights`]); the audio thread applies them
//!    from its next block and hands the copy back to be freed here.
//!
//! Nothing of this runs on the audio threads but the two ring writes: the callbacks never
//! allocate, lock or wait for it. A [`Session`](super::Session) with
//! [`SessionConfig::adapt`](super::SessionConfig::adapt) wires it all; an application with
//! its own audio callbacks wires the three parts of [`AdaptParts::new`] the same way.
//!
//! A ring that is full (the session's thread stalled for seconds) drops what does not
//! fit and counts it; the histories are then restarted and the lag estimated afresh,
//! since the sample counts no longer pair.
//!
//! The safety chain is the adapter's ([`crate::compensation::adapt`], *Safety chain*):
//! the weights keep a 0 dB mean, stay within the sweeps' boost and cut bounds, move by at
//! most 0.5 dB per update, and the limiter still has the last word.

// The taps are fed by audio streams: in a build without them only the tests drive the loop.
#![cfg_attr(not(feature = "audio"), allow(dead_code))]

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crate::compensation::adapt::{AdaptConfig, Adapter};
use crate::compensation::equalizer::{SpectralWeights, flatness};
use crate::compensation::sweep::FrequencyResponse;
use crate::engine::{Controller, Telemetry};
use crate::signal::delay::DelayEstimator;
use crate::units::{Decibels, Newtons, SampleRate, Seconds};

use super::LiveError;

/// Samples handed to the adapter at a time.
pub const BLOCK: usize = 256;
/// The delay estimator's window (2^16 samples: 1.4 s at 48 kHz, several steps' worth of
/// drive).
pub const WINDOW: usize = 1 << 16;
/// How close two delay estimates must be to agree, in samples.
pub const LAG_TOLERANCE: i64 = 8;
/// The least prominence of a delay estimate's peak ([`crate::signal::delay`]).
pub const MIN_PROMINENCE: f64 = 8.0;
/// Drive between checks of a locked delay.
pub const RECHECK: Seconds = Seconds(3.0);
/// Samples each ring holds: 2^18, 5.5 s at 48 kHz.
const RING: usize = 1 << 18;
/// The drive RMS below which a window says nothing about the delay (-70 dBFS): far above
/// silence, and under a walk at the materials' playback level (a walk on gravel, steps
/// peaking near -30 dBFS every 1.1 s, is -53 to -64 dBFS over a window).
const MIN_WINDOW_RMS: f64 = 3.2e-4;

/// Where the accelerometer is and how the adaptation runs.
#[derive(Debug, Clone, PartialEq)]
pub struct AdaptSettings {
    /// The engine channel whose equalizer adapts: its drive is analysed and its
    /// equalizer retuned.
    pub channel: u16,
    /// The input device the accelerometer is on; `None` takes the output's device (a
    /// sound card's inputs, or the JACK server's).
    pub device: Option<String>,
    /// The input channel (0-based) the accelerometer is on.
    pub input_channel: u16,
    /// How the adapter estimates the loaded device and moves the weights (by default
    /// [`AdaptConfig::default`] with an update after every 0.05 s of counted signal, see
    /// [`AdaptSettings::default`]).
    pub config: AdaptConfig,
    /// The largest drive-to-sensor delay searched, either way (0.5 s by default: far
    /// beyond any interface's buffering, well within the estimator's window).
    pub max_delay: Seconds,
}

impl Default for AdaptSettings {
    /// Channel 0, the output's device, input channel 0, a 0.5 s delay search, and the
    /// adapter's defaults but for the interval between updates: 0.05 s of counted signal
    /// (one analysis frame at 48 kHz) instead of 0.5 s. A walk's drive is the ring of each
    /// heel strike, a few frames per step, so the adapter's default (made for a steady
    /// drive) updated about once in four steps and took minutes; the spectra's 3 s memory
    /// still averages over many steps, and the 0.5 dB cap per update keeps each change
    /// small. On Table 1's mean leg (7.7 dB from flat) walking on gravel: below 1 dB after
    /// about 18 s, against 1.8 dB after 26 s with 0.1 s and 6 dB with 0.5 s (the offline
    /// test of this module).
    fn default() -> Self {
        Self {
            channel: 0,
            device: None,
            input_channel: 0,
            config: AdaptConfig {
                interval: Seconds(0.05),
                ..AdaptConfig::default()
            },
            max_delay: Seconds(0.5),
        }
    }
}

/// What the adaptation has done so far, for a status line and the summary.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AdaptStatus {
    /// The drive-to-sensor lag in use, in samples, once found.
    pub delay: Option<i64>,
    /// Times the lag was found again somewhere else (a stream skipped samples).
    pub realignments: u64,
    /// Frames the adapter has counted into its averages.
    pub frames: u64,
    /// Updates of the weights, each sent to the engine.
    pub updates: u64,
    /// Updates the engine's queue had no room for (the next one carries the same
    /// weights, moved further).
    pub queue_full: u64,
    /// Bins of the band trusted at the last update.
    pub trusted_bins: usize,
    /// The largest change of any bin at the last update.
    pub last_change: Decibels,
    /// The deviation from flat the adapter estimates for the loaded device with the
    /// current weights: the RMS over its trusted bins of the weight plus the estimated
    /// response, in dB, about their mean. An estimate from the sensor, not a measurement
    /// of the skin.
    pub estimated_deviation: Option<Decibels>,
    /// Samples either ring had no room for.
    pub dropped: u64,
    /// Non-finite samples seen by the adapter.
    pub non_finite: u64,
}

/// One sample of drive and the force under the foot when it was played.
#[derive(Debug, Clone, Copy, Default)]
struct DriveFrame {
    drive: f32,
    force: f32,
}

/// The output callback's half: copies the adapted channel's drive into the ring.
pub struct DriveTap {
    channel: usize,
    telemetry: Arc<Telemetry>,
    ring: rtrb::Producer<DriveFrame>,
    dropped: Arc<AtomicU64>,
}

impl DriveTap {
    /// Copies channel `channel` of the interleaved `out` (`device_channels` wide). Never
    /// allocates, locks or blocks.
    pub fn push(&mut self, out: &[f32], device_channels: usize) {
        let force = self
            .telemetry
            .force(self.channel)
            .map_or(0.0, |f| f.0 as f32);
        push_channel(
            &mut self.ring,
            &self.dropped,
            out,
            device_channels,
            self.channel,
            |drive| DriveFrame { drive, force },
        );
    }
}

/// The input callback's half: copies the accelerometer's channel into the ring.
pub struct SensorTap {
    channel: usize,
    ring: rtrb::Producer<f32>,
    dropped: Arc<AtomicU64>,
}

impl SensorTap {
    /// Copies channel `channel` of the interleaved `input` (`channels` wide). Never
    /// allocates, locks or blocks.
    pub fn push(&mut self, input: &[f32], channels: usize) {
        push_channel(
            &mut self.ring,
            &self.dropped,
            input,
            channels,
            self.channel,
            |v| v,
        );
    }
}

/// Writes channel `channel` of the interleaved `frames` (`width` wide; 0 for a channel
/// beyond it) into `ring`, each sample as `item` makes it; a ring without room for the
/// whole buffer takes none of it, and `dropped` counts its frames.
fn push_channel<T>(
    ring: &mut rtrb::Producer<T>,
    dropped: &AtomicU64,
    frames: &[f32],
    width: usize,
    channel: usize,
    item: impl Fn(f32) -> T,
) {
    let width = width.max(1);
    let n = frames.len() / width;
    match ring.write_chunk_uninit(n) {
        Ok(chunk) => {
            chunk.fill_from_iter(
                frames
                    .chunks_exact(width)
                    .map(|frame| item(frame.get(channel).copied().unwrap_or(0.0))),
            );
        }
        Err(_) => {
            dropped.fetch_add(n as u64, Ordering::Relaxed);
        }
    }
}

/// A stream's recent samples, indexed by the stream's own sample count.
#[derive(Debug)]
struct History<T> {
    samples: VecDeque<T>,
    /// The stream index of `samples[0]`.
    start: u64,
}

impl<T: Copy> History<T> {
    fn new() -> Self {
        Self {
            samples: VecDeque::with_capacity(2 * RING),
            start: 0,
        }
    }

    fn end(&self) -> u64 {
        self.start + self.samples.len() as u64
    }

    fn get(&self, index: u64) -> Option<T> {
        let i = index.checked_sub(self.start)?;
        self.samples.get(usize::try_from(i).ok()?).copied()
    }

    /// Forgets everything before `index`.
    fn trim_to(&mut self, index: u64) {
        let n = index
            .saturating_sub(self.start)
            .min(self.samples.len() as u64);
        self.samples.drain(..n as usize);
        self.start += n;
    }

    fn restart(&mut self) {
        self.samples.clear();
        self.start = 0;
    }
}

/// The session's half: aligns the two streams and runs the [`Adapter`]; see the
/// [module documentation](self).
pub struct AdaptLoop {
    channel: u16,
    adapter: Adapter,
    drive_rx: rtrb::Consumer<DriveFrame>,
    sensor_rx: rtrb::Consumer<f32>,
    drive_dropped: Arc<AtomicU64>,
    sensor_dropped: Arc<AtomicU64>,
    dropped_seen: u64,
    drive: History<DriveFrame>,
    sensor: History<f32>,
    estimator: DelayEstimator,
    /// The drive index at which the next delay window ends.
    next_check: u64,
    recheck: u64,
    candidate: Option<i64>,
    /// The next drive index to give the adapter.
    fed: u64,
    win_x: Vec<f32>,
    win_y: Vec<f32>,
    block_drive: Vec<f32>,
    block_sensor: Vec<f32>,
    status: AdaptStatus,
}

impl std::fmt::Debug for AdaptLoop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AdaptLoop")
            .field("channel", &self.channel)
            .field("status", &self.status)
            .finish_non_exhaustive()
    }
}

/// The two taps and the loop that reads them, made together by [`AdaptParts::new`].
pub struct AdaptParts {
    /// For the output's callback, after the engine has rendered into the buffer.
    pub drive: DriveTap,
    /// For the accelerometer input's callback.
    pub sensor: SensorTap,
    /// For the thread that holds the engine's [`Controller`].
    pub adapt: AdaptLoop,
}

impl AdaptParts {
    /// The taps and the loop for `settings`, starting from `weights` at `rate`, reading
    /// channel `settings.channel`'s force from `telemetry`. Allocates everything.
    ///
    /// # Errors
    /// [`LiveError::Adapt`] when the adapter refuses the weights or the settings.
    pub fn new(
        settings: &AdaptSettings,
        weights: &SpectralWeights,
        rate: SampleRate,
        telemetry: Arc<Telemetry>,
    ) -> Result<Self, LiveError> {
        let adapter = Adapter::new(weights, settings.config).map_err(LiveError::Adapt)?;
        let (drive_tx, drive_rx) = rtrb::RingBuffer::new(RING);
        let (sensor_tx, sensor_rx) = rtrb::RingBuffer::new(RING);
        let drive_dropped = Arc::new(AtomicU64::new(0));
        let sensor_dropped = Arc::new(AtomicU64::new(0));
        let max_lag = rate.samples_in(settings.max_delay);
        let recheck = rate.samples_in(RECHECK) as u64;
        Ok(Self {
            drive: DriveTap {
                channel: usize::from(settings.channel),
                telemetry,
                ring: drive_tx,
                dropped: Arc::clone(&drive_dropped),
            },
            sensor: SensorTap {
                channel: usize::from(settings.input_channel),
                ring: sensor_tx,
                dropped: Arc::clone(&sensor_dropped),
            },
            adapt: AdaptLoop {
                channel: settings.channel,
                adapter,
                drive_rx,
                sensor_rx,
                drive_dropped,
                sensor_dropped,
                dropped_seen: 0,
                drive: History::new(),
                sensor: History::new(),
                estimator: DelayEstimator::new(WINDOW, max_lag),
                next_check: WINDOW as u64,
                recheck,
                candidate: None,
                fed: 0,
                win_x: vec![0.0; WINDOW],
                win_y: vec![0.0; WINDOW],
                block_drive: vec![0.0; BLOCK],
                block_sensor: vec![0.0; BLOCK],
                status: AdaptStatus::default(),
            },
        })
    }
}

impl AdaptLoop {
    /// The weights the adaptation starts from (re-levelled by the adapter): send them
    /// first, so that the engine plays exactly what is adapted.
    pub fn weights(&self) -> &SpectralWeights {
        self.adapter.weights()
    }

    /// The engine channel it adapts.
    pub fn channel(&self) -> u16 {
        self.channel
    }

    /// What it has done so far.
    pub fn status(&self) -> AdaptStatus {
        self.status
    }

    /// Drains both rings, aligns them, runs the adapter and sends new weights to the
    /// engine. Call from the session's thread, often (every poll).
    pub fn poll(&mut self, controller: &mut Controller) {
        if let Ok(chunk) = self.drive_rx.read_chunk(self.drive_rx.slots()) {
            self.drive.samples.extend(chunk);
        }
        if let Ok(chunk) = self.sensor_rx.read_chunk(self.sensor_rx.slots()) {
            self.sensor.samples.extend(chunk);
        }
        let dropped = self.drive_dropped.load(Ordering::Relaxed)
            + self.sensor_dropped.load(Ordering::Relaxed);
        if dropped != self.dropped_seen {
            // The sample counts no longer pair: start both streams afresh.
            self.dropped_seen = dropped;
            self.status.dropped = dropped;
            self.drive.restart();
            self.sensor.restart();
            self.next_check = WINDOW as u64;
            self.candidate = None;
            self.fed = 0;
            if self.status.delay.take().is_some() {
                self.status.realignments += 1;
            }
            return;
        }
        self.check_delay();
        self.feed(controller);
        self.trim();
    }

    /// Estimates the lag on every complete window that is due.
    fn check_delay(&mut self) {
        while self.next_check <= self.drive.end() && self.next_check <= self.sensor.end() {
            let from = self.next_check - WINDOW as u64;
            let at = self.next_check;
            let estimate = if from >= self.drive.start && from >= self.sensor.start {
                let mut sum = 0.0;
                for (k, (x, y)) in self.win_x.iter_mut().zip(&mut self.win_y).enumerate() {
                    let i = from + k as u64;
                    *x = self.drive.get(i).map_or(0.0, |f| f.drive);
                    *y = self.sensor.get(i).unwrap_or(0.0);
                    sum += f64::from(*x).powi(2);
                }
                let rms = (sum / WINDOW as f64).sqrt();
                (rms >= MIN_WINDOW_RMS)
                    .then(|| self.estimator.estimate(&self.win_x, &self.win_y))
                    .flatten()
                    .filter(|d| d.prominence >= MIN_PROMINENCE)
                    .map(|d| d.lag)
            } else {
                None
            };
            let agrees = |a: i64, b: i64| (a - b).abs() <= LAG_TOLERANCE;
            match (self.status.delay, estimate) {
                (Some(lag), Some(new)) if !agrees(lag, new) => {
                    if self.candidate.is_some_and(|c| agrees(c, new)) {
                        self.status.delay = Some(new);
                        self.status.realignments += 1;
                        self.candidate = None;
                    } else {
                        self.candidate = Some(new);
                    }
                }
                (Some(_), _) => self.candidate = None,
                (None, Some(new)) => {
                    if self.candidate.is_some_and(|c| agrees(c, new)) {
                        self.status.delay = Some(new);
                        self.candidate = None;
                        // Start with the drive whose sensor samples are still here.
                        self.fed = self
                            .drive
                            .start
                            .max(self.sensor.start.saturating_add_signed(-new));
                    } else {
                        self.candidate = Some(new);
                    }
                }
                (None, None) => {}
            }
            self.next_check = if self.status.delay.is_some() {
                at + self.recheck.max(WINDOW as u64)
            } else {
                at + WINDOW as u64 / 2
            };
        }
    }

    /// Gives the adapter every aligned block available.
    fn feed(&mut self, controller: &mut Controller) {
        let Some(lag) = self.status.delay else {
            return;
        };
        let n = BLOCK as u64;
        // Drive trimmed away, or sensor samples not kept: skip ahead.
        self.fed = self
            .fed
            .max(self.drive.start)
            .max(self.sensor.start.saturating_add_signed(-lag));
        while self.fed + n <= self.drive.end()
            && self.fed.saturating_add_signed(lag) + n <= self.sensor.end()
        {
            let mut force = f32::INFINITY;
            for k in 0..BLOCK {
                let i = self.fed + k as u64;
                let frame = self.drive.get(i).unwrap_or_default();
                self.block_drive[k] = frame.drive;
                force = force.min(frame.force);
                self.block_sensor[k] = self.sensor.get(i.saturating_add_signed(lag)).unwrap_or(0.0);
            }
            self.fed += n;
            let updated = self.adapter.push(
                &self.block_drive,
                &self.block_sensor,
                Newtons(f64::from(force)),
            );
            if let Some(weights) = updated {
                if controller
                    .set_equalizer_weights(self.channel, weights)
                    .is_err()
                {
                    self.status.queue_full += 1;
                }
                self.status.updates = self.adapter.updates();
                self.status.trusted_bins = self.adapter.trusted_bins();
                self.status.last_change = self.adapter.last_change();
                self.status.estimated_deviation = self.estimated_deviation();
            }
        }
        self.status.frames = self.adapter.frames();
        self.status.non_finite = self.adapter.non_finite();
    }

    /// The RMS over the trusted bins of weight plus estimated response, about the mean.
    fn estimated_deviation(&self) -> Option<Decibels> {
        let loaded = self.adapter.loaded_response();
        let weights = self.adapter.weights();
        // The device as equalized: each trusted bin's estimate through its weight.
        let (freqs, response) = loaded
            .freqs
            .iter()
            .zip(&loaded.response)
            .filter(|(_, d)| d.norm() > 0.0)
            .map(|(&f, &d)| (f, d * Decibels(weights.gain_db_at(f)).to_amplitude()))
            .unzip();
        flatness(&FrequencyResponse { freqs, response })
            .ok()
            .map(|(rms, _)| rms)
    }

    /// Forgets what neither the delay check nor the adapter will read again.
    fn trim(&mut self) {
        let window_from = self.next_check.saturating_sub(WINDOW as u64);
        let lag = self.status.delay.unwrap_or(0);
        let drive_keep = window_from.min(if self.status.delay.is_some() {
            self.fed
        } else {
            window_from
        });
        self.drive.trim_to(drive_keep);
        let sensor_keep = if self.status.delay.is_some() {
            window_from.min(self.fed.saturating_add_signed(lag))
        } else {
            window_from
        };
        self.sensor.trim_to(sensor_keep);
        // A stream that outruns the other (its partner stopped) must not grow for ever.
        bound(&mut self.drive, 2 * RING);
        bound(&mut self.sensor, 2 * RING);
    }
}

/// Keeps at most `cap` of the newest samples.
fn bound<T: Copy>(history: &mut History<T>, cap: usize) {
    let excess = history.samples.len().saturating_sub(cap);
    if excess > 0 {
        history.trim_to(history.start + excess as u64);
    }
}

#[cfg(test)]
mod tests;
