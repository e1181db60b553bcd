//! Raw sensor counts to newtons at run time: one factor for every sensor, or a curve (or
//! factor) per sensor from a calibration file.
//!
//! A serial frame carries raw ADC counts (see `io::serial`); the host turns them into
//! newtons. The simplest scale is one `newtons_per_count` for all sensors, which is right
//! for a load cell and rough for a force-sensing resistor. A calibration made by
//! `underfoot calibrate sensors` ([`SensorCalibration`]) gives each sensor its own fitted
//! curve, clamped to the range it was fitted over. [`CountScale`] is either, and scales a
//! whole frame into a caller's buffer, so the poll thread allocates nothing per frame.

use super::calibration::{ApplyStats, CurveError, SensorCalibration, SensorCurve};

/// What is wrong with a [`CountScale`] for a frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ScaleError {
    /// A factor that is not positive and finite.
    #[error(
        "{}: newtons per count must be positive and finite, not {factor}",
        sensor.map_or_else(|| "every sensor".to_owned(), |i| format!("sensor {i}"))
    )]
    Factor {
        /// The sensor, or `None` for the one factor of every sensor.
        sensor: Option<usize>,
        /// The factor.
        factor: f32,
    },
    /// A per-sensor scale of another length than the frame.
    #[error("{scales} sensor scale(s) for {sensors} sensor(s) per frame")]
    Count {
        /// Scales given.
        scales: usize,
        /// Sensors per frame.
        sensors: usize,
    },
    /// A calibration curve that cannot be applied.
    #[error("sensor {sensor}: the calibration: {curve}")]
    Curve {
        /// The sensor, by its place in the frame.
        sensor: usize,
        /// What is wrong with its curve.
        curve: CurveError,
    },
}

/// How one sensor's raw count becomes newtons.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorScale {
    /// Proportional: `newtons = count × newtons_per_count`.
    Linear {
        /// Newtons per ADC count; positive and finite.
        newtons_per_count: f32,
    },
    /// A fitted calibration curve.
    Curve(SensorCurve),
}

/// How every sensor of a frame becomes newtons.
#[derive(Debug, Clone, PartialEq)]
pub enum CountScale {
    /// The same factor for every sensor.
    Uniform {
        /// Newtons per ADC count; positive and finite.
        newtons_per_count: f32,
    },
    /// One scale per sensor, in frame order.
    PerSensor(Vec<SensorScale>),
}

impl CountScale {
    /// Every sensor of `calibration`, in its order, by its own curve.
    #[must_use]
    pub fn calibrated(calibration: &SensorCalibration) -> Self {
        Self::PerSensor(
            calibration
                .sensors
                .iter()
                .cloned()
                .map(SensorScale::Curve)
                .collect(),
        )
    }

    /// Checks the factors and curves against a frame of `sensors` counts.
    ///
    /// # Errors
    /// [`ScaleError`]: a factor that is not positive and finite, an invalid curve, or a
    /// per-sensor scale whose length is not `sensors`.
    pub fn check(&self, sensors: usize) -> Result<(), ScaleError> {
        let factor = |f: f32, sensor: Option<usize>| {
            if f.is_finite() && f > 0.0 {
                Ok(())
            } else {
                Err(ScaleError::Factor { sensor, factor: f })
            }
        };
        match self {
            Self::Uniform { newtons_per_count } => factor(*newtons_per_count, None),
            Self::PerSensor(scales) => {
                if scales.len() != sensors {
                    return Err(ScaleError::Count {
                        scales: scales.len(),
                        sensors,
                    });
                }
                for (i, s) in scales.iter().enumerate() {
                    match s {
                        SensorScale::Linear { newtons_per_count } => {
                            factor(*newtons_per_count, Some(i))?;
                        }
                        SensorScale::Curve(curve) => curve
                            .check()
                            .map_err(|curve| ScaleError::Curve { sensor: i, curve })?,
                    }
                }
                Ok(())
            }
        }
    }

    /// Scales `counts[i]` into `out[i]`. No allocation, no panic: outputs without a count
    /// or a scale get 0 N and are counted as missing; a curve's clamping and non-finite
    /// results are counted as [`SensorCalibration::apply`] counts them.
    pub fn apply(&self, counts: &[u16], out: &mut [f32]) -> ApplyStats {
        let mut stats = ApplyStats::default();
        for (i, o) in out.iter_mut().enumerate() {
            let Some(&c) = counts.get(i) else {
                *o = 0.0;
                stats.missing += 1;
                continue;
            };
            let scale = match self {
                Self::Uniform { newtons_per_count } => {
                    *o = f32::from(c) * newtons_per_count;
                    continue;
                }
                Self::PerSensor(scales) => scales.get(i),
            };
            match scale {
                None => {
                    *o = 0.0;
                    stats.missing += 1;
                }
                Some(SensorScale::Linear { newtons_per_count }) => {
                    *o = f32::from(c) * newtons_per_count;
                }
                Some(SensorScale::Curve(curve)) => *o = stats.force(curve, f64::from(c)),
            }
        }
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::force::calibration::CurveModel;

    fn curve(name: &str, a: f64) -> SensorCurve {
        SensorCurve {
            name: name.into(),
            model: CurveModel::Power {
                a,
                b: 1.0,
                r0: 100.0,
            },
            raw_range: [100.0, 1100.0],
            drift: 0.0,
        }
    }

    #[test]
    fn uniform_scale_multiplies() {
        let s = CountScale::Uniform {
            newtons_per_count: 0.25,
        };
        assert!(s.check(3).is_ok());
        let mut out = [9.0; 3];
        let stats = s.apply(&[4, 0, 65535], &mut out);
        assert_eq!(out, [1.0, 0.0, 65535.0 * 0.25]);
        assert_eq!(stats, ApplyStats::default());
        // A short frame leaves the rest at zero, counted.
        let stats = s.apply(&[4], &mut out);
        assert_eq!(out, [1.0, 0.0, 0.0]);
        assert_eq!(stats.missing, 2);
    }

    #[test]
    fn calibration_gives_each_sensor_its_curve_and_clamps() {
        let cal = SensorCalibration {
            sensors: vec![curve("heel", 0.5), curve("toe", 2.0)],
        };
        let s = CountScale::calibrated(&cal);
        assert!(s.check(2).is_ok());
        assert!(s.check(3).is_err());
        let mut out = [0.0; 2];
        // 300 counts is 200 above r0: 100 N on the heel, 400 N on the toe.
        let stats = s.apply(&[300, 300], &mut out);
        assert_eq!(out, [100.0, 400.0]);
        assert_eq!(stats, ApplyStats::default());
        // Above the fitted range the force saturates at the range's top; below, at its
        // bottom (0 N here).
        let stats = s.apply(&[5000, 50], &mut out);
        assert_eq!(out, [500.0, 0.0]);
        assert_eq!((stats.above_range, stats.below_range), (1, 1));
    }

    #[test]
    fn mixed_scales_and_bad_factors() {
        let s = CountScale::PerSensor(vec![
            SensorScale::Linear {
                newtons_per_count: 2.0,
            },
            SensorScale::Curve(curve("toe", 1.0)),
        ]);
        let mut out = [0.0; 2];
        s.apply(&[10, 600], &mut out);
        assert_eq!(out, [20.0, 500.0]);
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert!(
                CountScale::Uniform {
                    newtons_per_count: bad
                }
                .check(1)
                .is_err()
            );
            assert!(
                CountScale::PerSensor(vec![SensorScale::Linear {
                    newtons_per_count: bad
                }])
                .check(1)
                .is_err()
            );
        }
        let mut reversed = curve("x", 1.0);
        reversed.raw_range = [5.0, 1.0];
        assert!(
            CountScale::PerSensor(vec![SensorScale::Curve(reversed)])
                .check(1)
                .is_err()
        );
    }
}
