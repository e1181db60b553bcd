//! The step clock's normalisation: a nominal step's activity.
//!
//! The step clock advances at `|dF/dt| / (W ḡ)` (see the [module documentation](super)),
//! with `ḡ` the mean of `|dF/dt| / W` over a nominal step's stance from its strike to its
//! toe-off: the nominal walker of the gait model ([`nominal_step`]: 70 kg, 1.8 steps/s),
//! struck where the step detector's rising threshold is crossed. On that step the clock
//! runs `τ = t` on average over the stance; `ḡ` is about 4.3 per second (the force loads
//! about 1.15 W, falls to 0.75 W, rises to 1.1 W and unloads, in 0.67 s).
//!
//! [`nominal_speeds`] is that step's clock speed sample by sample at a rate, what the
//! excitation's estimation renders with.

use crate::force::gait::nominal_step;
use crate::force::steps::DetectorConfig;
use crate::units::{Newtons, SampleRate};

/// The nominal walker's mass (kg) and cadence (steps/s).
const NOMINAL_KG: f64 = 70.0;
const NOMINAL_CADENCE: f64 = 1.8;
/// The rate `ḡ` is computed at: fine enough that it does not depend on it.
const REFERENCE_RATE: f64 = 20_000.0;

/// The nominal step's total force from its strike (the sample where it first reaches the
/// detector's rising threshold) to toe-off, at `rate` Hz.
fn from_strike(rate: f64) -> Vec<f64> {
    let step = nominal_step(NOMINAL_KG, NOMINAL_CADENCE, rate);
    let on = DetectorConfig::default().on.0;
    let strike = step.iter().position(|&f| f >= on).unwrap_or(0);
    step[strike..].to_vec()
}

/// `ḡ`: the mean of `|dF/dt| / W` over a nominal step from its strike to toe-off, per
/// second.
#[must_use]
pub fn nominal_activity() -> f64 {
    let f = from_strike(REFERENCE_RATE);
    let w = Newtons::weight_of(NOMINAL_KG).0;
    let travel: f64 = f.windows(2).map(|p| (p[1] - p[0]).abs()).sum();
    let duration = (f.len().max(2) - 1) as f64 / REFERENCE_RATE;
    travel / w / duration
}

/// The factor that turns `|dF/dt|` (N/s) into the clock's speed for a walker of `weight`:
/// `1 / (W ḡ)`.
#[must_use]
pub fn speed_per_newton_per_second(weight: Newtons) -> f64 {
    1.0 / (weight.0.max(1e-9) * nominal_activity())
}

/// The clock's speed through a nominal step at `rate`, from its strike (sample 0) to
/// toe-off: `|F[n] - F[n-1]| f_s / (W ḡ)`, the first sample's from the sample before the
/// strike.
#[must_use]
pub fn nominal_speeds(rate: SampleRate) -> Vec<f32> {
    let fs = rate.hz();
    let step = nominal_step(NOMINAL_KG, NOMINAL_CADENCE, fs);
    let on = DetectorConfig::default().on.0;
    let strike = step.iter().position(|&f| f >= on).unwrap_or(0);
    let k = speed_per_newton_per_second(Newtons::weight_of(NOMINAL_KG));
    (strike..step.len())
        .map(|n| {
            let previous = step[n.saturating_sub(1)];
            ((step[n] - previous).abs() * fs * k) as f32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nominal_clock_keeps_pace_over_the_stance() {
        let g = nominal_activity();
        assert!((4.2..4.4).contains(&g), "{g}");
        for rate in [2000, 48_000] {
            let v = nominal_speeds(SampleRate(rate));
            let tau: f64 = v.iter().map(|&s| f64::from(s)).sum::<f64>() / f64::from(rate);
            let t = v.len() as f64 / f64::from(rate);
            assert!((tau / t - 1.0).abs() < 0.01, "{rate}: {tau} over {t}");
        }
    }
}
