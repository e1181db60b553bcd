//! The analysis `compare` and `fit --report` use: a recording's measured response and
//! strikes, steps measured in time, and a render's steps against a material's.

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use underfoot::analysis::steps::{self as step_analysis, Step, StepConfig};
use underfoot::analysis::{AnalysisConfig, measure as measure_response};
use underfoot::material::evaluate;
use underfoot::units::{Decibels, Seconds};

use crate::errors::{Failure, Outcome, guarded};
use crate::fit::{band, read_sources, recordings, savgol, whole_rate};
use crate::material::Material;

/// The samples of a 1-D float64 array, copied only when it is not contiguous.
fn samples_of<'a>(array: &'a PyReadonlyArray1<'_, f64>) -> std::borrow::Cow<'a, [f64]> {
    match array.as_slice() {
        Ok(s) => std::borrow::Cow::Borrowed(s),
        Err(_) => std::borrow::Cow::Owned(array.as_array().iter().copied().collect()),
    }
}

/// Strike times in seconds, each finite and not negative, ascending.
fn strike_times(strikes: Option<Vec<f64>>) -> Outcome<Option<Vec<Seconds>>> {
    let Some(strikes) = strikes else {
        return Ok(None);
    };
    if let Some(t) = strikes.iter().find(|t| !(t.is_finite() && **t >= 0.0)) {
        return Err(Failure::input(format!(
            "strikes: {t} is not a time in seconds (finite, not negative)"
        )));
    }
    if strikes.windows(2).any(|w| w[1] < w[0]) {
        return Err(Failure::input(
            "strikes: the times must be in ascending order",
        ));
    }
    Ok(Some(strikes.into_iter().map(Seconds).collect()))
}

/// Checks a signal handed over for step analysis: not empty, every sample finite.
fn checked(samples: &[f64]) -> Outcome<()> {
    if samples.is_empty() {
        return Err(Failure::input("samples: the array is empty"));
    }
    if let Some((i, v)) = samples.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(Failure::input(format!(
            "samples[{i}] is {v}: every sample must be finite"
        )));
    }
    Ok(())
}

/// The steps of `samples` (see `underfoot.steps`).
fn described(
    samples: &[f64],
    rate: f64,
    strikes: Option<Vec<f64>>,
    lo: f64,
    hi: f64,
) -> Outcome<(Vec<Step>, StepConfig)> {
    checked(samples)?;
    let rate = whole_rate(rate, "samples")?;
    let strikes = strike_times(strikes)?;
    let cfg = StepConfig {
        band: band(lo, hi)?,
        ..StepConfig::default()
    };
    let steps = match &strikes {
        Some(t) => step_analysis::describe_struck(samples, rate, t, &cfg)?,
        None => step_analysis::describe_all(samples, rate, None, &cfg)?,
    };
    Ok((steps, cfg))
}

/// A measured response as Python gets it: `(bin_hz, magnitude, raw, strikes)`, each
/// strike `(recording, onset s)`.
type Measured<'py> = (
    f64,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Vec<(usize, f64)>,
);

/// The measured response of recordings.
#[pyfunction]
#[pyo3(signature = (sources, analysis_rate, band_lo, band_hi, savgol_setting))]
pub fn measure<'py>(
    py: Python<'py>,
    sources: Vec<Bound<'py, PyAny>>,
    analysis_rate: u32,
    band_lo: f64,
    band_hi: f64,
    savgol_setting: Bound<'py, PyAny>,
) -> PyResult<Measured<'py>> {
    let cfg = AnalysisConfig {
        rate: whole_rate(f64::from(analysis_rate), "analysis_rate")?,
        band: band(band_lo, band_hi)?,
        savgol: savgol(&savgol_setting)?,
        ..AnalysisConfig::default()
    };
    if !cfg.band.fits(cfg.rate) {
        return Err(Failure::input(format!(
            "band {} does not fit the analysis rate {}",
            cfg.band, cfg.rate
        ))
        .into());
    }
    let sources = read_sources(&sources)?;
    let measured = py.detach(|| {
        guarded(|| {
            let recordings = recordings(sources, None)?;
            Ok(measure_response(&recordings, &cfg)?)
        })
    })?;
    let strikes = measured
        .strikes
        .iter()
        .map(|s| (s.recording, s.onset.0))
        .collect();
    Ok((
        measured.bin_hz,
        PyArray1::from_vec(py, measured.magnitude),
        PyArray1::from_vec(py, measured.raw),
        strikes,
    ))
}

/// Each step of a signal, as JSON (a list of objects).
#[pyfunction]
#[pyo3(signature = (samples, rate, strikes, band_lo, band_hi))]
pub fn steps(
    py: Python<'_>,
    samples: PyReadonlyArray1<'_, f64>,
    rate: f64,
    strikes: Option<Vec<f64>>,
    band_lo: f64,
    band_hi: f64,
) -> PyResult<String> {
    let samples = samples_of(&samples);
    let (steps, _) =
        py.detach(|| guarded(|| described(&samples, rate, strikes, band_lo, band_hi)))?;
    let steps: Vec<serde_json::Value> = steps
        .iter()
        .map(|s| {
            serde_json::json!({
                "onset_s": s.onset.0,
                "energy": s.energy,
                "duration_ms": 1e3 * s.duration.0,
                "events": s.events.iter().map(|e| (e.time.0, e.level.0)).collect::<Vec<_>>(),
                "crest_db": s.crest.0,
                "decay_db": s.decay_db,
                "bands": s.bands,
            })
        })
        .collect();
    Ok(serde_json::Value::from(steps).to_string())
}

/// What the steps of a signal have in common, as JSON (a material's `time`).
#[pyfunction]
#[pyo3(signature = (samples, rate, strikes, band_lo, band_hi))]
pub fn summarize_steps(
    py: Python<'_>,
    samples: PyReadonlyArray1<'_, f64>,
    rate: f64,
    strikes: Option<Vec<f64>>,
    band_lo: f64,
    band_hi: f64,
) -> PyResult<String> {
    let samples = samples_of(&samples);
    let summary = py.detach(|| {
        guarded(|| {
            let (steps, cfg) = described(&samples, rate, strikes, band_lo, band_hi)?;
            Ok(step_analysis::summarize(&steps, &cfg))
        })
    })?;
    serde_json::to_string(&summary).map_err(|e| Failure::new("Error", e).into())
}

/// A rendered signal's steps against a material's recorded ones, as JSON (`null`
/// without recorded statistics).
#[pyfunction]
#[pyo3(signature = (samples, rate, material, strikes, gain_db))]
pub fn compare_steps(
    py: Python<'_>,
    samples: PyReadonlyArray1<'_, f64>,
    rate: f64,
    material: PyRef<'_, Material>,
    strikes: Option<Vec<f64>>,
    gain_db: f64,
) -> PyResult<String> {
    let samples = samples_of(&samples);
    let model = &material.model;
    let compared = py.detach(|| {
        guarded(|| {
            checked(&samples)?;
            let rate = whole_rate(rate, "samples")?;
            let strikes = strike_times(strikes)?;
            if !gain_db.is_finite() {
                return Err(Failure::input("gain_db must be finite"));
            }
            // A render is f32: the comparison takes what the engine wrote.
            let x: Vec<f32> = samples.iter().map(|v| *v as f32).collect();
            Ok(evaluate::compare_steps(
                &x,
                rate,
                strikes.as_deref(),
                model,
                Decibels(gain_db),
            )?)
        })
    })?;
    let json = compared.map(|c| {
        serde_json::json!({
            "rendered": c.rendered,
            "spectrum_db": c.spectrum_db,
            "level_db": c.level_db,
        })
    });
    Ok(serde_json::Value::from(json).to_string())
}
