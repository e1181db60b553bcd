//! What reaches the audio thread: force readings, explicit steps, material changes.

use crate::force::SensorReading;

pub use crate::safety::STEP_WINDOW;

/// One input to the engine. Small and `Copy`, so it crosses a lock-free queue by value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A reading of a channel's force sensors, in newtons.
    Force {
        /// The channel (actuator) the sensors belong to.
        channel: u16,
        /// The reading.
        reading: SensorReading,
    },
    /// An explicit heel strike, from a source that detects steps itself (a VR engine).
    /// It keeps the channel alive for [`STEP_WINDOW`], then the channel fades to silence
    /// unless another step or a force reading comes.
    Step {
        /// The channel.
        channel: u16,
        /// Strength relative to a nominal step (1.0).
        intensity: f32,
    },
    /// Switch a channel to the material in slot `slot` of the engine's material bank.
    Material {
        /// The channel.
        channel: u16,
        /// The slot, in the order of the library the engine was built from.
        slot: u16,
    },
}

impl Event {
    /// The channel the event is for.
    #[must_use]
    pub fn channel(&self) -> u16 {
        match *self {
            Event::Force { channel, .. }
            | Event::Step { channel, .. }
            | Event::Material { channel, .. } => channel,
        }
    }
}

/// An event and when it takes effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedEvent {
    /// The engine frame (sample index since start) it applies at; `None` for "as soon as
    /// possible", i.e. the start of the next block. Offline renders give every event a
    /// frame, which is what makes their output independent of the block size.
    pub at: Option<u64>,
    /// The event.
    pub event: Event,
}

impl TimedEvent {
    /// An event to apply as soon as possible.
    #[must_use]
    pub fn now(event: Event) -> Self {
        Self { at: None, event }
    }

    /// An event to apply at engine frame `frame`.
    #[must_use]
    pub fn at(frame: u64, event: Event) -> Self {
        Self {
            at: Some(frame),
            event,
        }
    }
}
