//! Sensor calibration: the readings CSV, and the fitted curves (JSON).

use super::text;
use crate::force::calibration::{
    CurveKind, LEGACY_FILE_KIND, SensorCalibration, fit_sensor, session_from_csv_str,
};

// ---- sensor calibration: the readings CSV, and the fitted curves (JSON) ----

pub(super) fn run_sensor_csv(data: &[u8]) {
    let Ok(sensors) = session_from_csv_str(&text(data), "fuzz") else {
        return;
    };
    // `calibrate sensors` fits each sensor next: the fit must end on anything parsed.
    for sensor in sensors.iter().take(4) {
        for kind in [CurveKind::Power, CurveKind::Piecewise] {
            let _ = fit_sensor(&sensor.name, &sensor.samples, kind);
        }
    }
}

pub(super) fn seeds_sensor_csv() -> Vec<Vec<u8>> {
    let mut csv = String::from("sensor,raw,load_n\n");
    for (name, r0) in [("left.heel", 200.0), ("left.toe", 150.0)] {
        for i in 0..10 {
            let load = 50.0 * f64::from(i);
            // The FSR's law inverted: raw = r0 + (F / a)^(1/b).
            let raw = r0 + (load / 0.012_f64).powf(1.0 / 1.4);
            csv.push_str(&format!("{name},{raw:.1},{load}\n"));
        }
    }
    vec![csv.into_bytes()]
}

pub(super) fn run_calibration_json(data: &[u8]) {
    let Ok(calibration) = SensorCalibration::from_json_str(&text(data), "fuzz") else {
        return;
    };
    let again = calibration
        .to_json()
        .and_then(|text| SensorCalibration::from_json_str(&text, "fuzz, saved"));
    assert!(
        again.is_ok(),
        "a loaded calibration does not reload: {again:?}"
    );
}

pub(super) fn seeds_calibration_json() -> Vec<Vec<u8>> {
    let documented = "{\"format\": \"underfoot.sensor-calibration/1\",\n \"sensors\": [{\"name\": \
                      \"heel\", \"model\": {\"power\": {\"a\": 0.012, \"b\": 1.4, \"r0\": 200.0}},\n \
                      \"raw_range\": [190.0, 3500.0], \"drift\": 0.0}]}\n";
    // A file written before the format tag: the old header must keep loading.
    let legacy = format!(
        "{{\"kind\": \"{LEGACY_FILE_KIND}\", \"version\": 1,\n \"sensors\": [{{\"name\": \"heel\", \
         \"model\": {{\"power\": {{\"a\": 0.012, \"b\": 1.4, \"r0\": 200.0}}}},\n \
         \"raw_range\": [190.0, 3500.0], \"drift\": 0.0}}]}}\n"
    );
    vec![documented.as_bytes().to_vec(), legacy.into_bytes()]
}
