//! Re-zeroing for drift: a curve shifted along the reading axis so that readings taken
//! at rest map to the force it gave at rest when it was fitted (see the parent module,
//! *Range, drift and bad readings at run time*).

use super::curve::{CurveModel, SensorCalibration, SensorCurve};
use super::error::SensorCalibrationError;

impl SensorCurve {
    /// The reading at which this curve, without drift, gives its rest force: `r0` for
    /// the power law, the bottom of the range for the piecewise model.
    fn rest_reading(&self) -> f64 {
        match &self.model {
            CurveModel::Power { r0, .. } => r0.max(self.raw_range[0]),
            CurveModel::Piecewise { .. } => self.raw_range[0],
        }
    }

    /// Re-zeros the curve from readings taken with the sensor unloaded: the median of
    /// `readings_at_rest` becomes the reading the curve treats as its rest reading. Returns
    /// the drift now removed, in reading units.
    ///
    /// # Errors
    /// [`SensorCalibrationError::Tare`] if there are no finite readings.
    pub fn tare(&mut self, readings_at_rest: &[f64]) -> Result<f64, SensorCalibrationError> {
        let mut finite: Vec<f64> = readings_at_rest
            .iter()
            .copied()
            .filter(|r| r.is_finite())
            .collect();
        if finite.is_empty() {
            return Err(SensorCalibrationError::Tare {
                reason: format!("sensor {:?}: no finite rest readings", self.name),
            });
        }
        self.drift = crate::numeric::median(&mut finite) - self.rest_reading();
        Ok(self.drift)
    }
}

impl SensorCalibration {
    /// Re-zeros every sensor from readings taken at rest: `readings_at_rest` holds whole
    /// rows of one reading per sensor, interleaved (`s0, s1, .., s0, s1, ..`). Returns the
    /// drift removed per sensor.
    ///
    /// # Errors
    /// [`SensorCalibrationError::Tare`] if the length is not a non-zero multiple of the sensor
    /// count, or a sensor has no finite rest reading.
    pub fn tare(&mut self, readings_at_rest: &[f32]) -> Result<Vec<f64>, SensorCalibrationError> {
        let n = self.sensors.len();
        if n == 0 || readings_at_rest.is_empty() || !readings_at_rest.len().is_multiple_of(n) {
            return Err(SensorCalibrationError::Tare {
                reason: format!(
                    "{} rest readings are not whole rows of {n} sensors",
                    readings_at_rest.len()
                ),
            });
        }
        let mut drifts = Vec::with_capacity(n);
        for (s, curve) in self.sensors.iter_mut().enumerate() {
            let column: Vec<f64> = readings_at_rest
                .iter()
                .skip(s)
                .step_by(n)
                .map(|&r| f64::from(r))
                .collect();
            drifts.push(curve.tare(&column)?);
        }
        Ok(drifts)
    }
}
