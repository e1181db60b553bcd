//! What drives a step: the heel impact and its train of micro-impacts, fitted from
//! recordings, played by every model.
//!
//! A fitted filter ([`crate::fit`]) or a surface of modes ([`crate::physical`]) says how
//! the ground *rings*. What rings it is the excitation. On concrete a step is one impact;
//! on gravel, sand or snow it is dozens of micro-impacts over a few hundred milliseconds,
//! each a little different, no two steps alike. Driving the filter with one impulse per
//! step gets the spectrum of a step right and its time structure wrong (a 7 ms thump where
//! gravel lasts 260 ms). This module models the excitation, fits it to the recordings, and
//! plays it in real time; the IIR voice filters it, and the physical model strikes its
//! surface with each of its impulses.
//!
//! # The model
//!
//! A step of intensity `i` (the detector's loading rate over the nominal one) is
//!
//! ```math
//! x(t) = i \Big( \sqrt{h}\, \delta(t) + \sum_j s_j\, a_{b(j)}\, q_j\, \delta(t - t_j) \Big)
//! ```
//!
//! - the **heel impact** carries the share `h` of a nominal step's energy;
//! - the **micro-impacts** arrive at times `t_j`, an inhomogeneous Poisson process whose
//!   rate follows a profile fitted from the recordings (per bin `b` of the step's clock,
//!   below), with random sign `s_j = ±1`, a per-bin RMS amplitude `a_b`, and a unit-RMS
//!   random magnitude `q_j ∝ X^{1/κ}`, `X ~ Exp(1)`: a Weibull law whose shape `κ` is
//!   fitted too. At `κ = 2` the energies are exponential (as in
//!   [`crate::physical::aggregate`]: many weak clicks, a few loud ones), at `κ = 1` more
//!   unequal, at 4 nearly alike;
//! - the energies add up to one: `h + Σ_b E_b = 1`, where `E_b = λ_b Δ a_b²` is bin `b`'s
//!   expected share (`λ_b` events per second of step clock, bins `Δ` wide). A unit
//!   impulse is what the fitted filter reproduces the recorded strike with, so a step
//!   has the recorded energy on average.
//!
//! **Why random signs.** The filter was fitted to the *average* spectrum of the recorded
//! steps, which already holds whatever colour the train gave them. With independent signs
//! the train is white on average, `E|Σ_j s_j a_j e^{-iωt_j}|² = Σ_j a_j²`, so the filtered
//! step has the fitted spectrum whatever the train's timing: the time structure is added
//! without undoing the fit. Each step's own spectrum fluctuates around it, which is part of
//! what makes steps differ. (In the recordings the micro-impacts' whitened residual has
//! both signs too.)
//!
//! # The step clock: the train follows the foot
//!
//! The tile paper drives its aggregate by the loading rate, `N(t) = α v_F(t)`: no change
//! of force, no crunch. The train here runs on a *step clock* `τ` that advances with the
//! foot's activity:
//!
//! ```math
//! \frac{d\tau}{dt} = \frac{|dF/dt|}{W\,\bar g\, s}
//! ```
//!
//! with `W` the walker's weight, `ḡ` the mean of `|dF/dt| / W` over a nominal step's stance
//! (from the strike to toe-off: [`clock`]), so that on a nominal step `τ` keeps pace with
//! `t` on average, and `s` the step's random time scale (below). The event rate in real
//! time is then `λ(τ) dτ/dt`: `N(t) = α(τ) |v_F(t)|`, the tile paper's mapping with a
//! gain `α` that depends on how far into the step the foot is, fitted from recordings. So
//! a slower roll (smaller `|dF/dt|`) spreads the same micro-impacts over a longer time, a
//! foot that stops moving stops the crunch, a heavier step is louder (its intensity) but
//! not shorter (the clock is normalised by `W`), and the unloading at toe-off advances the
//! clock too: where the recordings show activity at the time of the nominal toe-off, the
//! toe-off crunches. A step announced without force (an OSC step) runs the clock at
//! `dτ/dt = 1`.
//!
//! Each step draws its time scale `s = e^{σ_D z}`, `z ~ N(0, 1)`, so steps of one material
//! last differently, as the recorded ones do (`σ_D` from their durations).
//!
//! # What plays: the generator ([`Generator`])
//!
//! Prepared for one audio rate `f_s` ([`Tables`]), it runs sample by sample, never
//! allocating: the clock advances by `dτ = v / (f_s s)` for the speed `v` the caller gives
//! (`|dF/dt| / (W ḡ)`), and `λ_b dτ` micro-impacts are due in the sample: one 32-bit
//! uniform draw per whole one (each a sure event) and one against the fraction left
//! (`(λ_b dτ - k) 2^{32}`), at most [`MAX_DRAWS`] a sample, so the train's density does
//! not depend on the rate it is played at. Each event's magnitude `q` and sign come from
//! its own 64-bit draw: a 256-entry table of the quantiles of `X^{1/κ}` at
//! `(k + ½)/256`, scaled to unit RMS, and one bit. The time scale comes from a 64-entry table of the
//! quantiles of `s`. Tables rather than `exp` and `ln` at run time, so that the C export
//! ([`crate::export`]) plays the same excitation bit for bit: every run-time operation is
//! an integer or a correctly rounded IEEE operation (`+ - × ÷`, conversions). The random
//! stream is [`SplitMix64`](crate::signal::noise::SplitMix64), advanced only while a train
//! runs, so a render does not depend on how it is cut into blocks.
//!
//! # Fitted from recordings ([`estimate()`])
//!
//! Described there: each strike's energy envelope, deconvolved by the filter's energy
//! response, gives its excitation's energy over time; their average (each first stretched
//! to the strikes' geometric-mean duration) is the profile, the onset's excess the heel
//! share, the spread of their durations `σ_D`. The event density, the magnitudes' shape and
//! a correction of the time axis are then found by rendering nominal steps and measuring
//! them exactly as the recordings are measured ([`crate::analysis::steps`]): median
//! micro-event count, crest factor and duration. What the train leaves of the recordings' spread between steps is left to the
//! numerator perturbation ([`ExcitationModel::perturbation_db`]).
//!
//! | file | what |
//! |---|---|
//! | `model.rs` | [`ExcitationModel`], as a library stores it, and its checks |
//! | [`clock`] | the nominal step's activity: what normalises the step clock |
//! | `generator.rs` | [`Tables`] at an audio rate and the [`Generator`] that plays them |
//! | [`estimate`](mod@estimate) | the model fitted from recordings |

pub mod clock;
pub mod estimate;
mod generator;
mod model;

pub use estimate::{EstimateConfig, estimate};
pub use generator::{Generator, MAX_BINS, MAX_DRAWS, QUANTILES, SCALES, Tables};
pub use model::{ExcitationError, ExcitationModel};
