//! Reading a recorded session folder (`underfoot run --record`) into arrays.

use std::path::PathBuf;

use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use underfoot::live::record::SessionRecord;

use crate::errors::{Failure, guarded};

/// A session's record: JSON of its manifest, strikes, events and status; its force as
/// `(times, totals (channels x rows), readings (rows x columns), column names, channel
/// names)`; its
/// output `(channels x frames)` and rate, or `None`.
type Session<'py> = (
    String,
    Option<(
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Vec<String>,
        Vec<String>,
    )>,
    Option<(Bound<'py, PyArray2<f32>>, f64)>,
);

/// Reads the record in `path` (see the Python docstring of `underfoot.read_session`).
#[pyfunction]
pub fn read_session(py: Python<'_>, path: PathBuf) -> PyResult<Session<'_>> {
    let (record, output) = py.detach(|| {
        guarded(|| {
            let record = SessionRecord::read(&path)?;
            let output = record.read_output()?;
            Ok((record, output))
        })
    })?;
    let strikes: Vec<serde_json::Value> = record
        .strikes
        .iter()
        .map(|s| {
            serde_json::json!({
                // From 0, as the rows of the force array and a render's strikes (the
                // file counts from 1).
                "time": s.time, "frame": s.frame, "channel": s.channel.saturating_sub(1),
                "intensity": s.intensity, "material": s.material,
            })
        })
        .collect();
    let meta = serde_json::json!({
        "path": record.dir,
        "manifest": record.manifest,
        "rate": record.rate(),
        "finished": record.finished(),
        "strikes": strikes,
        "events": record.events,
        "markers": record.markers().collect::<Vec<_>>(),
        "status": record.status,
        "cut_lines": record.cut_lines,
    })
    .to_string();
    let force = match &record.force {
        None => None,
        Some(track) => {
            let rows = track.rows.len();
            let times: Vec<f64> = track.rows.iter().map(|r| r.time.0).collect();
            let channels = track.channels.len();
            let mut totals = vec![0.0; channels * rows];
            let columns: Vec<String> = track
                .channels
                .iter()
                .flat_map(|c| c.sensors.iter().map(move |s| format!("{}.{s}", c.name)))
                .collect();
            let mut readings = Vec::with_capacity(rows * columns.len());
            for (k, row) in track.rows.iter().enumerate() {
                for (c, reading) in row.readings.iter().enumerate() {
                    totals[c * rows + k] = f64::from(reading.total());
                    readings.extend(reading.as_slice().iter().map(|v| f64::from(*v)));
                }
            }
            let width = columns.len();
            Some((
                PyArray1::from_vec(py, times),
                PyArray1::from_vec(py, totals).reshape([channels, rows])?,
                PyArray1::from_vec(py, readings).reshape([rows, width])?,
                columns,
                track.channels.iter().map(|c| c.name.clone()).collect(),
            ))
        }
    };
    let output = match output {
        None => None,
        Some(out) => {
            let frames = out.channels.first().map_or(0, Vec::len);
            if out.channels.iter().any(|c| c.len() != frames) {
                return Err(Failure::new(
                    "SessionError",
                    format!("{}: the output's channels differ in length", path.display()),
                )
                .into());
            }
            let n = out.channels.len();
            let flat: Vec<f32> = out.channels.into_iter().flatten().collect();
            Some((PyArray1::from_vec(py, flat).reshape([n, frames])?, out.rate))
        }
    };
    Ok((meta, force, output))
}
