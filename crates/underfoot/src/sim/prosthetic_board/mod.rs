//! The prosthetic-skin interface's board, simulated: an insole under one walking foot,
//! and servos that follow the host's frames.
//!
//! [`SimulatedFoot`] walks the gait model of [`crate::force::gait`] on one foot, splits
//! the force between heel, midfoot and toe as the centre of pressure rolls over, quantises
//! it like an ADC, and moves its servos toward the targets it receives at its own slew
//! rate, recording what it received and where its servos were
//! ([`SimulatedReport`]). [`SimulatedFoot::serve`] runs it on any port (the far end of a
//! pseudo-terminal); [`open_interface`] starts it on a pseudo-terminal, against a
//! [`ProstheticHost`](crate::io::prosthetic::ProstheticHost), when the configuration says
//! `port = "simulated"`.
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

use std::io::{self, Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use crate::force::SensorReading;
use crate::force::gait;
use crate::interface::config::SimulatedConfig;
use crate::io::IoError;
use crate::io::serial::{
    Frame, FrameData, FrameDecoder, MAX_FRAME_SENSORS, MAX_FRAME_SERVOS, encode_frame,
};
use crate::units::Seconds;

mod launch;
#[cfg(test)]
mod tests;

pub use launch::{SimulatorHandle, open_interface};

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
