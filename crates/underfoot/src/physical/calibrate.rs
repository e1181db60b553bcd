//! Calibrating the physical model from recordings, with no hand tuning.
//!
//! The IIR paper's physical model was tuned by ear, "an iterative process for each type of
//! ground" (section V-B); the tile paper sketches how to identify it from data instead
//! (section 2.2). This module does the whole identification from the same recordings the
//! IIR fit uses ([`calibrate()`]):
//!
//! 1. **The measurement.** The strikes are conditioned and averaged exactly as for the IIR
//!    fit ([`crate::analysis::measure`]): the target is the same measured response `M(f)`.
//! 2. **Solid or aggregate** ([`KindChoice::Auto`]). A solid answers a step with one
//!    impact, whose energy arrives at once; an aggregate with a stream of micro-impacts
//!    spread over the loading. The rule: the median time a strike takes to go from 5% to
//!    50% of its energy (at the recording's own rate; counting from the first 5% rather
//!    than the detected onset keeps a quiet lead-in out of it), below
//!    `solid_half_energy` (30 ms) for a solid.
//!    On the shared recordings this puts concrete, wood, glass and ice with the solids
//!    (0-17 ms) and gravel, sand, snow, dirt, grass, water and metal with the aggregates
//!    (38-215 ms; the metal recordings are rattling gratings).
//! 3. **Impact onsets and the event rate** ([`crate::fit::crumpling`]). At the recording's
//!    rate, the Daubechies detail level whose band reaches closest to 12 kHz (level 2,
//!    6-12 kHz at 48 kHz, as in the paper; level 1 at 22.05 kHz) isolates impact onsets.
//!    They are counted in each strike window (`K` per strike), and the crumpling measure
//!    `I(t)` with the scale `a` of `N(t) = e^{a I(t)} - 1` is fitted so that the expected
//!    number of events equals the count (recorded as `rate_scale`).
//! 4. **The control mapping** `N(t) = α v_F(t)`. The recordings carry no force, so `α` is
//!    fixed by counting: a nominal step (the gait model's, 70 kg at 1.8 steps/s) must
//!    produce `K` events on average, `α = K / \int v_F dt`, where `\int v_F dt` is the
//!    force the step loads on (the sum of its rises). With a force track recorded
//!    alongside, [`fit_rate_mapping`] fits `α` to the event-rate profile by least squares,
//!    as the tile paper's Fig. 4 suggests (`N(t)` follows `v_F(t)`).
//! 5. **Modes by linear prediction** ([`crate::fit::lpc`]). The poles come from the
//!    isolated impacts: stretches of at least `2p` samples at the analysis rate (`p` the
//!    largest order) that start at an onset and end before the next one. Their
//!    autocorrelations are pooled (summed, which is the autocorrelation of their average
//!    power spectrum) and the Levinson-Durbin recursion gives one predictor per order; its
//!    roots in the upper half-plane, inside the unit circle and in the band are candidate
//!    modes (frequency and decay). With fewer than three isolated impacts (every solid,
//!    and aggregates whose impacts crowd) the strike windows take their place. Rather
//!    than guess the one right order, the orders 8, 12, 16, 24, 32 and 48 each contribute
//!    their poles to a dictionary (a pole closer than 0.002 in the z-plane to one already
//!    in it is the same mode): low orders give the broad resonances, high orders the
//!    sharp ones, and the gain fit below keeps what the spectrum needs. Decays are capped
//!    at `max_decay` (0.5 s), as the IIR voice caps its modes.
//! 6. **The hammer.** A Hunt-Crossley contact (α = 3/2) whose undamped contact time is
//!    `contact_time` (0.25 ms: a hard sole's first touch, or a grain's), at a strike speed
//!    `v` (0.5 m/s) and restitution `e` (0.7). From the theory in [`super::impact`],
//!    `x_max = T_c v / (2 \int_0^1 (1 - u^{5/2})^{-1/2} du)`,
//!    `k = (α+1) m v^2 / (2 x_max^{α+1})` and `λ = \frac{3}{2} k (1 - e) / v`. The mass is a
//!    grain's (5 g) for an aggregate and a heel's (0.5 kg) for a solid; it sets only how
//!    strongly hammer and surface couple (below).
//! 7. **Modal gains.** A mode of unit gain, struck by a unit impulse, moves at
//!    `V_k(s) = s ω_k / ((s + 1/τ_k)^2 + ω_k^2)`; the hammer's force pulse on a rigid
//!    surface has the spectrum `F(f)` (simulated). The gains solve, on 192 log-spaced
//!    frequencies of the band,
//!
//!    $$ \min_{g} \sum_i \left| \frac{|F(f_i)| \sum_k g_k V_k(f_i) - M(f_i) e^{j φ_i}}{M(f_i)} \right|^2
//!       + ρ \sum_k \lVert c_k \rVert^2 g_k^2 , $$
//!
//!    linear least squares on unit-norm columns `c_k` with a small ridge `ρ = 10^{-4}`
//!    (neighbouring poles of the dictionary are nearly parallel; without it their gains
//!    grow large and cancel). Dividing by `M` makes the error relative, close to the
//!    log-spectral distance. Only the magnitude is measured, so the phases `φ_i` start from
//!    the minimum-phase response with magnitude `M` and are then replaced by the model's
//!    own for 30 rounds; the round with the lowest log-spectral distance is kept. When the
//!    dictionary holds more than `max_modes` (32) modes, the 32 that carry most of the fit
//!    (`|g_k| ‖c_k‖`) are kept and refitted.
//!
//!    **Signs.** A gain at the point struck is positive, but the recordings were made
//!    elsewhere (a microphone, the shoe), where a mode's gain `φ_k(a) φ_k(b) / m_k` may be
//!    negative. The gains are therefore signed: their magnitudes are what the contact sees
//!    (the driving point), their signs shape what is felt (see
//!    [`super::resonator`]). Restricting them to be positive (non-negative least squares)
//!    was tried: the best fits were then 2-8 dB from the measurement instead of under 2.
//! 8. **Physical scale, level, and the render's own error.** The gains are scaled so that
//!    the surface's driving-point mass, `1 / \sum_k 2π f_k |g_k|`, is `mass_ratio` (10)
//!    times the hammer's: the ground is much heavier than what strikes it, so the contact
//!    stays close to the rigid one the gains were fitted with. Then `steps` (8) nominal
//!    steps are rendered at 48 kHz (a solid: one strike at the step detector's threshold
//!    crossing; an aggregate: events at `N(t) = α v_F(t)`, so the time structure of the
//!    micro-impacts, their random energies and sizes, the coupling and the analysis
//!    window all count), analysed exactly as the recordings were, and the output gain is
//!    set so that the mean level in dB over the band equals the measurement's. What the
//!    render still misses, `M(f) / R(f)`, multiplies the goal of the gain fit, and steps 7
//!    and 8 run again (`refine_rounds`, 1 by default: on the shared recordings a second
//!    or third round never came out best, and each costs a render); the round closest to
//!    the measurement is kept, and its render at that gain gives the recorded NRMSE and
//!    log-spectral distance ([`score_render`] computes the same figure again).
//!    The steps are independent draws, so the render runs in two halves on two threads
//!    (the second half with its own random stream) and their strikes are pooled.
//!
//! **Cost.** The renders are most of it (a nominal step is a second at 48 kHz through
//! 32 modes and four voices); the measurement is the IIR fit's, passed in by
//! [`calibrate_measured`], and [`crate::material::build`] runs the calibration beside the
//! IIR fit. `benches/calibration.rs` and `scripts/time-fit` measure it.
//!
//! On the shared recordings the calibrated models come within 0.8-2.1 dB (log-spectral
//! distance) of the measurement in the calibration render, and 0.8-2.4 dB in a render with
//! another seed (`tests/physical.rs`).

use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

use super::ground::Ground;
use super::model::{GroundKind, MAX_MODES, PhysicalModel, PhysicalRecord};
use super::{Impact, ImpactParams, Mode, PhysicalError, Surface};
use crate::analysis::{
    AnalysisConfig, AnalysisError, MeasuredResponse, StrikeSource, condition, measure,
};
use crate::fit::crumpling::{
    CrumplingError, OnsetConfig, calibrate_rate_scale, crumpling_measure, impact_onsets,
};
use crate::fit::lpc::{LpcError, autocorrelation, levinson_durbin};
use crate::fit::metrics::{METRIC_POINTS, Metrics, level_offset_db, lsd_db, nrmse};
use crate::fit::target::Target;
use crate::force::drive::DriveKind;
use crate::force::gait::nominal_step;
use crate::recording::Recording;
use crate::signal::spectrum::fractional_octave_smooth;
use crate::signal::wavelet::Wavelet;
use crate::units::{Hz, Newtons, SampleRate, Seconds};

/// Whether to decide solid or aggregate from the recordings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KindChoice {
    /// From how fast a strike's energy arrives (see the module documentation).
    #[default]
    Auto,
    /// Always this kind.
    Fixed(GroundKind),
}

/// Every setting of the calibration; the defaults are the module documentation's.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationConfig {
    /// How recordings become a measured response (the IIR fit's settings).
    pub analysis: AnalysisConfig,
    /// Solid or aggregate.
    pub kind: KindChoice,
    /// A strike that reaches half its energy sooner than this is a solid's.
    pub solid_half_energy: Seconds,
    /// The linear-prediction orders whose poles make the dictionary of candidate modes.
    pub lpc_orders: Vec<usize>,
    /// The most modes the model keeps (at most [`MAX_MODES`]).
    pub max_modes: usize,
    /// Longest decay time a mode keeps.
    pub max_decay: Seconds,
    /// The wavelet of the onset analysis.
    pub wavelet: Wavelet,
    /// The onset count.
    pub onsets: OnsetConfig,
    /// Width (standard deviation) of the Gaussian window of the crumpling measure.
    pub window: Seconds,
    /// Longest stretch of an isolated impact used for linear prediction.
    pub segment: Seconds,
    /// The hammer's undamped contact time.
    pub contact_time: Seconds,
    /// The strike speed (m/s).
    pub strike_speed: f64,
    /// Coefficient of restitution of the contact.
    pub restitution: f64,
    /// Mass of an aggregate's grain (kg).
    pub grain_mass: f64,
    /// Mass of the heel striking a solid (kg).
    pub heel_mass: f64,
    /// The surface's driving-point mass over the hammer's.
    pub mass_ratio: f64,
    /// Spread of fragment sizes (aggregates).
    pub size_spread: f64,
    /// Micro-impacts ringing at once (aggregates).
    pub voices: usize,
    /// Nominal walker's mass (kg) and cadence (steps/s) for the control mapping.
    pub nominal_weight_kg: f64,
    /// Steps per second of the nominal walker.
    pub nominal_cadence: f64,
    /// Rounds of refitting against the measurement corrected by the render's error.
    pub refine_rounds: usize,
    /// Steps rendered to set the level and score the model.
    pub steps: usize,
    /// The render's seed.
    pub seed: u64,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        Self {
            analysis: AnalysisConfig::default(),
            kind: KindChoice::Auto,
            solid_half_energy: Seconds(0.030),
            lpc_orders: vec![8, 12, 16, 24, 32, 48],
            max_modes: MAX_MODES,
            max_decay: Seconds(0.5),
            wavelet: Wavelet::Db4,
            onsets: OnsetConfig::default(),
            window: Seconds(0.005),
            segment: Seconds(0.1),
            contact_time: Seconds(0.00025),
            strike_speed: 0.5,
            restitution: 0.7,
            grain_mass: 0.005,
            heel_mass: 0.5,
            mass_ratio: 10.0,
            size_spread: 0.1,
            voices: 4,
            nominal_weight_kg: 70.0,
            nominal_cadence: 1.8,
            steps: 8,
            refine_rounds: 1,
            seed: 0x5EED,
        }
    }
}

/// The rate models are rendered at for the level calibration and the scores.
pub const RENDER_RATE: SampleRate = SampleRate(48_000);

/// What went wrong in a calibration.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibrationError {
    /// The recordings could not be analysed.
    #[error(transparent)]
    Analysis(#[from] AnalysisError),
    /// The onset or event-rate analysis failed.
    #[error("event-rate analysis of {name}: {source}")]
    Crumpling {
        /// The recording.
        name: String,
        /// What failed.
        source: CrumplingError,
    },
    /// Linear prediction failed.
    #[error("linear prediction: {0}")]
    Lpc(#[from] LpcError),
    /// No pole of the predictor is a mode in the band.
    #[error("linear prediction of order {order} found no mode in the band {lo}-{hi} Hz")]
    NoModes {
        /// The order.
        order: usize,
        /// The band's lower edge (Hz).
        lo: f64,
        /// Its upper edge (Hz).
        hi: f64,
    },
    /// The gains could not be fitted.
    #[error("the modal gains could not be fitted: {0}")]
    Gains(&'static str),
    /// A setting is out of range.
    #[error("invalid calibration setting: {0}")]
    InvalidSetting(&'static str),
    /// The model could not be built.
    #[error(transparent)]
    Physical(#[from] PhysicalError),
}

/// Calibrates a physical model from recordings of footsteps on one material.
///
/// # Errors
/// [`CalibrationError`] when the recordings hold no usable strike, no mode is found, or a
/// setting is out of range.
pub fn calibrate(
    recordings: &[Recording],
    cfg: &CalibrationConfig,
) -> Result<PhysicalModel, CalibrationError> {
    check(cfg)?;
    let measured = measure(recordings, &cfg.analysis)?;
    calibrate_measured(recordings, &measured, cfg)
}

/// As [`calibrate()`], from the measured response of `recordings` already computed with
/// `cfg.analysis` (the IIR fit's, in [`crate::material::build`]), so the recordings are
/// not measured twice.
///
/// # Errors
/// As [`calibrate()`]; [`CalibrationError::InvalidSetting`] when `measured` was taken at
/// another rate or band than `cfg.analysis`, or holds strikes of recordings not given.
pub fn calibrate_measured(
    recordings: &[Recording],
    measured: &MeasuredResponse,
    cfg: &CalibrationConfig,
) -> Result<PhysicalModel, CalibrationError> {
    check(cfg)?;
    let a = &cfg.analysis;
    if measured.rate != a.rate || measured.band != a.band {
        return Err(CalibrationError::InvalidSetting(
            "the measured response was taken at another rate or band than the calibration's",
        ));
    }
    if measured
        .strikes
        .iter()
        .any(|s| s.recording >= recordings.len())
    {
        return Err(CalibrationError::InvalidSetting(
            "the measured response holds strikes of recordings not given",
        ));
    }
    let fit_freqs = a.band.log_grid(2 * METRIC_POINTS);
    let metric_freqs = a.band.log_grid(METRIC_POINTS);
    let target = measured.on_grid(&metric_freqs);

    // Per strike: its energy's arrival and its impact onsets, at the recording's rate.
    let mut half_energy = Vec::new();
    let mut onset_counts = Vec::new();
    let mut onsets_by_recording = Vec::with_capacity(recordings.len());
    let mut rate_scales = Vec::new();
    for (index, rec) in recordings.iter().enumerate() {
        let wrap = |source| CalibrationError::Crumpling {
            name: rec.name.clone(),
            source,
        };
        let level = onset_level(rec.rate);
        let onsets =
            impact_onsets(&rec.samples, rec.rate, level, cfg.wavelet, &cfg.onsets).map_err(wrap)?;
        let strikes: Vec<f64> = measured
            .strikes
            .iter()
            .filter(|s| s.recording == index)
            .map(|s| s.onset.0)
            .collect();
        let mut count_here = 0;
        for &t0 in &strikes {
            let from = t0 - a.pre_onset.0;
            let to = t0 + a.strike_length.0;
            let n = onsets.iter().filter(|t| t.0 >= from && t.0 < to).count();
            onset_counts.push(n as f64);
            count_here += n;
            half_energy.push(half_energy_time(rec, from, to));
        }
        if count_here > 0 {
            let measure = crumpling_measure(&rec.samples, rec.rate, level, cfg.wavelet, cfg.window)
                .map_err(wrap)?;
            // Per recording: the expected count over it equals the onsets counted in it.
            let total = onsets.len();
            let scale = calibrate_rate_scale(&measure, rec.rate, total).map_err(wrap)?;
            if scale > 0.0 {
                rate_scales.push(scale);
            }
        }
        onsets_by_recording.push(onsets);
    }
    let onsets_per_strike = mean(&onset_counts);
    let half_energy_ms = 1e3 * crate::numeric::median(&mut half_energy);
    let kind = match cfg.kind {
        KindChoice::Fixed(k) => k,
        KindChoice::Auto if half_energy_ms < 1e3 * cfg.solid_half_energy.0 => GroundKind::Solid,
        KindChoice::Auto => GroundKind::Aggregate,
    };

    // Poles from the isolated impacts, or the strikes.
    let conditioned: Vec<Vec<f64>> = recordings
        .iter()
        .map(|r| condition(r, a))
        .collect::<Result<_, _>>()?;
    let min_len = 2 * cfg.lpc_orders.iter().copied().max().unwrap_or(2);
    let mut segments = Vec::new();
    if kind == GroundKind::Aggregate {
        for (x, onsets) in conditioned.iter().zip(&onsets_by_recording) {
            for (i, t) in onsets.iter().enumerate() {
                let end_t = onsets
                    .get(i + 1)
                    .map_or(t.0 + cfg.segment.0, |n| n.0.min(t.0 + cfg.segment.0));
                let (s, e) = (a.rate.samples_in(*t), a.rate.samples_in(Seconds(end_t)));
                if e > s && e - s >= min_len && e <= x.len() {
                    segments.push(x[s..e].to_vec());
                }
            }
        }
    }
    let isolated_impacts = segments.len() >= 3;
    if !isolated_impacts {
        segments.clear();
        let len = a.rate.samples_in(a.strike_length);
        for s in &measured.strikes {
            let x = &conditioned[s.recording];
            let start = a.rate.samples_in(s.onset);
            let end = (start + len).min(x.len());
            if end > start + min_len {
                segments.push(x[start..end].to_vec());
            }
        }
    }
    let poles = lpc_dictionary(&segments, a.rate, &cfg.lpc_orders, a, cfg.max_decay)?;

    // The hammer, and the spectrum of its force on a rigid surface.
    let mass = match kind {
        GroundKind::Solid => cfg.heel_mass,
        GroundKind::Aggregate => cfg.grain_mass,
    };
    let hammer = hammer_for(
        mass,
        cfg.contact_time,
        cfg.strike_speed,
        cfg.restitution,
        1.5,
    );
    let pulse = contact_spectrum(hammer, RENDER_RATE, &fit_freqs)?;

    // Gains against the measured magnitude, then the physical scale and the level; then
    // again against the measurement corrected by what the render missed.
    let fit_target = measured.on_grid(&fit_freqs);
    let phase0 = Target::minimum_phase(a.rate, a.band, &measured.magnitude, fit_freqs.len())
        .map_err(|_| CalibrationError::Gains("no minimum-phase target for the measurement"))?;
    let initial: Vec<f64> = phase0.h.iter().map(|h| h.arg()).collect();
    let rise = loading_rise(cfg);
    let events_per_newton = match kind {
        GroundKind::Aggregate if rise > 0.0 => onsets_per_strike.max(1.0) / rise,
        _ => 0.0,
    };
    let record = PhysicalRecord {
        onsets_per_strike,
        half_energy_ms,
        rate_scale: if rate_scales.is_empty() {
            0.0
        } else {
            crate::numeric::median(&mut rate_scales)
        },
        isolated_impacts,
        model: Vec::new(),
        nrmse: f64::NAN,
        lsd_db: f64::NAN,
    };
    let fit = GainFit {
        dictionary: &poles,
        freqs: &fit_freqs,
        pulse: &pulse,
        initial_phase: &initial,
        max_modes: cfg.max_modes,
    };
    let mut goal = fit_target.clone();
    let mut best: Option<PhysicalModel> = None;
    for _ in 0..=cfg.refine_rounds {
        let mut modes = fit.modes(&goal)?;
        let mobility: f64 = modes
            .iter()
            .map(|m| std::f64::consts::TAU * m.frequency.0 * m.gain.abs())
            .sum();
        let scale = 1.0 / (cfg.mass_ratio * mass * mobility);
        for m in &mut modes {
            m.gain *= scale;
        }
        let mut model = PhysicalModel {
            kind,
            modes,
            hammer,
            size_spread: if kind == GroundKind::Aggregate {
                cfg.size_spread
            } else {
                0.0
            },
            voices: cfg.voices,
            events_per_newton,
            output_gain: 1.0 / scale,
            record: record.clone(),
        };
        model.validate()?;
        // Level: render, analyse as a recording, match the mean level in dB.
        let got = render_measure(&model, cfg, cfg.seed)?;
        let scored = got.on_grid(&metric_freqs);
        let correction = 10f64.powf(-level_offset_db(&target, &scored) / 20.0);
        model.output_gain *= correction;
        let scored: Vec<f64> = scored.iter().map(|g| g * correction).collect();
        model.record.nrmse = nrmse(&target, &scored);
        model.record.lsd_db = lsd_db(&target, &scored);
        model.record.model = scored;
        for ((g, t), r) in goal
            .iter_mut()
            .zip(&fit_target)
            .zip(got.on_grid(&fit_freqs))
        {
            *g *= t / (r * correction);
        }
        if best
            .as_ref()
            .is_none_or(|b| model.record.lsd_db < b.record.lsd_db)
        {
            best = Some(model);
        }
    }
    best.ok_or(CalibrationError::Gains(
        "no round of the calibration finished",
    ))
}

/// The seed of the held-out render (`compare`'s second figure, the tests'): a random
/// stream of micro-impacts the calibration has not seen.
#[must_use]
pub fn held_out_seed(cfg: &CalibrationConfig) -> u64 {
    cfg.seed ^ 0x00C0_FFEE
}

/// How close `model` comes to the measured magnitude `measured` on `grid`: `cfg.steps`
/// nominal steps rendered with `seed` at the model's stored output gain, analysed as the
/// recordings were ([`analyse_render`]), and scored by [`crate::fit::metrics`]. Returns
/// the model's magnitude on `grid` and its metrics.
///
/// With `cfg.seed` this reproduces the figure the calibration records
/// ([`PhysicalRecord::lsd_db`], what `fit` prints: the render the level and the gains
/// were fitted on); with [`held_out_seed`] it is the held-out figure, a render of other
/// random micro-impacts (for a solid the two are the same render).
///
/// # Errors
/// As [`analyse_render`].
pub fn score_render(
    model: &PhysicalModel,
    cfg: &CalibrationConfig,
    grid: &[Hz],
    measured: &[f64],
    seed: u64,
) -> Result<(Vec<f64>, Metrics), CalibrationError> {
    let got = analyse_render(model, cfg, grid, seed)?;
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
    cfg: &CalibrationConfig,
    freqs: &[Hz],
    seed: u64,
) -> Result<Vec<f64>, CalibrationError> {
    Ok(render_measure(model, cfg, seed)?.on_grid(freqs))
}

fn render_measure(
    model: &PhysicalModel,
    cfg: &CalibrationConfig,
    seed: u64,
) -> Result<MeasuredResponse, CalibrationError> {
    // The steps are independent draws (a second apart, each with its own micro-impacts),
    // so they are rendered and analysed in two halves on two threads, the second with its
    // own random stream, and the halves' strikes pooled as `measure` pools a material's.
    let steps = cfg.steps.max(1);
    let first = steps.div_ceil(2);
    let second = steps - first;
    let half = |n: usize, seed: u64| -> Result<MeasuredResponse, CalibrationError> {
        let samples = render_n_steps(model, cfg, seed, n)?;
        let recording = Recording {
            name: "physical model (rendered)".into(),
            rate: RENDER_RATE,
            samples: samples.iter().map(|v| f64::from(*v)).collect(),
            sha256: String::new(),
        };
        Ok(measure(&[recording], &cfg.analysis)?)
    };
    if second == 0 {
        return half(first, seed);
    }
    let (a, b) = std::thread::scope(|scope| {
        let other = scope.spawn(|| half(second, second_half_seed(seed)));
        let a = half(first, seed);
        let b = other.join().unwrap_or(Err(CalibrationError::Gains(
            "the render's second half did not finish",
        )));
        (a, b)
    });
    Ok(pool(a?, b?, cfg.analysis.smoothing_fraction))
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

/// `cfg.steps` nominal steps, one second apart, through the model at [`RENDER_RATE`].
///
/// # Errors
/// The model is invalid.
pub fn render_steps(
    model: &PhysicalModel,
    cfg: &CalibrationConfig,
    seed: u64,
) -> Result<Vec<f32>, CalibrationError> {
    render_n_steps(model, cfg, seed, cfg.steps)
}

fn render_n_steps(
    model: &PhysicalModel,
    cfg: &CalibrationConfig,
    seed: u64,
    steps: usize,
) -> Result<Vec<f32>, CalibrationError> {
    let fs = RENDER_RATE.hz();
    let step = nominal_step(cfg.nominal_weight_kg, cfg.nominal_cadence, fs);
    if step.is_empty() {
        return Err(CalibrationError::InvalidSetting(
            "nominal walker must have a positive mass and cadence",
        ));
    }
    let period = RENDER_RATE.samples_in(Seconds(1.0)).max(step.len() + 1);
    let lead = RENDER_RATE.samples_in(Seconds(0.1));
    let block = 256;
    let mut ground = Ground::new(model, RENDER_RATE, seed, block)?;
    let threshold = crate::force::steps::DetectorConfig::default().on.0;
    let mut force = vec![0.0; lead + period * steps.max(1)];
    let mut strikes = Vec::new();
    for s in 0..steps.max(1) {
        let start = lead + s * period;
        force[start..start + step.len()].copy_from_slice(&step);
        if let Some(i) = step.iter().position(|&f| f >= threshold) {
            strikes.push(start + i);
        }
    }
    let loading = DriveKind::ForceRate.offline(&force, RENDER_RATE, Newtons(1.0));
    let mut out = vec![0.0f32; force.len()];
    let mut next = 0;
    for (b, chunk) in out.chunks_mut(block).enumerate() {
        let at = b * block;
        let end = at + chunk.len();
        let mut pos = at;
        while pos < end {
            let until = strikes
                .get(next)
                .copied()
                .filter(|&s| s < end)
                .unwrap_or(end);
            if until > pos {
                ground.process(&loading[pos..until], &mut chunk[pos - at..until - at]);
                pos = until;
            } else {
                ground.strike(1.0);
                next += 1;
            }
        }
    }
    Ok(out)
}

/// The force a nominal step loads on: the sum of its rises, in newtons.
fn loading_rise(cfg: &CalibrationConfig) -> f64 {
    let step = nominal_step(cfg.nominal_weight_kg, cfg.nominal_cadence, RENDER_RATE.hz());
    step.windows(2).map(|w| (w[1] - w[0]).max(0.0)).sum()
}

/// Fits the control mapping `N(t) ≈ α v_F(t)` by least squares through the origin, from an
/// event-rate profile and the loading rate sampled at the same instants (both per second).
/// Negative loading rates are taken as zero (the model only answers loading).
///
/// # Errors
/// [`CalibrationError::InvalidSetting`] for profiles of different lengths, a non-finite
/// value, or a loading rate that is zero throughout.
pub fn fit_rate_mapping(event_rate: &[f64], loading_rate: &[f64]) -> Result<f64, CalibrationError> {
    if event_rate.len() != loading_rate.len() {
        return Err(CalibrationError::InvalidSetting(
            "event rate and loading rate must have the same length",
        ));
    }
    if event_rate
        .iter()
        .chain(loading_rate)
        .any(|v| !v.is_finite())
    {
        return Err(CalibrationError::InvalidSetting(
            "event rate and loading rate must be finite",
        ));
    }
    let (mut num, mut den) = (0.0, 0.0);
    for (n, v) in event_rate.iter().zip(loading_rate) {
        let v = v.max(0.0);
        num += n * v;
        den += v * v;
    }
    if den <= 0.0 {
        return Err(CalibrationError::InvalidSetting(
            "the loading rate is zero throughout",
        ));
    }
    Ok((num / den).max(0.0))
}

/// The hammer of mass `mass` whose undamped Hunt-Crossley contact lasts `contact` at
/// `speed`, with restitution `restitution` and exponent `alpha`.
#[must_use]
pub fn hammer_for(
    mass: f64,
    contact: Seconds,
    speed: f64,
    restitution: f64,
    alpha: f64,
) -> ImpactParams {
    // T_c = 2 (x_max / v) ∫_0^1 (1 - u^(α+1))^(-1/2) du; the integral by the midpoint
    // rule after u = 1 - w^2, which removes the endpoint singularity.
    let integral = {
        let n = 4000;
        (0..n)
            .map(|i| {
                let w = (i as f64 + 0.5) / n as f64;
                let u = 1.0 - w * w;
                2.0 * w / (1.0 - u.powf(alpha + 1.0)).sqrt() / n as f64
            })
            .sum::<f64>()
    };
    let x_max = contact.0 * speed / (2.0 * integral);
    let stiffness = (alpha + 1.0) * mass * speed * speed / (2.0 * x_max.powf(alpha + 1.0));
    let damping = 1.5 * stiffness * (1.0 - restitution).max(0.0) / speed;
    ImpactParams {
        mass,
        stiffness,
        alpha,
        damping,
        velocity: speed,
    }
}

/// `|F(f)|` of the hammer's force pulse on a rigid surface (N·s), at `freqs`.
fn contact_spectrum(
    hammer: ImpactParams,
    rate: SampleRate,
    freqs: &[Hz],
) -> Result<Vec<f64>, CalibrationError> {
    let mut impact = Impact::new(hammer, Surface::Rigid, rate)?;
    let mut force = vec![0.0f32; rate.samples_in(Seconds(0.02)).max(64)];
    impact.process(&mut force);
    let t = 1.0 / rate.hz();
    Ok(freqs
        .iter()
        .map(|f| {
            let w = rate.omega(*f);
            // The pulse lasts a fraction of a millisecond: only its samples count.
            force
                .iter()
                .enumerate()
                .filter(|(_, x)| **x != 0.0)
                .map(|(n, x)| Complex64::from_polar(f64::from(*x) * t, -w * n as f64))
                .sum::<Complex64>()
                .norm()
        })
        .collect())
}

/// The Daubechies level whose detail band's top is closest (in octaves) to 12 kHz.
fn onset_level(rate: SampleRate) -> usize {
    let distance = |j: usize| (rate.hz() / 2f64.powi(j as i32) / 12_000.0).log2().abs();
    (1..=6)
        .min_by(|&p, &q| distance(p).total_cmp(&distance(q)))
        .unwrap_or(2)
}

/// Seconds from the time 5% of the energy of `[from, to)` has arrived to the time half of
/// it has: how long a strike takes to deliver its energy, from its first sizeable part on
/// (so a detected onset a little early, or a quiet scuff before, does not count).
fn half_energy_time(rec: &Recording, from: f64, to: f64) -> f64 {
    let fs = rec.rate.hz();
    let lo = ((from.max(0.0)) * fs) as usize;
    let hi = ((to * fs) as usize).min(rec.samples.len());
    if hi <= lo {
        return 0.0;
    }
    let seg = &rec.samples[lo..hi];
    let total: f64 = seg.iter().map(|v| v * v).sum();
    let mut acc = 0.0;
    let mut start = None;
    for (i, v) in seg.iter().enumerate() {
        acc += v * v;
        if start.is_none() && acc >= 0.05 * total {
            start = Some(i);
        }
        if acc >= 0.5 * total {
            return (i - start.unwrap_or(i)) as f64 / fs;
        }
    }
    0.0
}

/// The candidate modes: the poles of every order in `orders`, each pole kept once
/// (poles of different orders closer than 0.002 in the z-plane are the same mode).
fn lpc_dictionary(
    segments: &[Vec<f64>],
    rate: SampleRate,
    orders: &[usize],
    a: &AnalysisConfig,
    max_decay: Seconds,
) -> Result<Vec<Mode>, CalibrationError> {
    let mut found: Vec<(Complex64, Mode)> = Vec::new();
    let mut first_error = None;
    for &order in orders {
        match pooled_lpc_modes(segments, rate, order, a, max_decay) {
            Ok(modes) => {
                for m in modes {
                    let z = pole_of(&m, rate);
                    if found.iter().all(|(q, _)| (z - q).norm() > 2e-3) {
                        found.push((z, m));
                    }
                }
            }
            Err(e) => first_error = first_error.or(Some(e)),
        }
    }
    if found.is_empty() {
        return Err(first_error.unwrap_or(CalibrationError::NoModes {
            order: 0,
            lo: a.band.lo.0,
            hi: a.band.hi.0,
        }));
    }
    let mut modes: Vec<Mode> = found.into_iter().map(|(_, m)| m).collect();
    modes.sort_by(|p, q| p.frequency.0.total_cmp(&q.frequency.0));
    Ok(modes)
}

fn pole_of(m: &Mode, rate: SampleRate) -> Complex64 {
    Complex64::from_polar(
        (-1.0 / (m.decay.0 * rate.hz())).exp(),
        rate.omega(m.frequency),
    )
}

/// Modes (unit gain) from the pooled autocorrelation of `segments`.
fn pooled_lpc_modes(
    segments: &[Vec<f64>],
    rate: SampleRate,
    order: usize,
    a: &AnalysisConfig,
    max_decay: Seconds,
) -> Result<Vec<Mode>, CalibrationError> {
    let mut r = vec![0.0; order + 1];
    let mut used = 0;
    for s in segments {
        let Ok(rs) = autocorrelation(s, order) else {
            continue;
        };
        // `autocorrelation` is per sample; weight each segment by its length.
        for (acc, v) in r.iter_mut().zip(&rs) {
            *acc += v * s.len() as f64;
        }
        used += 1;
    }
    if used == 0 {
        return Err(CalibrationError::Lpc(LpcError::Silent));
    }
    let pred = levinson_durbin(&r, order)?;
    let roots = crate::numeric::roots(&pred.coefficients)
        .ok_or(LpcError::Numerical("predictor roots did not converge"))?;
    let fs = rate.hz();
    let mut modes: Vec<Mode> = roots
        .iter()
        .filter(|p| p.im > 0.0 && p.norm() < 1.0)
        .map(|p| Mode {
            frequency: Hz(p.arg() * fs / std::f64::consts::TAU),
            decay: Seconds(
                (-1.0 / (fs * p.norm().ln()))
                    .min(max_decay.0.min(super::resonator::LONGEST_DECAY.0)),
            ),
            gain: 1.0,
        })
        .filter(|m| m.frequency.0 >= 0.5 * a.band.lo.0 && m.frequency.0 <= a.band.hi.0)
        .collect();
    modes.sort_by(|p, q| p.frequency.0.total_cmp(&q.frequency.0));
    if modes.is_empty() {
        return Err(CalibrationError::NoModes {
            order,
            lo: a.band.lo.0,
            hi: a.band.hi.0,
        });
    }
    Ok(modes)
}

/// The velocity response of a unit-gain mode to a unit impulse, at `f`.
fn mode_velocity(mode: &Mode, f: Hz) -> Complex64 {
    let s = Complex64::new(0.0, std::f64::consts::TAU * f.0);
    let wd = std::f64::consts::TAU * mode.frequency.0;
    let sigma = 1.0 / mode.decay.0;
    s * wd / ((s + sigma).powi(2) + wd * wd)
}

/// The modal-gain fit of step 7 over a fixed dictionary of candidate modes.
struct GainFit<'a> {
    dictionary: &'a [Mode],
    freqs: &'a [Hz],
    pulse: &'a [f64],
    initial_phase: &'a [f64],
    max_modes: usize,
}

impl GainFit<'_> {
    /// Modes with gains (unscaled) whose response matches `goal` in magnitude, at most
    /// `max_modes` of them.
    fn modes(&self, goal: &[f64]) -> Result<Vec<Mode>, CalibrationError> {
        let mut poles = self.dictionary.to_vec();
        let mut gains = self.gains(&poles, goal)?;
        if poles.len() > self.max_modes {
            // Keep the modes that carry the most of the fitted (relative) response, refit.
            let mut ranked: Vec<(f64, Mode)> = poles
                .iter()
                .zip(&gains)
                .map(|(m, g)| (g.abs() * self.column(m, goal).norm(), *m))
                .collect();
            ranked.sort_by(|p, q| q.0.total_cmp(&p.0));
            poles = ranked
                .into_iter()
                .take(self.max_modes)
                .map(|(_, m)| m)
                .collect();
            poles.sort_by(|p, q| p.frequency.0.total_cmp(&q.frequency.0));
            gains = self.gains(&poles, goal)?;
        }
        let modes: Vec<Mode> = poles
            .iter()
            .zip(&gains)
            .filter(|(_, g)| **g != 0.0)
            .map(|(m, g)| Mode { gain: *g, ..*m })
            .collect();
        if modes.is_empty() {
            return Err(CalibrationError::Gains("every modal gain came out zero"));
        }
        Ok(modes)
    }

    /// A mode's response relative to `goal`, stacked real over imaginary parts.
    fn column(&self, mode: &Mode, goal: &[f64]) -> DVector<f64> {
        let n = self.freqs.len();
        let c: Vec<Complex64> = self
            .freqs
            .iter()
            .zip(self.pulse)
            .zip(goal)
            .map(|((f, p), t)| mode_velocity(mode, *f) * (p / t))
            .collect();
        DVector::from_fn(2 * n, |i, _| if i < n { c[i].re } else { c[i - n].im })
    }

    /// Ridge-regularised least-squares gains with phase iteration, best round kept.
    fn gains(&self, modes: &[Mode], goal: &[f64]) -> Result<Vec<f64>, CalibrationError> {
        let (n, k) = (self.freqs.len(), modes.len());
        if goal.iter().any(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(CalibrationError::Gains(
                "the measured magnitude is not positive",
            ));
        }
        let columns: Vec<DVector<f64>> = modes.iter().map(|m| self.column(m, goal)).collect();
        let norms: Vec<f64> = columns.iter().map(|c| c.norm().max(1e-300)).collect();
        // Unit-norm columns and a small ridge: neighbouring poles of the dictionary are
        // nearly parallel, and without it their gains grow large and cancel.
        let ridge = RIDGE.sqrt();
        let mut a = DMatrix::zeros(2 * n + k, k);
        for (j, c) in columns.iter().enumerate() {
            a.view_mut((0, j), (2 * n, 1)).copy_from(&(c / norms[j]));
            a[(2 * n + j, j)] = ridge;
        }
        let svd = crate::numeric::svd(a).map_err(|e| CalibrationError::Gains(e.0))?;
        let mut phase = self.initial_phase.to_vec();
        let mut best: Option<(f64, Vec<f64>)> = None;
        for _ in 0..PHASE_ROUNDS {
            let b = DVector::from_fn(2 * n + k, |i, _| match i {
                i if i < n => phase[i].cos(),
                i if i < 2 * n => phase[i - n].sin(),
                _ => 0.0,
            });
            let x = svd
                .solve(&b, 1e-12)
                .map_err(|_| CalibrationError::Gains("least squares failed"))?;
            let gains: Vec<f64> = x.iter().zip(&norms).map(|(v, s)| v / s).collect();
            let mut model = vec![Complex64::new(0.0, 0.0); n];
            for (c, g) in columns.iter().zip(&gains) {
                for (i, m) in model.iter_mut().enumerate() {
                    *m += Complex64::new(c[i], c[n + i]) * g;
                }
            }
            let ratio: Vec<f64> = model.iter().map(|m| m.norm().max(1e-300)).collect();
            let score = lsd_db(&vec![1.0; n], &ratio);
            if best.as_ref().is_none_or(|(s, _)| score < *s) {
                best = Some((score, gains));
            }
            for (p, m) in phase.iter_mut().zip(&model) {
                if m.norm() > 0.0 {
                    *p = m.arg();
                }
            }
        }
        best.map(|(_, g)| g)
            .ok_or(CalibrationError::Gains("no round of the fit finished"))
    }
}

/// Rounds of the phase iteration of the gain fit.
const PHASE_ROUNDS: usize = 30;

/// The ridge on unit-norm columns, relative to a column's squared norm.
const RIDGE: f64 = 1e-4;

fn check(cfg: &CalibrationConfig) -> Result<(), CalibrationError> {
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if cfg.lpc_orders.is_empty()
        || cfg
            .lpc_orders
            .iter()
            .any(|&p| !(2..=crate::fit::lpc::MAX_ORDER).contains(&p))
    {
        return Err(CalibrationError::InvalidSetting(
            "lpc_orders must be a non-empty list of orders from 2 to 128",
        ));
    }
    if cfg.max_modes == 0 || cfg.max_modes > MAX_MODES {
        return Err(CalibrationError::InvalidSetting(
            "max_modes must be 1 to 32",
        ));
    }
    if ![
        cfg.solid_half_energy.0,
        cfg.max_decay.0,
        cfg.window.0,
        cfg.segment.0,
        cfg.contact_time.0,
        cfg.strike_speed,
        cfg.grain_mass,
        cfg.heel_mass,
        cfg.mass_ratio,
        cfg.nominal_weight_kg,
        cfg.nominal_cadence,
    ]
    .into_iter()
    .all(positive)
    {
        return Err(CalibrationError::InvalidSetting(
            "times, masses, speeds and ratios must be positive and finite",
        ));
    }
    if !(0.0..1.0).contains(&cfg.restitution) {
        return Err(CalibrationError::InvalidSetting(
            "restitution must be in [0, 1)",
        ));
    }
    if !(0.0..=1.0).contains(&cfg.size_spread) {
        return Err(CalibrationError::InvalidSetting(
            "size_spread must be in [0, 1]",
        ));
    }
    if cfg.voices == 0 || cfg.voices > super::model::MAX_VOICES {
        return Err(CalibrationError::InvalidSetting("voices must be 1 to 8"));
    }
    if cfg.steps == 0 || cfg.steps > 64 {
        return Err(CalibrationError::InvalidSetting("steps must be 1 to 64"));
    }
    Ok(())
}

fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().sum::<f64>() / x.len() as f64
    }
}
