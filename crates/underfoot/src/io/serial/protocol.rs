//! The frame protocol: CRC, frames, the encoder and the decoder, with no I/O.
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
//! - **`u16` raw counts**, scaled on the host by
//!   [`SerialConfig::scale`](super::SerialConfig::scale) (one factor, or a calibration
//!   curve per sensor). ADCs of these parts give 10 or 12 bits, so a count fits without a
//!   32-bit multiply (slow on a
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

/// The type byte of a force frame (device to host) in protocol version 1.
pub const FRAME_VERSION: u8 = 0x01;

/// The type byte of a force frame: the same as [`FRAME_VERSION`], named for what it is.
pub const FORCE_FRAME: u8 = FRAME_VERSION;

/// The type byte of a servo-target frame (host to device).
pub const SERVO_FRAME: u8 = 0x02;

/// The most sensors one frame can carry: eight channels of
/// [`MAX_SENSORS`](crate::force::MAX_SENSORS) sensors.
pub const MAX_FRAME_SENSORS: usize = 64;

/// The most servo targets one servo frame can carry.
pub const MAX_FRAME_SERVOS: usize = 16;

/// Type, sequence number and value count.
const HEADER_LEN: usize = 4;
const CRC_LEN: usize = 2;
/// The longest valid payload; a longer one is rejected without being stored.
pub(crate) const MAX_PAYLOAD: usize = HEADER_LEN + 2 * MAX_FRAME_SENSORS + CRC_LEN;

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
pub(crate) fn cobs_encode(payload: &[u8], out: &mut Vec<u8>) {
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
