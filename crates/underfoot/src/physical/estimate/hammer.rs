//! Step 6 of the estimation: the hammer.
//!
//! A Hunt-Crossley contact (α = 3/2) whose undamped contact time is `contact_time`
//! (0.25 ms: a hard sole's first touch, or a grain's), at a strike speed `v` (0.5 m/s) and
//! restitution `e` (0.7). From the theory in [`crate::physical::impact`],
//! `x_max = T_c v / (2 \int_0^1 (1 - u^{5/2})^{-1/2} du)`,
//! `k = (α+1) m v^2 / (2 x_max^{α+1})` and `λ = \frac{3}{2} k (1 - e) / v`. The mass is a
//! grain's (5 g) for an aggregate and a heel's (0.5 kg) for a solid; it sets only how
//! strongly hammer and surface couple ([`super::gains`]). The gain fit needs the spectrum
//! of the hammer's force pulse on a rigid surface, `F(f)`, simulated here.

use super::EstimateError;
use crate::numeric::dtft;
use crate::physical::{Impact, ImpactParams, Surface};
use crate::units::{Hz, SampleRate, Seconds};

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
pub(super) fn contact_spectrum(
    hammer: ImpactParams,
    rate: SampleRate,
    freqs: &[Hz],
) -> Result<Vec<f64>, EstimateError> {
    let mut impact = Impact::new(hammer, Surface::Rigid, rate)?;
    let mut force = vec![0.0f32; rate.samples_in(Seconds(0.02)).max(64)];
    impact.process(&mut force);
    let t = 1.0 / rate.hz();
    // The pulse lasts a fraction of a millisecond: only its samples count.
    let end = force.iter().rposition(|x| *x != 0.0).map_or(0, |n| n + 1);
    let impulses: Vec<f64> = force[..end].iter().map(|x| f64::from(*x) * t).collect();
    Ok(freqs
        .iter()
        .map(|f| dtft(&impulses, rate.omega(*f)).norm())
        .collect())
}
