//! Force in: sensor readings, force tracks, the walking gait, and the drive they make.
//!
//! Force sensors (a tile's four corners, an insole's heel and toe) report at a sensor rate of
//! 100 Hz to 1 kHz. A *channel* is one actuator with its own sensors: a tile, or one foot's
//! shoe or insole. A [`SensorReading`] is one instant of one channel's sensors, in newtons;
//! a [`ForceTrack`](track::ForceTrack) is a recorded or generated sequence of them for
//! every channel, stored as CSV.
//!
//! | module | what it does |
//! |---|---|
//! | [`track`] | force tracks and their CSV file format |
//! | [`calibration`] | raw sensor readings to newtons: fitted per-sensor curves, tare, their files |
//! | [`scale`] | raw counts to newtons at run time: one factor, or a curve per sensor |
//! | [`gait`] | the vertical ground-reaction force of walking, for demos and tests |
//! | [`condition`] | sensor rate to audio rate without zipper noise; total force, centre of pressure |
//! | [`steps`] | heel-strike detection with hysteresis |
//! | [`drive`] | the signal that excites the material filter: force, dF/dt, or an impulse per step |
pub mod calibration;
pub mod condition;
pub mod drive;
pub mod gait;
pub mod scale;
pub mod steps;
pub mod track;

/// The most sensors one channel can have.
pub const MAX_SENSORS: usize = 8;

use crate::units::Seconds;

/// One reading of one channel's force sensors, in newtons, without allocation.
///
/// Fixed capacity so that it can cross a lock-free queue to the audio thread by value.
///
/// A reading may carry its *sensor time* ([`at`](Self::at)): when the sensors were read,
/// in seconds on the sensor's own clock (a track's `time_s`, a replay's clock). The engine
/// measures a step's loading rate from these times and schedules the reading on its frame
/// clock by them, so neither depends on when the reading happened to reach the audio
/// thread (see [`crate::engine`], *Timing*). A reading without one is timed by its arrival.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorReading {
    values: [f32; MAX_SENSORS],
    len: u8,
    time: Option<f64>,
}

impl SensorReading {
    /// A reading of `values.len()` sensors, or `None` if there are more than
    /// [`MAX_SENSORS`] or none.
    #[must_use]
    pub fn new(values: &[f32]) -> Option<Self> {
        if values.is_empty() || values.len() > MAX_SENSORS {
            return None;
        }
        let mut v = [0.0; MAX_SENSORS];
        v[..values.len()].copy_from_slice(values);
        Some(Self {
            values: v,
            len: values.len() as u8,
            time: None,
        })
    }

    /// A reading of a single sensor (or of a total force).
    #[must_use]
    pub fn single(newtons: f32) -> Self {
        let mut values = [0.0; MAX_SENSORS];
        values[0] = newtons;
        Self {
            values,
            len: 1,
            time: None,
        }
    }

    /// The same reading, stamped with its sensor time.
    #[must_use]
    pub fn at(self, time: Seconds) -> Self {
        Self {
            time: Some(time.0),
            ..self
        }
    }

    /// When the sensors were read, on the sensor's clock, if the source knows.
    #[must_use]
    pub fn time(&self) -> Option<Seconds> {
        self.time.map(Seconds)
    }

    /// The sensors' values in newtons.
    #[must_use]
    pub fn as_slice(&self) -> &[f32] {
        &self.values[..usize::from(self.len)]
    }

    /// Number of sensors.
    #[must_use]
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether the reading has no sensors (never true for a constructed reading).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The total force: the sum of the sensors. Non-finite readings are left for the
    /// caller to reject.
    #[must_use]
    pub fn total(&self) -> f32 {
        self.as_slice().iter().sum()
    }

    /// Whether every value, and the sensor time if there is one, is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.as_slice().iter().all(|v| v.is_finite()) && self.time.is_none_or(f64::is_finite)
    }
}
