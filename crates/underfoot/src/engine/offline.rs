//! Offline rendering: the real-time engine run as fast as it goes, on timed events.
//!
//! The same [`Engine`](super::Engine) renders a WAV file and drives a device, so what a
//! render sounds like is what a session feels like. Every event carries its frame, which
//! makes the output independent of the block size (tested for 1, 7, 64 and 512 frames).

use super::{
    EngineConfig, EngineError, Event, MaterialBank, StrikeRecord, TelemetrySnapshot, TimedEvent,
};
use crate::force::gait::{self, GaitConfig, GaitError};
use crate::force::track::ForceTrack;
use crate::units::{SampleRate, Seconds};

/// Events for a force track: each row's readings, stamped with the row's time as their
/// sensor time, at frame `round((t - t_0) * fs)` with `t_0` the first row's time (times
/// count from the first reading, so a track on a logger's clock renders from frame 0);
/// channel `k` of the track to engine channel `k`.
///
/// A live session of the same track (readings stamped alike, sent without a frame) plays
/// the same output shifted by a constant ([`super::clock`]).
#[must_use]
pub fn track_events(track: &ForceTrack, rate: SampleRate) -> Vec<TimedEvent> {
    let start = track.rows.first().map_or(0.0, |r| r.time.0);
    let mut events = Vec::with_capacity(track.rows.len() * track.channels.len());
    for row in &track.rows {
        let frame = ((row.time.0 - start) * rate.hz()).round().max(0.0) as u64;
        for (channel, reading) in row.readings.iter().enumerate() {
            events.push(TimedEvent::at(
                frame,
                Event::Force {
                    channel: channel as u16,
                    reading: reading.at(row.time),
                },
            ));
        }
    }
    events
}

/// An offline render: interleaved samples and the engine's counters at the end.
#[derive(Debug, Clone)]
pub struct Render {
    /// `frames x channels` samples, interleaved.
    pub samples: Vec<f32>,
    /// Channels per frame.
    pub channels: usize,
    /// The engine's counters.
    pub telemetry: TelemetrySnapshot,
    /// Every strike played, in order: detected from force or sent as a step.
    pub strikes: Vec<StrikeRecord>,
}

/// Renders `frames` frames of `events` (sorted by frame) in blocks of `block` frames.
///
/// # Errors
/// An invalid configuration or initial material.
pub fn render(
    config: &EngineConfig,
    bank: MaterialBank,
    initial: &[u16],
    events: &[TimedEvent],
    frames: usize,
    block: usize,
) -> Result<Render, EngineError> {
    let config = EngineConfig {
        // Every event is queued before its block: make room for a block's worth.
        queue_capacity: config.queue_capacity.max(events.len().min(1 << 20) + 1),
        ..config.clone()
    };
    let (mut controller, mut engine) = super::build(&config, bank, initial)?;
    let channels = config.channels;
    let block = block.max(1);
    let mut samples = vec![0.0f32; frames * channels];
    let mut strikes = Vec::new();
    let mut next = 0;
    let mut done = 0;
    while done < frames {
        let n = block.min(frames - done);
        let end = (done + n) as u64;
        while next < events.len() && events[next].at.is_none_or(|at| at < end) {
            controller.send(events[next])?;
            next += 1;
        }
        engine.process(
            &mut samples[done * channels..(done + n) * channels],
            channels,
        );
        done += n;
        controller.collect();
        // Drained every block, so the log (thousands of records) never fills.
        controller.take_strikes(|s| strikes.push(*s));
    }
    Ok(Render {
        samples,
        channels,
        telemetry: controller.telemetry(),
        strikes,
    })
}

/// The longest offline render: an hour of one channel (half an hour of two, ...). A
/// render is held in memory, 700 MB for an hour at 48 kHz; a longer session is for a live
/// session writing its output as it goes.
pub const MAX_RENDER: Seconds = Seconds(3600.0);

/// Renders a force track: its events ([`track_events`]) played by the engine of `config`
/// on `initial` materials (one slot per channel), from the track's first reading to
/// `tail` after its last, in blocks of `block` frames (the output does not depend on it).
///
/// # Errors
/// [`EngineError::TooLong`] past [`MAX_RENDER`] of output (over all channels),
/// [`EngineError::InvalidConfig`] for a tail beyond a minute, and as [`render`].
pub fn render_track(
    config: &EngineConfig,
    bank: MaterialBank,
    initial: &[u16],
    track: &ForceTrack,
    tail: Seconds,
    block: usize,
) -> Result<Render, EngineError> {
    if !(tail.0.is_finite() && (0.0..=60.0).contains(&tail.0)) {
        return Err(EngineError::InvalidConfig(format!(
            "tail {} s: need 0 to 60",
            tail.0
        )));
    }
    let rate = config.rate;
    let channels = config.channels.max(1);
    let events = track_events(track, rate);
    // Frames count from the track's first reading (`track_events`).
    let last = events.last().and_then(|e| e.at).unwrap_or(0);
    let limit = Seconds(MAX_RENDER.0 / channels as f64);
    let frames = usize::try_from(last)
        .ok()
        .and_then(|last| last.checked_add(rate.samples_in(tail) + 1))
        .filter(|&n| n <= rate.samples_in(limit))
        .ok_or(EngineError::TooLong {
            length: track.duration(),
            channels,
            limit,
        })?;
    render(config, bank, initial, &events, frames, block)
}

/// One material's stretch of a walk.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkSegment {
    /// The material.
    pub material: String,
    /// Its slot in the bank.
    pub slot: u16,
    /// When the walker steps onto it (mid-swing, with no foot on the ground).
    pub start: Seconds,
    /// When the walker leaves it.
    pub end: Seconds,
    /// The heel strikes on it.
    pub strikes: Vec<Seconds>,
}

/// A walk across several materials, one foot (channel 0), ready to render.
#[derive(Debug, Clone)]
pub struct Walk {
    /// The force track.
    pub track: ForceTrack,
    /// Force readings and material changes, sorted by frame.
    pub events: Vec<TimedEvent>,
    /// The materials in order.
    pub segments: Vec<WalkSegment>,
    /// Length of the walk in frames.
    pub frames: usize,
}

/// Why a walk cannot be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WalkError {
    /// The gait is invalid.
    #[error(transparent)]
    Gait(#[from] GaitError),
    /// A material is not in the bank.
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// No materials were given.
    #[error("a walk needs at least one material")]
    NoMaterials,
}

/// A walk of `steps` heel strikes on each of `materials`, one after the other, with the
/// gait of `gait` (its `steps` and `channels` are replaced). Each material change falls
/// in the middle of a swing, between a toe-off and the next heel strike.
///
/// # Errors
/// An invalid gait or an unknown material.
pub fn walk_across(
    bank: &MaterialBank,
    materials: &[&str],
    steps: usize,
    gait: &GaitConfig,
    rate: SampleRate,
) -> Result<Walk, WalkError> {
    if materials.is_empty() {
        return Err(WalkError::NoMaterials);
    }
    let slots = materials
        .iter()
        .map(|m| bank.slot(m))
        .collect::<Result<Vec<_>, _>>()?;
    let config = GaitConfig {
        steps: steps.max(1) * materials.len(),
        channels: 1,
        ..gait.clone()
    };
    let g = gait::generate(&config)?;
    let strikes = &g.strikes[0];
    let toe_offs = &g.toe_offs[0];
    let steps = steps.max(1);
    let end_time = g.track.rows.last().map_or(Seconds(0.0), |r| r.time);
    let mut events = track_events(&g.track, rate);
    let mut segments = Vec::with_capacity(materials.len());
    for (k, (name, slot)) in materials.iter().zip(&slots).enumerate() {
        let first = k * steps;
        let start = if k == 0 {
            Seconds(0.0)
        } else {
            Seconds(0.5 * (toe_offs[first - 1].0 + strikes[first].0))
        };
        if k > 0 {
            let frame = (start.0 * rate.hz()).round() as u64;
            events.push(TimedEvent::at(
                frame,
                Event::Material {
                    channel: 0,
                    slot: *slot,
                },
            ));
        }
        if let Some(previous) = segments.last_mut() {
            let previous: &mut WalkSegment = previous;
            previous.end = start;
        }
        segments.push(WalkSegment {
            material: (*name).to_string(),
            slot: *slot,
            start,
            end: end_time,
            strikes: strikes[first..first + steps].to_vec(),
        });
    }
    // Stable: a material change at the frame of a reading comes after it.
    events.sort_by_key(|e| e.at);
    let frames = (end_time.0 * rate.hz()).ceil() as usize + 1;
    Ok(Walk {
        track: g.track,
        events,
        segments,
        frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::PlaySettings;
    use crate::material::builtin::builtin;

    #[test]
    fn a_render_lists_every_strike_at_the_frame_its_sound_starts() {
        let settings = PlaySettings::default();
        let rate = settings.rate;
        let bank = settings.prepare(builtin(), Some(&["gravel"])).unwrap();
        let walk = walk_across(&bank, &["gravel"], 5, &GaitConfig::default(), rate).unwrap();
        let config = settings.engine_config(1).unwrap();
        let out = render(&config, bank, &[0], &walk.events, walk.frames, 64).unwrap();
        assert_eq!(out.strikes.len(), 5);
        assert_eq!(out.telemetry.strikes, 5);
        for (strike, landed) in out.strikes.iter().zip(&walk.segments[0].strikes) {
            // The detector sees the force cross its threshold some milliseconds after
            // the foot lands.
            let after = strike.frame as f64 / rate.hz() - landed.0;
            assert!((0.0..0.05).contains(&after), "{after} s after the landing");
            let start = strike.frame as usize;
            assert!(
                out.samples[..start]
                    .iter()
                    .rev()
                    .take(8)
                    .all(|v| v.abs() < 1e-3)
            );
            assert!(out.samples[start..start + 48].iter().any(|v| *v != 0.0));
            assert_eq!((strike.channel, strike.slot), (0, Some(0)));
        }
    }
}
