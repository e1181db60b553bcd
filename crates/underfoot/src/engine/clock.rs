//! Sensor time to engine frames, for readings that carry their sensor time but no frame.
//!
//! A live source knows when each reading was taken (its sensor time `t`), but not which
//! audio frame is playing: its readings reach the audio thread whenever the next
//! [`process`](super::Engine::process) call drains the queue. Applying them there puts every
//! onset on the block grid, late by anything from zero to one block. Instead the engine
//! maps sensor time onto its frame clock with one affine rule and applies each reading at
//! its own frame, splitting the block there as for [`TimedEvent::at`](super::TimedEvent).
//!
//! # The rule
//!
//! The first stamped reading, drained at the start of a `process` call at engine frame `F`
//! rendering `B` frames, *anchors* the clock:
//!
//! ```text
//! t_A = t,    A = F + B + M,    M = round(sensor_latency · fs)
//! ```
//!
//! and every stamped reading, that one included, applies at
//!
//! ```text
//! frame(t) = A + round((t − t_A) · fs)
//! ```
//!
//! `B + M` is the latency budget: a reading taken at `t` reaches the engine up to one
//! block after it was sent (it waits for the next call) plus the source's own jitter
//! (thread wake-up, the pacing of the output); `M` covers the jitter. Within the budget
//! every reading lands on its frame and the output is exactly the offline render's
//! (where `frame(t) = round((t − t_0) · fs)`), shifted by `A − round((t_A − t_0) · fs)`:
//! the same steps, as loud, as far apart, for every block size.
//!
//! A reading drained after its frame has been rendered is applied at once (counted as
//! late). One more than `B + M` late, or more than `B + M` plus a quarter second early
//! (the sensor clock jumped, or has drifted that far from the audio clock; a renderer
//! that stalled for less than that catches up and plays the readings on their frames),
//! re-anchors the clock on itself as the first reading did (counted as a resync): a
//! lasting offset becomes one jump in latency instead of every reading being late or held
//! back. Frames never go back: a reading is never scheduled before the one drained before
//! it, so a re-anchoring cannot reorder the readings (which the detector would take for a
//! sensor clock that restarted).

use crate::units::{SampleRate, Seconds};

/// Where the sensor clock is anchored: sensor time `time` plays at engine frame `frame`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockAnchor {
    /// The engine frame of `time`.
    pub frame: u64,
    /// The sensor time.
    pub time: Seconds,
}

/// The mapping from sensor time to engine frames. Never allocates.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct SensorClock {
    rate: f64,
    margin: u64,
    /// How far beyond the budget a reading may be early before the clock re-anchors.
    slack: f64,
    anchor: Option<ClockAnchor>,
    last: u64,
    resyncs: u64,
}

impl SensorClock {
    /// A clock for `rate` with jitter margin `latency` (`M` in the rule).
    pub(super) fn new(rate: SampleRate, latency: Seconds) -> Self {
        Self {
            rate: rate.hz(),
            margin: (latency.0.max(0.0) * rate.hz()).round() as u64,
            slack: 0.25 * rate.hz(),
            anchor: None,
            last: 0,
            resyncs: 0,
        }
    }

    pub(super) fn anchor(&self) -> Option<ClockAnchor> {
        self.anchor
    }

    pub(super) fn resyncs(&self) -> u64 {
        self.resyncs
    }

    /// The frame of a reading of sensor time `time` (finite), drained at the start of a
    /// call at frame `now` rendering `block` frames.
    pub(super) fn frame_of(&mut self, time: f64, now: u64, block: usize) -> u64 {
        let budget = block as u64 + self.margin;
        let fresh = ClockAnchor {
            frame: now + budget,
            time: Seconds(time),
        };
        let anchor = *self.anchor.get_or_insert(fresh);
        let offset = ((time - anchor.time.0) * self.rate).round();
        // In f64: a sensor time far from the anchor must not wrap.
        let frame = anchor.frame as f64 + offset;
        let (now_f, budget_f) = (now as f64, budget as f64);
        let frame = if frame < now_f - budget_f || frame > now_f + budget_f + self.slack {
            self.anchor = Some(fresh);
            self.resyncs += 1;
            fresh.frame
        } else {
            frame.max(0.0) as u64
        };
        self.last = self.last.max(frame);
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: SampleRate = SampleRate(48_000);

    #[test]
    fn the_first_reading_anchors_one_budget_after_its_block() {
        let mut c = SensorClock::new(RATE, Seconds(0.01));
        assert_eq!(c.anchor(), None);
        // Drained at frame 1000 in a 256-frame call: A = 1000 + 256 + 480.
        assert_eq!(c.frame_of(3.0, 1000, 256), 1736);
        assert_eq!(
            c.anchor(),
            Some(ClockAnchor {
                frame: 1736,
                time: Seconds(3.0)
            })
        );
        // Later readings keep their sensor spacing, whenever they are drained.
        assert_eq!(c.frame_of(3.002, 1256, 256), 1736 + 96);
        assert_eq!(c.frame_of(3.004, 1256, 256), 1736 + 192);
        assert_eq!(c.frame_of(3.1, 5800, 64), 1736 + 4800);
        assert_eq!(c.resyncs(), 0);
    }

    #[test]
    fn a_jump_or_a_drift_beyond_the_budget_re_anchors() {
        let mut c = SensorClock::new(RATE, Seconds(0.0));
        assert_eq!(c.frame_of(0.0, 0, 100), 100);
        // Late within the budget: kept (the engine applies it at once).
        assert_eq!(c.frame_of(0.001, 200, 100), 148);
        assert_eq!(c.resyncs(), 0);
        // Late beyond it: the clock moves.
        assert_eq!(c.frame_of(0.002, 400, 100), 500);
        assert_eq!(c.resyncs(), 1);
        // A sensor clock that jumps ahead by a second.
        assert_eq!(c.frame_of(1.002, 500, 100), 600);
        assert_eq!(c.resyncs(), 2);
        // Early by less than the budget and a quarter second (a renderer catching up).
        assert_eq!(c.frame_of(1.202, 500, 100), 600 + 9600);
        assert_eq!(c.resyncs(), 2);
        // One that jumps back re-anchors, but is not scheduled before the one before it.
        assert_eq!(c.frame_of(0.5, 600, 100), 600 + 9600);
        assert_eq!(c.resyncs(), 3);
        assert_eq!(c.frame_of(0.7, 700, 100), 700 + 9600);
    }
}
