//! Force tracks: timed sensor readings for every channel, and their CSV file format.
//!
//! (Being written: see issue 3.)

use super::SensorReading;
use crate::units::Seconds;

/// The sensors of one channel, by name (e.g. `heel`, `toe`, or `corner0..corner3`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelSensors {
    /// Sensor names, in reading order.
    pub sensors: Vec<String>,
}

/// One row of a track: the time and every channel's reading.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceRow {
    /// Time from the start of the track.
    pub time: Seconds,
    /// One reading per channel, in channel order.
    pub readings: Vec<SensorReading>,
}

/// A force track: rows at increasing times, the same sensors on every row.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceTrack {
    /// The channels and their sensors.
    pub channels: Vec<ChannelSensors>,
    /// The rows, in increasing time.
    pub rows: Vec<ForceRow>,
}
