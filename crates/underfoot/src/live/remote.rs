//! Steering a running session from another thread: a control panel, a script's server.
//!
//! A [`Remote`] sends [`RemoteCommand`]s to the session's own thread over a channel; the
//! session's poll loop (50 times a second) takes them and passes them on to the engine
//! through its lock-free command queue, exactly as it does the input's events. So the
//! audio thread never sees the remote: a material added from a panel was prepared by the
//! caller, off the audio thread, and reaches the engine as a pointer.

use std::sync::mpsc;
use std::time::Duration;

use crate::engine::{Controller, EngineError, Event, TimedEvent};
use crate::synthesis::PreparedMaterial;
use crate::units::Decibels;

use super::record::{Marker, Recorder};

/// What a [`Remote`] asks of a running session.
#[derive(Debug)]
#[non_exhaustive]
pub enum RemoteCommand {
    /// Switch `channel` to the material in `slot` (crossfaded like any material change).
    Material {
        /// The channel.
        channel: u16,
        /// The bank slot.
        slot: u16,
    },
    /// Lower `channel`'s output by `gain` below the configured gain (clamped to -120 to
    /// 0 dB: a remote can never raise the output, nor touch the limiter's ceiling).
    Trim {
        /// The channel.
        channel: u16,
        /// The trim.
        gain: Decibels,
    },
    /// Add a prepared material to one of the bank's spare slots; the reply is its slot.
    Add(Box<PreparedMaterial>),
    /// Put a marker into the session's record ([`super::record`]); refused when the
    /// session is not recorded.
    Marker(Marker),
    /// End the session: the output fades out and the session reports, as on Ctrl-C.
    Stop,
}

/// Why a remote command was not carried out.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RemoteError {
    /// The session has ended (or never started running).
    #[error("the session is not running")]
    Ended,
    /// The session did not answer in time.
    #[error("the session did not answer within {0:?}")]
    Timeout(Duration),
    /// The channel or slot is not the engine's.
    #[error("{0}")]
    Refused(String),
    /// The engine refused the command.
    #[error(transparent)]
    Engine(#[from] EngineError),
}

pub(super) struct Request {
    command: RemoteCommand,
    reply: mpsc::Sender<Result<Option<u16>, RemoteError>>,
}

/// A handle to steer a running session from any thread. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Remote {
    tx: mpsc::Sender<Request>,
}

/// How long [`Remote::send`] waits for the session's answer: the loop takes requests
/// every 20 ms, so this is only reached when it has stopped.
const ANSWER: Duration = Duration::from_secs(2);

impl Remote {
    pub(super) fn new() -> (Self, mpsc::Receiver<Request>) {
        let (tx, rx) = mpsc::channel();
        (Self { tx }, rx)
    }

    /// Sends `command` and waits (at most 2 s; normally one poll period, 20 ms) for the
    /// session to pass it on: `Some(slot)` for an added material.
    ///
    /// # Errors
    /// [`RemoteError::Ended`] once the session has ended; the engine's refusal or the
    /// session's ([`RemoteError::Refused`]) otherwise.
    pub fn send(&self, command: RemoteCommand) -> Result<Option<u16>, RemoteError> {
        let (reply, answer) = mpsc::channel();
        self.tx
            .send(Request { command, reply })
            .map_err(|_| RemoteError::Ended)?;
        match answer.recv_timeout(ANSWER) {
            Ok(result) => result,
            Err(mpsc::RecvTimeoutError::Timeout) => Err(RemoteError::Timeout(ANSWER)),
            Err(mpsc::RecvTimeoutError::Disconnected) => Err(RemoteError::Ended),
        }
    }
}

/// Carries out every request waiting, on the session's thread, and records each change
/// it makes; `true` if one asked the session to stop.
pub(super) fn serve(
    requests: &mpsc::Receiver<Request>,
    controller: &mut Controller,
    mut recorder: Option<&mut Recorder>,
) -> bool {
    let mut stop = false;
    while let Ok(Request { command, reply }) = requests.try_recv() {
        let telemetry = controller.telemetry_handle();
        let channels = telemetry.channels();
        let frame = telemetry.frames();
        let change = match &command {
            RemoteCommand::Material { channel, slot } => Some((
                "material",
                serde_json::json!({
                    "channel": u32::from(*channel) + 1,
                    "slot": slot,
                    "material": controller.material_names().get(usize::from(*slot)),
                    "from": "remote",
                }),
            )),
            RemoteCommand::Trim { channel, gain } => Some((
                "trim",
                serde_json::json!({ "channel": u32::from(*channel) + 1, "trim_db": gain.0 }),
            )),
            RemoteCommand::Add(m) => {
                Some(("material_added", serde_json::json!({ "material": m.name })))
            }
            RemoteCommand::Marker(_) | RemoteCommand::Stop => None,
        };
        // A channel is the engine's index here; a person calls it by its number, from 1.
        let beyond = |channel: u16| {
            RemoteError::Refused(format!(
                "channel {}: the session plays {channels} channel(s), 1 to {channels}",
                u32::from(channel) + 1
            ))
        };
        let result = match command {
            RemoteCommand::Material { channel, slot } => {
                if usize::from(channel) >= channels {
                    Err(beyond(channel))
                } else if usize::from(slot) >= controller.material_names().len() {
                    Err(RemoteError::Refused(format!(
                        "slot {slot}: the bank holds {} material(s)",
                        controller.material_names().len()
                    )))
                } else {
                    controller
                        .send(TimedEvent::now(Event::Material { channel, slot }))
                        .map(|()| None)
                        .map_err(RemoteError::from)
                }
            }
            RemoteCommand::Trim { channel, .. } if usize::from(channel) >= channels => {
                Err(beyond(channel))
            }
            RemoteCommand::Trim { channel, gain } => controller
                .set_trim(channel, gain)
                .map(|()| None)
                .map_err(RemoteError::from),
            RemoteCommand::Add(material) => controller
                .add_material(*material)
                .map(Some)
                .map_err(RemoteError::from),
            RemoteCommand::Marker(marker) => match (&mut recorder, marker.check()) {
                (_, Err(e)) => Err(RemoteError::Refused(e.to_string())),
                (None, Ok(())) => Err(RemoteError::Refused(
                    "this session is not recorded (--record DIR): a marker has nowhere to go"
                        .into(),
                )),
                (Some(r), Ok(())) => r
                    .marker(frame, &marker)
                    .map(|()| None)
                    .map_err(|e| RemoteError::Refused(format!("the record failed: {e}"))),
            },
            RemoteCommand::Stop => {
                stop = true;
                Ok(None)
            }
        };
        if let (Ok(_), Some((kind, fields)), Some(r)) = (&result, change, &mut recorder) {
            // A record that cannot take a change fails at its next write, which the
            // session reports: the change itself was made.
            let _ = r.event(frame, kind, fields);
        }
        // The caller may have given up waiting: nothing to tell then.
        let _ = reply.send(result);
    }
    stop
}
