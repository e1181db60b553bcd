//! The real-time engine: N channels, force in, vibration out.
//!
//! [`build`] splits the engine in two halves that talk only through lock-free
//! single-producer single-consumer queues ([`rtrb`]) and atomics:
//!
//! - the [`Engine`] lives on the audio thread. [`Engine::process`] renders into the buffer
//!   it is given and never allocates, locks, blocks or panics;
//! - the [`Controller`] lives anywhere else. It sends [`TimedEvent`]s (force readings,
//!   steps, material changes) and new materials, reads [`Telemetry`], and frees the
//!   materials the engine has retired, so that no deallocation happens on the audio
//!   thread either.
//!
//! Every material of the bank is prepared before the engine starts; changing a channel's
//! material is a slot index, and the voice copies the coefficients into its own fixed
//! arrays. A replaced material goes back over the retire queue.
//!
//! # Timing
//!
//! An event with a frame (`TimedEvent::at`) takes effect at exactly that sample, whatever
//! the block size: the block is split there. So an offline render is identical for every
//! block size.
//!
//! A force reading without a frame but with its sensor time ([`SensorReading::at`](crate::force::SensorReading::at); a
//! replay or a generated walk stamps every reading) is given a frame by the engine's
//! sensor clock ([`clock`], which states the rule): the first one anchors sensor time `t_A`
//! at frame `A = F + B + M` (drained at the start of a call at frame `F` of `B` frames,
//! `M` = [`EngineConfig::sensor_latency`]), and every one applies at
//! `frame(t) = A + round((t − t_A) · fs)`, exactly, like a timed event. A step's onset is
//! then `frame(t_s)`, `t_s` the sensor time of the reading that crosses the threshold, and
//! its intensity comes from the readings' sensor times ([`crate::force::steps`]): a live
//! session plays what an offline render of the same track plays, shifted by a constant,
//! for every block size (tested for 16 to 1024 frames). The price is a fixed latency of
//! one block plus `M`.
//!
//! Any other event without a frame (an explicit step, a material change, a reading that
//! knows no sensor time) takes effect at the start of the next block: its impulse reaches
//! the output in the first block rendered after it arrives.
//!
//! # Output
//!
//! Channel `c` goes to device channel `c`; device channels beyond the engine's are zero.
//! Each channel's synthesis leaves through its own [`OutputStage`], the one place where
//! the engine's samples become output: the configured compensation (the device equalizer
//! and the limb filter, [`EngineConfig::compensation`]), then the watchdog, the output
//! gain and the [`Fader`] (which ramps everything in at start and out at
//! [`Controller::stop`]), then the non-finite guard and the limiter's ceiling. Nothing
//! runs after it, so the safety stages hold for every model kind and every compensation
//! ([`crate::safety`]). A channel without a device channel runs its stage too, so its
//! state stays in time.

mod channel;
pub mod clock;
pub mod event;
pub mod offline;
mod output;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

pub use clock::ClockAnchor;
pub use event::{Event, TimedEvent};

use crate::compensation::CompensationError;
use crate::compensation::chain::{Compensation, CompensationChain};
use crate::force::drive::{DriveKind, Polarity};
use crate::force::steps::DetectorConfig;
use crate::material::Library;
use crate::safety::{Fader, LimiterReport, WatchdogConfig};
use crate::synthesis::{PreparedMaterial, VoiceConfig, VoiceError};
use crate::units::{Decibels, Hz, Newtons, SampleRate, Seconds};
use channel::Channel;
use clock::SensorClock;
pub use output::OutputStage;

/// Everything the engine is set up with.
#[derive(Debug, Clone, PartialEq)]
pub struct EngineConfig {
    /// Audio rate.
    pub rate: SampleRate,
    /// Number of channels (actuators), each with its own input and material.
    pub channels: usize,
    /// The largest block rendered in one go; larger device buffers are split.
    pub max_block: usize,
    /// What drives the filters.
    pub drive: DriveKind,
    /// Which half of `dF/dt` the `ForceRate` drive keeps.
    pub polarity: Polarity,
    /// Standard deviation of the per-step numerator perturbation (default 0.01).
    pub perturbation: f32,
    /// Seed of the perturbation; channel `c` uses a stream derived from it.
    pub seed: u64,
    /// Nominal body weight the force drives normalise by (default 70 kg).
    pub nominal_weight: Newtons,
    /// About how often sensor readings arrive (sets the force ramp, and the reading
    /// period assumed for readings without a sensor time; default 500 Hz).
    pub sensor_rate: Hz,
    /// Jitter margin of the sensor clock (`M` in [`clock`]): a stamped reading sent
    /// without a frame plays one block plus this after its sensor time (default 10 ms).
    pub sensor_latency: Seconds,
    /// Heel-strike detection.
    pub detector: DetectorConfig,
    /// Input watchdog.
    pub watchdog: WatchdogConfig,
    /// Output gain before the limiter (default 0 dB).
    pub gain: Decibels,
    /// Limiter ceiling relative to full scale (default -6 dB).
    pub ceiling: Decibels,
    /// Limiter release (default 50 ms).
    pub release: Seconds,
    /// Material crossfade (default 20 ms).
    pub crossfade: Seconds,
    /// Start-up and shut-down fade (default 10 ms).
    pub fade: Seconds,
    /// Capacity of the event queue (default 8192).
    pub queue_capacity: usize,
    /// Device equalizer and limb compensation, applied to every channel before its
    /// limiter (default: none).
    pub compensation: Compensation,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            rate: SampleRate(48_000),
            channels: 1,
            max_block: 512,
            drive: DriveKind::Impulse,
            polarity: Polarity::Loading,
            perturbation: 0.01,
            seed: 0x5EED,
            nominal_weight: Newtons::weight_of(70.0),
            sensor_rate: Hz(500.0),
            sensor_latency: Seconds(0.01),
            detector: DetectorConfig::default(),
            watchdog: WatchdogConfig::default(),
            gain: Decibels(0.0),
            ceiling: Decibels(-6.0),
            release: Seconds(0.05),
            crossfade: Seconds(0.02),
            fade: Seconds(0.01),
            queue_capacity: 8192,
            compensation: Compensation::default(),
        }
    }
}

/// Why an engine cannot be built or a command not sent.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EngineError {
    /// A setting is out of range.
    #[error("invalid engine setting: {0}")]
    InvalidConfig(String),
    /// A material cannot be played.
    #[error(transparent)]
    Voice(#[from] VoiceError),
    /// A material name is not in the bank.
    #[error("no material {name:?} in the engine's bank (available: {available})")]
    UnknownMaterial {
        /// The name asked for.
        name: String,
        /// The names there are.
        available: String,
    },
    /// The compensation cannot run at this engine's settings.
    #[error("compensation: {0}")]
    Compensation(#[from] CompensationError),
    /// The event queue is full: the audio thread is not running or not keeping up.
    #[error("the engine's event queue is full (is the audio device running?)")]
    QueueFull,
}

/// The materials an engine can play, prepared for its rate. Built off the audio thread.
#[derive(Debug, Clone, Default)]
pub struct MaterialBank {
    materials: Vec<PreparedMaterial>,
}

impl MaterialBank {
    /// Prepares every material of `library` for `rate`, normalising the force drives with
    /// `nominal_step` (total force of one nominal step at `rate`, see
    /// [`gait::nominal_step`](crate::force::gait::nominal_step)) for a walker of `weight`.
    ///
    /// # Errors
    /// The first material that cannot be played.
    pub fn prepare(
        library: &Library,
        rate: SampleRate,
        voice: &VoiceConfig,
        nominal_step: &[f64],
        weight: Newtons,
    ) -> Result<Self, VoiceError> {
        let materials = library
            .materials
            .iter()
            .map(|m| {
                let mut p = PreparedMaterial::prepare(m, rate, voice)?;
                p.normalise_drives(nominal_step, weight);
                Ok(p)
            })
            .collect::<Result<Vec<_>, VoiceError>>()?;
        Ok(Self { materials })
    }

    /// A bank of already prepared materials.
    #[must_use]
    pub fn from_prepared(materials: Vec<PreparedMaterial>) -> Self {
        Self { materials }
    }

    /// The materials' names, in slot order.
    #[must_use]
    pub fn names(&self) -> Vec<String> {
        self.materials.iter().map(|m| m.name.clone()).collect()
    }

    /// The slot of a material.
    ///
    /// # Errors
    /// [`EngineError::UnknownMaterial`] listing the names there are.
    pub fn slot(&self, name: &str) -> Result<u16, EngineError> {
        self.materials
            .iter()
            .position(|m| m.name == name)
            .map(|i| i as u16)
            .ok_or_else(|| EngineError::UnknownMaterial {
                name: name.to_string(),
                available: self.names().join(", "),
            })
    }

    /// The prepared materials.
    #[must_use]
    pub fn materials(&self) -> &[PreparedMaterial] {
        &self.materials
    }
}

/// Counters the engine publishes, readable from any thread.
#[derive(Debug)]
pub struct Telemetry {
    frames: AtomicU64,
    strikes: AtomicU64,
    non_finite: AtomicU64,
    limited: AtomicU64,
    rejected: AtomicU64,
    late: AtomicU64,
    dropped: AtomicU64,
    watchdog_trips: AtomicU64,
    peak_bits: AtomicU32,
    stopped: AtomicBool,
    anchor_frame: AtomicU64,
    anchor_time_bits: AtomicU64,
    resyncs: AtomicU64,
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
const NO_ANCHOR: u64 = u64::MAX;

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
    /// Where the sensor clock is anchored ([`clock`]), once a stamped reading has come
    /// without a frame: with it, a reading of sensor time `t` plays at frame
    /// `anchor.frame + round((t - anchor.time) * fs)`.
    pub sensor_clock: Option<ClockAnchor>,
    /// Times the sensor clock re-anchored (a jump, or a drift beyond its budget).
    pub resyncs: u64,
}

impl Telemetry {
    fn count_strike(&self) {
        self.strikes.fetch_add(1, Ordering::Relaxed);
    }

    fn count_rejected(&self) {
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

enum Command {
    Event(TimedEvent),
    Replace(u16, Box<PreparedMaterial>),
    Stop,
}

/// The control half: sends events and materials, reads telemetry, frees retired materials.
pub struct Controller {
    commands: rtrb::Producer<Command>,
    retired: rtrb::Consumer<Box<PreparedMaterial>>,
    telemetry: Arc<Telemetry>,
    names: Vec<String>,
    rate: SampleRate,
}

impl Controller {
    /// Sends an event.
    ///
    /// # Errors
    /// [`EngineError::QueueFull`] if the engine has not drained the queue.
    pub fn send(&mut self, event: TimedEvent) -> Result<(), EngineError> {
        self.commands
            .push(Command::Event(event))
            .map_err(|_| EngineError::QueueFull)
    }

    /// Replaces the material in `slot` (channels playing it crossfade to the new one at
    /// their next material change; use an [`Event::Material`] to switch). The old one
    /// comes back through [`collect`](Self::collect).
    ///
    /// # Errors
    /// [`EngineError::QueueFull`], or [`EngineError::InvalidConfig`] for a slot beyond
    /// the bank.
    pub fn replace_material(
        &mut self,
        slot: u16,
        material: PreparedMaterial,
    ) -> Result<(), EngineError> {
        if usize::from(slot) >= self.names.len() {
            return Err(EngineError::InvalidConfig(format!(
                "slot {slot} is beyond the bank of {}",
                self.names.len()
            )));
        }
        self.names[usize::from(slot)] = material.name.clone();
        self.commands
            .push(Command::Replace(slot, Box::new(material)))
            .map_err(|_| EngineError::QueueFull)
    }

    /// Starts the shut-down fade; [`TelemetrySnapshot::stopped`] turns true when it ends.
    ///
    /// # Errors
    /// [`EngineError::QueueFull`].
    pub fn stop(&mut self) -> Result<(), EngineError> {
        self.commands
            .push(Command::Stop)
            .map_err(|_| EngineError::QueueFull)
    }

    /// Frees the materials the engine has retired. Call now and then from a non-audio
    /// thread.
    pub fn collect(&mut self) -> usize {
        let mut n = 0;
        while self.retired.pop().is_ok() {
            n += 1;
        }
        n
    }

    /// The counters.
    #[must_use]
    pub fn telemetry(&self) -> TelemetrySnapshot {
        self.telemetry.snapshot()
    }

    /// A shared handle on the counters, for a monitoring thread.
    #[must_use]
    pub fn telemetry_handle(&self) -> Arc<Telemetry> {
        Arc::clone(&self.telemetry)
    }

    /// The bank's material names, in slot order.
    #[must_use]
    pub fn material_names(&self) -> &[String] {
        &self.names
    }

    /// The engine's rate.
    #[must_use]
    pub fn rate(&self) -> SampleRate {
        self.rate
    }
}

/// The audio half. Move it into the audio callback.
pub struct Engine {
    rate: SampleRate,
    channels: Vec<Channel>,
    // Boxed so that a replacement is a pointer swap on the audio thread, and the old one
    // goes back to the controller to be freed there.
    #[allow(
        clippy::vec_box,
        reason = "materials are swapped by pointer and freed elsewhere"
    )]
    bank: Vec<Box<PreparedMaterial>>,
    /// One per channel: compensation, watchdog, gain and fade, limiter.
    stages: Vec<OutputStage>,
    fader: Fader,
    gain: f32,
    frame: u64,
    /// Events waiting for their frame, sorted by frame; capacity fixed at build.
    pending: Vec<(u64, Event)>,
    commands: rtrb::Consumer<Command>,
    retired: rtrb::Producer<Box<PreparedMaterial>>,
    telemetry: Arc<Telemetry>,
    scratch: Vec<f32>,
    peak: f32,
    clock: SensorClock,
}

/// Builds an engine and its controller. `initial` is each channel's starting material
/// (slot in `bank`); a channel without one is silent until it gets a material event.
///
/// # Errors
/// An invalid configuration, or an initial slot beyond the bank.
pub fn build(
    config: &EngineConfig,
    bank: MaterialBank,
    initial: &[u16],
) -> Result<(Controller, Engine), EngineError> {
    if config.channels == 0 || config.channels > usize::from(u16::MAX) {
        return Err(EngineError::InvalidConfig(format!(
            "{} channels: need 1 to 65535",
            config.channels
        )));
    }
    if config.max_block == 0 || config.queue_capacity == 0 {
        return Err(EngineError::InvalidConfig(
            "max_block and queue_capacity must be positive".into(),
        ));
    }
    if !(config.ceiling.0.is_finite() && config.gain.0.is_finite()) || config.ceiling.0 > 0.0 {
        return Err(EngineError::InvalidConfig(format!(
            "ceiling {} and gain {} must be finite, the ceiling at most 0 dB (full scale)",
            config.ceiling, config.gain
        )));
    }
    if !(config.sensor_latency.0.is_finite() && (0.0..=1.0).contains(&config.sensor_latency.0)) {
        return Err(EngineError::InvalidConfig(format!(
            "sensor latency {} must be 0 to 1 s",
            config.sensor_latency
        )));
    }
    if !(config.perturbation.is_finite() && (0.0..=0.5).contains(&config.perturbation)) {
        return Err(EngineError::InvalidConfig(format!(
            "perturbation {} must be in 0..0.5",
            config.perturbation
        )));
    }
    if let Some(bad) = initial
        .iter()
        .find(|s| usize::from(**s) >= bank.materials.len())
    {
        return Err(EngineError::InvalidConfig(format!(
            "initial material slot {bad} is beyond the bank of {}",
            bank.materials.len()
        )));
    }
    let names = bank.names();
    let (command_tx, command_rx) = rtrb::RingBuffer::new(config.queue_capacity);
    // Room for every replacement that could be in flight, so the engine never has to
    // drop a retired material on the audio thread.
    let (retire_tx, retire_rx) = rtrb::RingBuffer::new(config.queue_capacity);
    let telemetry = Arc::new(Telemetry::default());
    let bank: Vec<Box<PreparedMaterial>> = bank.materials.into_iter().map(Box::new).collect();
    let prototype = bank.iter().find_map(|m| m.ground.as_ref());
    let mut channels: Vec<Channel> = (0..config.channels)
        .map(|c| Channel::new(config, c, prototype))
        .collect();
    for (ch, slot) in channels.iter_mut().zip(initial) {
        ch.set_material(*slot, &bank[usize::from(*slot)]);
    }
    let stages = (0..config.channels)
        .map(|_| {
            let chain = if config.compensation.is_identity() {
                None
            } else {
                Some(CompensationChain::new(
                    &config.compensation,
                    config.rate,
                    64,
                )?)
            };
            Ok(OutputStage::new(
                chain,
                &config.watchdog,
                config.ceiling,
                config.release,
                config.rate,
            ))
        })
        .collect::<Result<Vec<_>, CompensationError>>()?;
    let engine = Engine {
        rate: config.rate,
        stages,
        channels,
        bank,
        fader: Fader::fade_in(config.fade, config.rate),
        gain: config.gain.to_amplitude() as f32,
        frame: 0,
        pending: Vec::with_capacity(config.queue_capacity),
        commands: command_rx,
        retired: retire_tx,
        telemetry: Arc::clone(&telemetry),
        scratch: vec![0.0; config.max_block],
        peak: 0.0,
        clock: SensorClock::new(config.rate, config.sensor_latency),
    };
    let controller = Controller {
        commands: command_tx,
        retired: retire_rx,
        telemetry,
        names,
        rate: config.rate,
    };
    Ok((controller, engine))
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
                        if let Err(rtrb::PushError::Full(old)) = self.retired.push(old) {
                            // Never free on the audio thread: leak rather than deallocate.
                            std::mem::forget(old);
                        }
                    }
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
        match event {
            Event::Force { reading, .. } => {
                if channel.force(&reading, frame, &self.telemetry) {
                    stage.feed();
                }
            }
            Event::Step { intensity, .. } => {
                if channel.step(intensity, &self.telemetry) {
                    stage.feed_step();
                }
            }
            Event::Material { slot, .. } => match self.bank.get(usize::from(slot)) {
                Some(m) => channel.set_material(slot, m),
                None => self.telemetry.count_rejected(),
            },
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
        let mut channel_buf = [0.0f32; 64];
        for (c, (channel, stage)) in self
            .channels
            .iter_mut()
            .zip(self.stages.iter_mut())
            .enumerate()
        {
            // Render in sub-blocks through a stack buffer: no per-channel output storage.
            // A channel without a device channel still runs, so its state stays in time.
            let mut start = 0;
            while start < n {
                let len = (n - start).min(channel_buf.len());
                let buf = &mut channel_buf[..len];
                resets += channel.render(buf);
                // A channel that is not played runs its stage to keep it in time, but
                // what its limiter does is nobody's concern.
                let mut unplayed = LimiterReport::default();
                let counted = if c < device_channels {
                    &mut report
                } else {
                    &mut unplayed
                };
                resets += stage.process(buf, &fade[start..start + len], counted);
                if c < device_channels {
                    for (i, v) in buf.iter().enumerate() {
                        self.peak = self.peak.max(v.abs());
                        out[(start + i) * device_channels + c] = *v;
                    }
                }
                start += len;
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
