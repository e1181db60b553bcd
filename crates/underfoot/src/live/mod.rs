//! A live session: force in from a device, vibration out to another, in real time.
//!
//! A [`Session`] is what `underfoot run` runs. Force comes from a replayed track, a
//! generated walk, a serial port, OSC, or a prosthetic-skin interface
//! ([`crate::io::prosthetic`]: its insole frames become force events, one vibration
//! channel per `[[channel]]`, and its servo frames are written by the same poll, never by
//! the audio thread); vibration goes to an audio device, a WAV file or nowhere.
//!
//! The input is polled on the session's thread and crosses to the audio thread over the
//! engine's lock-free queue. `wav:` and `null` outputs are played by a [paced]
//! pseudo-device: a thread that renders one buffer per buffer period, as a device would,
//! so a session can run without a sound card. Like a device's, its frame clock keeps time
//! with the wall clock: a wake-up that comes late renders the buffers it missed at once
//! instead of dropping them from the timeline.
//!
//! A replay or a walk stamps each reading with its sensor time, and the engine plays it at
//! the frame its sensor clock gives it, one buffer plus the sensor latency after that time
//! ([`crate::engine`], *Timing*): the steps come out as loud and as far apart as in an
//! offline render, whatever the buffer size. The [`Summary`] gives the clock's anchor, so
//! the frame of every reading can be checked; late readings and re-anchorings are
//! counted.
//!
//! # The life of a session
//!
//! 1. [`Session::open`] checks a `wav:` output's file against the output policy
//!    ([`crate::atomic_file`]) with every file the session reads, then opens the input. It
//!    says how many channels the input carries, if it knows, and the caller prepares the
//!    engine's settings and materials for that many.
//! 2. [`Session::start`] builds the engine and starts the output.
//! 3. [`RunningSession::run`] polls the input and sends its events to the engine until the
//!    session ends: when a replay, walk or simulated board has played out (plus one
//!    second to ring out), after [`SessionConfig::duration`], or when the caller's stop
//!    flag is set (Ctrl-C, Enter). The output then fades out before the device is closed,
//!    and the [`Summary`] says what happened.
//!
//! A serial port that hangs up (or an interface board's) is reopened with a backoff
//! (100 ms doubling to 2 s) until it comes back; each loss and return is handed to the
//! caller as a [`LinkEvent`](crate::io::LinkEvent), and the engine's watchdog fades the
//! output meanwhile. With [`SessionConfig::exit_on_disconnect`] a loss ends the session
//! instead ([`Summary::lost`]). However a source behaves, the poll loop never spins: a
//! poll that reports anything but an open source is followed by a sleep for the rest of
//! the poll period.
//!
//! | file | what it holds |
//! |---|---|
//! | `session.rs` | [`Session`], [`SessionConfig`], [`RunningSession`], the poll loop and the [`Summary`] |
//! | `input.rs` | opening each kind of input: replay, walk, serial port, OSC, prosthetic interface |
//! | `output.rs` | starting the output: an audio device, or the paced pseudo-device into a WAV file or nowhere |
//! | `paced.rs` | [`PacedDevice`]: the engine at real-time pace without a sound card |
//! | `remote.rs` | [`Remote`]: steering a running session from another thread (a control panel) |
//! | [`record`] | the session's record: force, strikes, changes, markers, status and output, in one folder |
//! | `tests.rs` | sessions run end to end on short walks |
//!
//! # Example
//!
//! A two-step walk on gravel, played in real time into no device (about 1.6 s of walk,
//! then a second to ring out):
//!
//! ```
//! use std::sync::atomic::AtomicBool;
//!
//! use underfoot::engine::{EngineConfig, MaterialBank};
//! use underfoot::force::gait::nominal_step;
//! use underfoot::io::spec::OutputSpec;
//! use underfoot::live::{Session, SessionConfig, SessionInput};
//! use underfoot::material::builtin::builtin;
//! use underfoot::synthesis::VoiceConfig;
//! use underfoot::units::{Newtons, SampleRate};
//!
//! let walk = "gait:steps=2,channels=1,lead_in=0.2,tail=0.2".parse()?;
//! let config = SessionConfig::new(SessionInput::Spec(walk), OutputSpec::Null);
//! let session = Session::open(&config)?;
//! assert_eq!(session.channels(), Some(1));
//!
//! let rate = SampleRate(48_000);
//! let bank = MaterialBank::prepare(
//!     builtin(),
//!     rate,
//!     &VoiceConfig::default(),
//!     &nominal_step(70.0, 1.8, rate.hz()),
//!     Newtons::weight_of(70.0),
//! )?;
//! let gravel = bank.slot("gravel")?;
//! let engine = EngineConfig { rate, channels: 1, ..EngineConfig::default() };
//! let running = session.start(&engine, bank, &[gravel])?;
//!
//! // Nothing sets the stop flag: the session ends when the walk has played out.
//! let summary = running.run(&AtomicBool::new(false), |event| eprintln!("{event}"))?;
//! assert_eq!(summary.telemetry.strikes, 2);
//! assert_eq!(summary.input.rejected, 0);
//! assert!(summary.lost.is_none());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod adapt;
mod input;
mod output;
pub mod paced;
pub mod record;
mod remote;
mod session;
#[cfg(test)]
mod tests;

pub use output::{OutputInfo, OutputReport};
pub use paced::{PacedDevice, PacedReport};
pub use record::{EndReason, Marker, RecordCounts, RecordError, RecordSettings};
pub use remote::{Remote, RemoteCommand, RemoteError};
pub use session::{
    InterfaceSummary, RunningSession, SerialSettings, Session, SessionConfig, SessionInput, Status,
    Summary,
};

use crate::atomic_file::AtomicWriteError;
use crate::engine::EngineError;
use crate::force::calibration::SensorCalibrationError;
use crate::force::gait::GaitError;
use crate::force::track::TrackError;
use crate::interface::config::ConfigError;
use crate::io::IoError;

/// Why a live session could not start, or stopped with an error.
///
/// Each stage's own error is passed through as it is (`transparent`): the message is the
/// one the stage gives, with its sources.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LiveError {
    /// The `wav:` output's file is refused by the output policy.
    #[error(transparent)]
    Output(#[from] AtomicWriteError),
    /// The prosthetic interface's configuration does not load.
    #[error(transparent)]
    Interface(#[from] ConfigError),
    /// The replayed force track does not load.
    #[error(transparent)]
    Track(#[from] TrackError),
    /// The walk cannot be generated.
    #[error(transparent)]
    Gait(#[from] GaitError),
    /// The serial sensors' calibration does not load.
    #[error(transparent)]
    Calibration(#[from] SensorCalibrationError),
    /// A device, port or file failed (opening, reading, writing).
    #[error(transparent)]
    Io(#[from] IoError),
    /// The engine cannot be built, or refused a command.
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// An audio output was asked of a build without one.
    #[error(
        "this build has no audio output: run scripts/install-audio (Debian, Ubuntu), or \
         rebuild with `--features audio` (needs the \
         libasound2-dev package), or use --output wav:FILE or --output null"
    )]
    NoAudio,
    /// The audio host's name is not one this build knows.
    #[error("--host {host:?}: {error}")]
    Host {
        /// The name given.
        host: String,
        /// Why it is refused (its message is part of this one's, not a source after it).
        error: IoError,
    },
    /// The audio device reported an error while playing.
    #[error("the audio device reported an error")]
    DeviceFailed,
    /// The paced output's thread ended before the session did, on the error it gives.
    #[error("the output stopped")]
    OutputStopped(#[source] Option<IoError>),
    /// The paced output's thread panicked.
    #[error("the output thread panicked")]
    OutputPanicked,
    /// Adaptation was asked of an output that is not a sound card: it needs the
    /// accelerometer on the same device's clock.
    #[error(
        "adaptation needs an audio output (--output audio[:DEVICE]), with the \
         accelerometer on an input of the same host"
    )]
    AdaptNeedsAudio,
    /// Adaptation was asked without an equalizer to adapt.
    #[error("adaptation needs an equalizer to start from (--eq FILE, from `calibrate equalize`)")]
    AdaptNeedsEqualizer,
    /// The channel to adapt is not one the engine plays.
    #[error("--adapt-channel {}: the session plays {channels} channel(s), 1 to {channels}", u32::from(*channel) + 1)]
    AdaptChannel {
        /// The channel asked for (the engine's index, from 0).
        channel: u16,
        /// The engine's channels.
        channels: usize,
    },
    /// The session's record cannot be made, or failed.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The equalizer's weights or the adaptation's settings are refused.
    #[error("the equalizer cannot adapt")]
    Adapt(#[source] crate::compensation::CompensationError),
}
