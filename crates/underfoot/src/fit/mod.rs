//! Fitting an IIR filter to a measured response.
//!
//! The filter of the IIR paper's equation (1) is a ratio of polynomials of order `N` in `z^-1`;
//! here it is found and kept as second-order sections (see [`crate::signal::sos`]). For each
//! candidate order the fit runs three linear starts and two non-linear refinements, and keeps
//! what wins on the log-spectral distance:
//!
//! 1. **Starts.** [`levi`](levi::levi): Levi's linearised least squares, the IIR paper's initial
//!    guess and Octave's `invfreqz`; [`sanathanan_koerner`](levi::sanathanan_koerner): the same,
//!    re-weighted until the equation error approaches the output error (Steiglitz-McBride);
//!    [`vector_fit`](vector_fit::vector_fit): pole relocation in a partial-fraction basis,
//!    which stays well conditioned for low resonances at high rates. Unstable poles of a
//!    linear start are reflected into the unit circle.
//! 2. **Refinements** ([`refine`](refine::refine)), damped Gauss-Newton searches over a
//!    parametrisation in which every step is a stable filter: the search on both metrics
//!    at once (linear and log magnitude errors, each scaled by its target; what the metrics
//!    measure) from the Sanathanan-Koerner and vector-fitting starts, in parallel; and from
//!    the start nearest the targets, the output-error search of equation (2) followed by
//!    the same two-metric search. Levi's start is refined through Sanathanan-Koerner, which
//!    begins from it.
//!
//! All of it is evaluated on a log-spaced frequency grid of the band, so each octave counts
//! the same (the weighting a perceptual fit needs; a linear grid spends most of its points
//! on the top octave).
//!
//! **Decay limit.** No footstep rings for seconds, yet a free fit to a smoothed spectrum
//! happily parks a pole a hair inside the unit circle to shape the band's low edge. Such a
//! pole is inaudible on the metric grid and very audible in play (a hum between strikes), so
//! every search keeps every pole within the radius `rho = exp(-1 / (f_s tau))`, where `tau`
//! ([`FitConfig::longest_decay`], default 0.5 s, stored with the model) is the longest e-fold
//! decay allowed: the linear starts are pulled inside it radially, and the refinements
//! search over a parametrisation whose every point lies inside it
//! (see [`refine`](refine::refine)). The filter a fit returns is therefore exactly the
//! filter the voice plays; the voice's own decay limit finds nothing to change.
//!
//! **Order.** "Order" is the number of poles `N`, which equals the numerator degree. The
//! automatic search (see [`fit`]) keeps the lowest order up to a bound whose log-spectral
//! distance and NRMSE both reach their targets (defaults 0.5 dB, half the 1 dB intensity
//! JND, and 0.1), or else the order closest to them. Candidates are ranked by
//! `(LSD / target)^2 + (NRMSE / target)^2`.
//!
//! Every fit also records the plain Levi fit at the same order, so that a report can show
//! what the refinements bought.
//!
//! The general numerics a fit uses (the guarded SVD, polynomial roots, bounded least
//! squares) are in [`crate::numeric`], shared with the stages that are not IIR fits.
//!
//! **Bounded iterations.** Every iterative routine here stops: the SVDs run through
//! [`numeric::svd`](crate::numeric::svd), which refuses a matrix with a non-finite entry
//! (nalgebra's SVD iterates forever on one) and caps the iterations; the eigenvalue
//! solvers ([`numeric::roots`](crate::numeric::roots()), [`vector_fit`]) cap theirs; the
//! refinements cap their steps.
pub mod levi;
pub mod lpc;
pub mod metrics;
pub mod refine;
pub mod reflect;
pub mod target;
pub mod vector_fit;

pub use metrics::{MetricGrid, Metrics};
pub use refine::Objective;
pub use target::Target;

use crate::signal::Sos;
use crate::units::{Decibels, SampleRate, Seconds};

/// The largest pole radius of a filter at `rate` whose slowest mode decays by `e` in
/// `longest`: `exp(-1 / (rate * longest))`. `1.0` (stability only) for a non-positive or
/// non-finite `longest`.
#[must_use]
pub fn decay_radius(rate: SampleRate, longest: Seconds) -> f64 {
    let r = (-1.0 / (rate.hz() * longest.0)).exp();
    if longest.0 > 0.0 && r.is_finite() {
        r
    } else {
        1.0
    }
}

/// The e-fold decay time of a pole of radius `radius` at `rate` (infinite on or outside the
/// unit circle).
#[must_use]
pub fn decay_time(rate: SampleRate, radius: f64) -> Seconds {
    if radius >= 1.0 {
        Seconds(f64::INFINITY)
    } else if radius <= 0.0 {
        Seconds(0.0)
    } else {
        Seconds(-1.0 / (rate.hz() * radius.ln()))
    }
}

/// The largest order a fit accepts.
pub const MAX_FILTER_ORDER: usize = 64;

/// How the filter order is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OrderChoice {
    /// The lowest order (up to `max`) whose fit reaches the targets.
    Auto {
        /// Upper bound of the search.
        max: usize,
    },
    /// Exactly this order.
    Fixed(usize),
}

/// Parameters of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitConfig {
    /// Order choice (default: automatic up to 16).
    pub order: OrderChoice,
    /// The automatic search stops at the first order whose log-spectral distance is at most this.
    pub target_lsd: Decibels,
    /// ... and whose NRMSE is at most this.
    pub target_nrmse: f64,
    /// Frequencies of the fitting grid (log-spaced over the band).
    pub grid_points: usize,
    /// Jacobian evaluations allowed to each refinement.
    pub max_iterations: usize,
    /// The longest e-fold decay any pole of the fitted filter may have (default 0.5 s,
    /// a 60 dB decay in 3.5 s).
    pub longest_decay: Seconds,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            order: OrderChoice::Auto { max: 16 },
            target_lsd: Decibels(0.5),
            target_nrmse: 0.1,
            grid_points: 128,
            max_iterations: 60,
            longest_decay: Seconds(0.5),
        }
    }
}

/// What went wrong in a fit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FitError {
    /// The response to fit is unusable.
    #[error("cannot fit this response: {0}")]
    BadTarget(&'static str),
    /// The order is out of range.
    #[error("filter order {order} is out of range (1..={MAX_FILTER_ORDER})")]
    InvalidOrder {
        /// The order asked for.
        order: usize,
    },
    /// A linear-algebra step failed.
    #[error("numerical failure: {0}")]
    Numerical(&'static str),
    /// A refinement was given an unstable start.
    #[error("the filter to refine is unstable")]
    Unstable,
    /// No start produced a stable, finite filter at this order.
    #[error("no stable fit found at order {order}")]
    NoFit {
        /// The order.
        order: usize,
    },
}

impl From<crate::numeric::NumericalError> for FitError {
    fn from(e: crate::numeric::NumericalError) -> Self {
        Self::Numerical(e.0)
    }
}

/// The best fit at one order.
#[derive(Debug, Clone, PartialEq)]
pub struct OrderFit {
    /// Number of poles.
    pub order: usize,
    /// The stable filter.
    pub sos: Sos,
    /// Its metrics on the metric grid.
    pub metrics: Metrics,
    /// Which start and refinements produced it.
    pub method: String,
    /// The plain Levi fit's metrics at the same order (its response as fitted, unstable
    /// poles and all), when Levi's least squares could be solved.
    pub levi: Option<Metrics>,
}

/// The result of a fit with its order search.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOutcome {
    /// The chosen fit.
    pub best: OrderFit,
    /// Every order tried, in order, with its metrics and method.
    pub trials: Vec<(usize, Metrics, String)>,
}

/// How far a fit is from its targets: `(LSD / target)^2 + (NRMSE / target)^2`.
fn score(m: &Metrics, cfg: &FitConfig) -> f64 {
    (m.lsd_db / cfg.target_lsd.0).powi(2) + (m.nrmse / cfg.target_nrmse).powi(2)
}

/// The balanced objective whose unit errors are the targets' (see [`Objective::Balanced`]).
fn balanced(target: &Target, cfg: &FitConfig) -> Objective {
    let mags: Vec<f64> = target.h.iter().map(|h| h.norm()).collect();
    let mean = mags.iter().sum::<f64>() / mags.len() as f64;
    let spread = (mags.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / mags.len() as f64).sqrt();
    Objective::Balanced {
        lin_scale: (cfg.target_nrmse * spread).max(1e-300),
        log_scale: cfg.target_lsd.0 * std::f64::consts::LN_10 / 20.0,
    }
}

/// Fits one order: the linear starts, then the refinements of the most promising start,
/// keeping the candidate closest to the targets.
///
/// # Errors
/// [`FitError::InvalidOrder`] for order 0 or above [`MAX_FILTER_ORDER`]; [`FitError::NoFit`] when
/// no start yields a stable finite filter.
pub fn fit_order(
    target: &Target,
    grid: &MetricGrid,
    order: usize,
    cfg: &FitConfig,
) -> Result<OrderFit, FitError> {
    if order == 0 || order > MAX_FILTER_ORDER {
        return Err(FitError::InvalidOrder { order });
    }
    let levi_ba = levi::levi(target, order, order, None).ok();
    let levi_metrics = levi_ba
        .as_ref()
        .map(|(b, a)| grid.evaluate_magnitude(&levi::magnitude_on(b, a, grid.rate, &grid.freqs)));

    let rho = decay_radius(target.rate, cfg.longest_decay);
    let mut starts: Vec<(&'static str, Sos)> = Vec::new();
    if let Some((b, a)) = &levi_ba
        && let Some(s) = crate::signal::zpk::ba_to_sos(b, a)
    {
        starts.push(("levi", stabilise(&s, rho)));
    }
    if let Some(Ok((b, a))) = levi_ba
        .clone()
        .map(|start| levi::sanathanan_koerner(target, start, 3))
        && let Some(s) = crate::signal::zpk::ba_to_sos(&b, &a)
    {
        starts.push(("sanathanan-koerner", stabilise(&s, rho)));
    }
    if let Ok(s) = vector_fit::vector_fit(target, order, 6) {
        starts.push(("vector-fit", stabilise(&s, rho)));
    }
    let usable = |s: &Sos| {
        s.is_stable()
            && s.poles().iter().all(|p| p.norm() < rho)
            && s.sections
                .iter()
                .all(|q| q.b.iter().chain(&q.a).all(|c| c.is_finite()))
    };
    starts.retain(|(_, s)| usable(s));

    let objective = balanced(target, cfg);
    let mut best: Option<(f64, OrderFit)> = None;
    let mut consider = |sos: &Sos, method: String| {
        if !usable(sos) {
            return;
        }
        let m = grid.evaluate(sos);
        let sc = score(&m, cfg);
        if sc.is_finite() && best.as_ref().is_none_or(|(b, _)| sc < *b) {
            best = Some((
                sc,
                OrderFit {
                    order,
                    sos: sos.clone(),
                    metrics: m,
                    method,
                    levi: levi_metrics,
                },
            ));
        }
    };
    for (name, start) in &starts {
        consider(start, (*name).to_string());
    }
    // Equation (2) first, from the start nearest the targets: fitting the phase as well
    // sometimes leads the magnitude search out of a poor basin.
    let ranked = starts
        .iter()
        .map(|(name, s)| (refine::objective_cost(s, target, objective), *name, s))
        .filter(|(c, _, _)| c.is_finite())
        .min_by(|x, y| x.0.total_cmp(&y.0));
    // Sanathanan-Koerner starts from Levi's solution and lands in the same basin or a
    // better one, so Levi's start is refined through it rather than again on its own.
    let has_sk = starts.iter().any(|(n, _)| *n == "sanathanan-koerner");
    let to_refine: Vec<&(&str, Sos)> = starts
        .iter()
        .filter(|(n, _)| !(has_sk && *n == "levi"))
        .collect();
    // The balanced search from every start, as the linear starts land in different basins.
    // The searches are independent, so they run on their own threads.
    let (direct, chain) = std::thread::scope(|scope| {
        let handles: Vec<_> = to_refine
            .iter()
            .map(|(_, s)| {
                scope.spawn(move || refine::refine(s, target, objective, cfg.max_iterations, rho))
            })
            .collect();
        let chain = ranked.map(|(_, name, start)| -> Result<_, FitError> {
            let oe = refine::refine(
                start,
                target,
                Objective::OutputError,
                cfg.max_iterations / 2,
                rho,
            )?;
            let both = refine::refine(&oe.sos, target, objective, cfg.max_iterations, rho)?;
            Ok((name, oe.sos, both.sos))
        });
        let direct: Vec<_> = handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or(Err(FitError::Numerical("a refinement thread panicked")))
            })
            .collect();
        (direct, chain)
    });
    for ((name, _), refined) in to_refine.iter().zip(direct) {
        consider(&refined?.sos, format!("{name} + gauss-newton(balanced)"));
    }
    if let Some(chain) = chain {
        let (name, oe, both) = chain?;
        consider(&oe, format!("{name} + gauss-newton(output-error)"));
        consider(
            &both,
            format!("{name} + gauss-newton(output-error) + gauss-newton(balanced)"),
        );
    }
    best.map(|(_, f)| f).ok_or(FitError::NoFit { order })
}

/// Fits `target`, choosing the order as `cfg` says; `progress` sees each order tried.
///
/// The automatic search fits the bound first; if that cannot reach both targets, it is
/// kept (a lower order would only be worse). Otherwise it bisects over even orders (each
/// adds one resonance) for the lowest that reaches them, then tries the odd order just
/// below. Bisection assumes that a higher order never fits worse, which holds for nested
/// models up to the search's own imperfection; it costs `log2(max)` fits instead of `max`.
///
/// # Errors
/// As [`fit_order`]; the automatic search fails only if every order fails.
pub fn fit(
    target: &Target,
    grid: &MetricGrid,
    cfg: &FitConfig,
    progress: &mut dyn FnMut(&OrderFit),
) -> Result<FitOutcome, FitError> {
    let reached =
        |f: &OrderFit| f.metrics.lsd_db <= cfg.target_lsd.0 && f.metrics.nrmse <= cfg.target_nrmse;
    let mut trials = Vec::new();
    let mut last_err = None;
    let mut run = |order: usize, trials: &mut Vec<(usize, Metrics, String)>| match fit_order(
        target, grid, order, cfg,
    ) {
        Ok(f) => {
            progress(&f);
            trials.push((order, f.metrics, f.method.clone()));
            Some(f)
        }
        Err(e) => {
            last_err = Some(e);
            None
        }
    };
    let max = match cfg.order {
        OrderChoice::Fixed(n) => {
            return match run(n, &mut trials) {
                Some(best) => Ok(FitOutcome { best, trials }),
                None => Err(last_err.unwrap_or(FitError::NoFit { order: n })),
            };
        }
        OrderChoice::Auto { max } if max == 0 || max > MAX_FILTER_ORDER => {
            return Err(FitError::InvalidOrder { order: max });
        }
        OrderChoice::Auto { max } => max,
    };
    // The bound first: if even it cannot reach the targets, no lower order will.
    let Some(top) = run(max, &mut trials) else {
        return Err(last_err.unwrap_or(FitError::NoFit { order: max }));
    };
    if !reached(&top) || max == 1 {
        return Ok(FitOutcome { best: top, trials });
    }
    // Bisect over even orders for the lowest that reaches them: `hi` reaches, `lo` does not.
    let (mut lo, mut hi, mut chosen) = (0, max, top);
    while hi - lo > 2 {
        let mid = (lo + (hi - lo) / 2) & !1;
        let mid = if mid <= lo { lo + 2 } else { mid };
        if mid >= hi {
            break;
        }
        match run(mid, &mut trials) {
            Some(f) if reached(&f) => {
                hi = mid;
                chosen = f;
            }
            _ => lo = mid,
        }
    }
    if hi > 1
        && hi - 1 > lo
        && let Some(f) = run(hi - 1, &mut trials).filter(|f| reached(f))
    {
        chosen = f;
    }
    trials.sort_by_key(|t| t.0);
    Ok(FitOutcome {
        best: chosen,
        trials,
    })
}

/// Reflects the unstable poles of each section into the unit circle, keeping the
/// magnitude response, and pulls any pole outside `max_radius` in to just inside it
/// (a linear start's over-long decays; the refinement then re-fits around them).
fn stabilise(sos: &Sos, max_radius: f64) -> Sos {
    use crate::signal::sos::{Biquad, RootPair};
    let sections = sos
        .sections
        .iter()
        .map(|s| {
            let poles = s.poles();
            let inner = max_radius * (1.0 - 1e-9);
            if s.is_stable() && poles.iter().all(|p| p.norm() <= inner) {
                return *s;
            }
            let (fixed, gain) = reflect::reflect_unstable(&poles, inner);
            let pair = if s.a[2] == 0.0 {
                RootPair::Single(fixed[0].re)
            } else if fixed[0].im.abs() > 0.0 {
                RootPair::Conjugate(if fixed[0].im > 0.0 {
                    fixed[0]
                } else {
                    fixed[1]
                })
            } else {
                RootPair::Real(fixed[0].re, fixed[1].re)
            };
            Biquad {
                b: s.b.map(|c| c * gain),
                a: pair.monic(),
            }
        })
        .collect();
    Sos::new(sections)
}
