//! The calibration file: a [document](crate::document) of kind [`FILE_KIND`] (see the
//! parent module, *Files*).

use std::path::Path;

use super::curve::SensorCalibration;
use super::error::{CurveError, SensorCalibrationError};
use crate::atomic_file::OutputFile;
use crate::document::{self, Document};

/// The kind in a calibration file's format tag, `underfoot.sensor-calibration/1`.
pub const FILE_KIND: &str = "sensor-calibration";

/// The version of the calibration file this code writes: the shape of its body. Version
/// 1 is `{"sensors": [...]}`, the same under the format tag as under the old header.
pub const FILE_VERSION: u32 = 1;

/// The `"kind"` of calibration files written before the format tag; they still load.
pub const LEGACY_FILE_KIND: &str = "underfoot-sensor-calibration";

impl Document for SensorCalibration {
    const KIND: &'static str = FILE_KIND;
    const VERSION: u32 = FILE_VERSION;
    const LEGACY_KIND: Option<&'static str> = Some(LEGACY_FILE_KIND);
    const DESCRIPTION: &'static str = "sensor calibration";
    type Invalid = CurveError;

    fn validate(&self) -> Result<(), CurveError> {
        self.check()
    }
}

impl SensorCalibration {
    /// The calibration as file text, as [`document::to_json`] writes it: the format tag
    /// first, then the curves.
    ///
    /// # Errors
    /// [`SensorCalibrationError::Document`] for a curve that cannot be applied: a file
    /// written here always reads back.
    pub fn to_json(&self) -> Result<String, SensorCalibrationError> {
        Ok(document::to_json(self, "the sensor calibration")?)
    }

    /// Parses and checks calibration file text, as [`document::from_json`] does; `origin`
    /// names it in errors.
    ///
    /// # Errors
    /// [`SensorCalibrationError::Document`]: text that is not a sensor calibration of a
    /// version this build reads, or a curve that cannot be applied.
    pub fn from_json_str(text: &str, origin: &str) -> Result<Self, SensorCalibrationError> {
        Ok(document::from_json(text, origin)?)
    }

    /// Reads and checks a calibration file, as [`document::load`] does.
    ///
    /// # Errors
    /// [`SensorCalibrationError::Document`]: a file that cannot be read, or what
    /// [`SensorCalibration::from_json_str`] finds.
    pub fn load(path: &Path) -> Result<Self, SensorCalibrationError> {
        Ok(document::load(path)?)
    }

    /// Checks the calibration, then writes it atomically, as [`document::save`] does: a
    /// failure leaves any previous file as it was.
    ///
    /// # Errors
    /// [`SensorCalibrationError::Document`]: a curve that cannot be applied, or a file
    /// the output policy refuses or that cannot be written.
    pub fn save(&self, path: &Path) -> Result<(), SensorCalibrationError> {
        Ok(document::save(path, self)?)
    }

    /// [`SensorCalibration::save`] to an output the caller checked against the output
    /// policy ([`crate::atomic_file`]) together with its inputs.
    ///
    /// # Errors
    /// As [`SensorCalibration::save`].
    pub fn save_to(&self, out: &OutputFile) -> Result<(), SensorCalibrationError> {
        Ok(document::save_to(out, self)?)
    }
}
