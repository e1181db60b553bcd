//! The control half: events and materials in, telemetry out, retired materials freed
//! here rather than on the audio thread.

use std::sync::Arc;

use crate::synthesis::PreparedMaterial;
use crate::units::SampleRate;

use super::{EngineError, Telemetry, TelemetrySnapshot, TimedEvent};

pub(super) enum Command {
    Event(TimedEvent),
    Replace(u16, Box<PreparedMaterial>),
    Stop,
}

/// The control half: sends events and materials, reads telemetry, frees retired materials.
pub struct Controller {
    pub(super) commands: rtrb::Producer<Command>,
    pub(super) retired: rtrb::Consumer<Box<PreparedMaterial>>,
    pub(super) telemetry: Arc<Telemetry>,
    pub(super) names: Vec<String>,
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
