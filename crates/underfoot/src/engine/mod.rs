//! The real-time engine: N channels, force in, vibration out.
//!
//! (Being written: see issue 3.)
pub mod event;

pub use event::{Event, TimedEvent};
