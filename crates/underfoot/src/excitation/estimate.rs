//! The excitation fitted from recordings, with no hand tuning.
//!
//! The recordings are the strikes the measured response was made from
//! ([`crate::analysis::measure`]), at the analysis rate `f_a` after the same conditioning,
//! band-limited as [`crate::analysis::steps`] band-limits a step. Let `h` be the impulse
//! response the voice plays the material's fitted filter with, as far as the band can
//! tell: the minimum-phase filter of the fitted magnitude in the band (its slowest modes
//! ring for tens of milliseconds, and that ringing is part of how long a rendered step
//! lasts; what the fit does below the band, the voice's post filter cuts).
//!
//! 1. **Each strike's excitation in time.** A strike is `y = x * h`, `x` its excitation.
//!    With random signs ([`super`]) the expected energy envelope is
//!    `E[y²] = P * h²`: the excitation's energy density `P` smeared by the filter's energy
//!    response. `P` is recovered from the strike's energy envelope `y²` (over 1.5 ms) by
//!    Richardson-Lucy deconvolution, `P ← P · (h² ⋆ (y² / (P * h²)))` from `P = y²`
//!    (`iterations` rounds: it keeps `P ≥ 0` and its total, and sharpens what the filter
//!    rang out), over the strike window from `pre_onset` before its onset to `span` after
//!    it, or to the next strike.
//! 2. **The heel.** The strike starts where `P` first reaches a twentieth of its largest
//!    value (in the first 150 ms); the heel is the largest value of `P` in the 5 ms from
//!    there. The share of `P` from 1 ms before it to 2 ms after, less what the train's
//!    level just after (the median of `P` over the next 10 ms) would put there, is the heel
//!    impact's share `h_s`. A solid's strike is nearly all heel; an
//!    aggregate's nearly none.
//! 3. **Durations.** The rest of `P` from the onset on is the strike's train; `D_s` is the
//!    time from 5% to 95% of its energy. Each train is stretched to the geometric mean
//!    `D̄` of the `D_s` (`P_s(t D_s / D̄) D_s / D̄`), so that steps of one material that
//!    last differently add up to one profile of typical length rather than a smear; each
//!    is smoothed over `smoothing` (10 ms), and their mean is the profile, or with three
//!    strikes or more their median at each instant (scaled to the mean's energy), so that
//!    one recording's long tail is not given to every step.
//! 4. **The step clock.** Recording time becomes step-clock time through the nominal step,
//!    `τ(t) = ∫_0^t v_nom` ([`super::clock`]), and the profile is binned in `bin` (5 ms)
//!    of `τ`. What a recording holds after the nominal step's toe-off (where the clock
//!    stops) has no force to follow and is left out; the bins are scaled back to
//!    `1 - h` of a step's energy, `h` the mean heel share.
//! 5. **The time scale's spread** `σ_D`. The recorded steps' durations (`D90`,
//!    [`crate::analysis::steps`]) spread by `S²`, the variance of their logs pooled with a
//!    prior of `duration_prior` (0.15) worth two steps, `S² = (Σ (ln D - mean)² + 2 σ_0²)
//!    / (n + 1)`, so one or two recordings do not give a spread of 0 or of chance. The
//!    random train already makes rendered steps last differently, by `V` (the variance
//!    of the logs of the durations of rendered steps with `σ_D = 0`); the time scale adds
//!    the rest, `σ_D² = max(0, S² - V)`, as independent variations add.
//! 6. **Density and time axis, by rendering.** The micro-events' density `ρ` (events per
//!    second of step clock, every bin alike) and a stretch `c` of the recordings' time axis
//!    are what the recordings cannot give directly: how many distinct micro-impacts a
//!    dense train holds, and how the filter's ringing lengthens a step. Nominal steps are
//!    rendered (`renders`, through the [`Generator`] on the nominal step's clock and `h`),
//!    measured exactly as the recordings are (both at twice `f_a`, where a 1.5 ms envelope
//!    has six samples), and compared. First `ρ` and the magnitudes' shape `κ`, for the
//!    median micro-event count and crest factor closest to the recordings' (each error in
//!    units of what a render's acceptance tolerates: a count 1.5 times off, a crest 3 dB
//!    off): `ρ` over 50·2^k events/s up to 6400 at `κ = 2`; `κ` in {1, 2, 4} at the best
//!    `ρ`, half and twice it; the heel's share at twice and four times the measured
//!    one when the crest factor is more than 1 dB off (the deconvolution smears an impact
//!    over a few milliseconds), each at the best `ρ`, half and twice it (crest factors
//!    are true peaks, [`crate::analysis::steps`], so that the 4 kHz renders and the
//!    recordings compare as at 48 kHz). Then `c`, on four times as many steps: a step's
//!    duration spreads widely and often in two clusters (a long tail holds a few percent
//!    of its energy, or not), so the renders' duration is the mean of the middle half of their
//!    log-durations, which moves smoothly with `c` where a median jumps, against the log of
//!    the recordings' median; `c` is scaled by their ratio while that is more than 5% off
//!    and the render comes closer, at most three times (`c` within 1/4 to 4). Last `ρ`
//!    again on the corrected time axis, by √2, then 2^{1/4}. Renders share one seed, so
//!    that two candidates differ by their parameters, not their luck; so a candidate
//!    the searches come back to is not rendered again, and the candidates of one search
//!    step are rendered together on the cores there are, the choice between them made in
//!    their order afterwards (the result does not depend on how many ran at once).
//! 7. **The perturbation.** What the train's own variation leaves of the recordings'
//!    spread between steps, `sqrt(max(0, S_rec² - S_render²))`, at most 2.5 dB, is
//!    [`ExcitationModel::perturbation_db`] (0 with a single recorded step: nothing says
//!    how much steps differ). The cap: two recordings say little about the spread (the
//!    shared ones' pairs give 2-7 dB), and a larger perturbation fills in the filter's
//!    notches on average, moving the average spectrum from the fitted one (sand: 1.8 to
//!    3.2 dB from its recordings at 3.7 dB).
//!
//! A train holding under 5% of a step's energy is the deconvolution's residue of one
//! impact, not a train: the material is a solid, one heel impulse a step.
//!
//! The [`Estimate`] keeps the recordings' step descriptors at their own rates (what a
//! library stores, and what renders at any rate are compared with) and the calibration
//! render's beside the recordings' at `f_a`.

use num_complex::Complex64;
use underfoot_fft::RealFftPlanner;

use super::{ExcitationError, ExcitationModel, Generator, MAX_BINS, Tables, clock};
use crate::analysis::steps::{
    Step, StepConfig, StepSummary, band_limit, describe_all, describe_all_with, find_steps,
    summarize,
};
use crate::analysis::{AnalysisConfig, MeasuredResponse, condition};
use crate::fit::target::minimum_phase_spectrum;
use crate::recording::Recording;
use crate::signal::Sos;
use crate::signal::resample::Resampler;
use crate::units::{Hz, SampleRate, Seconds};

/// Every setting of the estimation; the defaults are those the module documentation
/// gives.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimateConfig {
    /// How the recordings were conditioned (the measured response's settings).
    pub analysis: AnalysisConfig,
    /// How a step is measured (its band is the analysis band).
    pub steps: StepConfig,
    /// Width of a bin of the profile, in step clock.
    pub bin: Seconds,
    /// How much of a strike after its onset the profile covers.
    pub span: Seconds,
    /// Rounds of the deconvolution.
    pub iterations: usize,
    /// Width of the moving average that smooths the profile.
    pub smoothing: Seconds,
    /// The prior of the time scale's spread (natural log units), worth one step.
    pub duration_prior: f64,
    /// Nominal steps rendered for each comparison.
    pub renders: usize,
    /// Rounds of the density and time-axis search.
    pub rounds: usize,
    /// The renders' random stream.
    pub seed: u64,
}

impl Default for EstimateConfig {
    fn default() -> Self {
        Self {
            analysis: AnalysisConfig::default(),
            steps: StepConfig::default(),
            bin: Seconds(0.005),
            span: Seconds(0.6),
            iterations: 40,
            smoothing: Seconds(0.01),
            duration_prior: 0.15,
            renders: 16,
            rounds: 3,
            seed: 0x57E9,
        }
    }
}

/// A fitted excitation and the step descriptors it was fitted against.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimate {
    /// The model.
    pub model: ExcitationModel,
    /// The recordings' steps, each measured at its recording's rate.
    pub recorded: StepSummary,
    /// The recordings' steps at the analysis rate: what the renders were compared with.
    pub target: StepSummary,
    /// The final calibration render's steps, at the analysis rate.
    pub rendered: StepSummary,
    /// The micro-event density found, events per second of step clock.
    pub density_hz: f64,
    /// The stretch of the recordings' time axis found.
    pub stretch: f64,
}

/// A train holding less than this share of a step's energy is taken for the residue of
/// deconvolving a single impact, and dropped: the ground is a solid.
const MIN_TRAIN: f64 = 0.05;

/// The most of the recordings' spread between steps left to the numerator perturbation:
/// one or two recordings say little about how much steps differ, and a large perturbation
/// fills in the filter's notches on average (it raises `E|H|²` where modes cancel), moving
/// the average spectrum away from the fitted one.
const MAX_PERTURBATION_DB: f64 = 2.5;

/// The magnitudes' shapes tried: heavier-tailed, exponential energies, nearly alike.
const SHAPES: [f64; 3] = [1.0, 2.0, 4.0];

/// The densities of the first round's search: 50 to 6400 events/s in octaves.
const DENSITIES: [f64; 8] = [50.0, 100.0, 200.0, 400.0, 800.0, 1600.0, 3200.0, 6400.0];

/// Fits the excitation of the steps of `recordings` (whose measured response with
/// `cfg.analysis` is `measured`) for `filter`, the material's fitted filter at the
/// analysis rate: the filter its steps will be played through.
///
/// # Errors
/// [`ExcitationError::Recordings`] when a recording cannot be conditioned, the strikes
/// hold no energy, or the measured response has no minimum-phase filter.
pub fn estimate(
    recordings: &[Recording],
    measured: &MeasuredResponse,
    filter: &Sos,
    cfg: &EstimateConfig,
) -> Result<Estimate, ExcitationError> {
    let bad = |m: String| ExcitationError::Recordings(m);
    let fs = measured.rate;
    if cfg.analysis.rate != fs || cfg.analysis.band != measured.band {
        return Err(bad(
            "the measured response was taken at another rate or band than the estimation's".into(),
        ));
    }
    if !(cfg.bin.0 > 0.0 && cfg.span.0 > 0.0 && cfg.renders > 0 && cfg.duration_prior >= 0.0) {
        return Err(bad("bin, span and renders must be positive".into()));
    }
    let steps_cfg = StepConfig {
        band: measured.band,
        ..cfg.steps.clone()
    };
    let h = kernel(filter, fs, fs, &steps_cfg)?;
    // The calibration renders at a multiple of the analysis rate (see `OVERSAMPLING`).
    let fine = SampleRate(fs.0.saturating_mul(OVERSAMPLING));
    let fine_kernel = kernel(filter, fs, fine, &steps_cfg)?;
    let upsampler = Resampler::shared(fs, fine).map_err(|e| bad(e.to_string()))?;
    let h2: Vec<f64> = {
        let e: Vec<f64> = h.iter().map(|v| v * v).collect();
        let total: f64 = e.iter().sum();
        e.iter().map(|v| v / total.max(f64::MIN_POSITIVE)).collect()
    };

    // Per recording: the conditioned signal at the analysis rate, and its strikes.
    let mut recorded_native = Vec::new();
    let mut recorded_here = Vec::new();
    let mut trains = Vec::new();
    for rec in recordings {
        let wrap = |e: crate::analysis::AnalysisError| bad(format!("{}: {e}", rec.name));
        let y = condition(rec, &cfg.analysis).map_err(wrap)?;
        let limited = band_limit(&y, fs, &steps_cfg).map_err(wrap)?;
        // Steps as the step analysis finds them (a burst after 300 ms of quiet), not the
        // measurement's strikes: the strike detector may cut one long step in two.
        let starts = find_steps(&limited, fs, &steps_cfg);
        if starts.is_empty() {
            continue;
        }
        let onsets: Vec<Seconds> = starts.iter().map(|&n| fs.duration_of(n)).collect();
        recorded_here.extend(
            describe_all(&upsampler.process(&y), fine, Some(&onsets), &steps_cfg).map_err(wrap)?,
        );
        recorded_native
            .extend(describe_all(&rec.samples, rec.rate, Some(&onsets), &steps_cfg).map_err(wrap)?);
        for (k, &onset) in starts.iter().enumerate() {
            let next = starts.get(k + 1).copied().unwrap_or(usize::MAX);
            if let Some(t) = strike_train(&limited, onset, next, fs, &h2, cfg) {
                trains.push(t);
            }
        }
    }
    if trains.is_empty() {
        return Err(bad("no strike holds any energy in the band".into()));
    }
    let target = summarize(&recorded_here, &steps_cfg);
    let recorded = summarize(&recorded_native, &steps_cfg);

    let heel = trains.iter().map(|t| t.heel).sum::<f64>() / trains.len() as f64;
    // What the deconvolution leaves of a single impact is not a train.
    let heel = if heel >= 1.0 - MIN_TRAIN { 1.0 } else { heel };
    let durations: Vec<f64> = recorded_here
        .iter()
        .map(|s| s.duration.0.max(1e-3))
        .collect();
    let recorded_spread = log_spread(&durations, cfg.duration_prior);
    let profile = average_profile(&trains, fs, cfg);
    let speeds = clock::nominal_speeds(fs);

    let fine_speeds = clock::nominal_speeds(fine);
    let renderer = Renderer::new(&fine_kernel, &fine_speeds, fine, &steps_cfg, cfg);
    let build_with = |c: Candidate, spread: f64| {
        model_from(
            &profile, c.heel, c.density, c.stretch, spread, &speeds, fs, cfg,
        )
        .map(|m| ExcitationModel {
            amplitude_shape: c.shape,
            ..m
        })
    };
    // A step's duration spreads widely (a long tail holds a few percent of the energy,
    // or not), so it is measured over four times the renders.
    let long = Renderer {
        count: 4 * cfg.renders,
        ..Renderer::new(&fine_kernel, &fine_speeds, fine, &steps_cfg, cfg)
    };
    let probe = DENSITIES[5];
    // The train alone already makes steps last differently; the time scale's spread adds
    // what it leaves of the recordings' (their variances add).
    let alone = long.describe(
        &build_with(
            Candidate {
                density: probe,
                stretch: 1.0,
                shape: 2.0,
                heel,
            },
            0.0,
        )?,
        false,
    )?;
    let logs: Vec<f64> = alone.iter().map(|s| s.duration.0.max(1e-3).ln()).collect();
    let mean = logs.iter().sum::<f64>() / logs.len().max(1) as f64;
    let train_variance =
        logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (logs.len().max(2) - 1) as f64;
    let duration_spread = (recorded_spread.powi(2) - train_variance)
        .max(0.0)
        .sqrt()
        .min(1.0);
    let build = |c: Candidate| build_with(c, duration_spread);
    let mut renders = Renders::new(&renderer, &build);
    // The density and the magnitudes' shape: the median micro-event count and crest
    // factor of rendered steps against the recordings', each error in units of what the
    // acceptance of a render tolerates (a count 1.5 times off, a crest 3 dB off, each
    // costs one).
    let events_target = target.events;
    let score = |s: &StepSummary| {
        ((s.events + 1.0) / (events_target + 1.0)).ln().abs() / 1.5f64.ln()
            + (s.crest_db - target.crest_db).abs() / 3.0
    };
    // The generator plays up to `MAX_DRAWS` events a sample, at a clock up to about twice
    // the mean pace (the loading): denser trains would be cut short.
    let densest = fine.hz() * f64::from(super::MAX_DRAWS) / 4.0;
    type Best = Option<(f64, Candidate, StepSummary)>;
    // The candidates in order, the first of the lowest score kept (the renders run
    // together, the choice is made in the order given).
    let mut search = |candidates: &[Candidate], best: &mut Best| {
        let candidates: Vec<Candidate> = candidates
            .iter()
            .map(|c| Candidate {
                density: c.density.min(densest),
                ..*c
            })
            .collect();
        for (c, summary) in candidates.iter().zip(renders.summaries(&candidates)?) {
            let s = score(&summary);
            if best.as_ref().is_none_or(|b| s < b.0) {
                *best = Some((s, *c, summary));
            }
        }
        Ok::<(), ExcitationError>(())
    };
    let around = |c: Candidate, factors: &[f64], shapes: &[f64]| -> Vec<Candidate> {
        let shapes: Vec<f64> = if shapes.is_empty() {
            vec![c.shape]
        } else {
            shapes.to_vec()
        };
        shapes
            .iter()
            .flat_map(|&shape| {
                factors.iter().map(move |&f| Candidate {
                    density: c.density * f,
                    shape,
                    ..c
                })
            })
            .collect()
    };
    // The density over octaves with exponential energies; then the shape beside the best
    // density and its neighbours.
    let mut best: Best = None;
    let octaves: Vec<Candidate> = DENSITIES
        .iter()
        .filter(|d| **d <= densest)
        .map(|&density| Candidate {
            density,
            stretch: 1.0,
            shape: 2.0,
            heel,
        })
        .collect();
    search(&octaves, &mut best)?;
    if let Some((_, c, _)) = best {
        search(&around(c, &[0.5, 1.0, 2.0], &SHAPES), &mut best)?;
    }
    // The heel: the deconvolution smears an impact over a few milliseconds and may give
    // the train some of its energy, which shows as a crest factor too low. Twice and four
    // times the measured share are tried (the train keeps at least a tenth), each at the
    // best density, half and twice it (a louder heel leaves fewer micro-events above the
    // range, which a sparser train of louder impulses gives back), each kept only if the
    // render comes closer.
    if heel > 0.0
        && heel < 1.0
        && let Some((_, c, summary)) = &best
        && target.crest_db - summary.crest_db > 1.0
    {
        let louder: Vec<Candidate> = [2.0, 4.0]
            .iter()
            .flat_map(|&m| {
                around(
                    Candidate {
                        heel: (heel * m).min(0.9),
                        ..*c
                    },
                    &[0.5, 1.0, 2.0],
                    &[],
                )
            })
            .collect();
        search(&louder, &mut best)?;
    }
    let Some((
        _,
        Candidate {
            density,
            shape,
            heel,
            ..
        },
        _,
    )) = best
    else {
        return Err(bad("no calibration render finished".into()));
    };

    // The time axis, at that density and shape. The profile comes from the recordings' own
    // envelopes, stretched to their typical duration, so it is right as it stands unless
    // smoothing, the deconvolution and the spread of time scales have lengthened or
    // shortened the rendered steps: at most three corrections, each kept only if the
    // (long) render comes closer.
    // A step's duration spreads widely, often in two clusters (a long tail holds a few
    // percent of its energy, or not), where a median over renders jumps from one to the
    // other: the renders' is taken as the mean of the middle half of their log-durations,
    // which moves smoothly, against the log of the recordings' median.
    let log_mean = |steps: &[Step]| {
        let mut logs: Vec<f64> = steps.iter().map(|s| s.duration.0.max(1e-4).ln()).collect();
        logs.sort_by(f64::total_cmp);
        let (a, b) = (logs.len() / 4, logs.len() - logs.len() / 4);
        logs[a..b].iter().sum::<f64>() / (b - a).max(1) as f64
    };
    let want = (target.duration_ms.max(0.1) / 1e3).ln();
    let mut stretch = 1.0;
    let at_stretch = |stretch: f64| Candidate {
        density,
        stretch,
        shape,
        heel,
    };
    let mut at = log_mean(&long.describe(&build(at_stretch(stretch))?, false)?);
    for _ in 0..3 {
        if (at - want).abs() <= 1.05f64.ln() {
            break;
        }
        let c = (stretch * (want - at).exp()).clamp(0.25, 4.0);
        let next = log_mean(&long.describe(&build(at_stretch(c))?, false)?);
        if (next - want).abs() >= (at - want).abs() {
            break;
        }
        (stretch, at) = (c, next);
    }
    // The density again, finer, on the corrected time axis: the first round's two
    // neighbours are rendered with the density itself (it is the best until they are
    // scored).
    let mut best: Best = None;
    let mut near = vec![at_stretch(stretch)];
    for round in 1..cfg.rounds.max(1) {
        let r = 2f64.powf(0.5f64.powi(round as i32));
        let centre = match &best {
            Some((_, c, _)) => {
                near.clear();
                *c
            }
            None => near[0],
        };
        near.extend(around(centre, &[1.0 / r, r], &[]));
        search(&near, &mut best)?;
    }
    if best.is_none() {
        search(&near, &mut best)?;
    }
    let Some((_, chosen, rendered)) = best else {
        return Err(bad("no calibration render finished".into()));
    };
    let density = chosen.density;
    let mut model = build(chosen)?;
    // The final render, over the long renders' steps, spectra and all: the spread between
    // its steps, beside their time structure.
    let rendered = {
        let steps = long.describe(&model, true)?;
        let summary = summarize(&steps, &steps_cfg);
        debug_assert!(rendered.events >= 0.0);
        summary
    };
    model.perturbation_db = match (target.spread_db, rendered.spread_db) {
        (Some(want), Some(got)) => (want * want - got * got)
            .max(0.0)
            .sqrt()
            .min(MAX_PERTURBATION_DB),
        _ => 0.0,
    };
    model.validate()?;
    Ok(Estimate {
        model,
        recorded,
        target,
        rendered,
        density_hz: density,
        stretch,
    })
}

/// How many times the analysis rate the calibration renders and measures steps at: a
/// 1.5 ms envelope is three samples at 2 kHz, too few for its peaks to be counted as they
/// are at an audio rate; six are enough (the counts at 4 kHz and 48 kHz of the shared
/// recordings agree within a count or two).
const OVERSAMPLING: u32 = 2;

/// The impulse response at `rate` the voice plays `filter` (at `filter_rate`) with, as
/// far as a step's band can tell:
/// the minimum-phase filter with `filter`'s magnitude in the band, held at its edge
/// values outside it, band-limited as a step is and cut where 99.9% of its energy has
/// come. Outside the band the voice is not the fitted filter (its post filter cuts below
/// half the band's bottom, where a fit may park a pole ringing for half a second), and
/// the fit aimed at a minimum-phase target.
fn kernel(
    filter: &Sos,
    filter_rate: SampleRate,
    rate: SampleRate,
    steps: &StepConfig,
) -> Result<Vec<f64>, ExcitationError> {
    let bad = |m: String| ExcitationError::Recordings(m);
    let n = rate.samples_in(Seconds(2.0)).max(64).next_power_of_two();
    // The filter's magnitude at each bin's frequency; above the filter's Nyquist frequency
    // (outside the band) it is held at the band's edge anyway.
    let magnitude: Vec<f64> = (0..=n / 2)
        .map(|k| {
            let f = (k as f64 * rate.hz() / n as f64).min(0.5 * filter_rate.hz());
            filter.response(filter_rate.omega(Hz(f))).norm()
        })
        .collect();
    let mut spectrum = minimum_phase_spectrum(rate, steps.band, &magnitude)
        .map_err(|e| bad(format!("the fitted filter: {e}")))?;
    let mut planner = RealFftPlanner::<f64>::new();
    let inverse = planner.plan_fft_inverse(n);
    if let Some(first) = spectrum.first_mut() {
        first.im = 0.0;
    }
    if let Some(last) = spectrum.last_mut() {
        last.im = 0.0;
    }
    let mut h = vec![0.0; n];
    inverse
        .process(&mut spectrum, &mut h)
        .map_err(|_| bad("the kernel's transform failed".into()))?;
    // Half the buffer (the rest is the circular transform's wrap-around), at most 0.5 s.
    h.truncate((n / 2).min(rate.samples_in(Seconds(0.5)).max(8)));
    for v in &mut h {
        *v /= n as f64;
    }
    let h = band_limit(&h, rate, steps).map_err(|e| bad(e.to_string()))?;
    let total: f64 = h.iter().map(|v| v * v).sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(bad(
            "the filter's impulse response holds no energy in the band".into(),
        ));
    }
    let mut acc = 0.0;
    let len = h
        .iter()
        .position(|v| {
            acc += v * v;
            acc >= 0.999 * total
        })
        .map_or(h.len(), |i| i + 1);
    Ok(h[..len].to_vec())
}

/// One strike's train: its heel share and the energy density of the rest, from its onset,
/// as shares of the strike's energy; and its duration.
struct Train {
    heel: f64,
    density: Vec<f64>,
    duration: f64,
}

fn strike_train(
    y: &[f64],
    onset: usize,
    next: usize,
    fs: SampleRate,
    h2: &[f64],
    cfg: &EstimateConfig,
) -> Option<Train> {
    // The detector's onset can be early (a conditioned strike's zero-phase pre-ringing
    // crosses its threshold) or a little late: the window starts well before it.
    let lead = fs.samples_in(Seconds(0.05));
    let start = onset.saturating_sub(lead);
    let end = (onset + fs.samples_in(cfg.span))
        .min(next.saturating_sub(fs.samples_in(cfg.analysis.pre_onset)))
        .min(y.len());
    if end <= onset + 2 {
        return None;
    }
    // The energy envelope over 1.5 ms (three samples at 2 kHz).
    let w = fs.samples_in(cfg.steps.envelope).max(1);
    let sq: Vec<f64> = y[start..end].iter().map(|v| v * v).collect();
    let envelope: Vec<f64> = (0..sq.len())
        .map(|i| {
            let lo = i.saturating_sub(w / 2);
            let hi = (i + w - w / 2).min(sq.len());
            sq[lo..hi].iter().sum::<f64>() / (hi - lo) as f64
        })
        .collect();
    let total: f64 = envelope.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let mut p = richardson_lucy(&envelope, h2, cfg.iterations);
    let sum: f64 = p.iter().sum();
    if sum.is_nan() || sum <= 0.0 {
        return None;
    }
    for v in &mut p {
        *v /= sum;
    }
    // The strike starts where its excitation first reaches a twentieth of its largest
    // value in the first 150 ms after the detector's onset.
    let search = (onset - start + fs.samples_in(Seconds(0.15))).min(p.len());
    let top = p[..search].iter().copied().fold(0.0, f64::max);
    let o = p[..search].iter().position(|v| *v >= 0.05 * top)?;
    // The heel is the largest value of the first 5 ms from there, with what lies within
    // 1 ms before and 2 ms after it.
    let early = (o + fs.samples_in(Seconds(0.005)).max(1)).min(p.len());
    let peak = (o..early)
        .max_by(|&a, &b| p[a].total_cmp(&p[b]))
        .unwrap_or(o);
    let before = fs.samples_in(Seconds(0.001));
    let after = fs.samples_in(Seconds(0.002)).max(1);
    let (lo, hi) = (peak.saturating_sub(before), (peak + after + 1).min(p.len()));
    let local_to = (hi + fs.samples_in(Seconds(0.01)).max(1)).min(p.len());
    let mut following = p[hi..local_to].to_vec();
    let local = if following.is_empty() {
        0.0
    } else {
        crate::numeric::median(&mut following)
    };
    let head: f64 = p[lo..hi].iter().sum();
    let heel = (head - local * (hi - lo) as f64).max(0.0);
    for v in &mut p[lo..hi] {
        *v = v.min(local);
    }
    let density = p[lo.min(o)..].to_vec();
    let train: f64 = density.iter().sum();
    let kept = heel + train;
    if kept.is_nan() || kept <= 0.0 {
        return None;
    }
    let density: Vec<f64> = density.iter().map(|v| v / kept).collect();
    Some(Train {
        heel: heel / kept,
        duration: duration_of(&density, fs),
        density,
    })
}

/// From 5% to 95% of `density`'s total, seconds (one sample at least).
fn duration_of(density: &[f64], fs: SampleRate) -> f64 {
    let total: f64 = density.iter().sum();
    if total <= 0.0 {
        return 1.0 / fs.hz();
    }
    let mut acc = 0.0;
    let (mut a, mut b) = (None, None);
    for (i, v) in density.iter().enumerate() {
        acc += v;
        if a.is_none() && acc >= 0.05 * total {
            a = Some(i);
        }
        if acc >= 0.95 * total {
            b = Some(i);
            break;
        }
    }
    let n = b
        .unwrap_or(density.len())
        .saturating_sub(a.unwrap_or(0))
        .max(1);
    n as f64 / fs.hz()
}

/// `σ` of the logs of `durations`, pooled with `prior` worth two observations:
/// `sqrt((Σ (ln D - mean)² + 2 σ_0²) / (n + 1))`.
fn log_spread(durations: &[f64], prior: f64) -> f64 {
    let logs: Vec<f64> = durations.iter().map(|d| d.ln()).collect();
    let n = logs.len() as f64;
    if logs.is_empty() {
        return prior;
    }
    let mean = logs.iter().sum::<f64>() / n;
    let ss: f64 = logs.iter().map(|l| (l - mean).powi(2)).sum();
    ((ss + 2.0 * prior * prior) / (n + 1.0)).sqrt()
}

/// The trains stretched to their geometric-mean duration, averaged and smoothed: energy
/// per sample of recording time from the onset (shares of a step's energy).
fn average_profile(trains: &[Train], fs: SampleRate, cfg: &EstimateConfig) -> Vec<f64> {
    let len = fs.samples_in(cfg.span).max(1);
    let mean_log = trains.iter().map(|t| t.duration.ln()).sum::<f64>() / trains.len().max(1) as f64;
    let typical = mean_log.exp();
    let w = fs.samples_in(cfg.smoothing).max(1);
    // Each train stretched to the typical duration and smoothed.
    let shapes: Vec<Vec<f64>> = trains
        .iter()
        .map(|t| {
            let r = t.duration / typical;
            let stretched: Vec<f64> = (0..len)
                .map(|n| sample_at(&t.density, n as f64 * r) * r)
                .collect();
            let mut prefix = vec![0.0; len + 1];
            for (i, v) in stretched.iter().enumerate() {
                prefix[i + 1] = prefix[i] + v;
            }
            (0..len)
                .map(|i| {
                    let lo = i.saturating_sub(w / 2);
                    let hi = (i + w - w / 2).min(len);
                    (prefix[hi] - prefix[lo]) / (hi - lo) as f64
                })
                .collect()
        })
        .collect();
    let mean: Vec<f64> = (0..len)
        .map(|n| shapes.iter().map(|s| s[n]).sum::<f64>() / shapes.len() as f64)
        .collect();
    if shapes.len() < 3 {
        return mean;
    }
    // With three or more, the median at each instant: one step's long tail is that step's,
    // not every step's. Scaled back to the mean's energy.
    let median: Vec<f64> = (0..len)
        .map(|n| {
            let mut v: Vec<f64> = shapes.iter().map(|s| s[n]).collect();
            crate::numeric::median(&mut v)
        })
        .collect();
    let (m, a): (f64, f64) = (median.iter().sum(), mean.iter().sum());
    if m > 0.0 {
        median.iter().map(|v| v * a / m).collect()
    } else {
        mean
    }
}

/// `x` at fractional index `at`, linearly interpolated, 0 beyond its ends.
fn sample_at(x: &[f64], at: f64) -> f64 {
    let i = at.floor();
    if i < 0.0 || i as usize + 1 >= x.len() {
        return if i >= 0.0 && (i as usize) < x.len() {
            x[i as usize]
        } else {
            0.0
        };
    }
    let k = i as usize;
    let f = at - i;
    x[k] * (1.0 - f) + x[k + 1] * f
}

/// The model for `profile` (recording time, stretched by `stretch`) on the nominal step's
/// clock, with every bin at `density` events per second of step clock.
#[expect(
    clippy::too_many_arguments,
    reason = "the search's free parameters and its fixed inputs"
)]
fn model_from(
    profile: &[f64],
    heel: f64,
    density: f64,
    stretch: f64,
    duration_spread: f64,
    speeds: &[f32],
    fs: SampleRate,
    cfg: &EstimateConfig,
) -> Result<ExcitationModel, ExcitationError> {
    let delta = cfg.bin.0;
    let mut energy = vec![0.0; MAX_BINS];
    let mut tau = 0.0;
    let len = ((profile.len() as f64) * stretch).ceil() as usize;
    for (n, &v) in speeds.iter().enumerate().take(len) {
        let b = (tau / delta) as usize;
        if b >= MAX_BINS {
            break;
        }
        energy[b] += sample_at(profile, n as f64 / stretch) / stretch;
        tau += f64::from(v) / fs.hz();
    }
    let bins = energy.iter().rposition(|e| *e > 1e-9).map_or(0, |b| b + 1);
    energy.truncate(bins);
    for e in &mut energy {
        if *e <= 1e-9 {
            *e = 0.0;
        }
    }
    let total: f64 = energy.iter().sum();
    let train = 1.0 - heel;
    let (heel, energy) = if total > 0.0 && train > 1e-6 {
        (heel, energy.iter().map(|e| e * train / total).collect())
    } else {
        (1.0, Vec::new())
    };
    let rate_hz = energy
        .iter()
        .map(|e: &f64| if *e > 0.0 { density } else { 0.0 })
        .collect();
    let model = ExcitationModel {
        heel,
        bin_s: delta,
        rate_hz,
        energy,
        duration_spread,
        amplitude_shape: 2.0,
        perturbation_db: 0.0,
    };
    // The shares are scaled to sum to one; rounding aside, so the check holds.
    let sum = model.heel + model.energy.iter().sum::<f64>();
    let model = ExcitationModel {
        heel: (model.heel / sum).min(1.0),
        energy: model.energy.iter().map(|e| e / sum).collect(),
        ..model
    };
    model.validate()?;
    Ok(model)
}

/// Richardson-Lucy deconvolution of `y` by the unit-sum kernel `k`: `P ≥ 0` with
/// `P * k ≈ y` (causal convolution, same length).
fn richardson_lucy(y: &[f64], k: &[f64], iterations: usize) -> Vec<f64> {
    let conv = FftConvolver::new(k, y.len());
    let mut p = y.to_vec();
    let floor = y.iter().copied().fold(0.0, f64::max) * 1e-12 + f64::MIN_POSITIVE;
    for _ in 0..iterations {
        let est = conv.convolve(&p);
        let ratio: Vec<f64> = y.iter().zip(&est).map(|(a, b)| a / b.max(floor)).collect();
        let back = conv.correlate(&ratio);
        for (v, c) in p.iter_mut().zip(&back) {
            *v *= c.max(0.0);
        }
    }
    p
}

/// Causal convolution and correlation with a fixed kernel, by FFT.
struct FftConvolver {
    size: usize,
    spectrum: Vec<Complex64>,
    forward: std::sync::Arc<dyn underfoot_fft::RealToComplex<f64>>,
    inverse: std::sync::Arc<dyn underfoot_fft::ComplexToReal<f64>>,
    len: usize,
}

impl FftConvolver {
    /// For signals of up to `len` samples.
    fn new(kernel: &[f64], len: usize) -> Self {
        let size = (len + kernel.len()).next_power_of_two().max(2);
        let mut planner = RealFftPlanner::<f64>::new();
        let forward = planner.plan_fft_forward(size);
        let inverse = planner.plan_fft_inverse(size);
        let mut this = Self {
            size,
            spectrum: Vec::new(),
            forward,
            inverse,
            len,
        };
        this.spectrum = this.transform(kernel);
        this
    }

    fn transform(&self, x: &[f64]) -> Vec<Complex64> {
        let mut buf = vec![0.0; self.size];
        let n = x.len().min(self.size);
        buf[..n].copy_from_slice(&x[..n]);
        let mut out = self.forward.make_output_vec();
        // Lengths come from the plan, so the transform cannot fail.
        let _ = self.forward.process(&mut buf, &mut out);
        out
    }

    fn back(&self, mut spec: Vec<Complex64>) -> Vec<f64> {
        if let Some(first) = spec.first_mut() {
            first.im = 0.0;
        }
        if let Some(last) = spec.last_mut() {
            last.im = 0.0;
        }
        let mut out = vec![0.0; self.size];
        let _ = self.inverse.process(&mut spec, &mut out);
        let scale = 1.0 / self.size as f64;
        out.iter_mut().for_each(|v| *v *= scale);
        out
    }

    /// The transform of `x` times the kernel's (or its conjugate's: a correlation), back.
    fn product(&self, x: &[f64], conjugate: bool) -> Vec<f64> {
        let spec: Vec<Complex64> = self
            .transform(x)
            .iter()
            .zip(&self.spectrum)
            .map(|(a, b)| if conjugate { a * b.conj() } else { a * b })
            .collect();
        self.back(spec)
    }

    /// `(x * k)[n]` for `n < len`.
    fn convolve(&self, x: &[f64]) -> Vec<f64> {
        let mut out = self.product(x, false);
        out.truncate(self.len);
        out
    }

    /// The whole causal convolution `x * k` (`x.len() + k.len() - 1` samples, at most the
    /// transform's size).
    fn convolve_full(&self, x: &[f64], k_len: usize) -> Vec<f64> {
        let mut out = self.product(x, false);
        out.truncate((x.len() + k_len).saturating_sub(1).min(self.size));
        out
    }

    /// `(x ⋆ k)[n] = Σ_m x[n + m] k[m]` for `n < len`.
    fn correlate(&self, x: &[f64]) -> Vec<f64> {
        let mut out = self.product(x, true);
        out.truncate(self.len);
        out
    }
}

/// What a calibration render varies: the excitation's density (events per second of
/// step clock), the stretch of the recordings' time axis, the magnitudes' shape and the
/// heel's share.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Candidate {
    density: f64,
    stretch: f64,
    shape: f64,
    heel: f64,
}

impl Candidate {
    /// The candidate as a map key: two candidates of the same bits are the same render.
    fn key(&self) -> [u64; 4] {
        [self.density, self.stretch, self.shape, self.heel].map(f64::to_bits)
    }
}

/// The calibration renders of the density, shape and heel searches (step 6): each
/// candidate's summary, rendered once (the searches come back to a candidate already
/// rendered, e.g. the best density when the shapes are tried around it; every render
/// shares one seed, so a candidate's render is the same whenever it is made), and a
/// search's new candidates rendered together on the cores there are (the renders are
/// independent; the choice between them is made in order afterwards, so the result does
/// not depend on how many ran at once).
struct Renders<'a, B> {
    renderer: &'a Renderer<'a>,
    build: &'a B,
    done: std::collections::HashMap<[u64; 4], StepSummary>,
}

impl<'a, B> Renders<'a, B>
where
    B: Fn(Candidate) -> Result<ExcitationModel, ExcitationError> + Sync,
{
    fn new(renderer: &'a Renderer<'a>, build: &'a B) -> Self {
        Self {
            renderer,
            build,
            done: std::collections::HashMap::new(),
        }
    }

    /// The summaries of `candidates`' renders, in their order.
    fn summaries(&mut self, candidates: &[Candidate]) -> Result<Vec<StepSummary>, ExcitationError> {
        let mut new: Vec<Candidate> = Vec::new();
        for c in candidates {
            if !self.done.contains_key(&c.key()) && !new.iter().any(|n| n.key() == c.key()) {
                new.push(*c);
            }
        }
        let threads = std::thread::available_parallelism()
            .map_or(1, std::num::NonZeroUsize::get)
            .min(new.len());
        let render = |c: &Candidate| self.renderer.summary(&(self.build)(*c)?);
        let rendered: Vec<Result<StepSummary, ExcitationError>> = if threads <= 1 {
            new.iter().map(render).collect()
        } else {
            // Thread `t` renders candidates t, t + threads, ...
            let mut by_thread: Vec<Vec<Result<StepSummary, ExcitationError>>> =
                std::thread::scope(|scope| {
                    let handles: Vec<_> = (1..threads)
                        .map(|t| {
                            let new = &new;
                            let render = &render;
                            scope.spawn(move || {
                                new.iter().skip(t).step_by(threads).map(render).collect()
                            })
                        })
                        .collect();
                    let mut all = vec![new.iter().step_by(threads).map(render).collect()];
                    for h in handles {
                        all.push(h.join().unwrap_or_else(|_| {
                            vec![Err(ExcitationError::Recordings(
                                "a calibration render did not finish".into(),
                            ))]
                        }));
                    }
                    all
                });
            let mut iters: Vec<_> = by_thread.iter_mut().map(|v| v.drain(..)).collect();
            (0..new.len())
                .map(|i| {
                    iters[i % threads].next().unwrap_or_else(|| {
                        Err(ExcitationError::Recordings(
                            "a calibration render did not finish".into(),
                        ))
                    })
                })
                .collect()
        };
        for (c, summary) in new.iter().zip(rendered) {
            self.done.insert(c.key(), summary?);
        }
        candidates
            .iter()
            .map(|c| {
                self.done.get(&c.key()).cloned().ok_or_else(|| {
                    ExcitationError::Recordings("a calibration render is missing".into())
                })
            })
            .collect()
    }
}

/// Nominal steps rendered through the kernel and measured as the recordings are.
struct Renderer<'a> {
    kernel_len: usize,
    conv: FftConvolver,
    speeds: &'a [f32],
    fs: SampleRate,
    steps: &'a StepConfig,
    count: usize,
    seed: u64,
}

impl<'a> Renderer<'a> {
    fn new(
        kernel: &[f64],
        speeds: &'a [f32],
        fs: SampleRate,
        steps: &'a StepConfig,
        cfg: &EstimateConfig,
    ) -> Self {
        Self {
            kernel_len: kernel.len(),
            conv: FftConvolver::new(kernel, speeds.len()),
            speeds,
            fs,
            steps,
            count: cfg.renders,
            seed: cfg.seed,
        }
    }

    /// `count` nominal steps of `model`, each followed by silence, as one signal; and the
    /// steps' onsets.
    fn render(&self, model: &ExcitationModel) -> Result<(Vec<f64>, Vec<Seconds>), ExcitationError> {
        let tables = Tables::new(model, self.fs)?;
        let mut generator = Generator::new(self.seed);
        let lead = self.fs.samples_in(self.steps.before) + 1;
        let step_len = self.speeds.len() + self.kernel_len;
        let period = lead + step_len + self.fs.samples_in(self.steps.after);
        let mut signal = vec![0.0; period * self.count];
        let mut onsets = Vec::with_capacity(self.count);
        let mut x = vec![0.0f32; self.speeds.len()];
        for k in 0..self.count {
            generator.strike(&tables, 1.0);
            generator.process(&tables, self.speeds, &mut x);
            generator.stop();
            let e: Vec<f64> = x.iter().map(|v| f64::from(*v)).collect();
            let y = self.conv.convolve_full(&e, self.kernel_len);
            let at = k * period + lead;
            for (s, v) in signal[at..].iter_mut().zip(&y) {
                *s = *v;
            }
            onsets.push(self.fs.duration_of(at));
        }
        Ok((signal, onsets))
    }

    /// The rendered steps' descriptors, with their band spectra if `spectrum`.
    fn describe(
        &self,
        model: &ExcitationModel,
        spectrum: bool,
    ) -> Result<Vec<Step>, ExcitationError> {
        let (signal, onsets) = self.render(model)?;
        describe_all_with(&signal, self.fs, Some(&onsets), self.steps, spectrum)
            .map_err(|e| ExcitationError::Recordings(format!("calibration render: {e}")))
    }

    /// In time only: no spectra, so no spread.
    fn summary(&self, model: &ExcitationModel) -> Result<StepSummary, ExcitationError> {
        Ok(summarize(&self.describe(model, false)?, self.steps))
    }
}

#[cfg(test)]
mod tests_support {
    use super::*;
    use crate::signal::noise::SplitMix64;

    /// A recording of `steps` synthetic strikes through a 150 Hz resonance: a heel impulse
    /// of share `heel`, then a train of `events` random micro-impulses spread evenly over
    /// `length` seconds.
    pub(super) fn recording(heel: f64, events: usize, length: f64, seed: u64) -> Recording {
        let fs = 8000.0;
        let mut g = SplitMix64::new(seed);
        let mut x = vec![0.0; 16_000];
        let onset = 2000;
        x[onset] = heel.sqrt();
        let a = ((1.0 - heel) / events.max(1) as f64).sqrt();
        for _ in 0..events {
            let t = onset + (g.uniform() * length * fs) as usize;
            x[t] += if g.uniform() < 0.5 { a } else { -a };
        }
        // Through a resonance: y[n] = x[n] + 2 r cos θ y[n-1] - r² y[n-2].
        let (r, theta) = (0.99f64, std::f64::consts::TAU * 150.0 / fs);
        let mut y = vec![0.0; x.len()];
        for n in 0..x.len() {
            let y1 = if n > 0 { y[n - 1] } else { 0.0 };
            let y2 = if n > 1 { y[n - 2] } else { 0.0 };
            y[n] = x[n] + 2.0 * r * theta.cos() * y1 - r * r * y2 + 1e-5 * g.symmetric();
        }
        Recording {
            name: format!("synthetic-{seed}.wav"),
            rate: SampleRate(8000),
            samples: y,
            sha256: String::new(),
            excerpt: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::tests_support::recording;
    use super::*;
    use crate::analysis::measure;

    fn fit(recs: &[Recording]) -> Estimate {
        let cfg = EstimateConfig::default();
        let measured = measure(recs, &cfg.analysis).unwrap();
        estimate(recs, &measured, &resonance(), &cfg).unwrap()
    }

    /// The recordings' resonance at the analysis rate: the filter their strikes ring.
    fn resonance() -> Sos {
        let (r, theta) = (0.99f64.powi(4), std::f64::consts::TAU * 150.0 / 2000.0);
        Sos::new(vec![
            crate::signal::Biquad::from_row([1.0, 0.0, 0.0, 1.0, -2.0 * r * theta.cos(), r * r])
                .unwrap(),
        ])
    }

    #[test]
    fn a_single_impact_is_a_heel() {
        let recs: Vec<_> = (0..3).map(|s| recording(1.0, 0, 0.0, s)).collect();
        let e = fit(&recs);
        assert!(e.model.heel > 0.8, "{:?}", e.model);
    }

    #[test]
    fn a_crunch_is_a_train_of_its_length_and_count() {
        let recs: Vec<_> = (0..3).map(|s| recording(0.0, 40, 0.25, s)).collect();
        let e = fit(&recs);
        assert!(e.model.heel < 0.2, "{:?}", e.model.heel);
        let ratio = |a: f64, b: f64| a / b;
        let d = ratio(e.rendered.duration_ms, e.target.duration_ms);
        let n = ratio(e.rendered.events, e.target.events);
        assert!((0.8..1.25).contains(&d), "{:?} {:?}", e.rendered, e.target);
        assert!((0.67..1.5).contains(&n), "{:?} {:?}", e.rendered, e.target);
        assert!(e.model.span_s() > 0.15, "{}", e.model.span_s());
    }

    #[test]
    fn deconvolution_undoes_a_known_smear() {
        // Two spikes smeared by an exponential energy response come back as two spikes.
        let k: Vec<f64> = (0..50).map(|n| (-(n as f64) / 8.0).exp()).collect();
        let total: f64 = k.iter().sum();
        let k: Vec<f64> = k.iter().map(|v| v / total).collect();
        let mut p = vec![0.0; 400];
        p[100] = 1.0;
        p[250] = 0.5;
        let y = FftConvolver::new(&k, 400).convolve(&p);
        let q = richardson_lucy(&y, &k, 200);
        let near = |i: usize| q[i - 2..=i + 2].iter().sum::<f64>();
        assert!(
            near(100) > 0.9 && near(250) > 0.45,
            "{} {}",
            near(100),
            near(250)
        );
    }
}
