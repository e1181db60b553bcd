//! Force from a microcontroller over a serial port: a small framed binary protocol.
//!
//! The sender is a 16-bit microcontroller (an ATmega, an MSP430) sampling force sensors with
//! its ADC. The protocol is shaped by what such a part does cheaply and by what a serial line
//! does wrong: it flips bits, drops bytes under load, and is opened half-way through a frame.
//!
//! # Frame
//!
//! A frame is a *payload*, byte-stuffed with COBS (Consistent Overhead Byte Stuffing) so that
//! it contains no `0x00`, between two `0x00` delimiters:
//!
//! ```text
//! 0x00 | COBS(payload) | 0x00
//! ```
//!
//! The payload, before stuffing (all multi-byte fields little-endian). There are two frame
//! types, told apart by the first byte, with one shared layout so that one decoder and one
//! CRC routine serve both directions:
//!
//! | offset | size | field | value |
//! |---|---|---|---|
//! | 0 | 1 | type | `0x01`: force frame ([`FORCE_FRAME`], device to host); `0x02`: servo-target frame ([`SERVO_FRAME`], host to device) |
//! | 1 | 2 | sequence number | `u16`, +1 per frame sent *of this type by this sender*, wrapping at 65535 |
//! | 3 | 1 | value count `n` | force: 1 to 64 ([`MAX_FRAME_SENSORS`]); servo: 1 to 16 ([`MAX_FRAME_SERVOS`]) |
//! | 4 | 2`n` | values | `n` × `u16`: force: raw ADC counts, in layout order; servo: target pulse widths in µs, servo 0 first |
//! | 4 + 2`n` | 2 | checksum | CRC-16/CCITT-FALSE of bytes 0 to 3 + 2`n` |
//!
//! So a frame of `n` values is `6 + 2n` payload bytes and `9 + 2n` bytes on the wire (COBS
//! adds one byte below 254, plus two delimiters): 17 bytes for heel and toe of both feet,
//! about 670 frames a second at 115200 baud; 15 bytes for three servos, so 100 servo
//! frames a second take 1.3% of the return direction.
//!
//! The type byte was the version byte of protocol version 1, which had only force frames;
//! a version-1 force frame is unchanged. A sound frame (checksum correct) of a type the
//! receiver does not know is rejected as one unit, counted ([`FrameError::UnknownType`],
//! [`DecoderStats::unknown_type`]), and decoding goes on at the next delimiter: a newer
//! sender does not crash an older receiver, and the count shows the mismatch.
//!
//! ## Servo-target frames
//!
//! The host sends one servo frame at a fixed rate (the interface configuration's
//! `servo_rate_hz`, 50 to 100 Hz; standard RC servos take a new pulse every 20 ms, so a
//! faster rate buys nothing), whether or not a target changed. The host already applies
//! the range, dead band and rate limit (`interface::servo`), so every target is one to
//! write to the servo's PWM timer as it is. The firmware must:
//!
//! - decode frames with the same COBS and CRC as it encodes force frames, and drop any
//!   frame whose CRC fails, whose type is not `0x02`, or whose count is not its servo
//!   count, keeping the previous targets;
//! - clamp each target to the servo's mechanical limits (a second guard, in case the host
//!   is misconfigured);
//! - treat the periodic frame as a heartbeat: with no valid servo frame for a timeout
//!   (a few frame periods, e.g. 200 ms) return every servo to its rest position slowly,
//!   so that a crashed host or a pulled cable leaves no pressure on the limb;
//! - keep sending force frames at its sensor rate regardless of servo traffic (the two
//!   directions are independent on a full-duplex UART).
//!
//! The host does the same in the other direction: with no force frame for
//! `insole_timeout_s` its servo targets return to rest at their rate limit, and the
//! engine's watchdog fades the vibration out. Servo frames are never sent from the audio
//! thread: the input poll thread decodes force frames, and a heartbeat thread of its own
//! writes servo frames on a fixed deadline, whatever the poll thread is doing
//! (`io::prosthetic`, *Heartbeat*).
//!
//! ## Why these choices
//!
//! - **COBS with a delimiter on both sides.** `0x00` appears only between frames, so the
//!   receiver resynchronises at the very next delimiter whatever came before: garbage, a
//!   truncated frame or a frame with a dropped byte end at the next `0x00` and are rejected
//!   as one unit. The leading delimiter matters: without it, garbage or a truncated frame
//!   would run into the following good frame and take it down too. Stuffing costs one byte
//!   per 254 and a single pass with no buffer on the sender. (Two consecutive delimiters make
//!   an empty frame, which is ignored.)
//! - **`u16` raw counts**, scaled on the host by [`SerialConfig::scale`] (one factor, or a
//!   calibration curve per sensor). ADCs of
//!   these parts give 10 or 12 bits, so a count fits without a 32-bit multiply (slow on a
//!   16-bit core), at half the bytes of `i32` milli-newtons, and the calibration can change
//!   without reflashing the firmware. A 24-bit load-cell amplifier has to be shifted down to
//!   16 bits by the firmware.
//! - **`u16` pulse widths in µs** for servos: what an RC-servo timer is loaded with, so the
//!   firmware does no arithmetic, and the whole 500 to 2500 µs range fits at 1 µs
//!   resolution (finer than a servo resolves).
//! - **One layout for both types**, so the firmware needs one encoder, one decoder, one
//!   CRC; only the type byte and the count limit differ.
//! - **CRC-16/CCITT-FALSE** (polynomial `0x1021`, initial value `0xFFFF`, not reflected, no
//!   final XOR; check value `0x29B1` for `"123456789"`). It catches every burst of up to 16
//!   flipped bits and every odd number of flipped bits, which is how serial lines fail.
//!   Fletcher-16 is cheaper but cannot tell `0x00` from `0xFF`, and a line held low reads as
//!   a run of zeros. The table-free form costs a few shifts per byte:
//!   `x = (crc >> 8) ^ byte; x ^= x >> 4; crc = (crc << 8) ^ (x << 12) ^ (x << 5) ^ x`.
//! - **A 16-bit sequence number**, so that a gap is counted correctly for up to 65535
//!   missing frames (over a minute at 1 kHz); an 8-bit one would wrap in a quarter second.
//!   Each type has its own counter, and the decoder tracks gaps per type.
//!
//! The sensor count in every frame lets the host check it against the sensors it expects
//! (the [`SerialConfig::layout`]) instead of misreading a frame from differently wired
//! firmware; the servo count does the same for the firmware.
//!
//! # Pieces
//!
//! - [`encode_frame`], [`encode_servo_frame`] and [`FrameDecoder`]: the protocol, with no
//!   I/O.
//! - [`SerialSource`]: a serial port as an [`EventSource`], one [`Event::Force`] per channel
//!   per frame. When the port hangs up it reopens the same path with a [`Backoff`]
//!   (see [`super`], *A lost device*).
//! - [`ReferenceSender`]: the firmware's side, in Rust, for tests and simulation.

use std::io::{self, Read, Write};
use std::time::Duration;

use serialport::SerialPort;

use super::{Backoff, EventSource, IoError, LinkEvent, Reconnect, Retry, SourceState, SourceStats};
use crate::engine::Event;
use crate::force::calibration::ApplyStats;
use crate::force::scale::CountScale;
use crate::force::track::{ForceRow, ForceTrack};
use crate::force::{MAX_SENSORS, SensorReading};

/// The type byte of a force frame (device to host) in protocol version 1.
pub const FRAME_VERSION: u8 = 0x01;

/// The type byte of a force frame: the same as [`FRAME_VERSION`], named for what it is.
pub const FORCE_FRAME: u8 = FRAME_VERSION;

/// The type byte of a servo-target frame (host to device).
pub const SERVO_FRAME: u8 = 0x02;

/// The most sensors one frame can carry: eight channels of [`MAX_SENSORS`] sensors.
pub const MAX_FRAME_SENSORS: usize = 64;

/// The most servo targets one servo frame can carry.
pub const MAX_FRAME_SERVOS: usize = 16;

/// Type, sequence number and value count.
const HEADER_LEN: usize = 4;
const CRC_LEN: usize = 2;
/// The longest valid payload; a longer one is rejected without being stored.
const MAX_PAYLOAD: usize = HEADER_LEN + 2 * MAX_FRAME_SENSORS + CRC_LEN;

/// CRC-16/CCITT-FALSE of `bytes`: polynomial `0x1021`, initial value `0xFFFF`, not
/// reflected, no final XOR.
#[must_use]
pub fn crc16_ccitt_false(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &byte in bytes {
        // The table-free byte step (eight polynomial divisions folded into shifts): what the
        // firmware runs, so the host is checked against the same arithmetic.
        let mut x = (crc >> 8) as u8 ^ byte;
        x ^= x >> 4;
        let x = u16::from(x);
        crc = (crc << 8) ^ (x << 12) ^ (x << 5) ^ x;
    }
    crc
}

/// The content of one frame: a sequence number and up to [`MAX_FRAME_SENSORS`] raw counts.
///
/// Fixed capacity, so that decoding allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameData {
    /// The sender's frame counter.
    pub seq: u16,
    counts: [u16; MAX_FRAME_SENSORS],
    len: u8,
}

impl FrameData {
    /// A frame of `counts`, or `None` if there are none or more than [`MAX_FRAME_SENSORS`].
    #[must_use]
    pub fn new(seq: u16, counts: &[u16]) -> Option<Self> {
        if counts.is_empty() || counts.len() > MAX_FRAME_SENSORS {
            return None;
        }
        let mut c = [0; MAX_FRAME_SENSORS];
        c[..counts.len()].copy_from_slice(counts);
        Some(Self {
            seq,
            counts: c,
            len: counts.len() as u8,
        })
    }

    /// The raw sensor counts, in layout order.
    #[must_use]
    pub fn counts(&self) -> &[u16] {
        &self.counts[..usize::from(self.len)]
    }
}

/// The content of one servo-target frame: a sequence number and up to
/// [`MAX_FRAME_SERVOS`] pulse widths in microseconds, servo `i`'s target at index `i`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServoFrame {
    /// The host's servo-frame counter.
    pub seq: u16,
    targets: [u16; MAX_FRAME_SERVOS],
    len: u8,
}

impl ServoFrame {
    /// A frame of `targets` (µs), or `None` if there are none or more than
    /// [`MAX_FRAME_SERVOS`].
    #[must_use]
    pub fn new(seq: u16, targets: &[u16]) -> Option<Self> {
        if targets.is_empty() || targets.len() > MAX_FRAME_SERVOS {
            return None;
        }
        let mut t = [0; MAX_FRAME_SERVOS];
        t[..targets.len()].copy_from_slice(targets);
        Some(Self {
            seq,
            targets: t,
            len: targets.len() as u8,
        })
    }

    /// The targets in µs, servo 0 first.
    #[must_use]
    pub fn targets(&self) -> &[u16] {
        &self.targets[..usize::from(self.len)]
    }
}

/// A decoded frame of either type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    /// Type `0x01`: raw sensor counts, device to host.
    Force(FrameData),
    /// Type `0x02`: servo targets, host to device.
    Servo(ServoFrame),
}

impl Frame {
    /// The frame's type byte.
    #[must_use]
    pub fn type_byte(&self) -> u8 {
        match self {
            Frame::Force(_) => FORCE_FRAME,
            Frame::Servo(_) => SERVO_FRAME,
        }
    }

    /// The sequence number.
    #[must_use]
    pub fn seq(&self) -> u16 {
        match self {
            Frame::Force(f) => f.seq,
            Frame::Servo(f) => f.seq,
        }
    }
}

/// Appends `frame` to `out` as it goes on the wire, both delimiters included.
pub fn encode_frame(frame: &FrameData, out: &mut Vec<u8>) {
    encode_payload(FORCE_FRAME, frame.seq, frame.counts(), out);
}

/// Appends a servo-target frame to `out` as it goes on the wire, both delimiters included.
pub fn encode_servo_frame(frame: &ServoFrame, out: &mut Vec<u8>) {
    encode_payload(SERVO_FRAME, frame.seq, frame.targets(), out);
}

/// Both frame types share one layout: type, sequence number, count, `u16` values, CRC.
fn encode_payload(kind: u8, seq: u16, values: &[u16], out: &mut Vec<u8>) {
    let mut payload = [0u8; MAX_PAYLOAD];
    let values = &values[..values.len().min(MAX_FRAME_SENSORS)];
    payload[0] = kind;
    payload[1..3].copy_from_slice(&seq.to_le_bytes());
    payload[3] = values.len() as u8;
    for (i, c) in values.iter().enumerate() {
        let at = HEADER_LEN + 2 * i;
        payload[at..at + 2].copy_from_slice(&c.to_le_bytes());
    }
    let body = HEADER_LEN + 2 * values.len();
    let crc = crc16_ccitt_false(&payload[..body]);
    payload[body..body + CRC_LEN].copy_from_slice(&crc.to_le_bytes());
    out.push(0);
    cobs_encode(&payload[..body + CRC_LEN], out);
    out.push(0);
}

/// COBS: each block is a code byte `k` followed by `k - 1` non-zero bytes, and stands for
/// those bytes followed by a zero, except after a full block (`k = 0xFF`) or at the end.
fn cobs_encode(payload: &[u8], out: &mut Vec<u8>) {
    let mut code_at = out.len();
    out.push(0);
    let mut code: u8 = 1;
    for &b in payload {
        if b != 0 {
            out.push(b);
            code += 1;
        }
        if b == 0 || code == 0xFF {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        }
    }
    out[code_at] = code;
}

/// Why a delimited chunk of bytes was not a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FrameError {
    /// Longer than any valid frame: garbage, or two frames whose delimiter was lost.
    #[error("longer than any valid frame")]
    TooLong,
    /// The byte stuffing ends inside a block: the frame was cut short or a byte dropped.
    #[error("byte stuffing broken (frame cut short)")]
    Stuffing,
    /// Shorter than a header and a checksum.
    #[error("{len} bytes is too short for a frame")]
    TooShort {
        /// Payload bytes after unstuffing.
        len: usize,
    },
    /// The checksum does not match the content.
    #[error("checksum {received:#06x}, content gives {computed:#06x}")]
    Checksum {
        /// The CRC of the received content.
        computed: u16,
        /// The CRC the frame carried.
        received: u16,
    },
    /// An unknown type byte (a newer protocol, or a sound frame from something else).
    #[error("unknown frame type {0:#04x}")]
    UnknownType(u8),
    /// A value count of 0 or more than the type allows ([`MAX_FRAME_SENSORS`] sensors,
    /// [`MAX_FRAME_SERVOS`] servos).
    #[error("value count {0} out of range")]
    SensorCount(u8),
    /// The value count does not match the frame's length.
    #[error("{sensors} values declared in a {len}-byte payload")]
    Length {
        /// The declared count.
        sensors: u8,
        /// Payload bytes after unstuffing.
        len: usize,
    },
}

/// What a [`FrameDecoder`] has seen so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecoderStats {
    /// Good frames decoded.
    pub frames: u64,
    /// Delimited chunks that were not good frames (every [`FrameError`]).
    pub rejected: u64,
    /// Of those, the ones with a bad checksum.
    pub bad_checksums: u64,
    /// Of those, sound frames (checksum correct) of an unknown type.
    pub unknown_type: u64,
    /// Bytes of rejected chunks, delimiters not included.
    pub skipped_bytes: u64,
    /// Frames missing from the sequence numbers of good frames (counted per frame type):
    /// lost on the line or rejected. A sender that restarts its counter shows up as a gap
    /// too.
    pub lost: u64,
}

/// Decodes frames from a byte stream cut into chunks of any size.
///
/// Memory is fixed (one longest payload); no input makes it allocate or panic.
#[derive(Debug, Clone)]
pub struct FrameDecoder {
    payload: [u8; MAX_PAYLOAD],
    len: usize,
    /// Data bytes left in the current COBS block; 0 when a code byte is due.
    block_left: u8,
    /// The code byte of the current block; 0 before the first block of a chunk.
    code: u8,
    /// Bytes of the current chunk, for [`DecoderStats::skipped_bytes`] if it is rejected.
    chunk_bytes: u64,
    overflow: bool,
    /// The last sequence number of each frame type (force, servo).
    last_seq: [Option<u16>; 2],
    stats: DecoderStats,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// A decoder with nothing buffered. Bytes before the first delimiter (a port opened in
    /// the middle of a frame) make one rejected chunk.
    #[must_use]
    pub fn new() -> Self {
        Self {
            payload: [0; MAX_PAYLOAD],
            len: 0,
            block_left: 0,
            code: 0,
            chunk_bytes: 0,
            overflow: false,
            last_seq: [None; 2],
            stats: DecoderStats::default(),
        }
    }

    /// Takes one byte; at the end of a chunk, returns the frame or why it is not one.
    ///
    /// Every outcome is already counted in [`stats`](Self::stats).
    pub fn push_byte(&mut self, byte: u8) -> Option<Result<Frame, FrameError>> {
        if byte == 0 {
            return self.end_chunk();
        }
        self.chunk_bytes = self.chunk_bytes.saturating_add(1);
        if self.overflow {
            return None;
        }
        if self.block_left == 0 {
            if self.code != 0 && self.code != 0xFF {
                self.store(0);
            }
            self.code = byte;
            self.block_left = byte - 1;
        } else {
            self.store(byte);
            self.block_left -= 1;
        }
        None
    }

    /// Forgets a partial chunk and the last sequence numbers, keeping the counts: the
    /// stream starts afresh (a port reopened), so what came before neither joins the next
    /// frame nor counts the outage as lost frames.
    pub fn resync(&mut self) {
        self.len = 0;
        self.block_left = 0;
        self.code = 0;
        self.chunk_bytes = 0;
        self.overflow = false;
        self.last_seq = [None; 2];
    }

    /// Takes `bytes` and hands each good frame to `on_frame`; errors are only counted.
    pub fn push(&mut self, bytes: &[u8], mut on_frame: impl FnMut(Frame)) {
        for &b in bytes {
            if let Some(Ok(frame)) = self.push_byte(b) {
                on_frame(frame);
            }
        }
    }

    /// Counts so far.
    #[must_use]
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    fn store(&mut self, byte: u8) {
        if self.len == MAX_PAYLOAD {
            self.overflow = true;
        } else {
            self.payload[self.len] = byte;
            self.len += 1;
        }
    }

    fn end_chunk(&mut self) -> Option<Result<Frame, FrameError>> {
        let bytes = self.chunk_bytes;
        let result = if bytes == 0 {
            None
        } else if self.overflow {
            Some(Err(FrameError::TooLong))
        } else if self.block_left != 0 {
            Some(Err(FrameError::Stuffing))
        } else {
            Some(parse_payload(&self.payload[..self.len]))
        };
        self.len = 0;
        self.block_left = 0;
        self.code = 0;
        self.chunk_bytes = 0;
        self.overflow = false;
        match &result {
            Some(Ok(frame)) => {
                self.stats.frames += 1;
                let slot = &mut self.last_seq[usize::from(matches!(frame, Frame::Servo(_)))];
                if let Some(last) = *slot {
                    self.stats.lost += u64::from(frame.seq().wrapping_sub(last).wrapping_sub(1));
                }
                *slot = Some(frame.seq());
            }
            Some(Err(e)) => {
                self.stats.rejected += 1;
                self.stats.skipped_bytes += bytes;
                match e {
                    FrameError::Checksum { .. } => self.stats.bad_checksums += 1,
                    FrameError::UnknownType(_) => self.stats.unknown_type += 1,
                    _ => {}
                }
            }
            None => {}
        }
        result
    }
}

fn parse_payload(p: &[u8]) -> Result<Frame, FrameError> {
    if p.len() < HEADER_LEN + CRC_LEN {
        return Err(FrameError::TooShort { len: p.len() });
    }
    let (body, crc) = p.split_at(p.len() - CRC_LEN);
    let received = u16::from_le_bytes([crc[0], crc[1]]);
    let computed = crc16_ccitt_false(body);
    if computed != received {
        return Err(FrameError::Checksum { computed, received });
    }
    let most = match body[0] {
        FORCE_FRAME => MAX_FRAME_SENSORS,
        SERVO_FRAME => MAX_FRAME_SERVOS,
        other => return Err(FrameError::UnknownType(other)),
    };
    let sensors = body[3];
    let n = usize::from(sensors);
    if n == 0 || n > most {
        return Err(FrameError::SensorCount(sensors));
    }
    if body.len() != HEADER_LEN + 2 * n {
        return Err(FrameError::Length {
            sensors,
            len: p.len(),
        });
    }
    let seq = u16::from_le_bytes([body[1], body[2]]);
    if body[0] == SERVO_FRAME {
        let mut targets = [0u16; MAX_FRAME_SERVOS];
        for (t, b) in targets.iter_mut().zip(body[HEADER_LEN..].chunks_exact(2)) {
            *t = u16::from_le_bytes([b[0], b[1]]);
        }
        return Ok(Frame::Servo(ServoFrame {
            seq,
            targets,
            len: sensors,
        }));
    }
    let mut counts = [0u16; MAX_FRAME_SENSORS];
    for (c, b) in counts.iter_mut().zip(body[HEADER_LEN..].chunks_exact(2)) {
        *c = u16::from_le_bytes([b[0], b[1]]);
    }
    Ok(Frame::Force(FrameData {
        seq,
        counts,
        len: sensors,
    }))
}

/// Where the force comes from and how its frames map to channels.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialConfig {
    /// The port: `/dev/ttyUSB0`, `/dev/ttyACM0`, `COM3`.
    pub port: String,
    /// Line speed in baud (8 data bits, no parity, 1 stop bit).
    pub baud: u32,
    /// Sensors per channel, in frame order: `[2, 2]` is two channels (feet) of heel and toe,
    /// taking sensors 0-1 and 2-3 of each frame. Every frame must carry exactly the sum.
    pub layout: Vec<usize>,
    /// Counts to newtons: one factor for every sensor, or a curve per sensor from
    /// `underfoot calibrate sensors` (one per sensor of the frame, in frame order).
    pub scale: CountScale,
}

/// Checks a layout and scale; returns the sensors a frame must carry.
fn check_config(config: &SerialConfig) -> Result<usize, String> {
    if config.layout.is_empty() {
        return Err("the layout has no channels".into());
    }
    if let Some(bad) = config.layout.iter().find(|&&n| n == 0 || n > MAX_SENSORS) {
        return Err(format!(
            "a channel of {bad} sensors (1 to {MAX_SENSORS} per channel)"
        ));
    }
    let sensors: usize = config.layout.iter().sum();
    if sensors > MAX_FRAME_SENSORS {
        return Err(format!(
            "{sensors} sensors in the layout, a frame carries at most {MAX_FRAME_SENSORS}"
        ));
    }
    config.scale.check(sensors).map_err(|e| e.to_string())?;
    Ok(sensors)
}

/// A serial port as an [`EventSource`]: each good frame becomes one [`Event::Force`] per
/// channel of the [`SerialConfig::layout`], in channel order.
///
/// Frames whose sensor count differs from the layout are rejected and counted in
/// [`SourceStats::rejected`] along with the decoder's rejections.
pub struct SerialSource {
    /// `None` while the port is lost.
    port: Option<Box<dyn SerialPort>>,
    device: String,
    baud: u32,
    link: Reconnect,
    layout: Vec<usize>,
    sensors: usize,
    scale: CountScale,
    decoder: FrameDecoder,
    /// One frame in newtons, reused so that scaling allocates nothing.
    newtons: [f32; MAX_FRAME_SENSORS],
    scaling: ApplyStats,
    /// The port's current read timeout, to skip setting it again on every poll.
    timeout: Duration,
    buf: [u8; 256],
    events: u64,
    mismatched: u64,
}

impl std::fmt::Debug for SerialSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialSource")
            .field("device", &self.device)
            .field("layout", &self.layout)
            .field("scale", &self.scale)
            .field("decoder", &self.decoder.stats())
            .finish_non_exhaustive()
    }
}

/// Most reads per poll after the first, so that a fast sender cannot hold a poll forever.
const MAX_DRAIN_READS: usize = 16;

impl SerialSource {
    /// Opens `config.port` at `config.baud`, 8N1, no flow control.
    ///
    /// # Errors
    /// [`IoError::Unsupported`] for a bad layout or scale; [`IoError::Open`] if the port
    /// cannot be opened or configured.
    pub fn open(config: &SerialConfig) -> Result<Self, IoError> {
        check_config(config).map_err(|reason| IoError::Unsupported {
            device: config.port.clone(),
            reason,
        })?;
        let port = open_port(&config.port, config.baud, Duration::from_millis(10))?;
        Self::with_port(port, config)
    }

    /// Uses a port that is already open and configured; `config.port` and `config.baud` are
    /// what a reconnection reopens if the port hangs up.
    ///
    /// # Errors
    /// [`IoError::Unsupported`] for a bad layout or scale.
    pub fn with_port(port: Box<dyn SerialPort>, config: &SerialConfig) -> Result<Self, IoError> {
        let sensors = check_config(config).map_err(|reason| IoError::Unsupported {
            device: config.port.clone(),
            reason,
        })?;
        let timeout = port.timeout();
        Ok(Self {
            port: Some(port),
            device: config.port.clone(),
            baud: config.baud,
            link: Reconnect::new(&config.port),
            layout: config.layout.clone(),
            sensors,
            scale: config.scale.clone(),
            decoder: FrameDecoder::new(),
            newtons: [0.0; MAX_FRAME_SENSORS],
            scaling: ApplyStats::default(),
            timeout,
            buf: [0; 256],
            events: 0,
            mismatched: 0,
        })
    }

    /// Replaces the delays between attempts to reopen a lost port (default: 100 ms,
    /// doubling to 2 s).
    #[must_use]
    pub fn with_backoff(mut self, backoff: Backoff) -> Self {
        self.link.set_backoff(backoff);
        self
    }

    /// The decoder's counts: checksum failures and lost frames, beyond [`SourceStats`].
    #[must_use]
    pub fn decoder_stats(&self) -> DecoderStats {
        self.decoder.stats()
    }

    /// What scaling met: readings clamped to a calibration curve's range, non-finite
    /// results. Always zero for a uniform scale.
    #[must_use]
    pub fn scaling_stats(&self) -> ApplyStats {
        self.scaling
    }

    /// Reads once, waiting up to the port's timeout. `None` when nothing came or the port
    /// was lost (then it is closed and an outage begins).
    fn read_some(&mut self) -> Option<usize> {
        let port = self.port.as_mut()?;
        match port.read(&mut self.buf) {
            // End of file on a terminal is a hang-up.
            Ok(0) => {
                self.lose("the port hung up (end of file)".into());
                None
            }
            Ok(n) => Some(n),
            Err(e) if is_quiet(&e) => None,
            // Every other failure of an open port is the device going away: serialport
            // reports a hang-up (a USB adapter unplugged, the far end of a pseudo-terminal
            // closed) as a broken pipe, a vanished device as EIO. Reopening is the only
            // remedy, and retrying the dead descriptor would return at once forever.
            Err(e) => {
                self.lose(describe(&e));
                None
            }
        }
    }

    /// Closes the lost port and starts waiting to reopen it.
    fn lose(&mut self, reason: String) {
        self.port = None;
        self.link.lose(reason);
    }

    /// While the port is lost: waits up to `timeout`, reopening it when an attempt is due.
    fn poll_lost(&mut self, timeout: Duration) -> SourceState {
        let (device, baud, port_timeout) = (&self.device, self.baud, self.timeout);
        match self
            .link
            .retry(timeout, || open_port(device, baud, port_timeout))
        {
            Retry::NotLost => SourceState::Open,
            Retry::Waiting => SourceState::Disconnected,
            Retry::Back(port) => {
                self.port = Some(port);
                self.decoder.resync();
                SourceState::Open
            }
        }
    }

    fn feed(&mut self, n: usize, out: &mut dyn FnMut(Event)) {
        for i in 0..n {
            let byte = self.buf[i];
            match self.decoder.push_byte(byte) {
                Some(Ok(Frame::Force(frame))) => self.deliver(&frame, out),
                // A servo frame travels host to device; one arriving here is echo or
                // crossed wiring, and is refused like a mismatched frame.
                Some(Ok(Frame::Servo(_))) => self.mismatched += 1,
                _ => {}
            }
        }
    }

    fn deliver(&mut self, frame: &FrameData, out: &mut dyn FnMut(Event)) {
        let counts = frame.counts();
        if counts.len() != self.sensors {
            self.mismatched += 1;
            return;
        }
        let s = self.scale.apply(counts, &mut self.newtons[..self.sensors]);
        self.scaling += s;
        let mut first = 0;
        for (channel, &n) in self.layout.iter().enumerate() {
            let newtons = &self.newtons[first..first + n];
            first += n;
            // The layout was checked at construction, so both always succeed.
            let (Ok(channel), Some(reading)) =
                (u16::try_from(channel), SensorReading::new(newtons))
            else {
                continue;
            };
            out(Event::Force { channel, reading });
            self.events += 1;
        }
    }
}

impl EventSource for SerialSource {
    fn poll(
        &mut self,
        timeout: Duration,
        out: &mut dyn FnMut(Event),
    ) -> Result<SourceState, IoError> {
        let Some(port) = self.port.as_mut() else {
            return Ok(self.poll_lost(timeout));
        };
        if timeout != self.timeout {
            port.set_timeout(timeout)
                .map_err(|e| IoError::Unsupported {
                    device: self.device.clone(),
                    reason: format!("cannot set a read timeout of {timeout:?}: {e}"),
                })?;
            self.timeout = timeout;
        }
        let Some(n) = self.read_some() else {
            return Ok(self.state());
        };
        self.feed(n, out);
        // Bytes that arrived while the first read was handled are taken now rather than a
        // poll later, bounded so that a fast sender cannot keep the poll from returning.
        for _ in 0..MAX_DRAIN_READS {
            let Some(port) = self.port.as_ref() else {
                break;
            };
            match port.bytes_to_read() {
                Ok(0) => break,
                Ok(_) => {}
                Err(e) => {
                    self.lose(e.to_string());
                    break;
                }
            }
            let Some(n) = self.read_some() else { break };
            self.feed(n, out);
        }
        Ok(self.state())
    }

    fn stats(&self) -> SourceStats {
        let d = self.decoder.stats();
        SourceStats {
            events: self.events,
            rejected: d.rejected + self.mismatched,
            skipped_bytes: d.skipped_bytes,
            disconnects: self.link.counts().0,
            reconnects: self.link.counts().1,
        }
    }

    fn link_event(&mut self) -> Option<LinkEvent> {
        self.link.next_event()
    }
}

impl SerialSource {
    fn state(&self) -> SourceState {
        if self.port.is_some() {
            SourceState::Open
        } else {
            SourceState::Disconnected
        }
    }
}

/// Opens `path` at `baud`, 8N1, no flow control, with a read timeout.
///
/// # Errors
/// [`IoError::Open`] if it cannot be opened or configured.
pub(crate) fn open_port(
    path: &str,
    baud: u32,
    timeout: Duration,
) -> Result<Box<dyn SerialPort>, IoError> {
    serialport::new(path, baud)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .timeout(timeout)
        .open()
        .map_err(|e| IoError::Open {
            device: path.to_owned(),
            reason: e.to_string(),
        })
}

/// A read that found nothing (yet): not a failure of the port.
pub(crate) fn is_quiet(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// A lost port's error, for the message.
pub(crate) fn describe(e: &io::Error) -> String {
    if e.kind() == io::ErrorKind::BrokenPipe {
        format!("the port hung up ({e})")
    } else {
        e.to_string()
    }
}

/// The firmware's side of the protocol, in Rust: numbers frames and writes them to any
/// [`Write`], e.g. the other end of a pseudo-terminal in tests, or a real port to stand in
/// for a board.
///
/// It does not pace: the caller sends each frame when it is due.
#[derive(Debug)]
pub struct ReferenceSender<W> {
    out: W,
    seq: u16,
    bytes: Vec<u8>,
}

impl<W: Write> ReferenceSender<W> {
    /// A sender whose first frame has sequence number 0.
    pub fn new(out: W) -> Self {
        Self {
            out,
            seq: 0,
            bytes: Vec::with_capacity(2 * MAX_PAYLOAD),
        }
    }

    /// The next frame of `counts`, taking a sequence number (whether or not it is then
    /// sent, as when firmware drops a frame); `None` if there are no counts or too many.
    pub fn next_frame(&mut self, counts: &[u16]) -> Option<FrameData> {
        let frame = FrameData::new(self.seq, counts)?;
        self.seq = self.seq.wrapping_add(1);
        Some(frame)
    }

    /// Writes `frame` as it is, with its own sequence number.
    ///
    /// # Errors
    /// The writer's.
    pub fn send_frame(&mut self, frame: &FrameData) -> io::Result<()> {
        self.bytes.clear();
        encode_frame(frame, &mut self.bytes);
        self.out.write_all(&self.bytes)
    }

    /// Sends the next frame of raw `counts`.
    ///
    /// # Errors
    /// [`io::ErrorKind::InvalidInput`] for no counts or more than [`MAX_FRAME_SENSORS`];
    /// otherwise the writer's.
    pub fn send_counts(&mut self, counts: &[u16]) -> io::Result<()> {
        let frame = self
            .next_frame(counts)
            .ok_or_else(|| too_many(counts.len()))?;
        self.send_frame(&frame)
    }

    /// Sends the next frame of forces in newtons, quantised as the ADC would: rounded to
    /// whole counts, below zero read as 0, above the range as 65535.
    ///
    /// # Errors
    /// [`io::ErrorKind::InvalidInput`] for a non-finite force or scale, no forces or more
    /// than [`MAX_FRAME_SENSORS`]; otherwise the writer's.
    pub fn send_newtons(&mut self, newtons: &[f32], newtons_per_count: f32) -> io::Result<()> {
        if newtons.len() > MAX_FRAME_SENSORS {
            return Err(too_many(newtons.len()));
        }
        let mut counts = [0u16; MAX_FRAME_SENSORS];
        for (c, &f) in counts.iter_mut().zip(newtons) {
            *c = to_counts(f, newtons_per_count).ok_or_else(|| {
                io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("{f} N at {newtons_per_count} N per count"),
                )
            })?;
        }
        self.send_counts(&counts[..newtons.len()])
    }

    /// Sends one row of a force track: every channel's sensors, in channel order.
    ///
    /// # Errors
    /// As [`send_newtons`](Self::send_newtons).
    pub fn send_row(&mut self, row: &ForceRow, newtons_per_count: f32) -> io::Result<()> {
        let mut newtons = [0.0f32; MAX_FRAME_SENSORS + 1];
        let mut n = 0;
        for v in row.readings.iter().flat_map(SensorReading::as_slice) {
            // One past the limit is enough for send_newtons to refuse the row.
            if n == newtons.len() {
                break;
            }
            newtons[n] = *v;
            n += 1;
        }
        self.send_newtons(&newtons[..n], newtons_per_count)
    }

    /// Sends every row of `track` back to back; returns the rows sent.
    ///
    /// # Errors
    /// As [`send_newtons`](Self::send_newtons), at the first row that fails.
    pub fn send_track(&mut self, track: &ForceTrack, newtons_per_count: f32) -> io::Result<usize> {
        for row in &track.rows {
            self.send_row(row, newtons_per_count)?;
        }
        Ok(track.rows.len())
    }

    /// The writer, e.g. to write deliberately broken bytes in a test.
    pub fn get_mut(&mut self) -> &mut W {
        &mut self.out
    }

    /// The writer back.
    pub fn into_inner(self) -> W {
        self.out
    }
}

fn too_many(sensors: usize) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{sensors} sensors, a frame carries 1 to {MAX_FRAME_SENSORS}"),
    )
}

fn to_counts(newtons: f32, newtons_per_count: f32) -> Option<u16> {
    if !(newtons.is_finite() && newtons_per_count.is_finite() && newtons_per_count > 0.0) {
        return None;
    }
    let counts = (newtons / newtons_per_count).round();
    // The float-to-int cast saturates, which is the ADC's own clipping.
    Some(counts as u16)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The CRC straight from its definition, one bit at a time.
    fn crc_bitwise(bytes: &[u8]) -> u16 {
        let mut crc: u16 = 0xFFFF;
        for &b in bytes {
            crc ^= u16::from(b) << 8;
            for _ in 0..8 {
                crc = if crc & 0x8000 != 0 {
                    (crc << 1) ^ 0x1021
                } else {
                    crc << 1
                };
            }
        }
        crc
    }

    fn encoded(seq: u16, counts: &[u16]) -> Vec<u8> {
        let mut v = Vec::new();
        encode_frame(&FrameData::new(seq, counts).unwrap(), &mut v);
        v
    }

    /// The force frames in `bytes` (a servo frame fails the test).
    fn decode_all(bytes: &[u8]) -> (Vec<FrameData>, DecoderStats) {
        let mut d = FrameDecoder::new();
        let mut frames = Vec::new();
        d.push(bytes, |f| match f {
            Frame::Force(f) => frames.push(f),
            Frame::Servo(f) => panic!("unexpected {f:?}"),
        });
        (frames, d.stats())
    }

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16_ccitt_false(b"123456789"), 0x29B1);
        assert_eq!(crc_bitwise(b"123456789"), 0x29B1);
        assert_eq!(crc16_ccitt_false(b""), 0xFFFF);
    }

    #[test]
    fn layout_of_a_frame() {
        // Two sensors, 0x0102 and 0x0000: the zeros in the payload are stuffed away.
        let wire = encoded(0x0304, &[0x0102, 0x0000]);
        let payload = [0x01, 0x04, 0x03, 0x02, 0x02, 0x01, 0x00, 0x00];
        let crc = crc16_ccitt_false(&payload).to_le_bytes();
        let mut expected = vec![0x00, 0x07, 0x01, 0x04, 0x03, 0x02, 0x02, 0x01, 0x01];
        // The CRC bytes, stuffed by hand: a zero closes the block.
        let mut block = vec![];
        for b in crc {
            if b == 0 {
                expected.push(block.len() as u8 + 1);
                expected.append(&mut block);
            } else {
                block.push(b);
            }
        }
        expected.push(block.len() as u8 + 1);
        expected.append(&mut block);
        expected.push(0x00);
        assert_eq!(wire, expected);
        assert_eq!(wire.len(), 9 + 2 * 2);
        assert!(!wire[1..wire.len() - 1].contains(&0));
    }

    #[test]
    fn round_trip_with_zeros_and_full_blocks() {
        for counts in [
            vec![0u16],
            vec![0; MAX_FRAME_SENSORS],
            vec![0xFFFF; MAX_FRAME_SENSORS],
            (0..MAX_FRAME_SENSORS as u16).map(|i| i * 1000).collect(),
        ] {
            let (frames, stats) = decode_all(&encoded(9, &counts));
            assert_eq!(frames.len(), 1);
            assert_eq!(frames[0].counts(), &counts[..]);
            assert_eq!(frames[0].seq, 9);
            assert_eq!(stats.rejected, 0);
        }
    }

    #[test]
    fn cobs_blocks_longer_than_254_round_trip() {
        // Frames never get this long, but the stuffing must still be COBS; decoded here by
        // the textbook rule rather than the decoder's length-limited state machine.
        for payload in [
            (0..600u32).map(|i| (i % 251 + 1) as u8).collect::<Vec<_>>(),
            vec![7; 254],
            vec![0; 3],
        ] {
            let mut wire = Vec::new();
            cobs_encode(&payload, &mut wire);
            assert!(!wire.contains(&0));
            let mut out = Vec::new();
            let mut at = 0;
            while at < wire.len() {
                let code = usize::from(wire[at]);
                out.extend(&wire[at + 1..at + code]);
                at += code;
                if code != 0xFF && at < wire.len() {
                    out.push(0);
                }
            }
            assert_eq!(out, payload);
        }
    }

    /// A delimited frame of `payload` and its correct checksum.
    fn frame_of(payload: &[u8]) -> Vec<u8> {
        let mut p = payload.to_vec();
        p.extend(crc16_ccitt_false(payload).to_le_bytes());
        let mut wire = vec![0];
        cobs_encode(&p, &mut wire);
        wire.push(0);
        wire
    }

    #[test]
    fn every_rejection_is_named_and_counted() {
        let check = |bytes: Vec<u8>, want: FrameError| {
            let mut d = FrameDecoder::new();
            let results: Vec<_> = bytes.iter().filter_map(|&b| d.push_byte(b)).collect();
            assert_eq!(results, vec![Err(want)], "{bytes:02x?}");
            assert_eq!(d.stats().rejected, 1);
            assert_eq!(d.stats().frames, 0);
            assert_eq!(
                d.stats().bad_checksums,
                u64::from(matches!(want, FrameError::Checksum { .. }))
            );
        };
        let good = encoded(1, &[10, 20]);
        // A bit flipped in a value (byte 6 is the low byte of 10).
        let mut flipped = good.clone();
        flipped[6] ^= 0x10;
        let crc = crc16_ccitt_false(&[1, 1, 0, 2, 10, 0, 20, 0]);
        check(
            flipped,
            FrameError::Checksum {
                computed: crc16_ccitt_false(&[1, 1, 0, 2, 0x1A, 0, 20, 0]),
                received: crc,
            },
        );
        // Cut short inside a block.
        let mut cut = good[..5].to_vec();
        cut.push(0);
        check(cut, FrameError::Stuffing);
        // Stuffing intact but too short.
        check(vec![0, 3, 1, 2, 0], FrameError::TooShort { len: 2 });
        // Garbage longer than any frame.
        let mut long = vec![0];
        long.extend(std::iter::repeat_n(0x55, 1000));
        long.push(0);
        check(long, FrameError::TooLong);
        // Sound frames with a bad header, checksum and all.
        check(frame_of(&[3, 0, 0, 1, 5, 0]), FrameError::UnknownType(3));
        check(frame_of(&[1, 0, 0, 0]), FrameError::SensorCount(0));
        check(frame_of(&[1, 0, 0, 65, 0, 0]), FrameError::SensorCount(65));
        check(
            frame_of(&[1, 0, 0, 3, 5, 0, 6, 0]),
            FrameError::Length {
                sensors: 3,
                len: 10,
            },
        );
    }

    #[test]
    fn resynchronises_after_garbage_with_and_without_zeros() {
        let mut stream = Vec::new();
        stream.extend([0x13, 0x00, 0x55, 0x00, 0x00, 0x41]); // junk, including zeros
        stream.extend(encoded(0, &[1, 2]));
        stream.extend(std::iter::repeat_n(0xAA, 5000)); // a long burst, no zero
        stream.extend(encoded(1, &[3, 4]));
        let (frames, stats) = decode_all(&stream);
        let counts: Vec<_> = frames.iter().map(|f| f.counts().to_vec()).collect();
        assert_eq!(counts, vec![vec![1, 2], vec![3, 4]]);
        // "13", "55", "41" and the burst; the empty chunks between zeros are idle line.
        assert_eq!(stats.rejected, 4);
        assert_eq!(stats.skipped_bytes, 3 + 5000);
        assert_eq!(stats.lost, 0);
    }

    #[test]
    fn lost_frames_are_counted_across_the_wrap() {
        let mut stream = Vec::new();
        for seq in [65533u16, 65534, 1, 2, 6] {
            stream.extend(encoded(seq, &[7]));
        }
        let (frames, stats) = decode_all(&stream);
        assert_eq!(frames.len(), 5);
        // 65535 and 0 between 65534 and 1, then 3, 4 and 5.
        assert_eq!(stats.lost, 5);
    }

    #[test]
    fn layout_of_a_servo_frame() {
        let mut wire = Vec::new();
        encode_servo_frame(
            &ServoFrame::new(0x0102, &[1500, 0x0A0B]).unwrap(),
            &mut wire,
        );
        let payload = [0x02, 0x02, 0x01, 0x02, 0xDC, 0x05, 0x0B, 0x0A];
        let mut want = vec![0];
        let mut p = payload.to_vec();
        p.extend(crc16_ccitt_false(&payload).to_le_bytes());
        cobs_encode(&p, &mut want);
        want.push(0);
        assert_eq!(wire, want);
        assert_eq!(wire.len(), 9 + 2 * 2);
        assert!(ServoFrame::new(0, &[]).is_none());
        assert!(ServoFrame::new(0, &[1; MAX_FRAME_SERVOS + 1]).is_none());
    }

    #[test]
    fn both_frame_types_share_a_stream_and_unknown_types_are_counted() {
        let mut stream = Vec::new();
        for i in 0..5u16 {
            stream.extend(encoded(i, &[i, 2 * i]));
            encode_servo_frame(&ServoFrame::new(i * 3, &[1000 + i]).unwrap(), &mut stream);
            // A sound frame of a type nobody knows, between them.
            stream.extend(frame_of(&[0x7F, 0, 0, 1, 5, 0]));
        }
        let mut d = FrameDecoder::new();
        let mut got = Vec::new();
        d.push(&stream, |f| got.push(f));
        assert_eq!(got.len(), 10);
        for (i, pair) in got.chunks(2).enumerate() {
            let i = i as u16;
            assert_eq!(
                pair[0],
                Frame::Force(FrameData::new(i, &[i, 2 * i]).unwrap())
            );
            assert_eq!(
                pair[1],
                Frame::Servo(ServoFrame::new(i * 3, &[1000 + i]).unwrap())
            );
            assert_eq!(pair[1].type_byte(), SERVO_FRAME);
        }
        let stats = d.stats();
        assert_eq!((stats.rejected, stats.unknown_type), (5, 5));
        // Gaps per type: force frames are consecutive, servo frames skip two each time.
        assert_eq!(stats.lost, 4 * 2);
        // A servo frame may carry at most 16 targets.
        let mut d = FrameDecoder::new();
        let mut p = vec![SERVO_FRAME, 0, 0, 17];
        p.extend([1u8; 34]);
        let results: Vec<_> = frame_of(&p)
            .iter()
            .filter_map(|&b| d.push_byte(b))
            .collect();
        assert_eq!(results, vec![Err(FrameError::SensorCount(17))]);
    }

    #[test]
    fn reference_sender_quantises_like_an_adc() {
        let mut s = ReferenceSender::new(Vec::new());
        s.send_newtons(&[1.26, -3.0, 1e9], 0.5).unwrap();
        assert!(s.send_newtons(&[f32::NAN], 0.5).is_err());
        assert!(s.send_newtons(&[1.0], 0.0).is_err());
        assert!(s.send_counts(&[]).is_err());
        assert!(s.send_newtons(&[1.0; MAX_FRAME_SENSORS + 1], 1.0).is_err());
        let (frames, _) = decode_all(&s.into_inner());
        assert_eq!(frames.len(), 1);
        assert_eq!(frames[0].counts(), &[3, 0, 65535]);
    }

    #[test]
    fn reference_sender_sends_a_track() {
        use crate::force::track::ChannelSensors;
        use crate::units::Seconds;
        let channel = |name: &str, names: &[&str]| ChannelSensors {
            name: name.into(),
            sensors: names.iter().map(|s| (*s).to_string()).collect(),
        };
        let track = ForceTrack {
            channels: vec![
                channel("left", &["heel", "toe"]),
                channel("right", &["heel", "toe"]),
            ],
            rows: (0..3)
                .map(|i| ForceRow {
                    time: Seconds(f64::from(i) * 0.01),
                    readings: vec![
                        SensorReading::new(&[i as f32, 1.0]).unwrap(),
                        SensorReading::new(&[2.0, 3.0]).unwrap(),
                    ],
                })
                .collect(),
        };
        let mut s = ReferenceSender::new(Vec::new());
        assert_eq!(s.send_track(&track, 0.25).unwrap(), 3);
        let (frames, stats) = decode_all(&s.into_inner());
        assert_eq!(stats.frames, 3);
        assert_eq!(frames[2].seq, 2);
        assert_eq!(frames[2].counts(), &[8, 4, 8, 12]);
    }

    #[test]
    fn bad_configs_are_refused() {
        let config = |layout: Vec<usize>, npc: f32| SerialConfig {
            port: "/dev/null".into(),
            baud: 115_200,
            layout,
            scale: CountScale::Uniform {
                newtons_per_count: npc,
            },
        };
        assert!(check_config(&config(vec![2, 2], 0.1)).is_ok());
        assert!(check_config(&config(vec![], 0.1)).is_err());
        assert!(check_config(&config(vec![0], 0.1)).is_err());
        assert!(check_config(&config(vec![9], 0.1)).is_err());
        assert!(check_config(&config(vec![8; 9], 0.1)).is_err());
        assert!(check_config(&config(vec![1], f32::NAN)).is_err());
        assert!(check_config(&config(vec![1], -1.0)).is_err());
        assert!(matches!(
            SerialSource::open(&config(vec![], 1.0)),
            Err(IoError::Unsupported { .. })
        ));
        assert!(matches!(
            SerialSource::open(&SerialConfig {
                port: "/nonexistent/tty".into(),
                ..config(vec![1], 1.0)
            }),
            Err(IoError::Open { .. })
        ));
    }

    /// How a valid frame's bytes get damaged on the line.
    #[derive(Debug, Clone)]
    enum Damage {
        None,
        Flip { at: usize, bit: u8 },
        Truncate { keep: usize },
        Drop { at: usize },
        Insert { at: usize, bytes: Vec<u8> },
        GarbageBefore(Vec<u8>),
    }

    fn damage() -> impl Strategy<Value = Damage> {
        prop_oneof![
            4 => Just(Damage::None),
            1 => (any::<usize>(), 0u8..8).prop_map(|(at, bit)| Damage::Flip { at, bit }),
            1 => any::<usize>().prop_map(|keep| Damage::Truncate { keep }),
            1 => any::<usize>().prop_map(|at| Damage::Drop { at }),
            1 => (any::<usize>(), proptest::collection::vec(any::<u8>(), 1..8))
                .prop_map(|(at, bytes)| Damage::Insert { at, bytes }),
            1 => proptest::collection::vec(any::<u8>(), 0..300).prop_map(Damage::GarbageBefore),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn random_bytes_never_panic(
            bytes in proptest::collection::vec(any::<u8>(), 0..4000),
            cuts in proptest::collection::vec(any::<usize>(), 0..20),
        ) {
            let mut d = FrameDecoder::new();
            let mut frames = 0u64;
            let mut rest = &bytes[..];
            for cut in cuts {
                let (now, later) = rest.split_at(cut % (rest.len() + 1));
                d.push(now, |_| frames += 1);
                rest = later;
            }
            d.push(rest, |_| frames += 1);
            let s = d.stats();
            prop_assert_eq!(s.frames, frames);
            prop_assert!(s.skipped_bytes <= bytes.len() as u64);
            prop_assert!(s.bad_checksums <= s.rejected);
        }

        #[test]
        fn damaged_frames_never_take_good_ones_down(
            frames in proptest::collection::vec(
                (proptest::collection::vec(any::<u16>(), 1..=MAX_FRAME_SENSORS), damage()),
                1..40,
            ),
            chunk in 1usize..64,
        ) {
            let mut stream = Vec::new();
            let mut intact = Vec::new();
            for (seq, (counts, damage)) in frames.iter().enumerate() {
                let seq = seq as u16;
                let mut wire = encoded(seq, counts);
                let n = wire.len();
                match damage {
                    Damage::None => intact.push((seq, counts.clone())),
                    Damage::Flip { at, bit } => wire[at % n] ^= 1 << bit,
                    Damage::Truncate { keep } => wire.truncate(keep % n),
                    Damage::Drop { at } => {
                        wire.remove(at % n);
                    }
                    Damage::Insert { at, bytes } => {
                        wire.splice(at % n..at % n, bytes.iter().copied());
                    }
                    Damage::GarbageBefore(bytes) => {
                        stream.extend(bytes);
                        intact.push((seq, counts.clone()));
                    }
                }
                stream.extend(wire);
            }
            let mut d = FrameDecoder::new();
            let mut got = Vec::new();
            for piece in stream.chunks(chunk) {
                d.push(piece, |f| {
                    if let Frame::Force(f) = f {
                        got.push((f.seq, f.counts().to_vec()));
                    }
                });
            }
            // Every intact frame arrives, in order; a damaged frame that happens to pass the
            // CRC (one in 65536) may show up between them.
            let mut next = got.iter();
            for want in &intact {
                prop_assert!(next.any(|g| g == want), "lost {:?}", want);
            }
            prop_assert_eq!(d.stats().frames, got.len() as u64);
        }
    }

    #[cfg(unix)]
    mod pty {
        use super::*;
        use serialport::TTYPort;
        use std::time::Instant;

        const GOOD: usize = 200;
        const NPC: f32 = 0.5;
        const LAYOUT: [usize; 2] = [2, 2];

        /// The counts of good frame `i`, recognisable at the other end.
        fn counts_of(i: usize) -> [u16; 4] {
            let i = i as u16;
            [i, 1000 + i, 2000 + i, 3000 + i]
        }

        /// Bad frames, cycling through the ways a frame goes wrong. Each is written between
        /// two good frames, so it forms exactly one chunk and one rejection.
        fn write_bad<W: Write>(kind: usize, s: &mut ReferenceSender<W>) -> io::Result<()> {
            let mut wire = Vec::new();
            match kind {
                0 => {
                    // A flipped bit in a value, the checksum as sent. The frame took a
                    // sequence number, so it also counts as lost.
                    let seq = s.next_frame(&[0]).unwrap().seq.to_le_bytes();
                    let mut p = vec![FRAME_VERSION, seq[0], seq[1], 4, 1, 0, 2, 0, 3, 0, 4, 0];
                    let crc = crc16_ccitt_false(&p).to_le_bytes();
                    p[6] ^= 0x40;
                    p.extend(crc);
                    wire.push(0);
                    cobs_encode(&p, &mut wire);
                    wire.push(0);
                }
                1 => {
                    // Cut short: the sender reset mid-frame.
                    let f = s.next_frame(&[1, 2, 3, 4]).unwrap();
                    encode_frame(&f, &mut wire);
                    wire.truncate(7);
                }
                2 => {
                    // Line noise, no zero in it.
                    wire.extend((0..23u8).map(|i| i.wrapping_mul(37) | 1));
                }
                3 => {
                    // Four sensors declared, three sent, checksum correct.
                    let seq = s.next_frame(&[0]).unwrap().seq.to_le_bytes();
                    wire = frame_of(&[FRAME_VERSION, seq[0], seq[1], 4, 1, 0, 2, 0, 3, 0]);
                }
                _ => {
                    // A sound frame from firmware wired for three sensors: the source, not the
                    // decoder, refuses it.
                    let f = s.next_frame(&[1, 2, 3]).unwrap();
                    encode_frame(&f, &mut wire);
                }
            }
            s.get_mut().write_all(&wire)
        }

        /// Run-time calibration: each sensor's counts go through its own curve from a
        /// `SensorCalibration`, clamped to the fitted range, instead of one factor.
        #[test]
        fn per_sensor_calibration_scales_each_sensor() {
            use crate::force::calibration::{CurveModel, SensorCalibration, SensorCurve};
            let curve = |name: &str, a: f64, b: f64| SensorCurve {
                name: name.into(),
                model: CurveModel::Power { a, b, r0: 100.0 },
                raw_range: [100.0, 4000.0],
                drift: 0.0,
            };
            let calibration = SensorCalibration {
                sensors: vec![curve("heel", 0.5, 1.0), curve("toe", 0.01, 1.5)],
            };
            let (mut master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
            master.set_timeout(Duration::from_secs(5)).unwrap();
            let config = SerialConfig {
                port: slave.name().expect("the slave end has a path"),
                baud: 115_200,
                layout: vec![2],
                scale: CountScale::calibrated(&calibration),
            };
            let mut source = SerialSource::open(&config).expect("open the slave end");
            // A calibration for three sensors does not fit a two-sensor layout.
            let mut wrong = config.clone();
            wrong.layout = vec![3];
            assert!(matches!(
                SerialSource::open(&wrong),
                Err(IoError::Unsupported { .. })
            ));
            let rows: [[u16; 2]; 4] = [[100, 100], [300, 500], [2100, 1700], [9000, 50]];
            let mut s = ReferenceSender::new(master);
            for r in rows {
                s.send_counts(&r).unwrap();
            }
            let mut events = Vec::new();
            let deadline = Instant::now() + Duration::from_secs(10);
            while events.len() < rows.len() && Instant::now() < deadline {
                source
                    .poll(Duration::from_millis(20), &mut |e| events.push(e))
                    .unwrap();
            }
            assert_eq!(events.len(), rows.len());
            for (e, r) in events.iter().zip(rows) {
                let want: Vec<f32> = calibration
                    .sensors
                    .iter()
                    .zip(r)
                    .map(|(c, raw)| c.force(f64::from(raw)).unwrap().0.0 as f32)
                    .collect();
                let Event::Force {
                    channel: 0,
                    reading,
                } = e
                else {
                    panic!("{e:?}")
                };
                assert_eq!(reading.as_slice(), &want[..]);
            }
            // The heel at 300 counts is 0.5 N per count above 100; the last row is
            // clamped above the heel's range and below the toe's.
            let Event::Force { reading, .. } = events[1] else {
                unreachable!()
            };
            assert_eq!(reading.as_slice()[0], 100.0);
            let stats = source.scaling_stats();
            assert_eq!((stats.above_range, stats.below_range), (1, 1));
            drop(s);
        }

        #[test]
        fn good_frames_survive_a_bad_line() {
            let (mut master, slave) = TTYPort::pair().expect("pseudo-terminal pair");
            master.set_timeout(Duration::from_secs(5)).unwrap();
            let slave_name = slave.name().expect("the slave end has a path");
            let config = SerialConfig {
                port: slave_name,
                baud: 115_200,
                layout: LAYOUT.to_vec(),
                scale: CountScale::Uniform {
                    newtons_per_count: NPC,
                },
            };
            // Opened by path as a real port would be, 8N1 and raw, next to the pair's own
            // handle (kept open so that the terminal does not hang up between the two).
            let mut source = SerialSource::open(&config).expect("open the slave end");

            let (done_tx, done_rx) = std::sync::mpsc::channel::<()>();
            let writer = std::thread::spawn(move || -> io::Result<usize> {
                let mut s = ReferenceSender::new(master);
                let mut bad = 0;
                for i in 0..GOOD {
                    s.send_counts(&counts_of(i))?;
                    if i % 4 == 1 {
                        write_bad(bad % 5, &mut s)?;
                        bad += 1;
                    }
                }
                // Keep the master open until the reader is done: a hang-up could cut off
                // bytes still in the terminal's buffer.
                let _ = done_rx.recv_timeout(Duration::from_secs(20));
                Ok(bad)
            });

            let mut events = Vec::new();
            let deadline = Instant::now() + Duration::from_secs(15);
            while events.len() < GOOD * LAYOUT.len() && Instant::now() < deadline {
                let state = source
                    .poll(Duration::from_millis(20), &mut |e| events.push(e))
                    .unwrap();
                assert_eq!(state, SourceState::Open);
            }
            // Anything straggling (a duplicate would show here).
            source
                .poll(Duration::from_millis(50), &mut |e| events.push(e))
                .unwrap();
            done_tx.send(()).unwrap();
            let bad = writer.join().unwrap().unwrap();
            drop(slave);

            assert_eq!(events.len(), GOOD * LAYOUT.len(), "events");
            for (i, pair) in events.chunks(2).enumerate() {
                let c = counts_of(i).map(|c| f32::from(c) * NPC);
                let want = [
                    Event::Force {
                        channel: 0,
                        reading: SensorReading::new(&c[..2]).unwrap(),
                    },
                    Event::Force {
                        channel: 1,
                        reading: SensorReading::new(&c[2..]).unwrap(),
                    },
                ];
                assert_eq!(pair, want, "frame {i}");
            }
            let stats = source.stats();
            let decoder = source.decoder_stats();
            eprintln!(
                "pty: {GOOD} good + {bad} bad frames sent; {} decoded, {} events, \
                 {} rejected ({} bad checksums), {} bytes skipped, {} lost",
                decoder.frames,
                stats.events,
                stats.rejected,
                decoder.bad_checksums,
                stats.skipped_bytes,
                decoder.lost,
            );
            assert_eq!(bad, 50);
            assert_eq!(stats.events, (GOOD * LAYOUT.len()) as u64);
            assert_eq!(stats.rejected, bad as u64);
            // Of each five bad frames, the flipped, the cut-short and the misdeclared one
            // took a sequence number and never arrived whole.
            assert_eq!(decoder.lost, 3 * bad as u64 / 5);
            assert_eq!(decoder.bad_checksums, bad as u64 / 5);
            assert!(stats.skipped_bytes > 0);
        }
    }
}
