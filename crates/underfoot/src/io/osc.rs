//! Force, steps and material changes from OSC over UDP, as a VR engine sends them.
//!
//! # Addresses
//!
//! | address | arguments | event |
//! |---|---|---|
//! | `/underfoot/force` | channel, then 1 to 8 forces in newtons | [`Event::Force`] |
//! | `/underfoot/step` | channel, optional intensity (default 1.0) | [`Event::Step`] |
//! | `/underfoot/material` | channel, material name (string) | [`Event::Material`] |
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
//! # What is rejected
//!
//! Counted in [`SourceStats::rejected`] and otherwise ignored: a packet that is not OSC (one
//! count per packet), and each message with an unknown address, the wrong number or types of
//! arguments, a channel out of range, an unknown material, a non-finite force or a
//! non-finite or negative intensity (one count per message; the good messages of a bundle
//! still go through). [`OscDecoder`] says why, for diagnostics and tests.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::time::Duration;

use rosc::{OscMessage, OscPacket, OscType};

use super::{EventSource, IoError, SourceState, SourceStats};
use crate::engine::Event;
use crate::force::{MAX_SENSORS, SensorReading};

/// The address of force readings.
pub const FORCE_ADDRESS: &str = "/underfoot/force";
/// The address of explicit steps.
pub const STEP_ADDRESS: &str = "/underfoot/step";
/// The address of material changes.
pub const MATERIAL_ADDRESS: &str = "/underfoot/material";

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
    /// Not one of the three addresses.
    #[error("unknown address")]
    UnknownAddress,
    /// The wrong number or types of arguments for the address.
    #[error("wrong number or types of arguments")]
    Arguments,
    /// A channel outside `0..channels`.
    #[error("channel {0} out of range")]
    Channel(i64),
    /// A material name not in the table.
    #[error("unknown material")]
    UnknownMaterial,
    /// A non-finite force, or a non-finite or negative intensity.
    #[error("non-finite force or bad intensity")]
    Value,
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
    /// A message if there are no channels, or more channels or materials than a `u16`
    /// index can name.
    pub fn new(material_names: Vec<String>, channels: usize) -> Result<Self, String> {
        if channels == 0 || channels > MAX_INDEX {
            return Err(format!("{channels} channels (1 to {MAX_INDEX})"));
        }
        if material_names.len() > MAX_INDEX {
            return Err(format!(
                "{} materials (at most {MAX_INDEX})",
                material_names.len()
            ));
        }
        Ok(Self {
            materials: material_names,
            channels,
        })
    }

    /// Decodes one datagram; hands `out` each event, or why a message (or the whole packet)
    /// was rejected, in the packet's order.
    pub fn decode(&self, datagram: &[u8], out: &mut dyn FnMut(Result<Event, OscReject>)) {
        // rosc recurses once per bundle level; check the nesting before handing it over.
        if !nesting_within(datagram, MAX_BUNDLE_DEPTH) {
            out(Err(OscReject::TooDeep));
            return;
        }
        match rosc::decoder::decode_udp(datagram) {
            Ok(([], packet)) => self.packet(&packet, out),
            Ok(_) | Err(_) => out(Err(OscReject::NotOsc)),
        }
    }

    fn packet(&self, packet: &OscPacket, out: &mut dyn FnMut(Result<Event, OscReject>)) {
        match packet {
            OscPacket::Message(m) => out(self.message(m)),
            OscPacket::Bundle(b) => {
                for p in &b.content {
                    self.packet(p, out);
                }
            }
        }
    }

    fn message(&self, m: &OscMessage) -> Result<Event, OscReject> {
        let Some((first, rest)) = m.args.split_first() else {
            return Err(match m.addr.as_str() {
                FORCE_ADDRESS | STEP_ADDRESS | MATERIAL_ADDRESS => OscReject::Arguments,
                _ => OscReject::UnknownAddress,
            });
        };
        match m.addr.as_str() {
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
                let [OscType::String(name)] = rest else {
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

    fn channel(&self, arg: &OscType) -> Result<u16, OscReject> {
        let ch = match *arg {
            OscType::Int(i) => i64::from(i),
            OscType::Long(l) => l,
            OscType::Float(f) => whole(f64::from(f))?,
            OscType::Double(d) => whole(d)?,
            _ => return Err(OscReject::Arguments),
        };
        match usize::try_from(ch) {
            Ok(c) if c < self.channels => u16::try_from(c).map_err(|_| OscReject::Channel(ch)),
            _ => Err(OscReject::Channel(ch)),
        }
    }
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
fn number(arg: &OscType) -> Result<f32, OscReject> {
    match *arg {
        OscType::Int(i) => Ok(i as f32),
        OscType::Long(l) => Ok(l as f32),
        OscType::Float(f) => Ok(f),
        OscType::Double(d) => Ok(d as f32),
        _ => Err(OscReject::Arguments),
    }
}

/// Whether bundles in `bytes` nest at most `levels` deep. Malformed bundles pass: rosc
/// rejects them, and only their depth is this check's business.
fn nesting_within(bytes: &[u8], levels: usize) -> bool {
    const TAG: &[u8] = b"#bundle\0";
    if !bytes.starts_with(TAG) {
        return true;
    }
    let Some(levels) = levels.checked_sub(1) else {
        return false;
    };
    // The tag, then an 8-byte time tag, then elements of a big-endian size and content.
    let mut rest = bytes.get(TAG.len() + 8..).unwrap_or_default();
    while let Some((size, after)) = rest.split_first_chunk::<4>() {
        let size = u32::from_be_bytes(*size) as usize;
        let Some(element) = after.get(..size) else {
            return true;
        };
        if !nesting_within(element, levels) {
            return false;
        }
        rest = &after[size..];
    }
    true
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
}

impl std::fmt::Debug for OscSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Not the datagram buffer: 64 KiB of bytes would drown the rest.
        f.debug_struct("OscSource")
            .field("device", &self.device)
            .field("decoder", &self.decoder)
            .field("stats", &self.stats)
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
            OscDecoder::new(material_names, channels).map_err(|reason| IoError::Unsupported {
                device: addr.to_string(),
                reason,
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
        })
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
        self.decoder
            .decode(&self.buf[..n], &mut |result| match result {
                Ok(event) => {
                    stats.events += 1;
                    out(event);
                }
                Err(_) => stats.rejected += 1,
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;
    use proptest::prelude::*;
    use rosc::{OscBundle, OscTime};
    use std::time::Instant;

    fn msg(addr: &str, args: Vec<OscType>) -> OscPacket {
        OscPacket::Message(OscMessage {
            addr: addr.to_string(),
            args,
        })
    }

    fn bundle(content: Vec<OscPacket>) -> OscPacket {
        OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content,
        })
    }

    fn bytes(p: &OscPacket) -> Vec<u8> {
        rosc::encoder::encode(p).unwrap()
    }

    fn names() -> Vec<String> {
        ["gravel", "snow", "wood"].map(String::from).to_vec()
    }

    fn decoded(d: &OscDecoder, datagram: &[u8]) -> Vec<Result<Event, OscReject>> {
        let mut v = Vec::new();
        d.decode(datagram, &mut |r| v.push(r));
        v
    }

    fn force(channel: u16, newtons: &[f32]) -> Event {
        Event::Force {
            channel,
            reading: SensorReading::new(newtons).unwrap(),
        }
    }

    /// Good packets and the events they should make.
    fn good() -> Vec<(OscPacket, Vec<Event>)> {
        use OscType::{Double, Float, Int, Long, String as Str};
        vec![
            (
                msg(FORCE_ADDRESS, vec![Int(1), Float(612.5)]),
                vec![force(1, &[612.5])],
            ),
            (
                msg(FORCE_ADDRESS, vec![Float(0.0), Int(300), Double(2.5)]),
                vec![force(0, &[300.0, 2.5])],
            ),
            (
                msg(STEP_ADDRESS, vec![Int(1)]),
                vec![Event::Step {
                    channel: 1,
                    intensity: 1.0,
                }],
            ),
            (
                msg(STEP_ADDRESS, vec![Long(0), Int(2)]),
                vec![Event::Step {
                    channel: 0,
                    intensity: 2.0,
                }],
            ),
            (
                msg(MATERIAL_ADDRESS, vec![Int(1), Str("wood".into())]),
                vec![Event::Material {
                    channel: 1,
                    slot: 2,
                }],
            ),
            (
                bundle(vec![
                    msg(MATERIAL_ADDRESS, vec![Int(0), Str("snow".into())]),
                    bundle(vec![msg(STEP_ADDRESS, vec![Int(0), Float(0.5)])]),
                    msg(FORCE_ADDRESS, vec![Int(0), Float(1.0), Float(2.0)]),
                ]),
                vec![
                    Event::Material {
                        channel: 0,
                        slot: 1,
                    },
                    Event::Step {
                        channel: 0,
                        intensity: 0.5,
                    },
                    force(0, &[1.0, 2.0]),
                ],
            ),
        ]
    }

    fn nested(levels: usize) -> OscPacket {
        let mut p = msg(STEP_ADDRESS, vec![OscType::Int(0)]);
        for _ in 0..levels {
            p = bundle(vec![p]);
        }
        p
    }

    /// Malformed datagrams, each to be rejected once, and the reason.
    fn malformed() -> Vec<(&'static str, Vec<u8>, OscReject)> {
        use OscType::{Float, Int, String as Str};
        let mut noise = SplitMix64::new(7);
        let random: Vec<u8> = (0..97).map(|_| noise.next_u64() as u8).collect();
        let mut truncated = bytes(&msg(FORCE_ADDRESS, vec![Int(0), Float(1.0)]));
        truncated.truncate(truncated.len() - 3);
        vec![
            ("random bytes", random, OscReject::NotOsc),
            ("empty", vec![], OscReject::NotOsc),
            ("truncated", truncated, OscReject::NotOsc),
            (
                "unknown address",
                bytes(&msg("/underfoot/jump", vec![Int(0)])),
                OscReject::UnknownAddress,
            ),
            (
                "force as a string",
                bytes(&msg(FORCE_ADDRESS, vec![Int(0), Str("heavy".into())])),
                OscReject::Arguments,
            ),
            (
                "force without a value",
                bytes(&msg(FORCE_ADDRESS, vec![Int(0)])),
                OscReject::Arguments,
            ),
            (
                "nine sensors",
                bytes(&msg(
                    FORCE_ADDRESS,
                    std::iter::once(Int(0))
                        .chain(std::iter::repeat_n(Float(1.0), 9))
                        .collect(),
                )),
                OscReject::Arguments,
            ),
            (
                "channel as a string",
                bytes(&msg(STEP_ADDRESS, vec![Str("0".into())])),
                OscReject::Arguments,
            ),
            (
                "fractional channel",
                bytes(&msg(STEP_ADDRESS, vec![Float(0.5)])),
                OscReject::Arguments,
            ),
            (
                "channel too high",
                bytes(&msg(STEP_ADDRESS, vec![Int(2)])),
                OscReject::Channel(2),
            ),
            (
                "negative channel",
                bytes(&msg(FORCE_ADDRESS, vec![Int(-1), Float(1.0)])),
                OscReject::Channel(-1),
            ),
            (
                "unknown material",
                bytes(&msg(MATERIAL_ADDRESS, vec![Int(0), Str("lava".into())])),
                OscReject::UnknownMaterial,
            ),
            (
                "material as a slot number",
                bytes(&msg(MATERIAL_ADDRESS, vec![Int(0), Int(1)])),
                OscReject::Arguments,
            ),
            (
                "NaN force",
                bytes(&msg(
                    FORCE_ADDRESS,
                    vec![Int(0), Float(1.0), Float(f32::NAN)],
                )),
                OscReject::Value,
            ),
            (
                "infinite force",
                bytes(&msg(FORCE_ADDRESS, vec![Int(0), OscType::Double(1e300)])),
                OscReject::Value,
            ),
            (
                "negative intensity",
                bytes(&msg(STEP_ADDRESS, vec![Int(0), Float(-1.0)])),
                OscReject::Value,
            ),
            ("bundles too deep", bytes(&nested(20)), OscReject::TooDeep),
        ]
    }

    #[test]
    fn good_packets_make_the_right_events() {
        let d = OscDecoder::new(names(), 2).unwrap();
        for (packet, want) in good() {
            let got = decoded(&d, &bytes(&packet));
            assert_eq!(
                got,
                want.into_iter().map(Ok).collect::<Vec<_>>(),
                "{packet:?}"
            );
        }
        assert_eq!(decoded(&d, &bytes(&nested(MAX_BUNDLE_DEPTH))).len(), 1);
    }

    #[test]
    fn malformed_packets_say_why() {
        let d = OscDecoder::new(names(), 2).unwrap();
        for (what, datagram, why) in malformed() {
            assert_eq!(decoded(&d, &datagram), vec![Err(why)], "{what}");
        }
        // A bad message in a bundle costs only itself.
        let mixed = bundle(vec![
            msg(STEP_ADDRESS, vec![OscType::Int(5)]),
            msg(STEP_ADDRESS, vec![OscType::Int(1)]),
        ]);
        let got = decoded(&d, &bytes(&mixed));
        assert_eq!(got[0], Err(OscReject::Channel(5)));
        assert!(got[1].is_ok());
        // Bytes after a message make the packet suspect.
        let mut trailing = bytes(&msg(STEP_ADDRESS, vec![OscType::Int(1)]));
        trailing.extend([0, 0, 0, 0]);
        assert_eq!(decoded(&d, &trailing), vec![Err(OscReject::NotOsc)]);
    }

    #[test]
    fn bad_tables_are_refused() {
        assert!(OscDecoder::new(names(), 0).is_err());
        assert!(OscDecoder::new(names(), MAX_INDEX + 1).is_err());
        assert!(OscDecoder::new(vec![String::new(); MAX_INDEX + 1], 1).is_err());
        assert!(matches!(
            OscSource::bind("127.0.0.1:0", names(), 0),
            Err(IoError::Unsupported { .. })
        ));
        assert!(matches!(
            OscSource::bind("not an address", names(), 1),
            Err(IoError::Open { .. })
        ));
    }

    /// Polls until `n` events arrived or a second passed.
    fn receive(source: &mut OscSource, n: usize) -> Vec<Event> {
        let mut events = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(2);
        while events.len() < n && Instant::now() < deadline {
            let state = source
                .poll(Duration::from_millis(20), &mut |e| events.push(e))
                .unwrap();
            assert_eq!(state, SourceState::Open);
        }
        events
    }

    #[test]
    fn udp_round_trip() {
        let mut source = OscSource::bind("127.0.0.1:0", names(), 2).unwrap();
        let to = source.local_addr().unwrap();
        let sender = UdpSocket::bind("127.0.0.1:0").unwrap();

        // Nothing sent: a poll waits about its timeout and returns empty.
        let start = Instant::now();
        let mut none = 0;
        source
            .poll(Duration::from_millis(30), &mut |_| none += 1)
            .unwrap();
        assert_eq!(none, 0);
        assert!(start.elapsed() >= Duration::from_millis(25));
        // A zero timeout does not wait at all.
        source.poll(Duration::ZERO, &mut |_| none += 1).unwrap();
        assert_eq!(none, 0);

        let mut want = Vec::new();
        for (packet, events) in good() {
            sender.send_to(&bytes(&packet), to).unwrap();
            want.extend(events);
        }
        assert_eq!(receive(&mut source, want.len()), want);
        assert_eq!(source.stats().events, want.len() as u64);
        assert_eq!(source.stats().rejected, 0);

        let bad = malformed();
        for (_, datagram, _) in &bad {
            sender.send_to(datagram, to).unwrap();
        }
        let after = msg(STEP_ADDRESS, vec![OscType::Int(1), OscType::Float(0.25)]);
        sender.send_to(&bytes(&after), to).unwrap();
        let got = receive(&mut source, 1);
        assert_eq!(
            got,
            vec![Event::Step {
                channel: 1,
                intensity: 0.25
            }]
        );
        let stats = source.stats();
        eprintln!(
            "osc: {} good datagrams, {} malformed; {} events, {} rejected",
            good().len() + 1,
            bad.len(),
            stats.events,
            stats.rejected
        );
        assert_eq!(stats.rejected, bad.len() as u64);
        assert_eq!(stats.events, want.len() as u64 + 1);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn random_datagrams_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let d = OscDecoder::new(names(), 2).unwrap();
            d.decode(&bytes, &mut |_| {});
        }

        #[test]
        fn damaged_packets_never_panic(
            which in 0usize..6,
            edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..8),
            cut in any::<usize>(),
        ) {
            let d = OscDecoder::new(names(), 2).unwrap();
            let mut datagram = bytes(&good()[which].0);
            for (at, b) in edits {
                let n = datagram.len();
                datagram[at % n] = b;
            }
            datagram.truncate(cut % (datagram.len() + 1));
            let mut events = 0;
            d.decode(&datagram, &mut |r| {
                if let Ok(e) = r {
                    events += 1;
                    // Whatever got through is within the table.
                    assert!(usize::from(e.channel()) < 2);
                    if let Event::Force { reading, .. } = e {
                        assert!(reading.is_finite());
                    }
                }
            });
            prop_assert!(events <= 3);
        }
    }
}
