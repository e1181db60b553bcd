//! Format 1 to 2: a format-1 file is read as what the voice played.
//!
//! Format 1 files were written before the decay limit was part of the fit, and some hold
//! poles that ring for minutes, which the voice always pulled in to 0.5 s when it played
//! them. Each such pole is moved radially to the radius that decays by `e` in 0.5 s,
//! `rho = exp(-1 / (0.5 f_s))`, and the record's model magnitude and metrics are
//! recomputed for the filter that results. Saving writes format 2.

use num_complex::Complex64;

use super::Library;
use crate::material::FilterCoefficients;
use crate::signal::{Biquad, Sos};
use crate::units::Hz;

impl Library {
    /// Pulls every pole beyond the legacy 0.5 s decay in to it, as the voice did when it
    /// played the file, and describes the resulting filter in the record.
    pub(super) fn upgrade_from_1(&mut self) {
        for m in &mut self.materials {
            m.fit.longest_decay = crate::material::model::LEGACY_DECAY;
            let Some(sos) = m.sos() else { continue };
            let rho = crate::fit::decay_radius(m.sample_rate, m.fit.longest_decay);
            let Some(limited) = limit_radius(&sos, rho) else {
                continue;
            };
            m.filter = FilterCoefficients::from_sos(&limited);
            m.fit.model = m
                .fit
                .grid_hz
                .iter()
                .map(|&f| limited.response(m.sample_rate.omega(Hz(f))).norm())
                .collect();
            m.fit.nrmse = crate::fit::metrics::nrmse(&m.fit.measured, &m.fit.model);
            m.fit.lsd_db = crate::fit::metrics::lsd_db(&m.fit.measured, &m.fit.model);
            m.fit.worst = None;
            m.fit.method = format!("{} + decay-limited on upgrade from format 1", m.fit.method);
        }
    }
}

/// `sos` with every pole beyond `rho` moved radially onto it (numerators kept), or `None`
/// when no pole lies beyond it. An unstable section is left as it is, so that validation
/// refuses it: the upgrade reproduces what the voice played, it does not repair a file.
fn limit_radius(sos: &Sos, rho: f64) -> Option<Sos> {
    let mut changed = false;
    let sections = sos
        .sections
        .iter()
        .map(|s| {
            let [p, q] = s.poles();
            if (p.norm() <= rho && q.norm() <= rho) || !s.is_stable() {
                return *s;
            }
            changed = true;
            let pull = |z: Complex64| {
                if z.norm() > rho {
                    z * (rho / z.norm())
                } else {
                    z
                }
            };
            let (p, q) = (pull(p), pull(q));
            // The monic quadratic with roots p, q (real coefficients: a conjugate pair or two
            // real poles); a first-order section's one pole is -a1.
            let a = if s.a[2] == 0.0 {
                [1.0, s.a[1].clamp(-rho, rho), 0.0]
            } else {
                [1.0, -(p + q).re, (p * q).re]
            };
            Biquad { b: s.b, a }
        })
        .collect();
    changed.then(|| Sos::new(sections))
}
