//! The audio half: renders into the buffer it is given, applying each event at its frame;
//! never allocates, locks, blocks or panics.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use crate::safety::{Fader, LimiterReport, peak_abs};
use crate::synthesis::{LANE_WIDTH, Lane, PreparedMaterial, VoiceLanes};
use crate::units::SampleRate;

use super::channel::Channel;
use super::clock::SensorClock;
use super::controller::{Command, Retired};
use super::event::StrikeRecord;
use super::telemetry::BlockLevels;
use super::{Event, OutputStage, Telemetry};

/// Partial sums of a channel's energy meter: as many as a vector holds.
const METER_LANES: usize = 8;

/// The peak and the energy (sum of squares) of a block the output stage has made
/// finite. The energy in `METER_LANES` partial sums, which changes only its last bits:
/// a single running sum would make every sample wait for the previous one's addition.
fn levels(buf: &[f32]) -> (f32, f64) {
    let mut energy = [0.0f32; METER_LANES];
    let chunks = buf.chunks_exact(METER_LANES);
    for (e, v) in energy.iter_mut().zip(chunks.remainder()) {
        *e += v * v;
    }
    for chunk in chunks {
        for (e, v) in energy.iter_mut().zip(chunk) {
            *e += v * v;
        }
    }
    (peak_abs(buf), energy.iter().map(|e| f64::from(*e)).sum())
}

/// The audio half. Move it into the audio callback.
pub struct Engine {
    pub(super) rate: SampleRate,
    pub(super) channels: Vec<Channel>,
    // Boxed so that a replacement is a pointer swap on the audio thread, and the old one
    // goes back to the controller to be freed there.
    pub(super) bank: Vec<Box<PreparedMaterial>>,
    /// One per channel: compensation, watchdog, gain and fade, limiter.
    pub(super) stages: Vec<OutputStage>,
    pub(super) fader: Fader,
    pub(super) gain: f32,
    pub(super) frame: u64,
    /// Events waiting for their frame, sorted by frame; capacity fixed at build.
    pub(super) pending: Vec<(u64, Event)>,
    pub(super) commands: rtrb::Consumer<Command>,
    pub(super) retired: rtrb::Producer<Retired>,
    /// Every strike, for a session's record ([`StrikeRecord`]).
    pub(super) strike_log: rtrb::Producer<StrikeRecord>,
    pub(super) telemetry: Arc<Telemetry>,
    pub(super) scratch: Vec<f32>,
    /// Runs the channels' IIR voices, [`LANE_WIDTH`] at a time: one for each
    /// [`LANE_WIDTH`] channels, each keeping its channels' coefficients between blocks.
    pub(super) lanes: Vec<VoiceLanes>,
    pub(super) peak: f32,
    pub(super) clock: SensorClock,
}

impl Engine {
    /// Renders `out.len() / device_channels` frames into `out`, interleaved.
    ///
    /// Never allocates, locks, blocks or panics. A buffer whose length is not a multiple
    /// of `device_channels` has its trailing partial frame zeroed.
    pub fn process(&mut self, out: &mut [f32], device_channels: usize) {
        if device_channels == 0 {
            return;
        }
        let frames = out.len() / device_channels;
        self.drain_commands(frames);
        out[frames * device_channels..].fill(0.0);
        let mut done = 0;
        while done < frames {
            let now = self.frame;
            self.apply_due(now);
            let until_event = self
                .pending
                .first()
                .map_or(u64::MAX, |(at, _)| at.saturating_sub(now));
            let n = (frames - done)
                .min(self.scratch.len())
                .min(usize::try_from(until_event).unwrap_or(usize::MAX))
                .max(1);
            self.render(
                &mut out[done * device_channels..(done + n) * device_channels],
                device_channels,
            );
            done += n;
        }
        self.publish();
    }

    /// The engine's rate.
    #[must_use]
    pub fn rate(&self) -> SampleRate {
        self.rate
    }

    /// Number of channels.
    #[must_use]
    pub fn channels(&self) -> usize {
        self.channels.len()
    }

    /// Frames rendered so far (the engine's clock).
    #[must_use]
    pub fn frame(&self) -> u64 {
        self.frame
    }

    /// Hands `old` back to the controller to be freed there.
    fn retire(&mut self, old: Retired) {
        if let Err(rtrb::PushError::Full(old)) = self.retired.push(old) {
            // Never free on the audio thread: leak rather than deallocate.
            std::mem::forget(old);
        }
    }

    fn drain_commands(&mut self, frames: usize) {
        while let Ok(command) = self.commands.pop() {
            match command {
                Command::Event(e) => match e.at.or_else(|| self.sensor_frame(&e.event, frames)) {
                    Some(at) if at > self.frame => {
                        if self.pending.len() < self.pending.capacity() {
                            // Stable: events for the same frame keep their order.
                            let i = self.pending.partition_point(|(f, _)| *f <= at);
                            self.pending.insert(i, (at, e.event));
                        } else {
                            self.telemetry.dropped.fetch_add(1, Ordering::Relaxed);
                            self.apply(e.event);
                        }
                    }
                    Some(at) => {
                        if at < self.frame {
                            self.telemetry.late.fetch_add(1, Ordering::Relaxed);
                        }
                        self.apply(e.event);
                    }
                    None => self.apply(e.event),
                },
                Command::Replace(slot, material) => {
                    if let Some(old) = self.bank.get_mut(usize::from(slot)) {
                        let old = std::mem::replace(old, material);
                        self.retire(Retired::Material(old));
                    }
                }
                Command::Add(material) => {
                    // The bank's spare capacity was reserved at build, and the controller
                    // sends no more than it holds: a push here never reallocates. A
                    // material beyond it (which the controller does not send) goes back.
                    if self.bank.len() < self.bank.capacity() {
                        self.bank.push(material);
                    } else {
                        self.retire(Retired::Material(material));
                    }
                }
                Command::Trim(channel, amplitude) => {
                    let applied = self
                        .stages
                        .get_mut(usize::from(channel))
                        .is_some_and(|stage| stage.set_trim(amplitude));
                    if !applied {
                        self.telemetry.count_rejected();
                    }
                }
                Command::Equalize(channel, gains) => {
                    let applied = self
                        .stages
                        .get_mut(usize::from(channel))
                        .is_some_and(|stage| stage.set_equalizer_weights(&gains));
                    self.telemetry.count_equalizer(applied);
                    self.retire(Retired::Weights(gains));
                }
                Command::Stop => self.fader.fade_out(),
            }
        }
    }

    /// The frame the sensor clock gives a stamped force reading sent without one.
    fn sensor_frame(&mut self, event: &Event, frames: usize) -> Option<u64> {
        let Event::Force { reading, .. } = event else {
            return None;
        };
        // A non-finite reading is rejected when applied, and must not move the clock.
        let time = reading.time().filter(|_| reading.is_finite())?;
        Some(self.clock.frame_of(time.0, self.frame, frames))
    }

    fn apply_due(&mut self, now: u64) {
        let due = self.pending.partition_point(|(f, _)| *f <= now);
        for i in 0..due {
            let event = self.pending[i].1;
            self.apply(event);
        }
        self.pending.drain(..due);
    }

    fn apply(&mut self, event: Event) {
        let frame = self.frame;
        let index = usize::from(event.channel());
        let (Some(channel), Some(stage)) =
            (self.channels.get_mut(index), self.stages.get_mut(index))
        else {
            self.telemetry.count_rejected();
            return;
        };
        let sensor_time = match event {
            Event::Force { reading, .. } => {
                if channel.force(&reading, frame, &self.telemetry) {
                    stage.feed();
                }
                reading.time()
            }
            Event::Step { intensity, .. } => {
                if channel.step(intensity, &self.telemetry) {
                    stage.feed_step();
                }
                None
            }
            Event::Material { slot, .. } => {
                match self.bank.get(usize::from(slot)) {
                    Some(m) => {
                        channel.set_material(slot, m);
                        self.telemetry.meter_slot(index, slot);
                    }
                    None => self.telemetry.count_rejected(),
                }
                None
            }
        };
        if let Some(intensity) = channel.take_struck() {
            let record = StrikeRecord {
                frame,
                channel: event.channel(),
                intensity,
                slot: channel.slot(),
                sensor_time,
            };
            if self.strike_log.push(record).is_err() {
                self.telemetry.count_unlogged_strike();
            }
        }
    }

    fn render(&mut self, out: &mut [f32], device_channels: usize) {
        let n = out.len() / device_channels;
        out.fill(0.0);
        let mut resets = 0;
        let mut report = LimiterReport::default();
        // The fader is shared by all channels: compute its gains once.
        let fade = &mut self.scratch[..n];
        for g in fade.iter_mut() {
            *g = self.fader.tick() * self.gain;
        }
        for channel in &mut self.channels {
            channel.prepare(n);
        }
        // The IIR voices of all channels together, a lane each (`synthesis::voice::lanes`).
        for (chunk, runner) in self
            .channels
            .chunks_mut(LANE_WIDTH)
            .zip(self.lanes.iter_mut())
        {
            let mut lanes: [Option<Lane<'_>>; LANE_WIDTH] = Default::default();
            for (lane, channel) in lanes.iter_mut().zip(chunk.iter_mut()) {
                *lane = channel.lane(n);
            }
            resets += runner.process(&mut lanes);
        }
        for (c, (channel, stage)) in self
            .channels
            .iter_mut()
            .zip(self.stages.iter_mut())
            .enumerate()
        {
            // A channel without a device channel still runs, so its state stays in time.
            let mut channel_report = LimiterReport::default();
            let mut channel_peak = 0.0f32;
            let mut energy = 0.0;
            let drive = channel.drive_peak();
            let (buf, finish_resets) = channel.finish(n);
            resets += finish_resets;
            resets += stage.process(buf, fade, &mut channel_report);
            if c < device_channels {
                (channel_peak, energy) = levels(buf);
                for (frame, v) in out.chunks_exact_mut(device_channels).zip(buf.iter()) {
                    frame[c] = *v;
                }
            }
            // A channel that is not played runs its stage to keep it in time, but what its
            // limiter does is nobody's concern.
            if c < device_channels {
                report.limited = report.limited.saturating_add(channel_report.limited);
                report.non_finite = report.non_finite.saturating_add(channel_report.non_finite);
                self.peak = self.peak.max(channel_peak);
                self.telemetry.meter_block(
                    c,
                    &BlockLevels {
                        peak: channel_peak,
                        energy,
                        samples: n as u32,
                        drive,
                        min_gain: stage.take_min_gain(),
                        limited: channel_report.limited,
                        live: stage.is_live(),
                        trim: stage.trim_target(),
                    },
                );
            }
        }
        self.frame += n as u64;
        let t = &self.telemetry;
        t.non_finite
            .fetch_add(u64::from(resets + report.non_finite), Ordering::Relaxed);
        t.limited
            .fetch_add(u64::from(report.limited), Ordering::Relaxed);
    }

    fn publish(&mut self) {
        let t = &self.telemetry;
        t.frames.store(self.frame, Ordering::Relaxed);
        t.peak_bits.store(self.peak.to_bits(), Ordering::Relaxed);
        t.stopped.store(self.fader.is_silent(), Ordering::Relaxed);
        if let Some(anchor) = self.clock.anchor() {
            t.anchor_time_bits
                .store(anchor.time.0.to_bits(), Ordering::Relaxed);
            t.anchor_frame.store(anchor.frame, Ordering::Relaxed);
        }
        t.resyncs.store(self.clock.resyncs(), Ordering::Relaxed);
        let trips: u64 = self.stages.iter().map(OutputStage::watchdog_trips).sum();
        t.watchdog_trips.store(trips, Ordering::Relaxed);
    }
}
