//! The signal that excites a material's filter.
//!
//! Three choices, all normalised by a nominal body weight `W` so that one material gain
//! serves every walker:
//!
//! | [`DriveKind`] | `x[n]` | source |
//! |---|---|---|
//! | `Impulse` (default) | `i_s e_s[n - n_s]` at each heel strike `s` of intensity `i_s`: the step's excitation, a heel impulse and its train of micro-impacts ([`crate::excitation`]; one impulse, `δ`, with `--excitation heel`) | paper 1, Fig. 4 and section V-A; its reference \[19\] |
//! | `Force` | `F[n] / W` | paper 1, section IV-C (the real-time Simulink model) |
//! | `ForceRate` | `v_F[n] / W`, `v_F = max(±dF/dt, 0)` | paper 2, equation (1) |
//!
//! **Which one the papers' results correspond to.** The IIR paper fits its filter to the
//! spectrum of a recorded heel strike, and its results (Fig. 4) compare that spectrum with
//! the filter's *unit impulse* response: what matches the recording is the impulse drive,
//! one impulse per step. Its Simulink model feeds the force signal itself into the filter;
//! a force profile has almost all its energy below 10 Hz, so the output is the filter's
//! response to the heel-strike transient, darker than the recording. The tile paper
//! drives its (physical) model with the half-wave-rectified rate of change of force,
//! `u = α v_F`: brighter than force, still shaped by how fast the foot loads the ground.
//! The gains of `Force` and `ForceRate` (the tile paper's `α`) are normalised per
//! material so that a nominal step gives the recorded energy
//! ([`PreparedMaterial::normalise_drives`](crate::synthesis::PreparedMaterial::normalise_drives)).
//!
//! **Sign of `v_F`.** The tile paper writes `v_F = -dF/dt` for `dF/dt < 0`, and says the
//! model responds when the user *increases* pressure: its force reading falls under load
//! (a force-sensing resistor's voltage divider). In newtons, load is positive and rises as
//! the foot comes down, so the default [`Polarity::Loading`] keeps `dF/dt > 0`;
//! [`Polarity::Unloading`] keeps the falling part, for sensors wired the other way or to
//! render the toe-off.

use crate::units::{Newtons, SampleRate};

/// What drives the material filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DriveKind {
    /// Each heel strike's excitation (its heel impulse and train of micro-impacts, or one
    /// impulse), scaled by the strike's intensity.
    #[default]
    Impulse,
    /// The total force.
    Force,
    /// The half-wave-rectified rate of change of force, `v_F`.
    ForceRate,
}

impl DriveKind {
    /// Number of kinds.
    pub const COUNT: usize = 3;

    /// A dense index, for per-kind tables.
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            DriveKind::Impulse => 0,
            DriveKind::Force => 1,
            DriveKind::ForceRate => 2,
        }
    }

    /// One sample of a continuous drive from the total force now and one sample ago (at
    /// `rate_hz`), normalised by `weight` newtons; 0 for [`DriveKind::Impulse`], whose
    /// impulses come from the step detector. The engine and [`offline`](Self::offline)
    /// share it, so the normalisation sees exactly the drive the engine plays.
    #[inline]
    #[must_use]
    pub fn sample(
        self,
        total: f64,
        previous: f64,
        rate_hz: f64,
        polarity: Polarity,
        weight: f64,
    ) -> f64 {
        match self {
            DriveKind::Impulse => 0.0,
            DriveKind::Force => total / weight,
            DriveKind::ForceRate => polarity.rectify((total - previous) * rate_hz) / weight,
        }
    }

    /// The drive for a whole force signal (newtons at `rate`), as the engine would make it
    /// sample by sample with [`Polarity::Loading`]. `Impulse` gives a unit impulse at the
    /// first sample.
    #[must_use]
    pub fn offline(self, force: &[f64], rate: SampleRate, weight: Newtons) -> Vec<f32> {
        let w = weight.0.max(f64::MIN_POSITIVE);
        match self {
            DriveKind::Impulse => {
                let mut x = vec![0.0; force.len().max(1)];
                x[0] = 1.0;
                x
            }
            DriveKind::Force | DriveKind::ForceRate => {
                let mut previous = force.first().copied().unwrap_or(0.0);
                force
                    .iter()
                    .map(|&f| {
                        let x = self.sample(f, previous, rate.hz(), Polarity::Loading, w);
                        previous = f;
                        x as f32
                    })
                    .collect()
            }
        }
    }
}

impl std::str::FromStr for DriveKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "impulse" => Ok(DriveKind::Impulse),
            "force" => Ok(DriveKind::Force),
            "force-rate" | "dfdt" | "vf" => Ok(DriveKind::ForceRate),
            _ => Err(format!(
                "unknown drive {s:?}: expected impulse, force or force-rate"
            )),
        }
    }
}

impl std::fmt::Display for DriveKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            DriveKind::Impulse => "impulse",
            DriveKind::Force => "force",
            DriveKind::ForceRate => "force-rate",
        })
    }
}

/// Which half of `dF/dt` the [`DriveKind::ForceRate`] drive keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Polarity {
    /// Rising force: the foot loading the ground (default).
    #[default]
    Loading,
    /// Falling force: the tile paper's literal sign convention.
    Unloading,
}

impl Polarity {
    /// The half-wave-rectified rate.
    #[must_use]
    pub fn rectify(self, rate: f64) -> f64 {
        match self {
            Polarity::Loading => rate.max(0.0),
            Polarity::Unloading => (-rate).max(0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn force_rate_keeps_only_the_loading_half() {
        let rate = SampleRate(100);
        let force = [0.0, 10.0, 30.0, 30.0, 20.0, 0.0];
        let x = DriveKind::ForceRate.offline(&force, rate, Newtons(100.0));
        assert_eq!(x, vec![0.0, 10.0, 20.0, 0.0, 0.0, 0.0]);
        assert_eq!(Polarity::Unloading.rectify(-5.0), 5.0);
        assert_eq!(Polarity::Unloading.rectify(5.0), 0.0);
    }

    #[test]
    fn kinds_parse_and_print() {
        for k in [DriveKind::Impulse, DriveKind::Force, DriveKind::ForceRate] {
            assert_eq!(k.to_string().parse::<DriveKind>().unwrap(), k);
        }
        assert!("push".parse::<DriveKind>().is_err());
    }
}
