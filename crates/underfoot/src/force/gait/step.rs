//! The force of one step: the stance curve `S(u)` (a C1 cubic Hermite through six
//! knots), its exact area for the impulse, and the toe's share (see the parent module,
//! *Shape*, *Impulse* and *Heel and toe*).

use super::{DEFAULT_STANCE_FRACTION, MAX_ROWS};
use crate::units::Newtons;

/// Knot positions (fraction of stance) and nominal heights (fraction of body weight).
pub(super) const RISE_U: f64 = 0.115;
pub(super) const RISE_LEVEL: f64 = 0.88;
pub(super) const PEAK1_U: f64 = 0.25;
pub(super) const VALLEY_U: f64 = 0.5;
pub(super) const PEAK2_U: f64 = 0.75;
pub(super) const PEAK1: f64 = 1.15;
pub(super) const VALLEY: f64 = 0.75;
pub(super) const PEAK2: f64 = 1.10;

/// Where the toe's share of the force starts and finishes rising.
pub(super) const TOE_FROM: f64 = 0.15;
pub(super) const TOE_TO: f64 = 0.70;

/// One nominal step's total vertical force in newtons (no variation, stance fraction
/// [`DEFAULT_STANCE_FRACTION`]), sampled at `rate` hertz from heel strike to toe-off,
/// both zeros included.
///
/// For calibrating gains against the force a walker makes. Empty if an argument is not
/// positive and finite.
#[must_use]
pub fn nominal_step(weight_kg: f64, cadence: f64, rate: f64) -> Vec<f64> {
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if !(positive(weight_kg) && positive(cadence) && positive(rate)) {
        return Vec::new();
    }
    let shape = Shape::new(PEAK1, VALLEY, PEAK2);
    let stance = DEFAULT_STANCE_FRACTION * 2.0 / cadence;
    let scale = 1.0 / (2.0 * DEFAULT_STANCE_FRACTION * shape.area());
    let weight = Newtons::weight_of(weight_kg).0;
    let samples = (stance * rate).floor();
    if samples > MAX_ROWS as f64 {
        return Vec::new();
    }
    (0..=samples as usize)
        .map(|i| weight * scale * shape.eval(i as f64 / rate / stance))
        .collect()
}

/// The toe's share of the force at stance fraction `u`: C1, 0 early, 1 late.
pub(super) fn toe_share(u: f64) -> f64 {
    let x = ((u - TOE_FROM) / (TOE_TO - TOE_FROM)).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// A knot of the Hermite curve: position, value, slope.
#[derive(Debug, Clone, Copy)]
struct Knot {
    u: f64,
    y: f64,
    m: f64,
}

/// The stance curve `S(u)`: a piecewise cubic Hermite through six knots.
#[derive(Debug, Clone)]
pub(super) struct Shape {
    knots: [Knot; 6],
}

impl Shape {
    pub(super) fn new(peak1: f64, valley: f64, peak2: f64) -> Self {
        let knot = |u, y, m| Knot { u, y, m };
        let rise = RISE_LEVEL * peak1;
        Self {
            knots: [
                knot(0.0, 0.0, 0.0),
                // Twice the secant to the crest: the segment after it is the parabola
                // with its vertex at the first peak, so the approach is concave.
                knot(RISE_U, rise, 2.0 * (peak1 - rise) / (PEAK1_U - RISE_U)),
                knot(PEAK1_U, peak1, 0.0),
                knot(VALLEY_U, valley, 0.0),
                knot(PEAK2_U, peak2, 0.0),
                knot(1.0, 0.0, 0.0),
            ],
        }
    }

    /// `S(u)`, zero outside `0..=1`.
    pub(super) fn eval(&self, u: f64) -> f64 {
        if !(0.0..=1.0).contains(&u) {
            return 0.0;
        }
        for w in self.knots.windows(2) {
            let (a, b) = (w[0], w[1]);
            if u <= b.u {
                let h = b.u - a.u;
                let s = (u - a.u) / h;
                let (s2, s3) = (s * s, s * s * s);
                return (2.0 * s3 - 3.0 * s2 + 1.0) * a.y
                    + (s3 - 2.0 * s2 + s) * h * a.m
                    + (3.0 * s2 - 2.0 * s3) * b.y
                    + (s3 - s2) * h * b.m;
            }
        }
        0.0
    }

    /// `∫_0^1 S(u) du`, exactly: a cubic Hermite segment integrates to
    /// `h (y_a + y_b) / 2 + h² (m_a - m_b) / 12`.
    pub(super) fn area(&self) -> f64 {
        self.knots
            .windows(2)
            .map(|w| {
                let h = w[1].u - w[0].u;
                h * (w[0].y + w[1].y) / 2.0 + h * h * (w[0].m - w[1].m) / 12.0
            })
            .sum()
    }
}
