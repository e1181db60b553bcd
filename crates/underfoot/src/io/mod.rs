//! Device I/O: where force comes from and where vibration goes.
//!
//! Every back-end sits behind a cargo feature, so the core builds without any of them:
//!
//! | feature | module | direction |
//! |---|---|---|
//! | `replay` | `replay` | force from a CSV track, at real-time pace |
//! | `serial` | `serial` | force from a microcontroller over a serial port (framed binary protocol) |
//! | `serial` | `prosthetic` | the prosthetic-skin interface: insole frames in, servo frames out; its simulated board |
//! | `osc` | `osc` | force, steps and material changes from OSC over UDP (a VR engine) |
//! | `wav` | `wav` | vibration to a WAV file |
//! | `audio` | `audio` | vibration to an audio device through cpal (ALSA; JACK with `jack`) |
//!
//! Inputs implement [`EventSource`]: a blocking poll, run on its own thread, whose events
//! go to the engine over its lock-free queue.

use std::time::Duration;

use crate::engine::Event;

#[cfg(feature = "audio")]
pub mod audio;
#[cfg(feature = "osc")]
pub mod osc;
#[cfg(feature = "serial")]
pub mod prosthetic;
#[cfg(feature = "replay")]
pub mod replay;
#[cfg(feature = "serial")]
pub mod serial;
pub mod spec;
#[cfg(feature = "wav")]
pub mod wav;

/// Whether a source may still produce events.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceState {
    /// More events may come.
    Open,
    /// The source has ended (a replay reached its end, a port closed).
    Ended,
}

/// What a source has seen so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SourceStats {
    /// Events delivered.
    pub events: u64,
    /// Frames or packets rejected (bad checksum, malformed, unknown address or material).
    pub rejected: u64,
    /// Bytes skipped while looking for the next frame (serial only).
    pub skipped_bytes: u64,
}

/// A source of engine events, polled on its own thread (never the audio thread).
pub trait EventSource: Send {
    /// Waits up to `timeout` for input and hands every event that arrived to `out`.
    ///
    /// # Errors
    /// An I/O failure of the underlying device. Malformed input is not an error: it is
    /// counted in [`SourceStats::rejected`] and skipped.
    fn poll(
        &mut self,
        timeout: Duration,
        out: &mut dyn FnMut(Event),
    ) -> Result<SourceState, IoError>;

    /// Counts so far.
    fn stats(&self) -> SourceStats;
}

/// What went wrong with a device.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// A device or file could not be opened.
    #[error("cannot open {device}: {reason}")]
    Open {
        /// The device, port, address or path.
        device: String,
        /// Why.
        reason: String,
    },
    /// Reading or writing failed after opening.
    #[error("{device}: {source}")]
    Io {
        /// The device.
        device: String,
        /// The failure.
        source: std::io::Error,
    },
    /// A setting cannot be honoured (rate, channels, buffer size).
    #[error("{device}: {reason}")]
    Unsupported {
        /// The device.
        device: String,
        /// What cannot be done.
        reason: String,
    },
}
