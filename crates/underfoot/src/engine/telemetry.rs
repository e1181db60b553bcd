//! The counters the audio half publishes and any thread reads: atomics, never a lock.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

use crate::force::{MAX_SENSORS, SensorReading};
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
    pub(super) unlogged_strikes: AtomicU64,
    /// The limiter's smallest gain over the whole run, of any played channel (`f32`
    /// bits; 1.0: it never acted).
    pub(super) min_gain_bits: AtomicU32,
    /// One meter per engine channel, allocated with the engine.
    pub(super) channels: Box<[ChannelMeter]>,
}

/// One channel's live levels, published by the audio thread: relaxed atomics, written
/// once per reading or per block, never a lock.
///
/// Peaks and the limiter's smallest gain are kept as `f32` bits: for non-negative floats
/// the bit patterns order as the values do, so `fetch_max`/`fetch_min` on them are the
/// maximum/minimum of the values. The output's energy is a fixed-point sum
/// ([`ENERGY_SCALE`]) that [`Telemetry::take_channel`] swaps out with the number of
/// samples it covers, so the reader gets the RMS over exactly its own interval.
#[derive(Debug)]
pub(super) struct ChannelMeter {
    /// The last total force taken, in newtons (`f32` bits).
    force_bits: AtomicU32,
    /// Each sensor of the last reading, in newtons (`f32` bits), and how many there were.
    sensor_bits: [AtomicU32; MAX_SENSORS],
    sensors: AtomicU32,
    strikes: AtomicU64,
    /// The largest absolute output sample since the last take.
    peak_bits: AtomicU32,
    /// The largest absolute drive sample (the filter's excitation) since the last take.
    drive_bits: AtomicU32,
    /// Sum of squared output samples since the last take, times [`ENERGY_SCALE`].
    energy: AtomicU64,
    /// Samples that sum covers.
    samples: AtomicU64,
    /// The limiter's smallest gain since the last take (1.0: it did nothing).
    min_gain_bits: AtomicU32,
    limited: AtomicU64,
    /// Whether the watchdog lets the channel play (input is arriving).
    live: AtomicBool,
    /// The bank slot the channel plays, [`NO_SLOT`] before its first.
    slot: AtomicU32,
    /// The channel's trim (the gain below the configured one), as an amplitude.
    trim_bits: AtomicU32,
}

/// Fixed-point scale of a meter's energy: a full-scale sample adds 2^32, so a u64 holds
/// 2^32 of them (a day at 48 kHz of a channel at full scale that nobody reads; the sum
/// wraps rather than panics if it ever does), and a sample at -100 dBFS still adds 0.4.
const ENERGY_SCALE: f64 = 4_294_967_296.0;

/// A meter's slot before the channel has a material.
const NO_SLOT: u32 = u32::MAX;

impl Default for ChannelMeter {
    fn default() -> Self {
        Self {
            force_bits: AtomicU32::new(0),
            sensor_bits: std::array::from_fn(|_| AtomicU32::new(0)),
            sensors: AtomicU32::new(0),
            strikes: AtomicU64::new(0),
            peak_bits: AtomicU32::new(0),
            drive_bits: AtomicU32::new(0),
            energy: AtomicU64::new(0),
            samples: AtomicU64::new(0),
            min_gain_bits: AtomicU32::new(1.0f32.to_bits()),
            limited: AtomicU64::new(0),
            live: AtomicBool::new(false),
            slot: AtomicU32::new(NO_SLOT),
            trim_bits: AtomicU32::new(1.0f32.to_bits()),
        }
    }
}

/// What the audio thread measured of one channel over one block, for its meter.
#[derive(Debug, Clone, Copy)]
pub(super) struct BlockLevels {
    /// Largest absolute output sample.
    pub peak: f32,
    /// Sum of the squared output samples.
    pub energy: f64,
    /// Samples in the block.
    pub samples: u32,
    /// Largest absolute drive sample.
    pub drive: f32,
    /// The limiter's smallest gain.
    pub min_gain: f32,
    /// Samples the limiter reduced.
    pub limited: u32,
    /// Whether the watchdog let the channel play at the block's end.
    pub live: bool,
    /// The channel's trim, as an amplitude.
    pub trim: f32,
}

/// One channel's levels, as [`Telemetry::take_channel`] reads them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelLevels {
    /// The last total force the channel took (sum of its sensors), in newtons.
    pub force: f32,
    /// Each sensor of the last reading, in newtons; the first
    /// [`sensor_count`](Self::sensor_count) are meaningful.
    pub sensors: [f32; MAX_SENSORS],
    /// How many sensors the last reading had (0 before any reading).
    pub sensor_count: u8,
    /// Heel strikes on this channel so far.
    pub strikes: u64,
    /// The largest absolute output sample since the previous take (full scale 1.0).
    pub peak: f32,
    /// The RMS of the output since the previous take (full scale 1.0; 0 if no sample was
    /// rendered in between).
    pub rms: f32,
    /// The largest absolute drive sample (the filter's excitation, before the output
    /// stage) since the previous take.
    pub drive: f32,
    /// The limiter's smallest gain since the previous take (1.0: no reduction).
    pub limiter_gain: f32,
    /// Samples of this channel the limiter reduced so far.
    pub limited: u64,
    /// Whether the watchdog lets the channel play (input is arriving); `false` once it
    /// has faded the channel to silence.
    pub live: bool,
    /// The bank slot the channel plays, `None` before its first material.
    pub slot: Option<u16>,
    /// The channel's trim below the configured gain ([`Controller::set_trim`](super::Controller::set_trim)), as an
    /// amplitude (1.0: none).
    pub trim: f32,
}

impl Default for ChannelLevels {
    fn default() -> Self {
        Self {
            force: 0.0,
            sensors: [0.0; MAX_SENSORS],
            sensor_count: 0,
            strikes: 0,
            peak: 0.0,
            rms: 0.0,
            drive: 0.0,
            limiter_gain: 1.0,
            limited: 0,
            live: false,
            slot: None,
            trim: 1.0,
        }
    }
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
        let sensor_count = m.sensors.load(Ordering::Relaxed).min(MAX_SENSORS as u32) as u8;
        let mut sensors = [0.0; MAX_SENSORS];
        for (v, bits) in sensors
            .iter_mut()
            .zip(&m.sensor_bits)
            .take(usize::from(sensor_count))
        {
            *v = f32::from_bits(bits.load(Ordering::Relaxed));
        }
        // The energy first: a block published between the two swaps adds its samples
        // to the next interval's count and its energy to this one's, which errs by one
        // block's worth at most and never divides by zero below.
        let energy = m.energy.swap(0, Ordering::Relaxed) as f64 / ENERGY_SCALE;
        let samples = m.samples.swap(0, Ordering::Relaxed);
        let rms = if samples == 0 {
            0.0
        } else {
            (energy / samples as f64).sqrt() as f32
        };
        Some(ChannelLevels {
            force: f32::from_bits(m.force_bits.load(Ordering::Relaxed)),
            sensors,
            sensor_count,
            strikes: m.strikes.load(Ordering::Relaxed),
            peak: f32::from_bits(m.peak_bits.swap(0, Ordering::Relaxed)),
            rms,
            drive: f32::from_bits(m.drive_bits.swap(0, Ordering::Relaxed)),
            limiter_gain: f32::from_bits(m.min_gain_bits.swap(1.0f32.to_bits(), Ordering::Relaxed)),
            limited: m.limited.load(Ordering::Relaxed),
            live: m.live.load(Ordering::Relaxed),
            slot: match m.slot.load(Ordering::Relaxed) {
                NO_SLOT => None,
                s => u16::try_from(s).ok(),
            },
            trim: f32::from_bits(m.trim_bits.load(Ordering::Relaxed)),
        })
    }

    /// Frames the engine has rendered, as of its last block.
    #[must_use]
    pub fn frames(&self) -> u64 {
        self.frames.load(Ordering::Relaxed)
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

    pub(super) fn meter_force(&self, c: usize, reading: &SensorReading) {
        if let Some(m) = self.channels.get(c) {
            m.force_bits
                .store(reading.total().to_bits(), Ordering::Relaxed);
            let values = reading.as_slice();
            for (bits, v) in m.sensor_bits.iter().zip(values) {
                bits.store(v.to_bits(), Ordering::Relaxed);
            }
            m.sensors.store(values.len() as u32, Ordering::Relaxed);
        }
    }

    pub(super) fn meter_slot(&self, c: usize, slot: u16) {
        if let Some(m) = self.channels.get(c) {
            m.slot.store(u32::from(slot), Ordering::Relaxed);
        }
    }

    pub(super) fn meter_block(&self, c: usize, block: &BlockLevels) {
        self.min_gain_bits
            .fetch_min(block.min_gain.to_bits(), Ordering::Relaxed);
        if let Some(m) = self.channels.get(c) {
            // Peaks are non-negative (absolute values) and finite (after the limiter;
            // the drive is checked by whoever measured it), so their bits order as
            // their values.
            m.peak_bits
                .fetch_max(block.peak.to_bits(), Ordering::Relaxed);
            m.drive_bits
                .fetch_max(block.drive.to_bits(), Ordering::Relaxed);
            m.min_gain_bits
                .fetch_min(block.min_gain.to_bits(), Ordering::Relaxed);
            m.energy
                .fetch_add((block.energy * ENERGY_SCALE) as u64, Ordering::Relaxed);
            m.samples
                .fetch_add(u64::from(block.samples), Ordering::Relaxed);
            m.limited
                .fetch_add(u64::from(block.limited), Ordering::Relaxed);
            m.live.store(block.live, Ordering::Relaxed);
            m.trim_bits.store(block.trim.to_bits(), Ordering::Relaxed);
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
            unlogged_strikes: AtomicU64::new(0),
            min_gain_bits: AtomicU32::new(1.0f32.to_bits()),
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
    /// Strikes that found the strike log full ([`super::StrikeRecord`]): counted, but
    /// missing from a session's record.
    pub unlogged_strikes: u64,
    /// The limiter's smallest gain over the whole run, of any played channel (1.0: it
    /// never acted): the loudest moment went `-20 log10` of it over the ceiling.
    pub limiter_min_gain: f32,
}

impl Telemetry {
    pub(super) fn count_unlogged_strike(&self) {
        self.unlogged_strikes.fetch_add(1, Ordering::Relaxed);
    }

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
            unlogged_strikes: self.unlogged_strikes.load(Ordering::Relaxed),
            limiter_min_gain: f32::from_bits(self.min_gain_bits.load(Ordering::Relaxed)),
        }
    }
}
