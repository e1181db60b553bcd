//! A serial port as an [`EventSource`]: the force frames of a board, decoded, scaled to
//! newtons and handed to the engine one [`Event::Force`] per channel.
//!
//! When the port hangs up, the source reopens the same path with a [`Backoff`] (see
//! [`crate::io`], *A lost device*).

use std::io::Read;
use std::time::Duration;

use serialport::SerialPort;

use super::port::{describe, is_quiet, open_port};
use super::protocol::{DecoderStats, Frame, FrameData, FrameDecoder, MAX_FRAME_SENSORS};
use crate::engine::Event;
use crate::force::calibration::ApplyStats;
use crate::force::scale::CountScale;
use crate::force::{MAX_SENSORS, SensorReading};
use crate::io::{
    Backoff, EventSource, IoError, LinkEvent, Reconnect, Retry, SourceState, SourceStats,
};

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
pub(super) fn check_config(config: &SerialConfig) -> Result<usize, String> {
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
