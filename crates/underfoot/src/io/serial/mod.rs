//! Force from a microcontroller over a serial port: a small framed binary protocol.
//!
//! The sender is a 16-bit microcontroller (an ATmega, an MSP430) sampling force sensors with
//! its ADC; it sends raw counts in frames that survive what a serial line does wrong (flipped
//! bits, dropped bytes, a port opened half-way through a frame). The host sends servo
//! targets back in frames of the same layout.
//!
//! | file | what it does |
//! |---|---|
//! | [`protocol`] | the wire format, and what the firmware must do; [`encode_frame`], [`encode_servo_frame`] and [`FrameDecoder`], with no I/O |
//! | [`source`] | [`SerialSource`]: a serial port as an [`EventSource`](super::EventSource), one [`Event::Force`](crate::engine::Event::Force) per channel per frame, reopened with a [`Backoff`](super::Backoff) when it hangs up (see [`super`], *A lost device*) |
//! | `port` | opening a port 8N1, telling a quiet line from a lost port (shared with [`prosthetic`](super::prosthetic)), and [`list_ports`] |
//!
//! The firmware's side of the protocol, in Rust, for tests and to stand in for a board,
//! is [`ReferenceSender`](crate::sim::ReferenceSender), among the simulators.

mod port;
pub mod protocol;
pub mod source;

#[cfg(test)]
mod tests;

pub use port::list_ports;
pub(crate) use port::{describe, is_quiet, open_port};
pub use protocol::{
    DecoderStats, FORCE_FRAME, FRAME_VERSION, Frame, FrameData, FrameDecoder, FrameError,
    MAX_FRAME_SENSORS, MAX_FRAME_SERVOS, SERVO_FRAME, ServoFrame, crc16_ccitt_false, encode_frame,
    encode_servo_frame,
};
pub use source::{SerialConfig, SerialSource};
