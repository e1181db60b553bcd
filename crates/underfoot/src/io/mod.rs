//! Device I/O: where force comes from and where vibration goes.
//!
//! Every back-end sits behind a cargo feature, so the core builds without any of them:
//!
//! | feature | module | direction |
//! |---|---|---|
//! | `replay` | `replay` | force from a CSV track, at real-time pace |
//! | `serial` | `serial` | force from a microcontroller over a serial port (framed binary protocol) |
//! | `serial` | `prosthetic` | the prosthetic-skin interface: insole frames in, servo frames out (its simulated board is in `sim`) |
//! | `osc` | `osc` | force, steps and material changes from OSC over UDP (a VR engine) |
//! | `wav` | `wav` | vibration to a WAV file |
//! | `audio` | `audio` | vibration to an audio device through cpal (ALSA; JACK with `jack`) |
//!
//! Inputs implement [`EventSource`]: a blocking poll, run on its own thread, whose events
//! go to the engine over its lock-free queue.
//!
//! # Example
//!
//! A generated walk replayed at 100 times real-time pace (a recorded track reads the same
//! way, from [`ForceTrack::read`](crate::force::track::ForceTrack::read)): every force
//! reading comes out as an engine [`Event`], stamped with its sensor time.
//!
//! ```
//! use std::time::Duration;
//! use underfoot::engine::Event;
//! use underfoot::force::gait::{GaitConfig, generate};
//! use underfoot::io::replay::ReplaySource;
//! use underfoot::io::{EventSource, SourceState};
//!
//! let walk = generate(&GaitConfig::from_spec("steps=2,channels=1")?)?;
//! let mut source = ReplaySource::new(walk.track, 100.0)?;
//! let mut readings = 0;
//! loop {
//!     let state = source.poll(Duration::from_millis(10), &mut |event| {
//!         if let Event::Force { reading, .. } = event {
//!             assert!(reading.time().is_some());
//!             readings += 1;
//!         }
//!     })?;
//!     if state == SourceState::Ended {
//!         break;
//!     }
//! }
//! assert_eq!(readings as u64, source.stats().events);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # A lost device
//!
//! A serial port can hang up (a USB adapter pulled, the board reset, the far end of a
//! pseudo-terminal closed). The source then reports [`SourceState::Disconnected`] and
//! reopens the same path with a [`Backoff`] (100 ms, doubling to 2 s), reporting the loss
//! and the return as [`LinkEvent`]s for the caller to print. While it waits, every poll
//! still waits out its timeout: a poll never returns early with nothing to do, so a
//! caller's loop cannot spin. No readings come meanwhile, so the engine's watchdog fades
//! the output to silence, as for any input that goes quiet.

#[cfg(feature = "serial")]
use std::collections::VecDeque;
use std::time::Duration;
#[cfg(feature = "serial")]
use std::time::Instant;

use crate::engine::Event;

#[cfg(feature = "audio")]
pub mod audio;
#[cfg(feature = "lsl")]
pub mod lsl;
pub mod marker;
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
    /// The source has ended (a replay reached its end, a simulated board its walk).
    Ended,
    /// The device is gone (a port hung up) and the source is trying to reopen it; no
    /// events come until it is back. A poll in this state still waits out its timeout.
    Disconnected,
}

/// A change of a source's link to its device, for the caller to report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkEvent {
    /// The device was lost; the source will try to reopen it.
    Lost {
        /// The device, port or path.
        device: String,
        /// What happened (the error as the system gave it).
        reason: String,
    },
    /// The first attempt to reopen the device failed (later failures are only counted,
    /// so that a long wait prints one line).
    RetryFailed {
        /// The device.
        device: String,
        /// Why it could not be opened.
        reason: String,
    },
    /// The device is open again.
    Back {
        /// The device.
        device: String,
        /// How long it was gone.
        after: Duration,
        /// Attempts it took.
        attempts: u32,
    },
}

impl std::fmt::Display for LinkEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkEvent::Lost { device, reason } => write!(f, "{device}: lost ({reason})"),
            LinkEvent::RetryFailed { device, reason } => {
                write!(f, "{device}: cannot reopen yet ({reason}); still trying")
            }
            LinkEvent::Back {
                device,
                after,
                attempts,
            } => write!(
                f,
                "{device}: reconnected after {:.1} s ({attempts} attempt(s))",
                after.as_secs_f64()
            ),
        }
    }
}

/// Delays between attempts to reopen a lost device: `first`, doubling up to `max`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    first: Duration,
    max: Duration,
    next: Duration,
}

impl Default for Backoff {
    /// 100 ms doubling to 2 s: a board that resets is back within a few hundred
    /// milliseconds, and a cable left unplugged costs one `open` every two seconds.
    fn default() -> Self {
        Self::new(Duration::from_millis(100), Duration::from_secs(2))
    }
}

impl Backoff {
    /// Starts at `first` (at least 1 ms), doubles up to `max` (at least `first`).
    #[must_use]
    pub fn new(first: Duration, max: Duration) -> Self {
        let first = first.max(Duration::from_millis(1));
        Self {
            first,
            max: max.max(first),
            next: first,
        }
    }

    /// The delay before the next attempt; the one after is twice as long, up to `max`.
    pub fn next_delay(&mut self) -> Duration {
        let d = self.next;
        self.next = (self.next * 2).min(self.max);
        d
    }

    /// Back to `first`, after a link that held.
    pub fn reset(&mut self) {
        self.next = self.first;
    }

    /// The longest delay.
    #[must_use]
    pub fn max(&self) -> Duration {
        self.max
    }
}

#[cfg(feature = "serial")]
/// A source's link to a device that can be lost and reopened: the loss, the backoff
/// between attempts, the attempts themselves, and the [`LinkEvent`]s and counts that
/// report them. The serial sources hold one each; what "reopen" means (a port, a port and
/// its writer) is the source's, given to [`Reconnect::retry`].
#[derive(Debug)]
pub(crate) struct Reconnect {
    device: String,
    backoff: Backoff,
    outage: Option<Outage>,
    /// When the device was last reopened, to tell a link that held from one that flaps.
    up_since: Instant,
    events: VecDeque<LinkEvent>,
    disconnects: u64,
    reconnects: u64,
}

#[cfg(feature = "serial")]
/// What [`Reconnect::retry`] did.
pub(crate) enum Retry<T> {
    /// The device is not lost.
    NotLost,
    /// Still lost: the poll's time was spent waiting (or on a failed attempt).
    Waiting,
    /// Reopened: here is the new handle.
    Back(T),
}

#[cfg(feature = "serial")]
impl Reconnect {
    /// A link to `device`, up, with the default [`Backoff`].
    pub(crate) fn new(device: &str) -> Self {
        Self {
            device: device.to_owned(),
            backoff: Backoff::default(),
            outage: None,
            up_since: Instant::now(),
            events: VecDeque::new(),
            disconnects: 0,
            reconnects: 0,
        }
    }

    pub(crate) fn set_backoff(&mut self, backoff: Backoff) {
        self.backoff = backoff;
    }

    /// The device went away: an outage begins, reported as [`LinkEvent::Lost`].
    pub(crate) fn lose(&mut self, reason: String) {
        self.disconnects += 1;
        if self.up_since.elapsed() >= self.backoff.max() {
            // The link held: a new outage starts from the shortest delay. One that drops
            // again at once keeps backing off instead of reopening ten times a second.
            self.backoff.reset();
        }
        self.outage = Some(Outage::start(&mut self.backoff));
        self.push(LinkEvent::Lost {
            device: self.device.clone(),
            reason,
        });
    }

    /// While lost: waits up to `timeout`, and calls `open` when an attempt is due. A
    /// success is reported as [`LinkEvent::Back`], the first failure of an outage as
    /// [`LinkEvent::RetryFailed`] (later ones would only repeat it every two seconds).
    pub(crate) fn retry<T>(
        &mut self,
        timeout: Duration,
        open: impl FnOnce() -> Result<T, IoError>,
    ) -> Retry<T> {
        let Some(outage) = self.outage.as_mut() else {
            return Retry::NotLost;
        };
        if !outage.wait(timeout) {
            return Retry::Waiting;
        }
        match open() {
            Ok(handle) => {
                let event = LinkEvent::Back {
                    device: self.device.clone(),
                    after: outage.since.elapsed(),
                    attempts: outage.attempts + 1,
                };
                self.outage = None;
                self.up_since = Instant::now();
                self.reconnects += 1;
                self.push(event);
                Retry::Back(handle)
            }
            Err(e) => {
                if outage.failed(&mut self.backoff) {
                    let reason = match e {
                        IoError::Open { reason, .. } => reason,
                        other => other.to_string(),
                    };
                    self.push(LinkEvent::RetryFailed {
                        device: self.device.clone(),
                        reason,
                    });
                }
                Retry::Waiting
            }
        }
    }

    /// Times lost, and times reopened.
    pub(crate) fn counts(&self) -> (u64, u64) {
        (self.disconnects, self.reconnects)
    }

    /// The oldest event not yet taken.
    pub(crate) fn next_event(&mut self) -> Option<LinkEvent> {
        self.events.pop_front()
    }

    /// Keeps a few events, the oldest dropped past them: a caller that never asks must not
    /// make a flapping link grow memory.
    fn push(&mut self, event: LinkEvent) {
        if self.events.len() >= 16 {
            self.events.pop_front();
        }
        self.events.push_back(event);
    }
}

#[cfg(feature = "serial")]
/// The reconnection state of a source whose device was lost: when to try next, since when,
/// how many attempts.
#[derive(Debug, Clone, Copy)]
struct Outage {
    since: Instant,
    next_attempt: Instant,
    attempts: u32,
}

#[cfg(feature = "serial")]
impl Outage {
    /// Lost now; the first attempt after `backoff`'s next delay.
    fn start(backoff: &mut Backoff) -> Self {
        let now = Instant::now();
        Self {
            since: now,
            next_attempt: now + backoff.next_delay(),
            attempts: 0,
        }
    }

    /// Waits until the next attempt is due or `timeout` has passed, whichever is first,
    /// and says whether an attempt is due. Never returns at once unless one is due (or
    /// `timeout` is zero), so a poll loop around it cannot spin.
    fn wait(&self, timeout: Duration) -> bool {
        let left = self.next_attempt.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return true;
        }
        std::thread::sleep(left.min(timeout));
        Instant::now() >= self.next_attempt
    }

    /// An attempt failed: the next after `backoff`'s next delay. Returns whether it was
    /// the first.
    fn failed(&mut self, backoff: &mut Backoff) -> bool {
        self.attempts += 1;
        self.next_attempt = Instant::now() + backoff.next_delay();
        self.attempts == 1
    }
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
    /// Times the device was lost (serial only).
    pub disconnects: u64,
    /// Times it came back.
    pub reconnects: u64,
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

    /// The next change of the link to the device since the last call (a loss, a return),
    /// oldest first; `None` for a source that has no device to lose.
    fn link_event(&mut self) -> Option<LinkEvent> {
        None
    }

    /// The next marker the source received (OSC's `/underfoot/v2/marker`), oldest first;
    /// `None` for a source that carries none.
    fn take_marker(&mut self) -> Option<marker::Marker> {
        None
    }

    /// Rejections so far by reason, for a person (only the reasons that occurred); empty
    /// for a source that does not tell them apart. They add up to
    /// [`SourceStats::rejected`] when it does.
    fn rejections(&self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }

    /// Why the most recent rejected input was refused, if the source says.
    fn last_reject(&self) -> Option<String> {
        None
    }
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
