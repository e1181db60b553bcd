//! The box of the bounds: the Coleman-Li scaling, how far a step may go, and the choice
//! between the cut, reflected and anti-gradient steps (see the parent module, *Reflection*).

use nalgebra::DVector;

use super::subproblem::Model;

/// The bounds as a box.
pub(super) struct Bounds<'a> {
    pub(super) lo: &'a [f64],
    pub(super) hi: &'a [f64],
}

impl Bounds<'_> {
    /// The Coleman-Li scaling `v` and its derivative `∂v`.
    pub(super) fn scaling(&self, x: &[f64], g: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let n = x.len();
        let mut v = vec![1.0; n];
        let mut dv = vec![0.0; n];
        for i in 0..n {
            if g[i] < 0.0 && self.hi[i].is_finite() {
                v[i] = self.hi[i] - x[i];
                dv[i] = -1.0;
            } else if g[i] > 0.0 && self.lo[i].is_finite() {
                v[i] = x[i] - self.lo[i];
                dv[i] = 1.0;
            }
        }
        (v, dv)
    }

    /// The largest `t >= 0` with `x + t d` in the box, and the components that meet a
    /// bound there (empty when the ray never leaves the box).
    pub(super) fn stride(&self, x: &[f64], d: &[f64]) -> (f64, Vec<usize>) {
        let mut t = f64::INFINITY;
        let mut hits = Vec::new();
        for i in 0..x.len() {
            let ti = if d[i] > 0.0 {
                (self.hi[i] - x[i]) / d[i]
            } else if d[i] < 0.0 {
                (self.lo[i] - x[i]) / d[i]
            } else {
                f64::INFINITY
            };
            let ti = ti.max(0.0);
            if ti < t {
                t = ti;
                hits.clear();
                hits.push(i);
            } else if ti == t && ti.is_finite() {
                hits.push(i);
            }
        }
        (t, hits)
    }

    pub(super) fn contains_strictly(&self, x: &[f64]) -> bool {
        x.iter()
            .zip(self.lo.iter().zip(self.hi))
            .all(|(&v, (&l, &h))| v > l && v < h)
    }

    /// `x` moved strictly inside: a value on (or within a relative `1e-10` of) a bound is
    /// pushed that far in, or to the middle of a box narrower than that.
    pub(super) fn interior(&self, x: &mut [f64]) {
        for ((xi, &l), &h) in x.iter_mut().zip(self.lo).zip(self.hi) {
            // An infinite bound needs no margin (and would make an infinite one).
            let lo_in = if l.is_finite() {
                l + 1e-10 * l.abs().max(1.0)
            } else {
                l
            };
            let hi_in = if h.is_finite() {
                h - 1e-10 * h.abs().max(1.0)
            } else {
                h
            };
            if lo_in >= hi_in {
                *xi = 0.5 * (l + h);
            } else if *xi < lo_in {
                *xi = lo_in;
            } else if *xi > hi_in {
                *xi = hi_in;
            }
        }
    }
}

/// The step (in scaled variables) to take from the trust-region solution `ph`, reflecting
/// off the bounds if it leaves the box, and its model value.
pub(super) fn select_step(
    bounds: &Bounds<'_>,
    x: &[f64],
    d: &[f64],
    model: &Model,
    ph: DVector<f64>,
    delta: f64,
    theta: f64,
) -> (DVector<f64>, f64) {
    let n = x.len();
    let to_x = |p: &DVector<f64>| -> Vec<f64> { p.iter().zip(d).map(|(a, b)| a * b).collect() };
    let step = to_x(&ph);
    let trial: Vec<f64> = x.iter().zip(&step).map(|(a, b)| a + b).collect();
    if bounds.contains_strictly(&trial) {
        let q = model.value(&ph);
        return (ph, q);
    }
    // 1. Cut back to the first bound, then θ of that.
    let (t_hit, hits) = bounds.stride(x, &step);
    let t_hit = t_hit.min(1.0);
    let cut = &ph * (theta * t_hit);
    let mut best = (model.value(&cut), cut);

    // 2. The reflected path from the point on the bound.
    let on_bound_h = &ph * t_hit;
    let mut rh = ph.clone();
    for &i in &hits {
        rh[i] = -rh[i];
    }
    let x_on: Vec<f64> = x
        .iter()
        .zip(&to_x(&on_bound_h))
        .map(|(a, b)| a + b)
        .collect();
    let (t_box, _) = bounds.stride(&x_on, &to_x(&rh));
    // Largest t with ‖on + t r‖ <= Δ.
    let (a2, a1, a0) = (
        rh.dot(&rh),
        2.0 * on_bound_h.dot(&rh),
        on_bound_h.dot(&on_bound_h) - delta * delta,
    );
    let t_region = if a2 > 0.0 {
        let disc = (a1 * a1 - 4.0 * a2 * a0).max(0.0);
        ((-a1 + disc.sqrt()) / (2.0 * a2)).max(0.0)
    } else {
        0.0
    };
    let t_max = t_box.min(t_region);
    if t_max.is_finite() && t_max > 0.0 {
        let (t, q) = model.line_min(&on_bound_h, &rh, (1.0 - theta) * t_max, theta * t_max);
        if q < best.0 {
            best = (q, &on_bound_h + &rh * t);
        }
    }

    // 3. The scaled anti-gradient (a Cauchy point).
    let gh_norm = model.gh.norm();
    if gh_norm > 0.0 {
        let dir = -&model.gh;
        let (t_box, _) = bounds.stride(x, &to_x(&dir));
        let t_max = t_box.min(delta / gh_norm);
        if t_max.is_finite() && t_max > 0.0 {
            let (t, q) = model.line_min(&DVector::zeros(n), &dir, 0.0, theta * t_max);
            if q < best.0 {
                best = (q, dir * t);
            }
        }
    }
    (best.1, best.0)
}
