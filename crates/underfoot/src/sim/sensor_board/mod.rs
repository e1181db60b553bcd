//! A sensor board, simulated: the firmware's side of the serial protocol
//! ([`crate::io::serial::protocol`]) in Rust.
//!
//! [`ReferenceSender`] numbers force frames and writes them to any [`Write`]: the other
//! end of a pseudo-terminal in tests, or a real port to stand in for a board. Its tests
//! play it against the host's [`SerialSource`](crate::io::serial::SerialSource) over a
//! pseudo-terminal, with broken frames between the good ones.

use std::io::{self, Write};

use crate::force::SensorReading;
use crate::force::track::{ForceRow, ForceTrack};
use crate::io::serial::protocol::{FrameData, MAX_FRAME_SENSORS, MAX_PAYLOAD, encode_frame};

#[cfg(test)]
mod tests;

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
