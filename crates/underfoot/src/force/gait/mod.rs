//! The vertical ground-reaction force of walking, for demos and tests.
//!
//! [`generate`] makes a [`ForceTrack`] of someone walking, so that every command runs
//! without hardware, and returns the true heel-strike instants with it, so that step
//! detection can be checked against them.
//!
//! # Model
//!
//! **One foot per channel.** A channel is one shoe or insole, or the tiles under one
//! foot; channel 0 is the left foot (`left`), channel 1 the right (`right`). Each has two
//! sensors, `heel` and `toe`. A one-channel track is the left foot of a walker whose
//! right foot is not instrumented: its steps come once per gait cycle.
//!
//! **Strikes.** The heel strikes of both feet form one alternating sequence
//! `t_0 < t_1 < ...`, left on even `n`, right on odd `n`, with cadence `c` (steps per
//! second, both feet together) and relative variation `v`:
//!
//! ```text
//! t_0 = lead_in,    t_(n+1) = t_n + (1 / c) (1 + v z_n),    z_n ~ N(0, 1) clipped to ±2.5
//! ```
//!
//! One sequence for both feet, rather than one per foot, so that the feet stay about half
//! a cycle apart however long the walk: per-foot jitter would let them drift together.
//! Step `n`'s gait cycle is `T_n = t_(n+2) - t_n` (nominally `2 / c`), and its stance
//! (heel strike to toe-off) lasts `sigma_n T_n`, with the stance fraction
//! `sigma_n = sigma (1 + v z / 2)` (nominally `sigma` = 0.62, clamped to 0.5..0.85). Half
//! as much variation as the timing, because the cycle it multiplies varies already.
//! A stance fraction above one half means both feet are down for a while twice per
//! cycle (double support), as in walking.
//!
//! **Shape.** In stance, with `u = (t - t_n) / (sigma_n T_n)` in `0..=1` and body weight
//! `W = weight_kg g`,
//!
//! ```text
//! F_n(t) = W k_n S_n(u),        k_n = 1 / (2 sigma_n ∫_0^1 S_n(u) du)
//! ```
//!
//! and zero outside stance. `S_n` is the piecewise cubic Hermite curve through the knots
//! `(u_i, y_i)` with slopes `m_i`; on `[u_i, u_(i+1)]`, with `h = u_(i+1) - u_i` and
//! `s = (u - u_i) / h`,
//!
//! ```text
//! S(u) = (2s³ - 3s² + 1) y_i + (s³ - 2s² + s) h m_i + (3s² - 2s³) y_(i+1) + (s³ - s²) h m_(i+1)
//! ```
//!
//! | `u` | `y` | slope `m` | meaning |
//! |---|---|---|---|
//! | 0 | 0 | 0 | heel strike |
//! | 0.115 | 0.88 `p1` | `2 (p1 - y) / 0.135` | end of the fast heel-strike rise |
//! | 0.25 | `p1` = 1.15 | 0 | first peak: weight acceptance |
//! | 0.50 | `q` = 0.75 | 0 | mid-stance valley |
//! | 0.75 | `p2` = 1.10 | 0 | second peak: push-off |
//! | 1 | 0 | 0 | toe-off |
//!
//! Each step draws its own `p1`, `q`, `p2` as `(1 + v z)` times the values above.
//! Every segment is monotone (its end slopes are within the Fritsch-Carlson bounds; the
//! second is exactly the parabola that crests at the first peak), so the curve is never
//! negative and its extremes are the knots. It is C1: value and slope are continuous,
//! also at heel strike and toe-off where they meet the zero of swing, because the force
//! is later differentiated and a kink would click. At 1.8 steps/s the rise reaches
//! 0.88 `p1`, about body weight, 80 ms after heel strike, and the first peak at 172 ms.
//! The steepest slope is then about 18 `W`/s, under 4% of body weight per sample at
//! 500 Hz.
//!
//! **Impulse.** `k_n` scales step `n` so that its impulse is `W T_n / 2`. Summed over
//! both feet these impulses tile time, so the mean force over whole cycles is `W`: the
//! body does not accelerate vertically on average. With the nominal knots and
//! `sigma` = 0.62, `k` = 0.994 and the peaks come out at 1.14, 0.75 and 1.09 `W`. The
//! impulse ties the curve to the stance fraction: at `sigma` = 0.6 the same knots are
//! scaled by `k` = 1.027, to peaks of 1.18, 0.77 and 1.13 `W`.
//!
//! **Heel and toe.** The centre of pressure moves from heel to toe over stance. The toe
//! carries the share `phi(u)` of the force, a smoothstep from 0 at `u` = 0.15 to 1 at
//! `u` = 0.70:
//!
//! ```text
//! heel = (1 - phi(u)) F,    toe = phi(u) F,    phi(u) = 3x² - 2x³,  x = clamp((u - 0.15) / 0.55, 0, 1)
//! ```
//!
//! so heel + toe = `F` (to `f32` rounding) and both stay C1.
//!
//! # Example
//!
//! ```
//! use underfoot::force::gait::{generate, GaitConfig};
//!
//! let config = GaitConfig::from_spec("steps=4,cadence=1.8,weight=70,seed=3")?;
//! let gait = generate(&config)?;
//! assert_eq!(gait.track.channel_count(), 2);
//! assert_eq!(gait.strikes[0].len(), 4);
//! assert_eq!(gait.track.sensor_rate().map(f64::round), Some(500.0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Layout
//!
//! | file | what it holds |
//! |---|---|
//! | `config.rs` | what to generate ([`GaitConfig`]): the settings, their defaults and ranges |
//! | `spec.rs` | the `key=value` spec ([`GaitConfig::from_spec`], [`SPEC_KEYS`]) |
//! | `step.rs` | the force of one step: the stance curve, its impulse, heel and toe ([`nominal_step`]) |
//! | `walk.rs` | the walk: strikes, each step's draw, the track sampled ([`generate`]) |
//! | `error.rs` | [`GaitError`] |

mod config;
mod error;
mod spec;
mod step;
#[cfg(test)]
mod tests;
mod walk;

pub use config::GaitConfig;
pub use error::GaitError;
pub use spec::{SPEC_HELP, SPEC_KEYS};
pub use step::nominal_step;
pub use walk::generate;

use super::track::ForceTrack;
use crate::units::Seconds;

/// The nominal stance fraction: the part of a gait cycle a foot is on the ground.
///
/// 0.62, in the usual 0.6-0.62 of walking, is where the impulse needs the nominal curve
/// scaled least (`k` = 0.994 in the [module docs](self)), so the nominal peaks are the
/// peaks generated.
pub const DEFAULT_STANCE_FRACTION: f64 = 0.62;

/// The most rows [`generate`] makes, about 67 minutes at 500 Hz, so that a typo in a spec
/// cannot ask for more memory than the machine has.
pub const MAX_ROWS: usize = 2_000_000;

/// Normal draws are clipped to this many standard deviations, so that even the largest
/// variation keeps every interval and peak positive.
const CLIP: f64 = 2.5;

/// A generated walk: the force track and the true instants of each step.
#[derive(Debug, Clone, PartialEq)]
pub struct Gait {
    /// The sensor readings: channels `left` (and `right`), sensors `heel` and `toe`.
    pub track: ForceTrack,
    /// Each channel's heel-strike instants, in order: where the force leaves zero.
    pub strikes: Vec<Vec<Seconds>>,
    /// Each channel's toe-off instants, one per strike: where the force returns to zero.
    pub toe_offs: Vec<Vec<Seconds>>,
}
