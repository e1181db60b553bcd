//! Fitting an IIR filter to a measured response.
//!
//! The filter of the paper's equation (1) is a ratio of polynomials of order `N` in `z^-1`;
//! here it is found and kept as second-order sections (see [`crate::signal::sos`]). For each
//! candidate order the fit runs three linear starts and two non-linear refinements, and keeps
//! what wins on the log-spectral distance:
//!
//! 1. **Starts.** [`levi`](levi::levi): Levi's linearised least squares, the paper's initial
//!    guess and Octave's `invfreqz`; [`sanathanan_koerner`](levi::sanathanan_koerner): the same,
//!    re-weighted until the equation error approaches the output error (Steiglitz-McBride);
//!    [`vector_fit`](vector_fit::vector_fit): pole relocation in a partial-fraction basis,
//!    which stays well conditioned for low resonances at high rates. Unstable poles of a
//!    linear start are reflected into the unit circle.
//! 2. **Refinements** ([`refine`](refine::refine)). The damped Gauss-Newton output-error
//!    search of equation (2), over a parametrisation in which every step is a stable filter;
//!    then the same search on the log-magnitude error, which is what the metrics measure.
//!
//! All of it is evaluated on a log-spaced frequency grid of the band, so each octave counts
//! the same (the weighting a perceptual fit needs; a linear grid spends most of its points
//! on the top octave).
//!
//! **Order.** "Order" is the number of poles `N`, which equals the numerator degree. The
//! automatic search tries `N = 1, 2, ...` up to a bound and keeps the lowest order whose
//! log-spectral distance and NRMSE both reach their targets (defaults 0.5 dB, below the
//! 1 dB intensity JND, and 0.1), or else the best order tried.
//!
//! Every fit also records the plain Levi fit at the same order, so that a report can show
//! what the refinements bought.
pub mod levi;
pub mod metrics;
pub mod refine;
pub mod roots;
pub mod target;
pub mod vector_fit;

pub use metrics::{MetricGrid, Metrics};
pub use refine::Objective;
pub use target::Target;

use crate::signal::Sos;
use crate::units::Decibels;

/// The largest order a fit accepts.
pub const MAX_ORDER: usize = 64;

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
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            order: OrderChoice::Auto { max: 16 },
            target_lsd: Decibels(0.5),
            target_nrmse: 0.1,
            grid_points: 256,
            max_iterations: 60,
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
    #[error("filter order {order} is out of range (1..={MAX_ORDER})")]
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

/// Fits one order: every start, every refinement, the best by log-spectral distance.
///
/// # Errors
/// [`FitError::InvalidOrder`] for order 0 or above [`MAX_ORDER`]; [`FitError::NoFit`] when
/// no start yields a stable finite filter.
pub fn fit_order(
    target: &Target,
    grid: &MetricGrid,
    order: usize,
    cfg: &FitConfig,
) -> Result<OrderFit, FitError> {
    if order == 0 || order > MAX_ORDER {
        return Err(FitError::InvalidOrder { order });
    }
    let levi_ba = levi::levi(target, order, order, None).ok();
    let levi_metrics = levi_ba.as_ref().map(|(b, a)| {
        let model: Vec<f64> = grid
            .freqs
            .iter()
            .map(|&f| {
                let w = grid.rate.omega(f);
                (levi::eval_poly(b, w) / levi::eval_poly(a, w)).norm()
            })
            .collect();
        grid.evaluate_magnitude(&model)
    });

    let mut starts: Vec<(&'static str, Sos)> = Vec::new();
    if let Some((b, a)) = &levi_ba {
        if let Some(s) = roots::ba_to_sos(b, a) {
            starts.push(("levi", stabilise(&s)));
        }
    }
    if let Ok((b, a)) = levi::sanathanan_koerner(target, order, order, 5) {
        if let Some(s) = roots::ba_to_sos(&b, &a) {
            starts.push(("sanathanan-koerner", stabilise(&s)));
        }
    }
    if let Ok(s) = vector_fit::vector_fit(target, order, 10) {
        starts.push(("vector-fit", stabilise(&s)));
    }

    let mut best: Option<OrderFit> = None;
    let mut consider = |sos: &Sos, method: String| {
        if !sos.is_stable()
            || sos
                .sections
                .iter()
                .any(|s| s.b.iter().any(|c| !c.is_finite()))
        {
            return;
        }
        let m = grid.evaluate(sos);
        if !(m.lsd_db.is_finite() && m.nrmse.is_finite()) {
            return;
        }
        if best.as_ref().is_none_or(|b| m.lsd_db < b.metrics.lsd_db) {
            best = Some(OrderFit {
                order,
                sos: sos.clone(),
                metrics: m,
                method,
                levi: levi_metrics,
            });
        }
    };
    for (name, start) in &starts {
        consider(start, (*name).to_string());
        let Ok(oe) = refine::refine(start, target, Objective::OutputError, cfg.max_iterations)
        else {
            continue;
        };
        consider(&oe.sos, format!("{name} + gauss-newton(output-error)"));
        if let Ok(lm) = refine::refine(&oe.sos, target, Objective::LogMagnitude, cfg.max_iterations)
        {
            consider(
                &lm.sos,
                format!("{name} + gauss-newton(output-error) + gauss-newton(log-magnitude)"),
            );
        }
    }
    best.ok_or(FitError::NoFit { order })
}

/// Fits `target`, choosing the order as `cfg` says; `progress` sees each order tried.
///
/// # Errors
/// As [`fit_order`]; the automatic search fails only if every order fails.
pub fn fit(
    target: &Target,
    grid: &MetricGrid,
    cfg: &FitConfig,
    progress: &mut dyn FnMut(&OrderFit),
) -> Result<FitOutcome, FitError> {
    let orders: Vec<usize> = match cfg.order {
        OrderChoice::Fixed(n) => vec![n],
        OrderChoice::Auto { max } => {
            if max == 0 || max > MAX_ORDER {
                return Err(FitError::InvalidOrder { order: max });
            }
            (1..=max).collect()
        }
    };
    let mut trials = Vec::new();
    let mut best: Option<OrderFit> = None;
    let mut last_err = None;
    for order in orders {
        let f = match fit_order(target, grid, order, cfg) {
            Ok(f) => f,
            Err(e) => {
                last_err = Some(e);
                continue;
            }
        };
        progress(&f);
        trials.push((order, f.metrics, f.method.clone()));
        let reached = f.metrics.lsd_db <= cfg.target_lsd.0 && f.metrics.nrmse <= cfg.target_nrmse;
        if best
            .as_ref()
            .is_none_or(|b| f.metrics.lsd_db < b.metrics.lsd_db)
            || reached
        {
            best = Some(f);
        }
        if reached {
            break;
        }
    }
    match best {
        Some(best) => Ok(FitOutcome { best, trials }),
        None => Err(last_err.unwrap_or(FitError::NoFit { order: 0 })),
    }
}

/// Reflects the unstable poles of each section into the unit circle, keeping the
/// magnitude response.
fn stabilise(sos: &Sos) -> Sos {
    use crate::signal::sos::{Biquad, RootPair};
    let sections = sos
        .sections
        .iter()
        .map(|s| {
            if s.is_stable() {
                return *s;
            }
            let poles = s.poles();
            let (fixed, gain) = roots::reflect_unstable(&poles, 1.0 - 1e-9);
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
