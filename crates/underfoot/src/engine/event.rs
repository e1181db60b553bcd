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

/// A strike the engine played: what a session's record keeps of it
/// ([`Controller::take_strikes`](super::Controller::take_strikes)).
///
/// The audio thread pushes one per strike, detected from force or given as a step,
/// into a queue of [`STRIKE_LOG`] records that the controller drains; a record that
/// finds the queue full is counted ([`TelemetrySnapshot::unlogged_strikes`](super::TelemetrySnapshot::unlogged_strikes))
/// instead, so every strike counted is either in the log or in that count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrikeRecord {
    /// The engine frame it started at: the sample of the output it starts on.
    pub frame: u64,
    /// The channel (engine index, from 0).
    pub channel: u16,
    /// Strength relative to a nominal step (1.0).
    pub intensity: f32,
    /// The bank slot the channel played, if it had a material.
    pub slot: Option<u16>,
    /// The sensor time of the reading that crossed the threshold; `None` for an
    /// explicit step or a reading without one.
    pub sensor_time: Option<crate::units::Seconds>,
}

/// Records the strike log holds between two drains: over a minute of a 64-channel tile
/// at two steps a second, where a session drains it 50 times a second.
pub const STRIKE_LOG: usize = 8192;
