//! The host end: [`ProstheticHost`] decodes the insole's frames, hands force to the
//! engine and to the servos, and keeps the servo heartbeat running.

use std::io::{self, Read};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serialport::SerialPort;

use super::heartbeat::{Heartbeat, Shared, lock};
use crate::engine::Event;
use crate::force::SensorReading;
use crate::force::calibration::ApplyStats;
use crate::force::scale::CountScale;
use crate::interface::config::{InterfaceConfig, VibrationChannel};
use crate::interface::servo::ServoBank;
use crate::io::serial::{Frame, FrameDecoder, MAX_FRAME_SENSORS, describe, is_quiet, open_port};
use crate::io::{
    Backoff, EventSource, IoError, LinkEvent, Reconnect, Retry, SourceState, SourceStats,
};
use crate::units::Seconds;

/// What the host has seen and done.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ProstheticStats {
    /// Good insole frames.
    pub insole_frames: u64,
    /// Chunks the decoder rejected, plus sound frames of the wrong size or direction.
    pub rejected: u64,
    /// Of the decoder's rejections, sound frames of an unknown type.
    pub unknown_type: u64,
    /// Insole frames missing from the sequence numbers.
    pub lost: u64,
    /// Servo frames written.
    pub servo_frames_sent: u64,
    /// Force events handed to the engine.
    pub events: u64,
    /// Times the insole input stopped for longer than the timeout.
    pub input_timeouts: u64,
    /// Servo updates whose force was not finite (the target was held, see
    /// `interface::servo`).
    pub non_finite: u64,
    /// Scaling: readings clamped to a calibration's range, non-finite results.
    pub scaling: ApplyStats,
    /// The longest time from decoding an insole frame to sending the servo frame that
    /// reflects it.
    pub max_servo_delay: Seconds,
    /// The mean of the same delay over servo frames that reflected a new insole frame.
    pub mean_servo_delay: Seconds,
    /// The longest time between two servo frames written while the port was open: the
    /// heartbeat's worst gap, to hold against the firmware's timeout.
    pub max_servo_gap: Seconds,
}

/// The host end of the interface: see the module doc.
pub struct ProstheticHost {
    /// The port insole frames are read from; `None` while it is lost.
    port: Option<Box<dyn SerialPort>>,
    device: String,
    /// The baud rate to reopen a lost port at (its path is `device`); `None` for a port
    /// handed in, which ends the source when it hangs up.
    reopen: Option<u32>,
    link: Reconnect,
    decoder: FrameDecoder,
    frame_sensors: usize,
    scale: CountScale,
    channels: Vec<VibrationChannel>,
    newtons: [f32; MAX_FRAME_SENSORS],
    period: Duration,
    buf: [u8; 256],
    timeout: Duration,
    stats: ProstheticStats,
    mismatched: u64,
    ended: bool,
    /// Set by a simulated board when its walk is over.
    finished: Option<Arc<AtomicBool>>,
    /// Set on the first poll: a simulated board waits for it before it starts its walk.
    polled: Option<Arc<AtomicBool>>,
    shared: Arc<Mutex<Shared>>,
    /// Only held: dropping it stops and joins the heartbeat thread.
    _heartbeat: Heartbeat,
}

impl std::fmt::Debug for ProstheticHost {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ProstheticHost")
            .field("device", &self.device)
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

impl ProstheticHost {
    /// The host end on a port that is already open; `device` names it in messages. A
    /// hang-up of this port ends the source (only [`open`](super::open) knows how to reopen one).
    /// Starts the servo heartbeat thread, which writes to a clone of `port`.
    ///
    /// # Errors
    /// [`IoError::Unsupported`] if the servos or scale do not fit the configuration;
    /// [`IoError::Io`] if the port cannot be cloned or the thread cannot start.
    pub fn with_port(
        port: Box<dyn SerialPort>,
        device: &str,
        config: &InterfaceConfig,
    ) -> Result<Self, IoError> {
        let unsupported = |reason: String| IoError::Unsupported {
            device: device.to_owned(),
            reason,
        };
        config
            .scale
            .check(config.frame_sensors)
            .map_err(|e| unsupported(e.to_string()))?;
        let bank = ServoBank::new(
            config.servos.clone(),
            config.frame_sensors,
            config.insole_timeout,
        )
        .map_err(|e| unsupported(e.to_string()))?;
        let period = Duration::from_secs_f64(1.0 / config.servo_rate.0.clamp(1.0, 500.0));
        let timeout = port.timeout();
        let writer = writer_of(port.as_ref(), period).map_err(|source| IoError::Io {
            device: device.to_owned(),
            source,
        })?;
        let shared = Arc::new(Mutex::new(Shared {
            bank,
            pending_since: None,
            new_writer: None,
            write_lost: None,
            sent: 0,
            delay_sum: 0.0,
            delay_count: 0,
            max_delay: 0.0,
            max_gap: 0.0,
        }));
        let heartbeat =
            Heartbeat::start(Arc::clone(&shared), writer, period).map_err(|source| {
                IoError::Io {
                    device: device.to_owned(),
                    source,
                }
            })?;
        Ok(Self {
            port: Some(port),
            device: device.to_owned(),
            reopen: None,
            link: Reconnect::new(device),
            decoder: FrameDecoder::new(),
            frame_sensors: config.frame_sensors,
            scale: config.scale.clone(),
            channels: config.channels.clone(),
            newtons: [0.0; MAX_FRAME_SENSORS],
            period,
            buf: [0; 256],
            timeout,
            stats: ProstheticStats::default(),
            mismatched: 0,
            ended: false,
            finished: None,
            polled: None,
            shared,
            _heartbeat: heartbeat,
        })
    }

    /// Replaces the delays between attempts to reopen a lost port (default: 100 ms,
    /// doubling to 2 s).
    #[must_use]
    pub fn with_backoff(mut self, backoff: Backoff) -> Self {
        self.link.set_backoff(backoff);
        self
    }

    /// Reopens the port at its path and `baud` when it hangs up, instead of ending.
    pub(super) fn reopen_at(&mut self, baud: u32) {
        self.reopen = Some(baud);
    }

    /// Follows a board that waits for its host and says when it is done (the simulated
    /// board, [`crate::sim::SimulatedFoot`]): `polled` is set at the first poll, and the
    /// source ends once `finished` is set.
    pub(crate) fn follow_board(&mut self, polled: Arc<AtomicBool>, finished: Arc<AtomicBool>) {
        self.polled = Some(polled);
        self.finished = Some(finished);
    }

    /// Counts so far.
    #[must_use]
    pub fn stats(&self) -> ProstheticStats {
        let d = self.decoder.stats();
        let mut s = self.stats;
        s.rejected = d.rejected + self.mismatched;
        s.unknown_type = d.unknown_type;
        s.lost = d.lost;
        let shared = lock(&self.shared);
        s.input_timeouts = shared.bank.timeouts();
        s.non_finite = shared
            .bank
            .servos()
            .iter()
            .map(|s| s.stats().non_finite)
            .sum();
        s.servo_frames_sent = shared.sent;
        s.max_servo_delay = Seconds(shared.max_delay);
        s.mean_servo_delay = Seconds(if shared.delay_count == 0 {
            0.0
        } else {
            shared.delay_sum / shared.delay_count as f64
        });
        s.max_servo_gap = Seconds(shared.max_gap);
        s
    }

    /// The servos' current state (a copy: the heartbeat thread owns them).
    #[must_use]
    pub fn servos(&self) -> ServoBank {
        lock(&self.shared).bank.clone()
    }

    fn handle(&mut self, frame: Frame, out: &mut dyn FnMut(Event)) {
        let Frame::Force(frame) = frame else {
            // Servo frames go the other way: an echo or crossed wiring.
            self.mismatched += 1;
            return;
        };
        let counts = frame.counts();
        if counts.len() != self.frame_sensors {
            self.mismatched += 1;
            return;
        }
        let s = self
            .scale
            .apply(counts, &mut self.newtons[..self.frame_sensors]);
        self.stats.scaling += s;
        {
            let mut shared = lock(&self.shared);
            shared.bank.reading(&self.newtons[..self.frame_sensors]);
            shared.pending_since.get_or_insert_with(Instant::now);
        }
        self.stats.insole_frames += 1;
        for (k, ch) in self.channels.iter().enumerate() {
            let mut values = [0.0f32; crate::force::MAX_SENSORS];
            let n = ch.sensors.len().min(values.len());
            for (v, &i) in values.iter_mut().zip(&ch.sensors) {
                *v = self.newtons.get(i).copied().unwrap_or(0.0);
            }
            let (Ok(channel), Some(reading)) = (u16::try_from(k), SensorReading::new(&values[..n]))
            else {
                continue;
            };
            out(Event::Force { channel, reading });
            self.stats.events += 1;
        }
    }

    /// The port is gone: reopen it later, or end if it cannot be reopened.
    fn lose(&mut self, reason: String) {
        self.port = None;
        if self.reopen.is_none() {
            self.ended = true;
            return;
        }
        self.link.lose(reason);
    }

    /// While the port is lost: waits up to `timeout`, reopening it when an attempt is due,
    /// and hands the heartbeat a write handle of the new port.
    fn poll_lost(&mut self, timeout: Duration) -> SourceState {
        let Some(baud) = self.reopen else {
            return SourceState::Ended;
        };
        let (device, port_timeout, period) = (&self.device, self.timeout, self.period);
        let open = || {
            let port = open_port(device, baud, port_timeout)?;
            let writer = writer_of(port.as_ref(), period).map_err(|e| IoError::Open {
                device: device.clone(),
                reason: e.to_string(),
            })?;
            Ok((port, writer))
        };
        match self.link.retry(timeout, open) {
            // Not lost and not ended: nothing to wait for.
            Retry::NotLost => SourceState::Ended,
            Retry::Waiting => SourceState::Disconnected,
            Retry::Back((port, writer)) => {
                {
                    let mut shared = lock(&self.shared);
                    shared.new_writer = Some(writer);
                    shared.write_lost = None;
                }
                self.port = Some(port);
                self.decoder.resync();
                SourceState::Open
            }
        }
    }

    fn state(&self) -> SourceState {
        if self.ended {
            SourceState::Ended
        } else if self.port.is_none() {
            SourceState::Disconnected
        } else {
            SourceState::Open
        }
    }
}

/// A second handle on `port` for the heartbeat to write with, its timeout one period so a
/// line that does not drain cannot hold the heartbeat past the next frame.
fn writer_of(port: &dyn SerialPort, period: Duration) -> io::Result<Box<dyn SerialPort>> {
    let mut w = port.try_clone().map_err(io::Error::from)?;
    w.set_timeout(period).map_err(io::Error::from)?;
    Ok(w)
}

impl EventSource for ProstheticHost {
    fn poll(
        &mut self,
        timeout: Duration,
        out: &mut dyn FnMut(Event),
    ) -> Result<SourceState, IoError> {
        if self.ended {
            return Ok(SourceState::Ended);
        }
        if let Some(polled) = &self.polled {
            polled.store(true, Ordering::SeqCst);
        }
        if self
            .finished
            .as_ref()
            .is_some_and(|f| f.load(Ordering::SeqCst))
        {
            self.ended = true;
        }
        let write_lost = lock(&self.shared).write_lost.take();
        if let (Some(reason), Some(_)) = (write_lost, self.port.as_ref()) {
            self.lose(reason);
        }
        let Some(port) = self.port.as_mut() else {
            return Ok(self.poll_lost(timeout));
        };
        // Servo frames go out on the heartbeat thread, so this wait is only the caller's.
        let wait = timeout.max(Duration::from_millis(1));
        if wait != self.timeout {
            port.set_timeout(wait).map_err(|e| IoError::Unsupported {
                device: self.device.clone(),
                reason: format!("cannot set a read timeout of {wait:?}: {e}"),
            })?;
            self.timeout = wait;
        }
        for _ in 0..16 {
            let Some(port) = self.port.as_mut() else {
                break;
            };
            match port.read(&mut self.buf) {
                Ok(0) => {
                    self.lose("the port hung up (end of file)".into());
                    break;
                }
                Ok(n) => {
                    for i in 0..n {
                        if let Some(Ok(frame)) = self.decoder.push_byte(self.buf[i]) {
                            self.handle(frame, out);
                        }
                    }
                }
                Err(e) if is_quiet(&e) => break,
                // Any other failure of an open port is the device going away (see
                // `serial`): retrying the dead descriptor would return at once forever.
                Err(e) => {
                    self.lose(describe(&e));
                    break;
                }
            }
            match self.port.as_ref().map(|p| p.bytes_to_read()) {
                Some(Ok(0)) | None => break,
                Some(Ok(_)) => {}
                Some(Err(e)) => {
                    self.lose(e.to_string());
                    break;
                }
            }
        }
        Ok(self.state())
    }

    fn stats(&self) -> SourceStats {
        let s = ProstheticHost::stats(self);
        SourceStats {
            events: s.events,
            rejected: s.rejected,
            skipped_bytes: self.decoder.stats().skipped_bytes,
            disconnects: self.link.counts().0,
            reconnects: self.link.counts().1,
        }
    }

    fn link_event(&mut self) -> Option<LinkEvent> {
        self.link.next_event()
    }
}
