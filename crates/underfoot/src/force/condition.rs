//! Sensor rate to audio rate: total force without zipper noise, and the centre of pressure.
//!
//! Readings arrive at the sensor rate (100 Hz to 1 kHz), the synthesis runs at the audio
//! rate. Holding each reading until the next would put a step into the force at every
//! reading, a buzz at the sensor rate in anything driven by force or its derivative. The
//! conditioner instead ramps linearly from the current value to each new reading over one
//! nominal sensor period (a first-order hold): continuous, with a derivative that is
//! constant between readings, at the cost of one sensor period of delay in the force
//! drives. Heel strikes are detected on the readings themselves
//! ([`super::steps`]), so the impulse drive has no such delay.
//!
//! A reading that arrives before the ramp to the previous one has finished starts a new
//! ramp from wherever the force is: the output never jumps.

use super::SensorReading;
use crate::units::{Hz, SampleRate};

/// One channel's total force at the audio rate.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceConditioner {
    ramp: u32,
    value: f32,
    target: f32,
    increment: f32,
    remaining: u32,
}

impl ForceConditioner {
    /// A conditioner for readings that come at about `sensor_rate`.
    #[must_use]
    pub fn new(rate: SampleRate, sensor_rate: Hz) -> Self {
        let ramp = (rate.hz() / sensor_rate.0.max(1.0)).round().max(1.0) as u32;
        Self {
            ramp,
            value: 0.0,
            target: 0.0,
            increment: 0.0,
            remaining: 0,
        }
    }

    /// The ramp length in samples.
    #[must_use]
    pub fn ramp(&self) -> u32 {
        self.ramp
    }

    /// A new reading: the total force ramps to its sum over the next sensor period.
    pub fn push(&mut self, reading: &SensorReading) {
        self.push_total(reading.total());
    }

    /// A new total force.
    pub fn push_total(&mut self, total: f32) {
        self.target = total;
        self.increment = (total - self.value) / self.ramp as f32;
        self.remaining = self.ramp;
    }

    /// The total force at the next audio sample.
    #[inline]
    pub fn next_total(&mut self) -> f32 {
        if self.remaining > 0 {
            self.remaining -= 1;
            self.value = if self.remaining == 0 {
                self.target
            } else {
                self.value + self.increment
            };
        }
        self.value
    }

    /// The current total force.
    #[must_use]
    pub fn total(&self) -> f32 {
        self.value
    }

    /// Back to zero force, at once.
    pub fn reset(&mut self) {
        self.value = 0.0;
        self.target = 0.0;
        self.remaining = 0;
    }
}

/// The centre of pressure of a reading: the force-weighted mean of the sensors'
/// positions (in whatever unit the positions are in, e.g. metres on the tile, or a
/// fraction of foot length from the heel). `None` when the total force is not positive.
#[must_use]
pub fn centre_of_pressure(reading: &SensorReading, positions: &[[f32; 2]]) -> Option<[f32; 2]> {
    let mut total = 0.0;
    let mut moment = [0.0f32; 2];
    for (f, p) in reading.as_slice().iter().zip(positions) {
        let f = f.max(0.0);
        total += f;
        moment[0] += f * p[0];
        moment[1] += f * p[1];
    }
    (total > 0.0 && total.is_finite()).then(|| [moment[0] / total, moment[1] / total])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_linearly_to_each_reading_without_jumps() {
        let mut c = ForceConditioner::new(SampleRate(48_000), Hz(500.0));
        assert_eq!(c.ramp(), 96);
        c.push(&SensorReading::new(&[300.0, 180.0]).unwrap());
        let ramp: Vec<f32> = (0..100).map(|_| c.next_total()).collect();
        assert!((ramp[0] - 5.0).abs() < 1e-4);
        assert!((ramp[47] - 240.0).abs() < 1e-3);
        assert_eq!(ramp[95], 480.0);
        assert_eq!(ramp[99], 480.0);
        // A reading mid-ramp starts from where the force is.
        c.push_total(0.0);
        let a = c.next_total();
        c.push_total(960.0);
        let b = c.next_total();
        assert!((a - 475.0).abs() < 1e-3 && (b - a - (960.0 - a) / 96.0).abs() < 1e-3);
    }

    #[test]
    fn centre_of_pressure_weights_the_sensors() {
        let corners = [[0.0, 0.0], [0.3, 0.0], [0.0, 0.3], [0.3, 0.3]];
        let r = SensorReading::new(&[100.0, 100.0, 0.0, 0.0]).unwrap();
        assert_eq!(centre_of_pressure(&r, &corners), Some([0.15, 0.0]));
        let r = SensorReading::new(&[100.0, 100.0, 100.0, 100.0]).unwrap();
        assert_eq!(centre_of_pressure(&r, &corners), Some([0.15, 0.15]));
        assert_eq!(
            centre_of_pressure(&SensorReading::new(&[0.0; 4]).unwrap(), &corners),
            None
        );
    }
}
