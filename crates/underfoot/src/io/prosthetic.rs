//! The prosthetic-skin interface over a serial link: insole force in, servo targets out.
//!
//! The interface's board sends force frames (type `0x01`, raw counts of the insole's
//! sensors) and receives servo-target frames (type `0x02`); both use the framing, CRC and
//! timing rules documented in [`super::serial`]. This module has the two ends:
//!
//! - [`ProstheticHost`], the host: an [`EventSource`] that decodes insole frames, scales
//!   them to newtons (per-sensor calibration or a factor, [`CountScale`]), hands one
//!   [`Event::Force`] per vibration channel to the engine, feeds the
//!   [`ServoBank`], and writes a servo frame every `1 / servo_rate_hz` seconds from
//!   its own heartbeat thread (*Heartbeat* below). Decoding runs in
//!   [`EventSource::poll`], on the input poll thread; neither runs on the audio thread.
//!   When a real board's port hangs up the host reopens it with a backoff (see
//!   [`super`], *A lost device*).
//! - [`SimulatedFoot`], the board, simulated: it walks the gait model of
//!   [`crate::force::gait`] on one foot, splits the force between heel, midfoot and toe as
//!   the centre of pressure rolls over, quantises it like an ADC, and moves its servos
//!   toward the targets it receives at its own slew rate, recording what it received and
//!   where its servos were. [`SimulatedFoot::serve`] runs it on any port (the far end of a
//!   pseudo-terminal); [`open`] starts it on a pseudo-terminal when the configuration says
//!   `port = "simulated"`.
//!
//! # Heel, midfoot, toe
//!
//! The gait model gives each foot a heel and a toe sensor, the toe's share `φ` of the
//! force `F` rising smoothly from 0 to 1 over stance. The simulated insole reads the
//! centre of pressure `p = φ` as a position along the foot (heel 0, midfoot ½, toe 1)
//! and shares `F` between the three sensors by linear interpolation between them:
//!
//! ```text
//! heel = F max(0, 1 − 2p),   midfoot = F (1 − |2p − 1|),   toe = F max(0, 2p − 1)
//! ```
//!
//! so the three add up to `F` and the load rolls heel, midfoot, toe in that order.
//!
//! # Heartbeat
//!
//! The firmware takes the servo frames as a heartbeat: with none for a few periods
//! (about 200 ms) it returns the servos to rest. So the frames must not wait for the
//! poll loop, which a loaded machine, a slow consumer or a long read can hold up (sent
//! from the poll loop, they were seen to stop for 1.04 s under CPU load). A dedicated thread sends them on a
//! deadline: frame `k` is due at `t₀ + k·T`, so a late wake-up delays one frame without
//! shifting the ones after it, and a stall of more than a period resumes the cadence
//! from now instead of sending a burst. Each tick advances the [`ServoBank`] by the real
//! time since the last one (the rate limit and the insole timeout run on this clock, so
//! the servos return to rest even if the poll thread stops) and writes its targets; the
//! poll thread only hands in readings. The two share the bank under a mutex held for
//! microseconds and never across a write; the heartbeat writes through its own handle
//! on the port (a duplicate descriptor), whose timeout is one period, so a line that
//! does not drain drops a frame rather than holding up the next.
//! [`ProstheticStats::max_servo_gap`] reports the worst gap.
//!
//! # Timing and latency
//!
//! The host timestamps each insole frame as it is decoded and reports the delay from
//! the oldest frame not yet reflected in a servo frame to the servo frame that reflects
//! it ([`ProstheticStats::max_servo_delay`]): at most one servo period plus the
//! heartbeat's scheduling slack. The serial line adds `bytes × 10 / baud` each way (about 1.3 ms for a
//! 15-byte frame at 115200 baud), and the servo's own mechanics dominate everything.

use std::io::{self, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread;
use std::time::{Duration, Instant};

use serialport::SerialPort;

use super::serial::{
    Frame, FrameData, FrameDecoder, MAX_FRAME_SENSORS, MAX_FRAME_SERVOS, ServoFrame, describe,
    encode_frame, encode_servo_frame, is_quiet, open_port,
};
use super::{Backoff, EventSource, IoError, LinkEvent, Reconnect, Retry, SourceState, SourceStats};
use crate::engine::Event;
use crate::force::SensorReading;
use crate::force::calibration::ApplyStats;
use crate::force::gait;
use crate::force::scale::CountScale;
use crate::interface::config::{InterfaceConfig, Link, SimulatedConfig, VibrationChannel};
use crate::interface::servo::ServoBank;
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

/// What the poll thread and the heartbeat thread share: the servos and the heartbeat's
/// counts. Held for a few microseconds at a time, never while writing to the port.
struct Shared {
    bank: ServoBank,
    /// When the oldest insole frame not yet reflected in a servo frame was decoded.
    pending_since: Option<Instant>,
    /// A reopened port's write handle, for the heartbeat to take.
    new_writer: Option<Box<dyn SerialPort>>,
    /// Set by the heartbeat when a write failed: the port is gone.
    write_lost: Option<String>,
    sent: u64,
    delay_sum: f64,
    delay_count: u64,
    max_delay: f64,
    max_gap: f64,
}

fn lock(shared: &Mutex<Shared>) -> MutexGuard<'_, Shared> {
    // A panic on the other thread leaves plain counters and servo state, still usable.
    shared.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The heartbeat thread: stopped and joined on drop.
struct Heartbeat {
    stop: Arc<AtomicBool>,
    thread: Option<thread::JoinHandle<()>>,
}

impl Drop for Heartbeat {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

impl Heartbeat {
    fn start(
        shared: Arc<Mutex<Shared>>,
        writer: Box<dyn SerialPort>,
        period: Duration,
    ) -> Result<Self, io::Error> {
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = Arc::clone(&stop);
            thread::Builder::new()
                .name("servo-heartbeat".into())
                .spawn(move || heartbeat(&shared, &stop, period, writer))?
        };
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }
}

/// Every `period`, on its own deadline: advances the servos by the real time since the
/// last tick and writes their targets as one servo frame.
fn heartbeat(
    shared: &Mutex<Shared>,
    stop: &AtomicBool,
    period: Duration,
    writer: Box<dyn SerialPort>,
) {
    let mut writer = Some(writer);
    let mut seq: u16 = 0;
    let mut targets = [0u16; MAX_FRAME_SERVOS];
    let mut wire = Vec::with_capacity(64);
    let mut last_update = Instant::now();
    let mut last_sent: Option<Instant> = None;
    let mut next = last_update + period;
    while !stop.load(Ordering::SeqCst) {
        let now = Instant::now();
        if now < next {
            // Unparked early by a stop; a spurious wake-up just goes round again.
            thread::park_timeout(next - now);
            continue;
        }
        // The next frame is due one period after this one was due, not after it went
        // out, so wake-up latency does not accumulate into a slower rate ...
        next += period;
        if next <= now {
            // ... unless the thread was stalled for over a period: resume the cadence
            // from now rather than send a burst of catch-up frames.
            next = now + period;
        }
        let (n, pending) = {
            let mut s = lock(shared);
            if let Some(w) = s.new_writer.take() {
                writer = Some(w);
                last_sent = None;
            }
            s.bank
                .update(Seconds(now.duration_since(last_update).as_secs_f64()));
            last_update = now;
            let n = s.bank.commands(&mut targets);
            let pending = if writer.is_some() {
                s.pending_since.take()
            } else {
                None
            };
            (n, pending)
        };
        let (Some(w), Some(frame)) = (writer.as_mut(), ServoFrame::new(seq, &targets[..n])) else {
            continue; // the port is lost, or no servos are configured
        };
        seq = seq.wrapping_add(1);
        wire.clear();
        encode_servo_frame(&frame, &mut wire);
        let result = w.write_all(&wire);
        let sent = Instant::now();
        let mut s = lock(shared);
        match result {
            Ok(()) => {
                s.sent += 1;
                if let Some(last) = last_sent {
                    s.max_gap = s.max_gap.max(sent.duration_since(last).as_secs_f64());
                }
                last_sent = Some(sent);
                if let Some(since) = pending {
                    let d = sent.duration_since(since).as_secs_f64();
                    s.delay_sum += d;
                    s.delay_count += 1;
                    s.max_delay = s.max_delay.max(d);
                }
            }
            // The line did not take the frame within a period (a board that stopped
            // reading): this frame is dropped, the next one carries the same targets.
            Err(e) if is_quiet(&e) => {}
            Err(e) => {
                writer = None;
                last_sent = None;
                s.write_lost = Some(describe(&e));
            }
        }
    }
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
    /// hang-up of this port ends the source (only [`open`] knows how to reopen one).
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

/// What the simulated board received and did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimulatedReport {
    /// Insole frames sent.
    pub insole_frames: u64,
    /// Servo frames received intact.
    pub servo_frames: u64,
    /// Servo frames of the wrong size or type, and the decoder's rejections.
    pub rejected: u64,
    /// `(time since start, servo positions in µs)` after each received servo frame.
    pub positions: Vec<(Seconds, Vec<f64>)>,
    /// `(time, heel, midfoot, toe newtons)` of each insole frame sent.
    pub insole: Vec<(Seconds, [f32; 3])>,
}

/// The interface's board, simulated: see the module doc.
#[derive(Debug, Clone)]
pub struct SimulatedFoot {
    config: SimulatedConfig,
    frame_sensors: usize,
    /// Heel + toe force of the one foot, per sensor row.
    rows: Vec<(f32, f32)>,
    rate: f64,
    servos: usize,
    positions: Vec<f64>,
    targets: Vec<f64>,
}

impl SimulatedFoot {
    /// The board for `config` with `servos` servos (the highest id plus one) and
    /// `frame_sensors` counts per insole frame, servos at `rest` µs each.
    ///
    /// # Errors
    /// [`IoError::Unsupported`] if the gait cannot be generated or the counts do not fit.
    pub fn new(
        config: &SimulatedConfig,
        frame_sensors: usize,
        rest: &[u16],
    ) -> Result<Self, IoError> {
        let unsupported = |reason: String| IoError::Unsupported {
            device: "simulated".into(),
            reason,
        };
        if frame_sensors == 0 || frame_sensors > MAX_FRAME_SENSORS {
            return Err(unsupported(format!("{frame_sensors} sensors per frame")));
        }
        if config.heel_midfoot_toe.iter().any(|&i| i >= frame_sensors) {
            return Err(unsupported(
                "a heel/midfoot/toe index outside the frame".into(),
            ));
        }
        let g = gait::generate(&config.gait).map_err(|e| unsupported(e.to_string()))?;
        let rows = g
            .track
            .rows
            .iter()
            .map(|r| {
                let s = r.readings.first().map_or(&[][..], SensorReading::as_slice);
                (
                    s.first().copied().unwrap_or(0.0),
                    s.get(1).copied().unwrap_or(0.0),
                )
            })
            .collect();
        let positions: Vec<f64> = rest
            .iter()
            .take(MAX_FRAME_SERVOS)
            .map(|&r| f64::from(r))
            .collect();
        Ok(Self {
            config: config.clone(),
            frame_sensors,
            rows,
            rate: config.gait.sensor_rate,
            servos: positions.len(),
            targets: positions.clone(),
            positions,
        })
    }

    /// How long the walk lasts.
    #[must_use]
    pub fn duration(&self) -> Seconds {
        Seconds(self.rows.len() as f64 / self.rate)
    }

    /// Heel, midfoot and toe newtons at insole row `i` (zero past the walk).
    #[must_use]
    pub fn heel_midfoot_toe(&self, i: usize) -> [f32; 3] {
        let (heel, toe) = self.rows.get(i).copied().unwrap_or((0.0, 0.0));
        let f = heel + toe;
        if !(f.is_finite() && f > 0.0) {
            return [0.0; 3];
        }
        let p = (toe / f).clamp(0.0, 1.0);
        [
            f * (1.0 - 2.0 * p).max(0.0),
            f * (1.0 - (2.0 * p - 1.0).abs()),
            f * (2.0 * p - 1.0).max(0.0),
        ]
    }

    /// The insole frame's counts at row `i`, quantised like the ADC.
    fn counts(&self, i: usize, out: &mut [u16; MAX_FRAME_SENSORS]) -> [f32; 3] {
        let hmt = self.heel_midfoot_toe(i);
        out.fill(0);
        for (&idx, &f) in self.config.heel_midfoot_toe.iter().zip(&hmt) {
            // Rounded to whole counts; the float-to-int cast saturates like the ADC clips.
            out[idx] = (f / self.config.newtons_per_count).round().max(0.0) as u16;
        }
        hmt
    }

    /// Moves every servo toward its target by at most `slew × dt`.
    fn advance(&mut self, dt: f64) {
        let step = self.config.slew * dt.max(0.0);
        for (p, &t) in self.positions.iter_mut().zip(&self.targets) {
            let e = t - *p;
            *p = if e.abs() <= step {
                t
            } else {
                *p + step.copysign(e)
            };
        }
    }

    /// Runs the board on `port` until the walk is over and `linger` has passed, or `stop`
    /// is set: sends an insole frame per gait row at the gait's sensor rate, decodes servo
    /// frames and moves the servos. Sets `finished` when the walk is over.
    ///
    /// # Errors
    /// The port's, other than timeouts.
    pub fn serve<P: Read + Write + ?Sized>(
        mut self,
        port: &mut P,
        stop: &AtomicBool,
        finished: &AtomicBool,
        linger: Duration,
    ) -> io::Result<SimulatedReport> {
        let mut report = SimulatedReport::default();
        let mut decoder = FrameDecoder::new();
        let mut seq: u16 = 0;
        let mut counts = [0u16; MAX_FRAME_SENSORS];
        let mut wire = Vec::with_capacity(2 * MAX_FRAME_SENSORS + 16);
        let mut buf = [0u8; 256];
        let start = Instant::now();
        let mut last = start;
        let mut row = 0usize;
        let walk = Duration::from_secs_f64(self.duration().0);
        let mut done_at = None;
        while !stop.load(Ordering::SeqCst) {
            let now = Instant::now();
            self.advance(now.duration_since(last).as_secs_f64());
            last = now;
            let elapsed = now.duration_since(start);
            // Every row that is due, so a late wake-up does not slow the walk.
            let due = (elapsed.as_secs_f64() * self.rate) as usize;
            while row <= due && row < self.rows.len() {
                let hmt = self.counts(row, &mut counts);
                let Some(frame) = FrameData::new(seq, &counts[..self.frame_sensors]) else {
                    break;
                };
                seq = seq.wrapping_add(1);
                wire.clear();
                encode_frame(&frame, &mut wire);
                port.write_all(&wire)?;
                report.insole_frames += 1;
                report.insole.push((Seconds(row as f64 / self.rate), hmt));
                row += 1;
            }
            if elapsed >= walk && done_at.is_none() {
                finished.store(true, Ordering::SeqCst);
                done_at = Some(now);
            }
            if done_at.is_some_and(|t| now.duration_since(t) >= linger) {
                break;
            }
            match port.read(&mut buf) {
                Ok(n) => {
                    for &b in &buf[..n] {
                        match decoder.push_byte(b) {
                            Some(Ok(Frame::Servo(f))) if f.targets().len() == self.servos => {
                                for (t, &v) in self.targets.iter_mut().zip(f.targets()) {
                                    *t = f64::from(v);
                                }
                                report.servo_frames += 1;
                                report.positions.push((
                                    Seconds(start.elapsed().as_secs_f64()),
                                    self.positions.clone(),
                                ));
                            }
                            Some(Ok(_)) => report.rejected += 1,
                            _ => {}
                        }
                    }
                    if n == 0 {
                        thread::sleep(Duration::from_millis(1));
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut
                            | io::ErrorKind::WouldBlock
                            | io::ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(e),
            }
        }
        report.rejected += decoder.stats().rejected;
        finished.store(true, Ordering::SeqCst);
        Ok(report)
    }
}

/// A simulated board running on its own thread.
#[derive(Debug)]
pub struct SimulatorHandle {
    stop: Arc<AtomicBool>,
    thread: Option<thread::JoinHandle<io::Result<SimulatedReport>>>,
}

impl SimulatorHandle {
    /// Stops the board and returns what it recorded.
    ///
    /// # Errors
    /// [`IoError::Io`] if its port failed, or the thread panicked.
    pub fn finish(mut self) -> Result<SimulatedReport, IoError> {
        self.stop.store(true, Ordering::SeqCst);
        match self.thread.take().map(thread::JoinHandle::join) {
            Some(Ok(Ok(r))) => Ok(r),
            Some(Ok(Err(source))) => Err(IoError::Io {
                device: "simulated".into(),
                source,
            }),
            _ => Err(IoError::Unsupported {
                device: "simulated".into(),
                reason: "the simulated board's thread panicked".into(),
            }),
        }
    }
}

impl Drop for SimulatorHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

/// Opens the interface a configuration names: its serial port, or a [`SimulatedFoot`] on
/// a pseudo-terminal (unix only) whose walk ends the source when it is over.
///
/// # Errors
/// [`IoError::Open`] if the port cannot be opened; [`IoError::Unsupported`] for a
/// configuration the host cannot run.
pub fn open(
    config: &InterfaceConfig,
) -> Result<(ProstheticHost, Option<SimulatorHandle>), IoError> {
    match &config.link {
        Link::Serial { port, baud } => {
            let p = open_port(port, *baud, Duration::from_millis(10))?;
            let mut host = ProstheticHost::with_port(p, port, config)?;
            // A real board's port is reopened when it hangs up.
            host.reopen = Some(*baud);
            Ok((host, None))
        }
        Link::Simulated(sim) => open_simulated(config, sim),
    }
}

#[cfg(unix)]
fn open_simulated(
    config: &InterfaceConfig,
    sim: &SimulatedConfig,
) -> Result<(ProstheticHost, Option<SimulatorHandle>), IoError> {
    let open_err = |e: serialport::Error| IoError::Open {
        device: "simulated".into(),
        reason: format!("pseudo-terminal: {e}"),
    };
    let (mut master, slave) = serialport::TTYPort::pair().map_err(open_err)?;
    master
        .set_timeout(Duration::from_millis(2))
        .map_err(open_err)?;
    let servos = config
        .servos
        .iter()
        .map(|s| usize::from(s.id) + 1)
        .max()
        .unwrap_or(0);
    let mut rest = vec![0u16; servos];
    for s in &config.servos {
        rest[usize::from(s.id)] = s.calibration.rest.0;
    }
    let foot = SimulatedFoot::new(sim, config.frame_sensors, &rest)?;
    let mut host = ProstheticHost::with_port(Box::new(slave), "simulated", config)?;
    let stop = Arc::new(AtomicBool::new(false));
    let finished = Arc::new(AtomicBool::new(false));
    host.finished = Some(Arc::clone(&finished));
    let polled = Arc::new(AtomicBool::new(false));
    host.polled = Some(Arc::clone(&polled));
    let thread = {
        let stop = Arc::clone(&stop);
        thread::spawn(move || {
            // Like a board that waits for its host: frames sent before anyone reads them
            // would reach the engine in one burst, a walk squeezed into an instant (whose
            // strikes the detector cannot tell apart) when the host is slow to start.
            while !polled.load(Ordering::SeqCst) && !stop.load(Ordering::SeqCst) {
                thread::sleep(Duration::from_millis(1));
            }
            // Linger so the host's last servo frames still arrive and are recorded.
            foot.serve(&mut master, &stop, &finished, Duration::from_millis(300))
        })
    };
    Ok((
        host,
        Some(SimulatorHandle {
            stop,
            thread: Some(thread),
        }),
    ))
}

#[cfg(not(unix))]
fn open_simulated(
    _config: &InterfaceConfig,
    _sim: &SimulatedConfig,
) -> Result<(ProstheticHost, Option<SimulatorHandle>), IoError> {
    Err(IoError::Unsupported {
        device: "simulated".into(),
        reason: "the simulated interface runs on a pseudo-terminal, which needs unix".into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interface::config::InterfaceConfig;
    use crate::io::serial::{ReferenceSender, crc16_ccitt_false};
    use std::path::Path;

    fn sim_config(servo_rate: u32, gait: &str) -> InterfaceConfig {
        let text = format!(
            r#"
[link]
port = "simulated"
servo_rate_hz = {servo_rate}
insole_timeout_s = 0.1

[insole]
newtons_per_count = 0.5

[[sensor]]
name = "heel"
index = 0
[[sensor]]
name = "midfoot"
index = 1
[[sensor]]
name = "toe"
index = 2

{servos}

[[channel]]
name = "disc"
sensors = ["heel", "midfoot", "toe"]

[simulated]
gait = "{gait}"
newtons_per_count = 0.5
slew_us_per_s = 4000
"#,
            servos = ["heel", "midfoot", "toe"]
                .iter()
                .enumerate()
                .map(|(i, s)| format!(
                    "[[servo]]\nid = {i}\nsensors = [\"{s}\"]\nrange_us = [1000, 2000]\n\
                     rest_us = 1000\nfull_us = 2000\nthreshold_n = 20\nfull_force_n = 500\n\
                     dead_band_us = 4\nrate_us_per_s = 6000\n"
                ))
                .collect::<Vec<_>>()
                .join("\n"),
        );
        InterfaceConfig::parse(&text, Path::new("test.toml"), |_| unreachable!()).unwrap()
    }

    #[test]
    fn heel_midfoot_toe_share_the_force_and_roll_over() {
        let c = sim_config(50, "steps=1,rate=500,lead_in=0,tail=0");
        let Link::Simulated(sim) = &c.link else {
            unreachable!()
        };
        let foot = SimulatedFoot::new(sim, 3, &[1000; 3]).unwrap();
        let g = gait::generate(&sim.gait).unwrap();
        let mut peaks = [(0.0f32, 0usize); 3];
        for (i, row) in g.track.rows.iter().enumerate() {
            let hmt = foot.heel_midfoot_toe(i);
            let total = row.readings[0].total();
            assert!((hmt.iter().sum::<f32>() - total).abs() <= 1e-3 * total.max(1.0));
            assert!(hmt.iter().all(|&f| f >= 0.0));
            for (p, &f) in peaks.iter_mut().zip(&hmt) {
                if f > p.0 {
                    *p = (f, i);
                }
            }
        }
        assert!(peaks.iter().all(|p| p.0 > 100.0), "{peaks:?}");
        assert!(
            peaks[0].1 < peaks[1].1 && peaks[1].1 < peaks[2].1,
            "heel, midfoot, toe peak in order: {peaks:?}"
        );
    }

    /// The firmware end of a pty sends insole frames with bad ones between, the host end
    /// sends servo frames with bad ones between; each end must get every good frame intact,
    /// count the bad ones and resynchronise.
    #[cfg(unix)]
    #[test]
    fn pty_round_trip_both_directions_survives_a_bad_line() {
        use serialport::TTYPort;
        const GOOD: u16 = 150;
        /// Bad chunks of either direction, each a single rejection.
        fn bad(kind: u16, seq: u16, type_byte: u8) -> Vec<u8> {
            let mut w = Vec::new();
            match kind % 4 {
                0 => {
                    // A flipped bit.
                    encode_servo_or_force(type_byte, seq, &mut w);
                    let n = w.len();
                    w[n / 2] ^= 0x10;
                    if w[n / 2] == 0 {
                        w[n / 2] = 0x33;
                    }
                }
                1 => {
                    encode_servo_or_force(type_byte, seq, &mut w);
                    w.truncate(6);
                }
                2 => w.extend((1..=19u8).map(|i| i.wrapping_mul(29) | 1)),
                _ => {
                    // Sound, but of an unknown type.
                    let p = [0x09, 0, 0, 1, 7, 0];
                    let mut payload = p.to_vec();
                    payload.extend(crc16_ccitt_false(&p).to_le_bytes());
                    w.push(0);
                    cobs(&payload, &mut w);
                    w.push(0);
                }
            }
            w
        }
        fn cobs(p: &[u8], out: &mut Vec<u8>) {
            // Plain COBS for short payloads (< 254 bytes).
            let mut code_at = out.len();
            out.push(0);
            let mut code = 1u8;
            for &b in p {
                if b == 0 {
                    out[code_at] = code;
                    code_at = out.len();
                    out.push(0);
                    code = 1;
                } else {
                    out.push(b);
                    code += 1;
                }
            }
            out[code_at] = code;
        }
        fn encode_servo_or_force(type_byte: u8, seq: u16, w: &mut Vec<u8>) {
            if type_byte == 0x02 {
                encode_servo_frame(&ServoFrame::new(seq, &[1500, 1600, 1700]).unwrap(), w);
            } else {
                encode_frame(&FrameData::new(seq, &[1, 2, 3]).unwrap(), w);
            }
        }
        fn servo_targets(i: u16) -> [u16; 3] {
            [1000 + i, 1200 + i, 1400 + i]
        }
        fn insole_counts(i: u16) -> [u16; 3] {
            [i, 500 + i, 1000 + i]
        }

        let (mut device, mut host) = TTYPort::pair().expect("pseudo-terminal pair");
        device.set_timeout(Duration::from_millis(5)).unwrap();
        host.set_timeout(Duration::from_millis(5)).unwrap();
        let device_thread = thread::spawn(move || -> (Vec<ServoFrame>, u64, u64) {
            let mut sender = ReferenceSender::new(device);
            let mut decoder = FrameDecoder::new();
            let mut got = Vec::new();
            let mut buf = [0u8; 256];
            let deadline = Instant::now() + Duration::from_secs(15);
            let mut sent = 0u16;
            while (got.len() < usize::from(GOOD) || sent < GOOD) && Instant::now() < deadline {
                if sent < GOOD {
                    sender.send_counts(&insole_counts(sent)).unwrap();
                    if sent % 3 == 1 {
                        let junk = bad(sent / 3, sent, 0x01);
                        sender.get_mut().write_all(&junk).unwrap();
                    }
                    sent += 1;
                }
                if let Ok(n) = sender.get_mut().read(&mut buf) {
                    decoder.push(&buf[..n], |f| {
                        if let Frame::Servo(s) = f {
                            got.push(s);
                        }
                    });
                }
            }
            let s = decoder.stats();
            (got, s.rejected, s.unknown_type)
        });

        let mut decoder = FrameDecoder::new();
        let mut got: Vec<FrameData> = Vec::new();
        let mut buf = [0u8; 256];
        let mut wire = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(15);
        let mut sent = 0u16;
        while (got.len() < usize::from(GOOD) || sent < GOOD) && Instant::now() < deadline {
            if sent < GOOD {
                wire.clear();
                encode_servo_frame(
                    &ServoFrame::new(sent, &servo_targets(sent)).unwrap(),
                    &mut wire,
                );
                if sent % 3 == 1 {
                    wire.extend(bad(sent / 3, sent, 0x02));
                }
                host.write_all(&wire).unwrap();
                sent += 1;
            }
            if let Ok(n) = host.read(&mut buf) {
                decoder.push(&buf[..n], |f| {
                    if let Frame::Force(f) = f {
                        got.push(f);
                    }
                });
            }
        }
        let (servo_got, servo_rejected, servo_unknown) = device_thread.join().unwrap();
        let bad_count = u64::from(GOOD.div_ceil(3));
        // Host side: every insole frame, intact and in order.
        assert_eq!(got.len(), usize::from(GOOD));
        for (i, f) in got.iter().enumerate() {
            let i = i as u16;
            assert_eq!((f.seq, f.counts()), (i, &insole_counts(i)[..]));
        }
        let s = decoder.stats();
        assert_eq!(s.rejected, bad_count, "{s:?}");
        assert_eq!(s.unknown_type, bad_count / 4);
        assert_eq!(s.lost, 0);
        // Device side: every servo frame.
        assert_eq!(servo_got.len(), usize::from(GOOD));
        for (i, f) in servo_got.iter().enumerate() {
            let i = i as u16;
            assert_eq!((f.seq, f.targets()), (i, &servo_targets(i)[..]));
        }
        assert_eq!(servo_rejected, bad_count);
        assert_eq!(servo_unknown, bad_count / 4);
    }

    /// When the insole stops mid-stance, the host keeps sending servo frames and their
    /// targets walk back to rest at the rate limit, after the input timeout.
    #[cfg(unix)]
    #[test]
    fn servos_return_to_rest_when_the_insole_stops() {
        use serialport::TTYPort;
        let config = sim_config(100, "steps=1");
        let (mut device, host_end) = TTYPort::pair().expect("pseudo-terminal pair");
        device.set_timeout(Duration::from_millis(5)).unwrap();
        let mut host = ProstheticHost::with_port(Box::new(host_end), "pty", &config).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let board = {
            let stop = Arc::clone(&stop);
            thread::spawn(move || {
                let mut sender = ReferenceSender::new(device);
                let mut decoder = FrameDecoder::new();
                let mut got: Vec<(Instant, Vec<u16>)> = Vec::new();
                let mut buf = [0u8; 256];
                let start = Instant::now();
                while !stop.load(Ordering::SeqCst) {
                    // Full force on the heel (1000 counts = 500 N) for 0.4 s, then silence.
                    if start.elapsed() < Duration::from_millis(400) {
                        sender.send_counts(&[1000, 0, 0]).unwrap();
                    }
                    if let Ok(n) = sender.get_mut().read(&mut buf) {
                        decoder.push(&buf[..n], |f| {
                            if let Frame::Servo(f) = f {
                                got.push((Instant::now(), f.targets().to_vec()));
                            }
                        });
                    }
                }
                (start, got)
            })
        };
        let until = Instant::now() + Duration::from_millis(1200);
        while Instant::now() < until {
            host.poll(Duration::from_millis(20), &mut |_| {}).unwrap();
        }
        stop.store(true, Ordering::SeqCst);
        let (start, got) = board.join().unwrap();
        let stats = host.stats();
        assert_eq!(stats.input_timeouts, 1, "{stats:?}");
        // The heel servo reached full pressure while the insole was live ...
        let peak = got.iter().map(|(_, t)| t[0]).max().unwrap();
        assert_eq!(peak, 2000);
        // ... and is back at rest at the end, having moved no faster than its rate limit
        // (6000 µs/s) between frames.
        assert_eq!(got.last().unwrap().1[0], 1000);
        for w in got.windows(2) {
            let dt = w[1].0.duration_since(w[0].0).as_secs_f64();
            let moved = (f64::from(w[1].1[0]) - f64::from(w[0].1[0])).abs();
            // Arrival times jitter around the sending times: allow a frame period.
            assert!(
                moved <= 6000.0 * (dt + 0.01) + 1.0,
                "moved {moved} µs in {dt} s"
            );
        }
        // Not before the timeout: full pressure held until 0.4 s + 0.1 s.
        let left_full = got
            .iter()
            .find(|(t, v)| t.duration_since(start) > Duration::from_millis(400) && v[0] < 2000)
            .map(|(t, _)| t.duration_since(start).as_secs_f64())
            .unwrap();
        assert!(left_full >= 0.45, "left full pressure at {left_full} s");
    }

    /// The host and the simulated board over a pty, in real time: the engine gets force
    /// events, the servos follow heel, midfoot, toe in order within each step, and return to
    /// rest after the walk.
    #[cfg(unix)]
    #[test]
    fn simulated_walk_drives_servos_heel_to_toe() {
        let config = sim_config(
            100,
            "steps=3,cadence=2.5,rate=250,lead_in=0.1,tail=0.4,variation=0",
        );
        let (mut host, sim) = open(&config).unwrap();
        let sim = sim.unwrap();
        let mut events = 0u64;
        let deadline = Instant::now() + Duration::from_secs(20);
        while Instant::now() < deadline {
            let state = host
                .poll(Duration::from_millis(20), &mut |e| {
                    assert!(matches!(e, Event::Force { channel: 0, .. }));
                    events += 1;
                })
                .unwrap();
            if state == SourceState::Ended {
                break;
            }
        }
        // Keep serving servo frames while the board lingers, so the return to rest shows.
        let until = Instant::now() + Duration::from_millis(250);
        while Instant::now() < until {
            let _ = host.poll(Duration::from_millis(10), &mut |_| {});
        }
        let hs = host.stats();
        let report = sim.finish().unwrap();
        eprintln!(
            "simulated: {} insole frames sent, host got {} ({} rejected), {} servo frames sent, \
             board got {}; servo delay max {:.1} ms mean {:.1} ms",
            report.insole_frames,
            hs.insole_frames,
            hs.rejected,
            hs.servo_frames_sent,
            report.servo_frames,
            hs.max_servo_delay.0 * 1e3,
            hs.mean_servo_delay.0 * 1e3
        );
        assert_eq!(hs.insole_frames, report.insole_frames);
        assert_eq!(hs.rejected, 0);
        assert_eq!(events, hs.insole_frames);
        assert!(hs.servo_frames_sent > 50);
        assert!(report.servo_frames + 5 >= hs.servo_frames_sent);
        assert_eq!(report.rejected, 0);
        // Within each step (the foot's stance), servo k peaks after servo k - 1.
        let step = 1.0 / 2.5 * 2.0; // one foot: a strike per gait cycle
        for n in 0..3 {
            let (from, to) = (0.1 + step * n as f64, 0.1 + step * (n as f64 + 0.9));
            let mut peak = [(0.0f64, 0.0f64); 3];
            for (t, pos) in &report.positions {
                if t.0 < from || t.0 > to {
                    continue;
                }
                for (p, &x) in peak.iter_mut().zip(pos) {
                    if x > p.0 {
                        *p = (x, t.0);
                    }
                }
            }
            assert!(peak.iter().all(|p| p.0 > 1200.0), "step {n}: {peak:?}");
            assert!(
                peak[0].1 < peak[1].1 && peak[1].1 < peak[2].1,
                "step {n}: heel, midfoot, toe in order: {peak:?}"
            );
        }
        // After the walk, everything back at rest.
        let last = &report.positions.last().unwrap().1;
        assert!(last.iter().all(|&p| (p - 1000.0).abs() < 1.0), "{last:?}");
    }
}
