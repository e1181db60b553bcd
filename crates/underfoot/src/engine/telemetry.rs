//! The counters the audio half publishes and any thread reads: atomics, never a lock.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

use crate::units::{Newtons, Seconds};

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
    pub(super) equalizer_updates: AtomicU64,
    pub(super) equalizer_refused: AtomicU64,
    /// One meter per engine channel, allocated with the engine.
    pub(super) channels: Box<[ChannelMeter]>,
}

/// One channel's live levels, published by the audio thread: relaxed atomics, written
/// once per reading or per block, never a lock.
#[derive(Debug, Default)]
pub(super) struct ChannelMeter {
    /// The last total force taken, in newtons (`f32` bits).
    force_bits: AtomicU32,
    strikes: AtomicU64,
    /// The largest absolute sample since the last [`Telemetry::take_channel`] (`f32`
    /// bits: for non-negative floats the bit patterns order as the values do, so
    /// `fetch_max` on them is a maximum of the values).
    peak_bits: AtomicU32,
    limited: AtomicU64,
}

/// One channel's levels, as [`Telemetry::take_channel`] reads them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ChannelLevels {
    /// The last total force the channel took (sum of its sensors), in newtons.
    pub force: f32,
    /// Heel strikes on this channel so far.
    pub strikes: u64,
    /// The largest absolute output sample since the previous take (full scale 1.0).
    pub peak: f32,
    /// Samples of this channel the limiter reduced so far.
    pub limited: u64,
}

impl Telemetry {
    /// Counters for an engine of `channels` channels (set-up: allocates the meters).
    #[must_use]
    pub fn new(channels: usize) -> Self {
        Self {
            channels: (0..channels).map(|_| ChannelMeter::default()).collect(),
            ..Self::default()
        }
    }

    /// Channel `c`'s levels, or `None` beyond the engine's channels. The peak is the
    /// largest sample since the previous take, which resets it: one reader (a status
    /// display) takes it at its own pace; [`snapshot`](Self::snapshot)'s peak is the
    /// session's and unaffected.
    #[must_use]
    pub fn take_channel(&self, c: usize) -> Option<ChannelLevels> {
        let m = self.channels.get(c)?;
        Some(ChannelLevels {
            force: f32::from_bits(m.force_bits.load(Ordering::Relaxed)),
            strikes: m.strikes.load(Ordering::Relaxed),
            peak: f32::from_bits(m.peak_bits.swap(0, Ordering::Relaxed)),
            limited: m.limited.load(Ordering::Relaxed),
        })
    }

    /// The number of channels metered.
    #[must_use]
    pub fn channels(&self) -> usize {
        self.channels.len()
    }

    /// Channel `c`'s last total force, without taking its levels (the peak is left for
    /// [`take_channel`](Self::take_channel)'s reader); `None` beyond the engine's
    /// channels. Lock-free: an audio callback may read it.
    #[must_use]
    pub fn force(&self, c: usize) -> Option<Newtons> {
        let m = self.channels.get(c)?;
        Some(Newtons(f64::from(f32::from_bits(
            m.force_bits.load(Ordering::Relaxed),
        ))))
    }

    pub(super) fn meter_force(&self, c: usize, newtons: f32) {
        if let Some(m) = self.channels.get(c) {
            m.force_bits.store(newtons.to_bits(), Ordering::Relaxed);
        }
    }

    pub(super) fn meter_block(&self, c: usize, peak: f32, limited: u32) {
        if let Some(m) = self.channels.get(c) {
            // Non-negative (an absolute value) and finite (after the limiter).
            m.peak_bits.fetch_max(peak.to_bits(), Ordering::Relaxed);
            m.limited.fetch_add(u64::from(limited), Ordering::Relaxed);
        }
    }
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
            equalizer_updates: AtomicU64::new(0),
            equalizer_refused: AtomicU64::new(0),
            channels: Box::new([]),
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
    /// Equalizer weights applied ([`Controller::set_equalizer_weights`](super::Controller::set_equalizer_weights)).
    pub equalizer_updates: u64,
    /// Equalizer weights refused: another shape, non-finite, or no equalizer on the channel.
    pub equalizer_refused: u64,
}

impl Telemetry {
    pub(super) fn count_strike(&self, channel: usize) {
        self.strikes.fetch_add(1, Ordering::Relaxed);
        if let Some(m) = self.channels.get(channel) {
            m.strikes.fetch_add(1, Ordering::Relaxed);
        }
    }

    pub(super) fn count_equalizer(&self, applied: bool) {
        let counter = if applied {
            &self.equalizer_updates
        } else {
            &self.equalizer_refused
        };
        counter.fetch_add(1, Ordering::Relaxed);
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
            equalizer_updates: self.equalizer_updates.load(Ordering::Relaxed),
            equalizer_refused: self.equalizer_refused.load(Ordering::Relaxed),
        }
    }
}
