//! The counters the audio half publishes and any thread reads: atomics, never a lock.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

use crate::units::Seconds;

use super::ClockAnchor;

/// Counters the engine publishes, readable from any thread.
#[derive(Debug)]
pub struct Telemetry {
    pub(super) frames: AtomicU64,
    pub(super) strikes: AtomicU64,
    pub(super) non_finite: AtomicU64,
    pub(super) limited: AtomicU64,
    pub(super) rejected: AtomicU64,
    pub(super) late: AtomicU64,
    pub(super) dropped: AtomicU64,
    pub(super) watchdog_trips: AtomicU64,
    pub(super) peak_bits: AtomicU32,
    pub(super) stopped: AtomicBool,
    pub(super) anchor_frame: AtomicU64,
    pub(super) anchor_time_bits: AtomicU64,
    pub(super) resyncs: AtomicU64,
}

impl Default for Telemetry {
    fn default() -> Self {
        Self {
            frames: AtomicU64::new(0),
            strikes: AtomicU64::new(0),
            non_finite: AtomicU64::new(0),
            limited: AtomicU64::new(0),
            rejected: AtomicU64::new(0),
            late: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            watchdog_trips: AtomicU64::new(0),
            peak_bits: AtomicU32::new(0),
            stopped: AtomicBool::new(false),
            anchor_frame: AtomicU64::new(NO_ANCHOR),
            anchor_time_bits: AtomicU64::new(0),
            resyncs: AtomicU64::new(0),
        }
    }
}

/// `anchor_frame` before the sensor clock is anchored.
pub(super) const NO_ANCHOR: u64 = u64::MAX;

/// A snapshot of [`Telemetry`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TelemetrySnapshot {
    /// Frames rendered.
    pub frames: u64,
    /// Heel strikes (detected or sent).
    pub strikes: u64,
    /// Non-finite samples caught (voice resets plus limiter catches).
    pub non_finite: u64,
    /// Samples the limiter reduced.
    pub limited: u64,
    /// Events rejected on arrival (non-finite force, channel or slot out of range).
    pub rejected: u64,
    /// Timed events that arrived after their frame had been rendered (applied late).
    pub late: u64,
    /// Events dropped because the pending list was full.
    pub dropped: u64,
    /// Times a channel's watchdog faded it out.
    pub watchdog_trips: u64,
    /// Largest absolute output sample so far.
    pub peak: f32,
    /// Whether the shut-down fade has finished.
    pub stopped: bool,
    /// Where the sensor clock is anchored ([`clock`](super::clock)), once a stamped reading has come
    /// without a frame: with it, a reading of sensor time `t` plays at frame
    /// `anchor.frame + round((t - anchor.time) * fs)`.
    pub sensor_clock: Option<ClockAnchor>,
    /// Times the sensor clock re-anchored (a jump, or a drift beyond its budget).
    pub resyncs: u64,
}

impl Telemetry {
    pub(super) fn count_strike(&self) {
        self.strikes.fetch_add(1, Ordering::Relaxed);
    }

    pub(super) fn count_rejected(&self) {
        self.rejected.fetch_add(1, Ordering::Relaxed);
    }

    /// A snapshot of every counter.
    #[must_use]
    pub fn snapshot(&self) -> TelemetrySnapshot {
        TelemetrySnapshot {
            frames: self.frames.load(Ordering::Relaxed),
            strikes: self.strikes.load(Ordering::Relaxed),
            non_finite: self.non_finite.load(Ordering::Relaxed),
            limited: self.limited.load(Ordering::Relaxed),
            rejected: self.rejected.load(Ordering::Relaxed),
            late: self.late.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
            watchdog_trips: self.watchdog_trips.load(Ordering::Relaxed),
            peak: f32::from_bits(self.peak_bits.load(Ordering::Relaxed)),
            stopped: self.stopped.load(Ordering::Relaxed),
            sensor_clock: match self.anchor_frame.load(Ordering::Relaxed) {
                NO_ANCHOR => None,
                frame => Some(ClockAnchor {
                    frame,
                    time: Seconds(f64::from_bits(
                        self.anchor_time_bits.load(Ordering::Relaxed),
                    )),
                }),
            },
            resyncs: self.resyncs.load(Ordering::Relaxed),
        }
    }
}
