//! `render`: force (an array or a gait) in, the engine's output out, rendered as
//! `underfoot render` renders it.

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2};
use pyo3::prelude::*;
use underfoot::engine::offline::{MAX_RENDER, render_track};
use underfoot::engine::{EngineError, PlaySettings};
use underfoot::force::SensorReading;
use underfoot::force::gait::{self, GaitConfig};
use underfoot::force::track::{ChannelSensors, ForceRow, ForceTrack};
use underfoot::material::Library as LibraryModel;
use underfoot::units::{Decibels, Hz, Newtons, SampleRate, Seconds};

use crate::errors::{Failure, Outcome, guarded};
use crate::material::{Library, Material};

/// The most channels a force array may have: far beyond any tile or pair of shoes, few
/// enough that the engine's channels stay cheap to set up.
const MAX_CHANNELS: usize = 256;

/// A force array `(channels, samples)` in newtons at `rate` Hz as a force track: one
/// sensor per channel, sample `k` at `k / rate` seconds.
fn track_of(force: &PyReadonlyArray2<'_, f64>, rate: f64) -> Outcome<ForceTrack> {
    let force = force.as_array();
    let (channels, samples) = force.dim();
    if channels == 0 || samples == 0 {
        return Err(Failure::input(format!(
            "force has shape ({channels}, {samples}): need at least one channel and one sample"
        )));
    }
    if channels > MAX_CHANNELS {
        return Err(Failure::input(format!(
            "force has {channels} channels (rows): at most {MAX_CHANNELS} (is it transposed? \
             the shape is (channels, samples))"
        )));
    }
    if !(rate.is_finite() && (1.0..=100_000.0).contains(&rate)) {
        return Err(Failure::input(format!(
            "force_rate {rate:?}: need 1 to 100000 Hz"
        )));
    }
    // Refused before the track is built, as `render_track` would refuse it: a reading
    // takes some 50 bytes, so an hour of sixteen channels would be gigabytes first.
    let limit = Seconds(MAX_RENDER.0 / channels as f64);
    let length = Seconds((samples - 1) as f64 / rate);
    if length.0 > limit.0 {
        return Err(EngineError::TooLong {
            length,
            channels,
            limit,
        }
        .into());
    }
    let mut rows = Vec::with_capacity(samples);
    for k in 0..samples {
        let mut readings = Vec::with_capacity(channels);
        for c in 0..channels {
            let v = force[[c, k]];
            // The engine reads force as f32: a value beyond its range is as unusable as a
            // NaN, and said so here rather than as the row of a file the caller never wrote.
            let reading = SensorReading::new(&[v as f32]).filter(|r| r.is_finite());
            readings.push(reading.ok_or_else(|| {
                Failure::input(format!(
                    "force[{c}, {k}] is {v:?}: force must be finite newtons, within f32's range"
                ))
            })?);
        }
        rows.push(ForceRow {
            time: Seconds(k as f64 / rate),
            readings,
        });
    }
    let track = ForceTrack {
        channels: (0..channels)
            .map(|c| ChannelSensors {
                name: c.to_string(),
                sensors: vec!["f".into()],
            })
            .collect(),
        rows,
    };
    track.validate("force")?;
    Ok(track)
}

/// The played settings, from the keyword arguments.
#[expect(
    clippy::too_many_arguments,
    reason = "the keyword arguments of underfoot.render"
)]
fn settings(
    model: &str,
    drive: &str,
    excitation: &str,
    audio_rate: u32,
    gain_db: f64,
    ceiling_db: f64,
    perturbation: Option<f32>,
    seed: u64,
    lowpass_order: usize,
    weight: f64,
    step_threshold: f64,
    sensor_rate: f64,
) -> Outcome<PlaySettings> {
    let settings = PlaySettings {
        rate: SampleRate(audio_rate),
        drive: drive
            .parse()
            .map_err(|e| Failure::input(format!("drive: {e}")))?,
        model: model
            .parse()
            .map_err(|e| Failure::input(format!("model: {e}")))?,
        excitation: excitation
            .parse()
            .map_err(|e| Failure::input(format!("excitation: {e}")))?,
        gain: Decibels(gain_db),
        ceiling: Decibels(ceiling_db),
        perturbation,
        seed,
        lowpass_order,
        weight_kg: weight,
        step_threshold: Newtons(step_threshold),
        sensor_rate: Hz(sensor_rate),
    };
    settings.check().map_err(Failure::input)?;
    Ok(settings)
}

/// What plays on each channel: a material of the library by name, or one given whole.
fn played(
    materials: &[Bound<'_, PyAny>],
    library: Option<&Library>,
) -> Outcome<(LibraryModel, Vec<String>)> {
    if materials.is_empty() {
        return Err(Failure::input("no material given"));
    }
    let builtin;
    let library = match library {
        Some(l) => &l.library,
        None => {
            builtin = underfoot::material::builtin::builtin();
            builtin
        }
    };
    let mut played = LibraryModel::new();
    let mut names = Vec::with_capacity(materials.len());
    for item in materials {
        let model = if let Ok(m) = item.cast::<Material>() {
            m.get().model.clone()
        } else if let Ok(name) = item.extract::<String>() {
            library.get(&name)?.clone()
        } else {
            return Err(Failure::new(
                "InputTypeError",
                "a material is a name or an underfoot.Material",
            ));
        };
        names.push(model.name.clone());
        played.upsert(model);
    }
    Ok((played, names))
}

/// What a render returns to Python: the interleaved `(frames, channels)` output, the
/// strikes `(channel, frame, intensity, material)`, and the telemetry as JSON.
type Rendered<'py> = (
    Bound<'py, PyAny>,
    Vec<(u16, u64, f32, Option<String>)>,
    String,
);

/// Renders force through the engine (see the Python docstring of `underfoot.render`).
#[pyfunction]
#[pyo3(signature = (materials, library, force, force_rate, gait, model, drive, excitation,
    audio_rate, gain_db, ceiling_db, perturbation, seed, lowpass_order, weight, step_threshold,
    sensor_rate, tail, block))]
#[expect(
    clippy::too_many_arguments,
    reason = "the keyword arguments of underfoot.render"
)]
pub fn render<'py>(
    py: Python<'py>,
    materials: Vec<Bound<'py, PyAny>>,
    library: Option<PyRef<'py, Library>>,
    force: Option<PyReadonlyArray2<'py, f64>>,
    force_rate: Option<f64>,
    gait: Option<String>,
    model: &str,
    drive: &str,
    excitation: &str,
    audio_rate: u32,
    gain_db: f64,
    ceiling_db: f64,
    perturbation: Option<f32>,
    seed: u64,
    lowpass_order: usize,
    weight: f64,
    step_threshold: f64,
    sensor_rate: f64,
    tail: f64,
    block: usize,
) -> PyResult<Rendered<'py>> {
    let settings = settings(
        model,
        drive,
        excitation,
        audio_rate,
        gain_db,
        ceiling_db,
        perturbation,
        seed,
        lowpass_order,
        weight,
        step_threshold,
        sensor_rate,
    )?;
    if !(1..=65_536).contains(&block) {
        return Err(Failure::input(format!("block {block}: need 1 to 65536 frames")).into());
    }
    let (library, names) = played(&materials, library.as_deref())?;
    let track = match (&force, force_rate, gait) {
        (Some(force), Some(rate), None) => track_of(force, rate)?,
        (Some(_), None, None) => {
            return Err(Failure::input("force needs its force_rate (Hz)").into());
        }
        (None, _, Some(spec)) => {
            py.detach(|| guarded(|| Ok(gait::generate(&GaitConfig::from_spec(&spec)?)?.track)))?
        }
        _ => {
            return Err(Failure::input("give force (with force_rate) or gait, not both").into());
        }
    };
    let out = py.detach(|| {
        guarded(|| {
            let channels = track.channel_count();
            let bank = settings.prepare(&library, None)?;
            let slots = (0..channels)
                .map(|c| bank.slot(names.get(c).or(names.last()).map_or("", String::as_str)))
                .collect::<Result<Vec<u16>, _>>()?;
            let config = settings.engine_config(channels)?;
            Ok(render_track(
                &config,
                bank,
                &slots,
                &track,
                Seconds(tail),
                block,
            )?)
        })
    })?;
    let strikes = out
        .strikes
        .iter()
        .map(|s| {
            let material = s
                .slot
                .and_then(|slot| library.materials.get(usize::from(slot)))
                .map(|m| m.name.clone());
            (s.channel, s.frame, s.intensity, material)
        })
        .collect();
    let telemetry = telemetry_json(&out.telemetry);
    let channels = out.channels.max(1);
    let frames = out.samples.len() / channels;
    // The engine's buffer becomes the array's: no copy of the (possibly large) output.
    let samples = PyArray1::from_vec(py, out.samples).reshape([frames, channels])?;
    Ok((samples.into_any(), strikes, telemetry))
}

/// The engine's counters as JSON.
fn telemetry_json(t: &underfoot::engine::TelemetrySnapshot) -> String {
    serde_json::json!({
        "frames": t.frames,
        "strikes": t.strikes,
        "non_finite": t.non_finite,
        "limited": t.limited,
        "rejected": t.rejected,
        "late": t.late,
        "dropped": t.dropped,
        "watchdog_trips": t.watchdog_trips,
        "peak": t.peak,
        "limiter_min_gain": t.limiter_min_gain,
    })
    .to_string()
}
