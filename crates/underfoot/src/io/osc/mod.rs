//! Force, steps and material changes from OSC over UDP, as a VR engine sends them.
//!
//! # Addresses (protocol 2)
//!
//! | address | arguments | event |
//! |---|---|---|
//! | `/underfoot/v2/force` | channel, then 1 to 8 forces in newtons | [`Event::Force`] |
//! | `/underfoot/v2/step` | channel, optional intensity (default 1.0) | [`Event::Step`] |
//! | `/underfoot/v2/material` | channel, material name (string) | [`Event::Material`] |
//! | `/underfoot/v2/marker` | text, then optionally trial (int), participant, condition (strings) | a [`Marker`] for the session's record |
//!
//! Channels count from 1, as audio tools number ports and as every other place a person
//! reads or types a channel (the status, the panel, the flags): channel 1 is the engine's
//! first. Protocol 1 (`/underfoot/force` and its siblings, channels from 0) is refused,
//! each message counted as [`OscReject::OldProtocol`], rather than obeyed: the same
//! numbers would drive the wrong actuator.
//!
//! A step plays for [`STEP_WINDOW`](crate::engine::event::STEP_WINDOW) (0.5 s) and the
//! channel is silent within 100 ms after it, unless more steps or forces arrive: a sender
//! that stops sending leaves no actuator on.
//!
//! Numbers may be sent as `i` (int32), `h` (int64), `f` (float32) or `d` (float64): game
//! engines differ in what their OSC plug-ins send. A channel sent as a float must be a whole
//! number. A material name is looked up in the table given to [`OscSource::bind`], in the
//! order of the engine's material bank.
//!
//! Bundles are taken apart recursively, up to [`MAX_BUNDLE_DEPTH`] levels, and their
//! messages applied in order as soon as they arrive: time tags are ignored, because the
//! sender's clock is not the engine's and a step is wanted now, not at a tag's time.
//!
//! The wire format (OSC 1.0) is read and written by [`wire`], which also gives senders
//! written in Rust, and the tests, [`wire::encode_message`] and [`wire::encode_bundle`].
//!
//! # What is rejected
//!
//! Counted in [`SourceStats::rejected`] and otherwise ignored: a packet that is not OSC (one
//! count per packet), and each message with an unknown address, the wrong number or types of
//! arguments, a channel out of range, an unknown material, a non-finite force or a
//! non-finite or negative intensity (one count per message; the good messages of a bundle
//! still go through). [`OscDecoder`] says why, for diagnostics and tests, and
//! [`OscSource::rejections`] counts each reason apart, so that a sender whose messages are
//! all refused can be told which rule it broke rather than a bare total.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::time::Duration;

use super::{EventSource, IoError, SourceState, SourceStats};
use crate::engine::Event;
use crate::force::{MAX_SENSORS, SensorReading};
use crate::io::marker::Marker;

pub mod wire;

use wire::{Arg, Malformed, Message};

/// The protocol's version, in every address.
pub const PROTOCOL: u32 = 2;
/// The address of force readings.
pub const FORCE_ADDRESS: &str = "/underfoot/v2/force";
/// The address of explicit steps.
pub const STEP_ADDRESS: &str = "/underfoot/v2/step";
/// The address of material changes.
pub const MATERIAL_ADDRESS: &str = "/underfoot/v2/material";
/// The address of markers.
pub const MARKER_ADDRESS: &str = "/underfoot/v2/marker";
/// Protocol 1's addresses (channels from 0), refused as [`OscReject::OldProtocol`].
pub const PROTOCOL_1_ADDRESSES: [&str; 3] =
    ["/underfoot/force", "/underfoot/step", "/underfoot/material"];

/// Markers waiting for the session, at most: a flood of them is counted, not queued.
const MAX_PENDING_MARKERS: usize = 256;

/// The deepest nesting of bundles accepted. Real senders nest one or two levels; the limit
/// keeps a hostile packet from recursing the decoder off the end of its thread's stack.
pub const MAX_BUNDLE_DEPTH: usize = 8;

/// More channels or materials than this cannot be named by a `u16`.
const MAX_INDEX: usize = u16::MAX as usize + 1;

/// Why a packet or message was ignored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum OscReject {
    /// Not an OSC packet, or bytes left over after one.
    #[error("not an OSC packet")]
    NotOsc,
    /// Bundles nested deeper than [`MAX_BUNDLE_DEPTH`].
    #[error("bundles nested deeper than {MAX_BUNDLE_DEPTH}")]
    TooDeep,
    /// Not one of the protocol's addresses.
    #[error("unknown address")]
    UnknownAddress,
    /// An address of protocol 1, whose channels counted from 0.
    #[error(
        "an address of protocol 1 (channels from 0); this build speaks protocol 2: \
         /underfoot/v2/force, /step, /material, /marker, with channels from 1"
    )]
    OldProtocol,
    /// The wrong number or types of arguments for the address.
    #[error("wrong number or types of arguments")]
    Arguments,
    /// A channel outside `1..=channels`.
    #[error("channel {0} is not one of the session's (they count from 1)")]
    Channel(i64),
    /// A material name not in the table.
    #[error("unknown material")]
    UnknownMaterial,
    /// A non-finite force, or a non-finite or negative intensity.
    #[error("non-finite force or bad intensity")]
    Value,
    /// A marker the record cannot take (no text, too long, a control character), or
    /// too many markers waiting.
    #[error("a marker without text, too long, or with a control character")]
    Marker,
}

/// What a message decodes to: an event for the engine, or a marker for the record.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// An event for the engine.
    Event(Event),
    /// A marker for the session's record.
    Marker(Marker),
}

/// Rejections so far, one count per [`OscReject`] reason; they add up to
/// [`SourceStats::rejected`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OscRejectCounts {
    /// [`OscReject::NotOsc`].
    pub not_osc: u64,
    /// [`OscReject::TooDeep`].
    pub too_deep: u64,
    /// [`OscReject::UnknownAddress`].
    pub unknown_address: u64,
    /// [`OscReject::Arguments`].
    pub arguments: u64,
    /// [`OscReject::Channel`].
    pub channel: u64,
    /// [`OscReject::UnknownMaterial`].
    pub unknown_material: u64,
    /// [`OscReject::Value`].
    pub value: u64,
    /// [`OscReject::OldProtocol`].
    pub old_protocol: u64,
    /// [`OscReject::Marker`].
    pub marker: u64,
}

impl OscRejectCounts {
    /// Counts one rejection under its reason.
    pub fn record(&mut self, reject: &OscReject) {
        let count = match reject {
            OscReject::NotOsc => &mut self.not_osc,
            OscReject::TooDeep => &mut self.too_deep,
            OscReject::UnknownAddress => &mut self.unknown_address,
            OscReject::Arguments => &mut self.arguments,
            OscReject::Channel(_) => &mut self.channel,
            OscReject::UnknownMaterial => &mut self.unknown_material,
            OscReject::Value => &mut self.value,
            OscReject::OldProtocol => &mut self.old_protocol,
            OscReject::Marker => &mut self.marker,
        };
        *count += 1;
    }

    /// All reasons together.
    pub fn total(&self) -> u64 {
        self.not_osc
            + self.too_deep
            + self.unknown_address
            + self.arguments
            + self.channel
            + self.unknown_material
            + self.value
            + self.old_protocol
            + self.marker
    }

    /// Each reason with a name for a person and its count, in a fixed order, zeros included.
    pub fn by_reason(&self) -> [(&'static str, u64); 9] {
        [
            ("protocol 1 address", self.old_protocol),
            ("not OSC", self.not_osc),
            ("bundles too deep", self.too_deep),
            ("unknown address", self.unknown_address),
            ("bad arguments", self.arguments),
            ("channel out of range", self.channel),
            ("unknown material", self.unknown_material),
            ("bad value", self.value),
            ("bad marker", self.marker),
        ]
    }
}

/// Why an [`OscDecoder`] cannot be made: a table a `u16` cannot index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum OscDecoderError {
    /// No channels, or more than a `u16` index can name.
    #[error("{0} channels (1 to {MAX_INDEX})")]
    Channels(usize),
    /// More materials than a `u16` index can name.
    #[error("{0} materials (at most {MAX_INDEX})")]
    Materials(usize),
}

/// Turns OSC packets into events, without I/O.
#[derive(Debug, Clone)]
pub struct OscDecoder {
    materials: Vec<String>,
    channels: usize,
}

impl OscDecoder {
    /// A decoder for `channels` channels and the materials `material_names`, slot by slot.
    /// A name listed twice maps to its first slot.
    ///
    /// # Errors
    /// [`OscDecoderError`] if there are no channels, or more channels or materials than a
    /// `u16` index can name.
    pub fn new(material_names: Vec<String>, channels: usize) -> Result<Self, OscDecoderError> {
        if channels == 0 || channels > MAX_INDEX {
            return Err(OscDecoderError::Channels(channels));
        }
        if material_names.len() > MAX_INDEX {
            return Err(OscDecoderError::Materials(material_names.len()));
        }
        Ok(Self {
            materials: material_names,
            channels,
        })
    }

    /// Decodes one datagram; hands `out` each event, or why a message (or the whole packet)
    /// was rejected, in the packet's order.
    pub fn decode(&self, datagram: &[u8], out: &mut dyn FnMut(Result<Decoded, OscReject>)) {
        match wire::parse(datagram, MAX_BUNDLE_DEPTH) {
            Ok(messages) => {
                for m in &messages {
                    out(self.message(m));
                }
            }
            Err(Malformed::Bytes) => out(Err(OscReject::NotOsc)),
            Err(Malformed::TooDeep) => out(Err(OscReject::TooDeep)),
        }
    }

    fn message(&self, m: &Message<'_>) -> Result<Decoded, OscReject> {
        if PROTOCOL_1_ADDRESSES.contains(&m.address) {
            return Err(OscReject::OldProtocol);
        }
        let Some((first, rest)) = m.args.split_first() else {
            return Err(match m.address {
                FORCE_ADDRESS | STEP_ADDRESS | MATERIAL_ADDRESS | MARKER_ADDRESS => {
                    OscReject::Arguments
                }
                _ => OscReject::UnknownAddress,
            });
        };
        if m.address == MARKER_ADDRESS {
            return marker(first, rest).map(Decoded::Marker);
        }
        self.event(m.address, first, rest).map(Decoded::Event)
    }

    fn event(&self, address: &str, first: &Arg<'_>, rest: &[Arg<'_>]) -> Result<Event, OscReject> {
        match address {
            FORCE_ADDRESS => {
                let channel = self.channel(first)?;
                if rest.is_empty() || rest.len() > MAX_SENSORS {
                    return Err(OscReject::Arguments);
                }
                let mut newtons = [0.0f32; MAX_SENSORS];
                for (v, arg) in newtons.iter_mut().zip(rest) {
                    *v = number(arg)?;
                    if !v.is_finite() {
                        return Err(OscReject::Value);
                    }
                }
                let reading =
                    SensorReading::new(&newtons[..rest.len()]).ok_or(OscReject::Arguments)?;
                Ok(Event::Force { channel, reading })
            }
            STEP_ADDRESS => {
                let channel = self.channel(first)?;
                let intensity = match rest {
                    [] => 1.0,
                    [i] => number(i)?,
                    _ => return Err(OscReject::Arguments),
                };
                if !(intensity.is_finite() && intensity >= 0.0) {
                    return Err(OscReject::Value);
                }
                Ok(Event::Step { channel, intensity })
            }
            MATERIAL_ADDRESS => {
                let channel = self.channel(first)?;
                let [Arg::Str(name)] = rest else {
                    return Err(OscReject::Arguments);
                };
                let slot = self
                    .materials
                    .iter()
                    .position(|m| m == name)
                    .and_then(|s| u16::try_from(s).ok())
                    .ok_or(OscReject::UnknownMaterial)?;
                Ok(Event::Material { channel, slot })
            }
            _ => Err(OscReject::UnknownAddress),
        }
    }

    fn channel(&self, arg: &Arg<'_>) -> Result<u16, OscReject> {
        let ch = match *arg {
            Arg::Int(i) => i64::from(i),
            Arg::Long(l) => l,
            Arg::Float(f) => whole(f64::from(f))?,
            Arg::Double(d) => whole(d)?,
            _ => return Err(OscReject::Arguments),
        };
        // Channel 1 is the engine's first.
        match usize::try_from(ch) {
            Ok(c) if (1..=self.channels).contains(&c) => {
                u16::try_from(c - 1).map_err(|_| OscReject::Channel(ch))
            }
            _ => Err(OscReject::Channel(ch)),
        }
    }
}

/// A marker's arguments: its text, then optionally its trial (a whole number), its
/// participant and its condition.
fn marker(first: &Arg<'_>, rest: &[Arg<'_>]) -> Result<Marker, OscReject> {
    let Arg::Str(text) = *first else {
        return Err(OscReject::Arguments);
    };
    let mut m = Marker::new(text);
    let mut rest = rest.iter();
    if let Some(trial) = rest.next() {
        let t = match *trial {
            Arg::Int(i) => i64::from(i),
            Arg::Long(l) => l,
            Arg::Float(f) => whole(f64::from(f))?,
            Arg::Double(d) => whole(d)?,
            _ => return Err(OscReject::Arguments),
        };
        m.trial = Some(u32::try_from(t).map_err(|_| OscReject::Arguments)?);
    }
    for field in [&mut m.participant, &mut m.condition] {
        match rest.next() {
            Some(Arg::Str(s)) => *field = Some((*s).to_owned()),
            Some(_) => return Err(OscReject::Arguments),
            None => break,
        }
    }
    if rest.next().is_some() {
        return Err(OscReject::Arguments);
    }
    m.check().map_err(|_| OscReject::Marker)?;
    Ok(m)
}

/// A float channel number as an integer, if it is a whole one.
fn whole(x: f64) -> Result<i64, OscReject> {
    // Beyond 2^53 every float is whole, but no channel is that large; the range check
    // keeps the cast exact.
    if x.fract() == 0.0 && x.abs() < 9.0e15 {
        Ok(x as i64)
    } else {
        Err(OscReject::Arguments)
    }
}

/// Any numeric argument as `f32`; out-of-range values become infinite and are caught by the
/// finiteness checks.
fn number(arg: &Arg<'_>) -> Result<f32, OscReject> {
    match *arg {
        Arg::Int(i) => Ok(i as f32),
        Arg::Long(l) => Ok(l as f32),
        Arg::Float(f) => Ok(f),
        Arg::Double(d) => Ok(d as f32),
        _ => Err(OscReject::Arguments),
    }
}

/// OSC over UDP as an [`EventSource`].
pub struct OscSource {
    socket: UdpSocket,
    device: String,
    decoder: OscDecoder,
    /// One datagram; the largest UDP payload fits, so nothing is cut short.
    buf: Vec<u8>,
    /// The socket's current settings, to skip setting them again on every poll.
    nonblocking: bool,
    read_timeout: Option<Duration>,
    stats: SourceStats,
    rejections: OscRejectCounts,
    /// The most recent rejection, so that a log can say what the last refused message did wrong.
    last_reject: Option<OscReject>,
    /// Markers received, waiting for the session to take them.
    markers: std::collections::VecDeque<Marker>,
}

impl std::fmt::Debug for OscSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Not the datagram buffer: 64 KiB of bytes would drown the rest.
        f.debug_struct("OscSource")
            .field("device", &self.device)
            .field("decoder", &self.decoder)
            .field("stats", &self.stats)
            .field("rejections", &self.rejections)
            .finish_non_exhaustive()
    }
}

/// Most datagrams taken per poll after the first, so that a flood cannot hold a poll forever.
const MAX_DRAIN_DATAGRAMS: usize = 64;

impl OscSource {
    /// Listens on `addr` (`0.0.0.0:9000`; port 0 picks a free one) for `channels` channels,
    /// with `material_names` naming the engine's material slots in order.
    ///
    /// # Errors
    /// [`IoError::Unsupported`] for no channels, or more channels or materials than a `u16`
    /// can index; [`IoError::Open`] if the address cannot be bound.
    pub fn bind(addr: &str, material_names: Vec<String>, channels: usize) -> Result<Self, IoError> {
        let decoder =
            OscDecoder::new(material_names, channels).map_err(|e| IoError::Unsupported {
                device: addr.to_string(),
                reason: e.to_string(),
            })?;
        let socket = UdpSocket::bind(addr).map_err(|e| IoError::Open {
            device: addr.to_string(),
            reason: e.to_string(),
        })?;
        Ok(Self {
            socket,
            device: addr.to_string(),
            decoder,
            buf: vec![0; 1 << 16],
            nonblocking: false,
            read_timeout: None,
            stats: SourceStats::default(),
            rejections: OscRejectCounts::default(),
            last_reject: None,
            markers: std::collections::VecDeque::new(),
        })
    }

    /// Rejections so far by reason; [`SourceStats::rejected`] is their total.
    pub fn rejections(&self) -> OscRejectCounts {
        self.rejections
    }

    /// Why the most recent rejected packet or message was refused, if any was.
    pub fn last_reject(&self) -> Option<OscReject> {
        self.last_reject
    }

    /// The address actually bound, e.g. to learn the port picked for port 0.
    ///
    /// # Errors
    /// [`IoError::Io`] if the socket cannot say.
    pub fn local_addr(&self) -> Result<SocketAddr, IoError> {
        self.socket.local_addr().map_err(|e| self.io_error(e))
    }

    fn io_error(&self, source: io::Error) -> IoError {
        IoError::Io {
            device: self.device.clone(),
            source,
        }
    }

    /// Receives one datagram, waiting up to `wait` (not at all for `None` or zero).
    fn recv(&mut self, wait: Option<Duration>) -> Result<Option<usize>, IoError> {
        let wait = wait.filter(|w| !w.is_zero());
        let nonblocking = wait.is_none();
        if nonblocking != self.nonblocking {
            self.socket
                .set_nonblocking(nonblocking)
                .map_err(|e| self.io_error(e))?;
            self.nonblocking = nonblocking;
        }
        if wait.is_some() && wait != self.read_timeout {
            self.socket
                .set_read_timeout(wait)
                .map_err(|e| self.io_error(e))?;
            self.read_timeout = wait;
        }
        match self.socket.recv(&mut self.buf) {
            Ok(n) => Ok(Some(n)),
            Err(e) => match e.kind() {
                // Timeouts show as either kind depending on the platform. A refused or reset
                // "connection" is an ICMP error from an earlier send reported on this socket
                // (Windows does so); it says nothing about the next datagram.
                io::ErrorKind::WouldBlock
                | io::ErrorKind::TimedOut
                | io::ErrorKind::Interrupted
                | io::ErrorKind::ConnectionRefused
                | io::ErrorKind::ConnectionReset => Ok(None),
                _ => Err(self.io_error(e)),
            },
        }
    }

    fn handle(&mut self, n: usize, out: &mut dyn FnMut(Event)) {
        let stats = &mut self.stats;
        let rejections = &mut self.rejections;
        let last_reject = &mut self.last_reject;
        let markers = &mut self.markers;
        self.decoder
            .decode(&self.buf[..n], &mut |result| match result {
                Ok(Decoded::Event(event)) => {
                    stats.events += 1;
                    out(event);
                }
                Ok(Decoded::Marker(marker)) if markers.len() < MAX_PENDING_MARKERS => {
                    stats.events += 1;
                    markers.push_back(marker);
                }
                Ok(Decoded::Marker(_)) => {
                    stats.rejected += 1;
                    rejections.record(&OscReject::Marker);
                    *last_reject = Some(OscReject::Marker);
                }
                Err(reject) => {
                    stats.rejected += 1;
                    rejections.record(&reject);
                    *last_reject = Some(reject);
                }
            });
    }
}

impl EventSource for OscSource {
    fn poll(
        &mut self,
        timeout: Duration,
        out: &mut dyn FnMut(Event),
    ) -> Result<SourceState, IoError> {
        let Some(n) = self.recv(Some(timeout))? else {
            return Ok(SourceState::Open);
        };
        self.handle(n, out);
        for _ in 0..MAX_DRAIN_DATAGRAMS {
            let Some(n) = self.recv(None)? else { break };
            self.handle(n, out);
        }
        Ok(SourceState::Open)
    }

    fn stats(&self) -> SourceStats {
        self.stats
    }

    fn take_marker(&mut self) -> Option<Marker> {
        self.markers.pop_front()
    }

    fn rejections(&self) -> Vec<(&'static str, u64)> {
        self.rejections
            .by_reason()
            .into_iter()
            .filter(|(_, n)| *n > 0)
            .collect()
    }

    fn last_reject(&self) -> Option<String> {
        self.last_reject.map(|r| r.to_string())
    }
}

#[cfg(test)]
mod tests;
