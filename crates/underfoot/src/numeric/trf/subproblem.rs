//! The trust-region subproblem: the quadratic model and its exact minimiser in the region
//! (see the parent module, *Subproblem*).

use nalgebra::{DMatrix, DVector};

/// The quadratic model: `q(p) = ĝ·p + ½ p^T B p`.
pub(super) struct Model {
    pub(super) gh: DVector<f64>,
    pub(super) b: DMatrix<f64>,
}

impl Model {
    pub(super) fn value(&self, p: &DVector<f64>) -> f64 {
        self.gh.dot(p) + 0.5 * p.dot(&(&self.b * p))
    }

    /// The minimiser of `q(a + t d)` for `t` in `[t0, t1]`, and its value.
    pub(super) fn line_min(
        &self,
        a: &DVector<f64>,
        d: &DVector<f64>,
        t0: f64,
        t1: f64,
    ) -> (f64, f64) {
        let bd = &self.b * d;
        let curv = d.dot(&bd);
        let slope = self.gh.dot(d) + a.dot(&bd);
        let q = |t: f64| self.value(&(a + d * t));
        let mut best = if q(t0) <= q(t1) { t0 } else { t1 };
        if curv > 0.0 {
            let t = (-slope / curv).clamp(t0, t1);
            if q(t) < q(best) {
                best = t;
            }
        }
        (best, q(best))
    }
}

/// `p(α)` for the SVD data: `−V (s/(s² + α)) uf`.
fn tr_step(v: &DMatrix<f64>, s: &DVector<f64>, uf: &DVector<f64>, alpha: f64) -> DVector<f64> {
    let mut c = DVector::zeros(s.len());
    for i in 0..s.len() {
        let den = s[i] * s[i] + alpha;
        c[i] = if den > 0.0 { -s[i] * uf[i] / den } else { 0.0 };
    }
    v * c
}

/// The exact minimiser of `½‖A p + f‖²` over `‖p‖ <= Δ`, and whether the constraint is active.
pub(super) fn solve_trust_region(
    a: &DMatrix<f64>,
    f: &DVector<f64>,
    delta: f64,
) -> Option<DVector<f64>> {
    let svd = crate::numeric::svd(a.clone()).ok()?;
    let u = svd.u?;
    let vt = svd.v_t?;
    let v = vt.transpose();
    let s = svd.singular_values;
    let uf = u.transpose() * f;
    let smax = s.iter().copied().fold(0.0, f64::max);
    let full_rank = s.iter().all(|&si| si > smax * 1e-12 * s.len() as f64);
    if full_rank {
        let p = tr_step(&v, &s, &uf, 0.0);
        if p.norm() <= delta {
            return Some(p);
        }
    }
    // ‖p(α)‖ decreases from ‖p(0)‖ (possibly infinite) to 0. Bracket: at α_hi = ‖A^T f‖/Δ,
    // ‖p‖ <= ‖A^T f‖/α = Δ.
    let atf = (a.transpose() * f).norm();
    if atf == 0.0 {
        return Some(DVector::zeros(s.len()));
    }
    let (mut lo, mut hi) = (0.0f64, atf / delta);
    let phi = |alpha: f64| -> (f64, f64) {
        // ‖p‖ and d‖p‖/dα.
        let mut n2 = 0.0;
        let mut d = 0.0;
        for i in 0..s.len() {
            let den = s[i] * s[i] + alpha;
            let c = s[i] * uf[i];
            n2 += c * c / (den * den);
            d -= c * c / (den * den * den);
        }
        let n = n2.sqrt();
        (n, if n > 0.0 { d / n } else { 0.0 })
    };
    let mut alpha = (lo * hi).sqrt().max(1e-3 * hi);
    for _ in 0..60 {
        if !(alpha > lo && alpha < hi) {
            alpha = (1e-3 * hi).max((lo * hi).sqrt());
        }
        let (n, dn) = phi(alpha);
        if (n - delta).abs() <= 1e-3 * delta {
            break;
        }
        if n > delta {
            lo = alpha;
        } else {
            hi = alpha;
        }
        // Newton on 1/‖p‖ − 1/Δ, which is close to linear in α.
        if dn < 0.0 && n > 0.0 {
            alpha -= (n - delta) / dn * (n / delta);
        } else {
            alpha = 0.5 * (lo + hi);
        }
    }
    let mut p = tr_step(&v, &s, &uf, alpha);
    let pn = p.norm();
    if pn > delta {
        p *= delta / pn;
    }
    Some(p)
}
