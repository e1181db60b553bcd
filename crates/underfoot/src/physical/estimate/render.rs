//! Rendering a model as the recordings were made, to set its level and score it (step 8).
//!
//! `steps` (16: steps now differ as recorded ones do, and the average of 16 is within
//! about a decibel of their expectation) nominal steps are rendered at 48 kHz ([`RENDER_RATE`]), each struck by the
//! material's excitation from the step detector's threshold crossing on, its clock driven
//! by the nominal step's force ([`crate::excitation`]), as the engine plays it: the time
//! structure of the micro-impacts, their random energies
//! and sizes, the coupling and the analysis window all count. The render is analysed
//! exactly as the recordings were ([`crate::analysis::measure`]).
//!
//! The steps are independent draws, so the render runs in two halves on two threads (the
//! second half with its own random stream) and their strikes are pooled.

use super::{EstimateConfig, EstimateError};
use crate::analysis::{MeasuredResponse, StrikeSource, measure};
use crate::excitation::clock::speed_per_newton_per_second;
use crate::excitation::{ExcitationModel, Generator, Tables};
use crate::fit::metrics::{Metrics, lsd_db, nrmse};
use crate::force::gait::nominal_step;
use crate::physical::ground::Ground;
use crate::physical::model::PhysicalModel;
use crate::recording::Recording;
use crate::signal::spectrum::fractional_octave_smooth;
use crate::units::{Hz, Newtons, SampleRate, Seconds};

/// The rate models are rendered at to set their level and to score them.
pub const RENDER_RATE: SampleRate = SampleRate(48_000);

/// The seed of the held-out render (`compare`'s second figure, the tests'): a random
/// stream of micro-impacts the estimation has not seen.
#[must_use]
pub fn held_out_seed(cfg: &EstimateConfig) -> u64 {
    cfg.seed ^ 0x00C0_FFEE
}

/// How close `model` comes to the measured magnitude `measured` on `grid`: `cfg.steps`
/// nominal steps rendered with `seed` at the model's stored output gain, analysed as the
/// recordings were ([`analyse_render`]), and scored by [`crate::fit::metrics`]. Returns
/// the model's magnitude on `grid` and its metrics.
///
/// With `cfg.seed` this reproduces the figure the estimation records
/// ([`PhysicalRecord::lsd_db`](crate::physical::PhysicalRecord::lsd_db), what `fit` prints: the render the level and the gains
/// were fitted on); with [`held_out_seed`] it is the held-out figure, a render of other
/// random micro-impacts (for a solid the two are the same render).
///
/// # Errors
/// As [`analyse_render`].
pub fn score_render(
    model: &PhysicalModel,
    excitation: &ExcitationModel,
    cfg: &EstimateConfig,
    grid: &[Hz],
    measured: &[f64],
    seed: u64,
) -> Result<(Vec<f64>, Metrics), EstimateError> {
    let got = analyse_render(model, excitation, cfg, grid, seed)?;
    let metrics = Metrics {
        nrmse: nrmse(measured, &got),
        lsd_db: lsd_db(measured, &got),
    };
    Ok((got, metrics))
}

/// The model's magnitude on `freqs` when `steps` nominal steps are rendered at
/// [`RENDER_RATE`] and analysed as recordings are, at the model's output gain.
///
/// # Errors
/// The model is invalid, or the render holds no strike the analysis can find.
pub fn analyse_render(
    model: &PhysicalModel,
    excitation: &ExcitationModel,
    cfg: &EstimateConfig,
    freqs: &[Hz],
    seed: u64,
) -> Result<Vec<f64>, EstimateError> {
    Ok(render_measure(model, excitation, cfg, seed)?
        .0
        .on_grid(freqs))
}

/// The render's measured response, and its largest sample.
pub(super) fn render_measure(
    model: &PhysicalModel,
    excitation: &ExcitationModel,
    cfg: &EstimateConfig,
    seed: u64,
) -> Result<(MeasuredResponse, f64), EstimateError> {
    // The steps are independent draws (a second apart, each with its own micro-impacts),
    // so they are rendered and analysed in two halves on two threads, the second with its
    // own random stream, and the halves' strikes pooled as `measure` pools a material's.
    let steps = cfg.steps.max(1);
    let first = steps.div_ceil(2);
    let second = steps - first;
    let half = |n: usize, seed: u64| -> Result<(MeasuredResponse, f64), EstimateError> {
        let samples = render_n_steps(model, excitation, cfg, seed, n)?;
        let peak = samples
            .iter()
            .fold(0.0f64, |m, v| m.max(f64::from(v.abs())));
        let recording = Recording {
            name: "physical model (rendered)".into(),
            rate: RENDER_RATE,
            samples: samples.iter().map(|v| f64::from(*v)).collect(),
            sha256: String::new(),
            excerpt: None,
        };
        Ok((measure(&[recording], &cfg.analysis)?, peak))
    };
    if second == 0 {
        return half(first, seed);
    }
    let (a, b) = std::thread::scope(|scope| {
        let other = scope.spawn(|| half(second, second_half_seed(seed)));
        let a = half(first, seed);
        let b = other.join().unwrap_or(Err(EstimateError::Gains(
            "the render's second half did not finish",
        )));
        (a, b)
    });
    let ((a, pa), (b, pb)) = (a?, b?);
    Ok((pool(a, b, cfg.analysis.smoothing_fraction), pa.max(pb)))
}

/// The random stream of the second half of a render.
fn second_half_seed(seed: u64) -> u64 {
    seed ^ 0x9E37_79B9_7F4A_7C15
}

/// Two measured responses of the same analysis as one: the RMS over all their strikes of
/// the strikes' spectra, smoothed, exactly as [`measure`] averages the strikes of several
/// recordings (its steps 5 and 6).
fn pool(a: MeasuredResponse, b: MeasuredResponse, smoothing_fraction: f64) -> MeasuredResponse {
    let (na, nb) = (a.strikes.len() as f64, b.strikes.len() as f64);
    let raw: Vec<f64> = a
        .raw
        .iter()
        .zip(&b.raw)
        .map(|(x, y)| ((na * x * x + nb * y * y) / (na + nb)).sqrt())
        .collect();
    let magnitude = fractional_octave_smooth(&raw, a.bin_hz, smoothing_fraction);
    let mut strikes = a.strikes;
    strikes.extend(
        b.strikes
            .into_iter()
            .map(|s| StrikeSource { recording: 1, ..s }),
    );
    MeasuredResponse {
        magnitude,
        raw,
        strikes,
        ..a
    }
}

/// `cfg.steps` nominal steps, one second apart, through the model at [`RENDER_RATE`],
/// struck by `excitation`.
///
/// # Errors
/// The model or the excitation is invalid.
pub fn render_steps(
    model: &PhysicalModel,
    excitation: &ExcitationModel,
    cfg: &EstimateConfig,
    seed: u64,
) -> Result<Vec<f32>, EstimateError> {
    render_n_steps(model, excitation, cfg, seed, cfg.steps)
}

fn render_n_steps(
    model: &PhysicalModel,
    excitation: &ExcitationModel,
    cfg: &EstimateConfig,
    seed: u64,
    steps: usize,
) -> Result<Vec<f32>, EstimateError> {
    let fs = RENDER_RATE.hz();
    let step = nominal_step(cfg.nominal_weight_kg, cfg.nominal_cadence, fs);
    if step.is_empty() {
        return Err(EstimateError::InvalidSetting(
            "nominal walker must have a positive mass and cadence",
        ));
    }
    let period = RENDER_RATE.samples_in(Seconds(1.0)).max(step.len() + 1);
    let lead = RENDER_RATE.samples_in(Seconds(0.1));
    let tables = Tables::new(excitation, RENDER_RATE)?;
    let mut ground = Ground::new(model, RENDER_RATE, seed, tables.mean_impulse_energy())?;
    // Its own stream: the grains' sizes and the train's draws are independent.
    let mut generator = Generator::new(seed ^ 0xE7C1_7A71_0000_0001);
    let threshold = crate::force::steps::DetectorConfig::default().on.0;
    let strike = step.iter().position(|&f| f >= threshold).unwrap_or(0);
    let mut force = vec![0.0; lead + period * steps.max(1)];
    for s in 0..steps.max(1) {
        let start = lead + s * period;
        force[start..start + step.len()].copy_from_slice(&step);
    }
    let k = speed_per_newton_per_second(Newtons::weight_of(cfg.nominal_weight_kg)) * fs;
    let mut x = vec![0.0f32; force.len()];
    for (n, v) in x.iter_mut().enumerate() {
        if n >= lead && (n - lead) % period == strike {
            generator.strike(&tables, 1.0);
        }
        let speed = (force[n] - force[n.saturating_sub(1)]).abs() * k;
        *v = generator.next(&tables, speed as f32);
    }
    let mut out = vec![0.0f32; force.len()];
    ground.process(&x, &mut out);
    Ok(out)
}
