//! The control half: events and materials in, telemetry out, retired materials freed
//! here rather than on the audio thread.

use std::sync::Arc;

use crate::synthesis::PreparedMaterial;
use crate::units::{Decibels, SampleRate};

use super::{EngineError, StrikeRecord, Telemetry, TelemetrySnapshot, TimedEvent};

pub(super) enum Command {
    Event(TimedEvent),
    Replace(u16, Box<PreparedMaterial>),
    /// A new material into one of the bank's spare slots.
    Add(Box<PreparedMaterial>),
    /// A channel's trim below the configured gain, as an amplitude.
    Trim(u16, f32),
    /// New equalizer weights for a channel (dB per bin, the shape it was built with).
    Equalize(u16, Box<[f64]>),
    Stop,
}

/// What the audio thread hands back to be freed elsewhere.
pub(super) enum Retired {
    Material(Box<PreparedMaterial>),
    Weights(Box<[f64]>),
}

/// The control half: sends events and materials, reads telemetry, frees retired materials.
pub struct Controller {
    pub(super) commands: rtrb::Producer<Command>,
    pub(super) retired: rtrb::Consumer<Retired>,
    pub(super) strike_log: rtrb::Consumer<StrikeRecord>,
    pub(super) telemetry: Arc<Telemetry>,
    pub(super) names: Vec<String>,
    /// Slots the bank can hold in all: its materials and the spare ones reserved at
    /// build for [`add_material`](Controller::add_material).
    pub(super) capacity: usize,
    pub(super) rate: SampleRate,
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
    /// their next material change; use an [`Event::Material`](super::Event::Material) to switch). The old one
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

    /// Adds a material to the bank, in one of the spare slots reserved at build
    /// ([`EngineConfig::spare_slots`](super::EngineConfig::spare_slots)), and returns its slot; an
    /// [`Event::Material`](super::Event::Material) for that slot then plays it. The
    /// material is prepared by the caller, off the audio thread; the engine only stores
    /// its pointer.
    ///
    /// # Errors
    /// [`EngineError::BankFull`] when every spare slot is taken, or
    /// [`EngineError::QueueFull`].
    pub fn add_material(&mut self, material: PreparedMaterial) -> Result<u16, EngineError> {
        if self.names.len() >= self.capacity {
            return Err(EngineError::BankFull {
                capacity: self.capacity,
            });
        }
        let slot = self.names.len() as u16;
        let name = material.name.clone();
        self.commands
            .push(Command::Add(Box::new(material)))
            .map_err(|_| EngineError::QueueFull)?;
        self.names.push(name);
        Ok(slot)
    }

    /// Sets channel `channel`'s trim: `gain` below the configured output gain, clamped to
    /// -120 to 0 dB (the trim can only lower the output; the limiter's ceiling is not
    /// touched), reached smoothly over about 10 ms from the engine's next block.
    ///
    /// # Errors
    /// [`EngineError::InvalidConfig`] for a channel beyond the engine or a non-finite
    /// gain, or [`EngineError::QueueFull`].
    pub fn set_trim(&mut self, channel: u16, gain: Decibels) -> Result<(), EngineError> {
        if usize::from(channel) >= self.telemetry.channels() || !gain.0.is_finite() {
            return Err(EngineError::InvalidConfig(format!(
                "trim {gain} on channel {channel}: need a finite gain and a channel below {}",
                self.telemetry.channels()
            )));
        }
        let amplitude = Decibels(gain.0.clamp(-120.0, 0.0)).to_amplitude() as f32;
        self.commands
            .push(Command::Trim(channel, amplitude))
            .map_err(|_| EngineError::QueueFull)
    }

    /// Retunes channel `channel`'s equalizer to `gains_db` (dB per bin, as many bins as
    /// the equalizer it was built with: [`SpectralWeights::gains_db`]), applied smoothly
    /// from the engine's next block ([`EqualizerFilter::set_weights`]). Weights of another
    /// shape, non-finite ones, or a channel without an equalizer are refused on the audio
    /// thread and counted ([`TelemetrySnapshot::equalizer_refused`]). Allocates the copy
    /// that crosses the queue; the engine sends it back to be freed by
    /// [`collect`](Self::collect).
    ///
    /// [`SpectralWeights::gains_db`]: crate::compensation::equalizer::SpectralWeights::gains_db
    /// [`EqualizerFilter::set_weights`]: crate::compensation::equalizer::EqualizerFilter::set_weights
    ///
    /// # Errors
    /// [`EngineError::QueueFull`], or [`EngineError::InvalidConfig`] for a channel beyond
    /// the engine.
    pub fn set_equalizer_weights(
        &mut self,
        channel: u16,
        gains_db: &[f64],
    ) -> Result<(), EngineError> {
        if usize::from(channel) >= self.telemetry.channels() {
            return Err(EngineError::InvalidConfig(format!(
                "channel {channel} is beyond the engine's {}",
                self.telemetry.channels()
            )));
        }
        self.commands
            .push(Command::Equalize(channel, gains_db.into()))
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

    /// Frees what the engine has retired (replaced materials, applied equalizer weights).
    /// Call now and then from a non-audio thread.
    pub fn collect(&mut self) -> usize {
        let mut n = 0;
        while let Ok(retired) = self.retired.pop() {
            // Freed here, on this thread, whichever it is.
            match retired {
                Retired::Material(material) => drop(material),
                Retired::Weights(weights) => drop(weights),
            }
            n += 1;
        }
        n
    }

    /// Hands every strike the engine has logged since the last call to `each`, in the
    /// order played ([`StrikeRecord`]). Call it at least every few seconds when the log
    /// matters: records that find the log full are only counted
    /// ([`TelemetrySnapshot::unlogged_strikes`]).
    pub fn take_strikes(&mut self, mut each: impl FnMut(&StrikeRecord)) -> usize {
        let mut n = 0;
        while let Ok(record) = self.strike_log.pop() {
            each(&record);
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
