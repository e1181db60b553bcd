//! Force from a recorded or generated [`ForceTrack`], at real-time pace (or faster, or
//! slower).
//!
//! The clock starts at the first [`poll`](EventSource::poll): row times count from there,
//! relative to the first row's time (a track on a logger's clock, starting at
//! `1700000000`, plays at once), divided by the speed. Rows more than
//! [`MAX_TRACK_GAP`] apart are refused, as by the track's reader. A poll sleeps until the next row is due or its timeout runs out,
//! whichever is first, then hands over every row that is due, each as one [`Event::Force`]
//! per channel in channel order. A poll that comes late hands over every row it missed, in
//! order: rows are never dropped, so a replay always delivers the whole track.
//!
//! Times are measured from one [`Instant`], not summed from row to row, so the error of each
//! sleep does not accumulate over a long track.
//!
//! Every reading is stamped with its row's time over the speed as its sensor time
//! ([`SensorReading::at`](crate::force::SensorReading::at)): the time at which the replayed foot produced it. The engine
//! times the step's loading rate and the reading's frame by that, not by when the poll
//! happened to hand it over (see [`crate::engine`], *Timing*), so a replay plays like an
//! offline render of the same track.

use std::time::{Duration, Instant};

use super::{EventSource, IoError, SourceState, SourceStats};
use crate::engine::Event;
use crate::force::track::ForceTrack;
use crate::limits::MAX_TRACK_GAP;
use crate::units::Seconds;

/// A force track as an [`EventSource`].
#[derive(Debug, Clone)]
pub struct ReplaySource {
    track: ForceTrack,
    /// When each row is due, from the start, at the replay speed.
    due: Vec<Duration>,
    /// The first row's time: row times count from it.
    first: f64,
    speed: f64,
    next: usize,
    start: Option<Instant>,
    stats: SourceStats,
}

const DEVICE: &str = "replay";

fn unsupported(reason: String) -> IoError {
    IoError::Unsupported {
        device: DEVICE.to_string(),
        reason,
    }
}

impl ReplaySource {
    /// A replay of `track` at `speed` times real time (1.0 is real time, 2.0 twice as fast).
    ///
    /// # Errors
    /// [`IoError::Unsupported`] if `speed` is not positive and finite, if a row's time is
    /// not finite, earlier than the row before, more than [`MAX_TRACK_GAP`] after it, or
    /// too far out to schedule, if a
    /// row has not one reading per channel, or if a reading is not finite.
    pub fn new(track: ForceTrack, speed: f64) -> Result<Self, IoError> {
        if !(speed.is_finite() && speed > 0.0) {
            return Err(unsupported(format!(
                "speed must be positive and finite, not {speed}"
            )));
        }
        if track.channels.len() > usize::from(u16::MAX) + 1 {
            return Err(unsupported(format!(
                "{} channels, at most 65536",
                track.channels.len()
            )));
        }
        let mut due = Vec::with_capacity(track.rows.len());
        let first = track.rows.first().map_or(0.0, |r| r.time.0);
        let mut last = first;
        for (i, row) in track.rows.iter().enumerate() {
            let t = row.time.0;
            if !(t.is_finite() && t >= last) {
                return Err(unsupported(format!(
                    "row {i}: time {t} s is not finite or goes back from {last} s"
                )));
            }
            if t - last > MAX_TRACK_GAP.0 {
                return Err(unsupported(format!(
                    "row {i}: time {t} s is {} s after the row before; rows may be at most \
                     {} s apart",
                    t - last,
                    MAX_TRACK_GAP.0
                )));
            }
            last = t;
            // From the first reading: a logger's clock would otherwise schedule the first
            // row decades out.
            let t = t - first;
            if row.readings.len() != track.channels.len() {
                return Err(unsupported(format!(
                    "row {i}: {} readings for {} channels",
                    row.readings.len(),
                    track.channels.len()
                )));
            }
            if !row.readings.iter().all(|r| r.is_finite()) {
                return Err(unsupported(format!("row {i}: a reading is not finite")));
            }
            due.push(Duration::try_from_secs_f64(t / speed).map_err(|_| {
                unsupported(format!("row {i}: {t} s at speed {speed} is too far out"))
            })?);
        }
        Ok(Self {
            track,
            due,
            first,
            speed,
            next: 0,
            start: None,
            stats: SourceStats::default(),
        })
    }

    /// How long the replay takes in wall-clock time: when its last row is due.
    #[must_use]
    pub fn duration(&self) -> Duration {
        self.due.last().copied().unwrap_or_default()
    }

    /// Rows not yet handed over.
    #[must_use]
    pub fn rows_left(&self) -> usize {
        self.due.len() - self.next
    }

    fn state(&self) -> SourceState {
        if self.next == self.due.len() {
            SourceState::Ended
        } else {
            SourceState::Open
        }
    }

    /// Hands over every row due by `elapsed`.
    fn emit_due(&mut self, elapsed: Duration, out: &mut dyn FnMut(Event)) {
        while self.next < self.due.len() && self.due[self.next] <= elapsed {
            let row = &self.track.rows[self.next];
            let time = Seconds((row.time.0 - self.first) / self.speed);
            for (channel, reading) in row.readings.iter().enumerate() {
                // Channel counts above u16 were refused in `new`.
                let Ok(channel) = u16::try_from(channel) else {
                    break;
                };
                out(Event::Force {
                    channel,
                    reading: reading.at(time),
                });
                self.stats.events += 1;
            }
            self.next += 1;
        }
    }
}

impl EventSource for ReplaySource {
    fn poll(
        &mut self,
        timeout: Duration,
        out: &mut dyn FnMut(Event),
    ) -> Result<SourceState, IoError> {
        let start = *self.start.get_or_insert_with(Instant::now);
        if let Some(&due) = self.due.get(self.next) {
            let elapsed = start.elapsed();
            if due > elapsed {
                std::thread::sleep((due - elapsed).min(timeout));
            }
            self.emit_due(start.elapsed(), out);
        }
        Ok(self.state())
    }

    fn stats(&self) -> SourceStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::force::SensorReading;
    use crate::force::track::{ChannelSensors, ForceRow};

    /// Two channels of heel and toe; row `i` at `i * step` seconds reads `i` on every sensor
    /// of channel 0 and `-i` on channel 1, so order can be checked from the values.
    fn track(rows: usize, step: f64) -> ForceTrack {
        let channel = |name: &str| ChannelSensors {
            name: name.into(),
            sensors: vec!["heel".into(), "toe".into()],
        };
        ForceTrack {
            channels: vec![channel("left"), channel("right")],
            rows: (0..rows)
                .map(|i| ForceRow {
                    time: Seconds(i as f64 * step),
                    readings: vec![
                        SensorReading::new(&[i as f32, i as f32]).unwrap(),
                        SensorReading::new(&[-(i as f32), -(i as f32)]).unwrap(),
                    ],
                })
                .collect(),
        }
    }

    /// Replays to the end; returns each event with its time from the first poll, and the
    /// total time.
    fn replay(source: &mut ReplaySource) -> (Vec<(Duration, Event)>, Duration) {
        let start = Instant::now();
        let mut events = Vec::new();
        for _ in 0..100_000 {
            let state = source
                .poll(Duration::from_millis(50), &mut |e| {
                    events.push((start.elapsed(), e));
                })
                .unwrap();
            if state == SourceState::Ended {
                break;
            }
        }
        (events, start.elapsed())
    }

    /// Checks the rows' order and values, and that each reading carries its row's time
    /// (`step` seconds apart in the track) over the speed.
    fn check_order(events: &[(Duration, Event)], rows: usize, step: f64, speed: f64) {
        assert_eq!(events.len(), 2 * rows);
        for (i, pair) in events.chunks(2).enumerate() {
            let v = i as f32;
            let t = Seconds(i as f64 * step / speed);
            assert_eq!(
                [pair[0].1, pair[1].1],
                [
                    Event::Force {
                        channel: 0,
                        reading: SensorReading::new(&[v, v]).unwrap().at(t)
                    },
                    Event::Force {
                        channel: 1,
                        reading: SensorReading::new(&[-v, -v]).unwrap().at(t)
                    }
                ],
                "row {i}"
            );
        }
    }

    #[test]
    fn real_time_pace() {
        // 31 rows, 10 ms apart: 0.3 s.
        let mut source = ReplaySource::new(track(31, 0.01), 1.0).unwrap();
        assert_eq!(source.duration(), Duration::from_millis(300));
        let (events, took) = replay(&mut source);
        eprintln!("replay at 1x: 0.300 s track took {took:?}");
        check_order(&events, 31, 0.01, 1.0);
        assert!(
            took >= Duration::from_millis(300) && took <= Duration::from_millis(330),
            "{took:?}"
        );
        // No row early: each arrives at or after its time.
        for (i, (at, _)) in events.iter().enumerate() {
            let due = Duration::from_millis(10 * (i / 2) as u64);
            assert!(*at >= due, "row {} at {at:?}, due {due:?}", i / 2);
        }
        assert_eq!(source.stats().events, 62);
        assert_eq!(source.rows_left(), 0);
        // Ended stays ended.
        let mut more = 0;
        assert_eq!(
            source
                .poll(Duration::from_millis(10), &mut |_| more += 1)
                .unwrap(),
            SourceState::Ended
        );
        assert_eq!(more, 0);
    }

    #[test]
    fn ten_times_faster() {
        let mut source = ReplaySource::new(track(31, 0.01), 10.0).unwrap();
        let (events, took) = replay(&mut source);
        eprintln!("replay at 10x: 0.300 s track took {took:?}");
        check_order(&events, 31, 0.01, 10.0);
        assert!(
            took >= Duration::from_millis(30) && took <= Duration::from_millis(45),
            "{took:?}"
        );
    }

    #[test]
    fn a_poll_waits_no_longer_than_its_timeout() {
        let mut t = track(2, 0.0);
        t.rows[1].time = Seconds(0.2);
        let mut source = ReplaySource::new(t, 1.0).unwrap();
        let mut n = 0;
        let start = Instant::now();
        // The first row is due at once; the second not within this poll.
        let state = source
            .poll(Duration::from_millis(20), &mut |_| n += 1)
            .unwrap();
        assert_eq!((state, n), (SourceState::Open, 2));
        let state = source
            .poll(Duration::from_millis(20), &mut |_| n += 1)
            .unwrap();
        let took = start.elapsed();
        assert_eq!((state, n), (SourceState::Open, 2));
        assert!(took >= Duration::from_millis(20) && took < Duration::from_millis(150));
    }

    #[test]
    fn an_empty_track_ends_at_once() {
        let mut source = ReplaySource::new(track(0, 0.01), 1.0).unwrap();
        assert_eq!(
            source.poll(Duration::from_secs(1), &mut |_| {}).unwrap(),
            SourceState::Ended
        );
    }

    #[test]
    fn a_track_on_a_loggers_clock_plays_from_its_first_row() {
        // Issue 14: rows at 1700000000 s made a replay wait 54 years for its first row.
        let mut t = track(31, 0.01);
        for row in &mut t.rows {
            row.time.0 += 1_700_000_000.0;
        }
        let mut source = ReplaySource::new(t, 1.0).unwrap();
        assert!(source.duration() < Duration::from_millis(301));
        let start = Instant::now();
        let (events, took) = replay(&mut source);
        assert!(took < Duration::from_millis(400), "{took:?}");
        assert!(start.elapsed() < Duration::from_secs(1));
        assert_eq!(events.len(), 62);
        // Stamped from the first row too.
        let Event::Force { reading, .. } = events[60].1 else {
            panic!("a force event")
        };
        let time = reading.time().unwrap();
        assert!((time.0 - 0.3).abs() < 1e-6, "{time:?}");
    }

    #[test]
    fn bad_tracks_and_speeds_are_refused() {
        for speed in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(ReplaySource::new(track(3, 0.01), speed).is_err(), "{speed}");
        }
        let mut backwards = track(3, 0.01);
        backwards.rows[2].time = Seconds(0.005);
        let mut nan_time = track(3, 0.01);
        nan_time.rows[1].time = Seconds(f64::NAN);
        let mut negative = track(3, 0.01);
        negative.rows[1].time = Seconds(-1.0);
        let mut far = track(3, 0.01);
        far.rows[2].time = Seconds(1e300);
        let mut gap = track(3, 0.01);
        gap.rows[2].time = Seconds(10.5);
        let mut short_row = track(3, 0.01);
        short_row.rows[1].readings.pop();
        let mut nan_force = track(3, 0.01);
        nan_force.rows[1].readings[0] = SensorReading::single(f32::NAN);
        for (what, t) in [
            ("backwards", backwards),
            ("NaN time", nan_time),
            ("negative time", negative),
            ("too far", far),
            ("a gap over 10 s", gap),
            ("short row", short_row),
            ("NaN force", nan_force),
        ] {
            assert!(
                matches!(ReplaySource::new(t, 1e-3), Err(IoError::Unsupported { .. })),
                "{what}"
            );
        }
    }
}
