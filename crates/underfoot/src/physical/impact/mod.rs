//! A hammer striking a surface through a Hunt-Crossley contact.
//!
//! # The model
//!
//! A hammer of mass `m` moves toward a surface. Both positions are measured along the
//! hammer's travel, so the compression of the contact is `x = y_h - y_s` (`x > 0` in
//! contact), and the force the contact exerts (pushing the hammer back and the surface on)
//! is Hunt and Crossley's (*Coefficient of restitution interpreted as damping in vibroimpact*,
//! J. Appl. Mech. 42, 1975):
//!
//! ```math
//! F = \max\left(0,\; k x^{\alpha} + \lambda x^{\alpha} \dot x\right) \quad (x > 0),
//!   \qquad F = 0 \quad (x \le 0),
//! ```
//!
//! with stiffness `k` (N/m^α), exponent `α` (3/2 for Hertzian contact of curved bodies, 1
//! for a linear spring) and damping `λ` (N·s/m^(α+1)). The damping scales with the
//! compression, so the force starts and ends at zero instead of jumping as a linear
//! dashpot's does. Late in the restitution phase `λ ẋ < -k` can make the sum negative: the
//! clamp keeps the contact from pulling (no sticking, the bodies just separate).
//!
//! The hammer obeys `m ÿ_h = -F`. The surface is either rigid (`y_s = 0`) or a
//! [`ResonatorBank`] driven by `+F` (its modal gains are the point's mobility, so they are
//! non-negative).
//!
//! # Theory the tests check
//!
//! Undamped (`λ = 0`) on a rigid surface, energy conservation gives the largest
//! compression and the peak force,
//!
//! ```math
//! x_{max} = \left(\frac{(\alpha+1) m v^2}{2k}\right)^{1/(\alpha+1)}, \qquad
//!   F_{max} = k x_{max}^{\alpha},
//! ```
//!
//! and integrating `dt = dx / \dot x` with `\dot x = v \sqrt{1 - (x/x_{max})^{α+1}}` the
//! contact time `T_c = 2 (x_{max}/v) \int_0^1 du / \sqrt{1 - u^{α+1}}` (`π \sqrt{m/k}` for
//! `α = 1`, `≈ 2.943 x_{max}/v` for `α = 3/2`).
//!
//! With a little damping, the energy lost is, to first order, the damping force's work
//! along the undamped path: `ΔE ≈ 2 λ \int_0^{x_{max}} x^α \dot x\, dx
//! = \frac{2}{3} λ m v^3 / k` (substitute `u = x/x_{max}`; `\int_0^1 u^α \sqrt{1-u^{α+1}} du
//! = \frac{2}{3(α+1)}`). With `E = m v^2/2`, the coefficient of restitution is
//!
//! ```math
//! e = \frac{v_{out}}{v_{in}} = \sqrt{1 - ΔE/E} \approx 1 - \frac{2}{3} \frac{\lambda}{k} v_{in},
//! ```
//!
//! whatever `α`: Hunt and Crossley's relation `λ = \frac{3}{2} a k` for `e = 1 - a v_{in}`.

//!
//! # Files
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the hammer, the surface, striking, running and withdrawing the hammer |
//! | `step.rs` | one sample of contact: the discrete-gradient step, its implicit force and its energy |
//! | `tests.rs` | the tests, against the theory above |

mod step;

use step::{compliance, compliance_of};

use super::{PhysicalError, ResonatorBank};
use crate::units::{Newtons, SampleRate, Seconds};

/// The hammer and its contact.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImpactParams {
    /// The hammer's mass, in kilograms.
    pub mass: f64,
    /// The contact stiffness `k`, in N/m^α.
    pub stiffness: f64,
    /// The contact exponent `α` (3/2 for Hertzian contact, 1 for a linear spring); at least 1.
    pub alpha: f64,
    /// The Hunt-Crossley damping `λ`, in N·s/m^(α+1); zero for a lossless contact.
    pub damping: f64,
    /// The speed of the first strike toward the surface, in m/s (zero: no strike yet).
    pub velocity: f64,
}

/// What the hammer strikes.
#[derive(Debug, Clone, PartialEq)]
pub enum Surface {
    /// An immovable surface: the output is the contact force.
    Rigid,
    /// A resonating surface: the output is its velocity at the contact point.
    Resonant(ResonatorBank),
}

/// A hammer striking a surface, sample by sample.
///
/// Prepared by [`new`](Self::new); [`strike`](Self::strike) and
/// [`process`](Self::process) never allocate.
#[derive(Debug, Clone)]
pub struct Impact {
    params: ImpactParams,
    surface: Option<ResonatorBank>,
    period: f64,
    /// `C = T^2/(2m) + T h[1]`: how much one newton over one sample closes the contact.
    compliance: f64,
    /// Whether a hammer has been thrown at all.
    armed: bool,
    /// Compression `x = y_h - y_s`.
    x: f64,
    /// Hammer velocity toward the surface.
    v: f64,
    /// Surface displacement now.
    ys: f64,
    stats: StrikeStats,
}

#[derive(Debug, Clone, Copy, Default)]
struct StrikeStats {
    /// Samples since the strike.
    samples: u64,
    /// Start of the first contact, in samples since the strike (fractional).
    start: Option<f64>,
    /// Its end.
    end: Option<f64>,
    peak: f64,
}

impl Impact {
    /// A hammer over `surface`, running at `rate`; a first strike is armed when
    /// `params.velocity > 0`.
    ///
    /// # Errors
    /// A parameter out of range (mass and stiffness positive, `α ≥ 1`, damping and
    /// velocity non-negative, all finite), a zero rate, a surface prepared for another
    /// rate, or a surface mode with a negative gain.
    pub fn new(
        params: ImpactParams,
        surface: Surface,
        rate: SampleRate,
    ) -> Result<Self, PhysicalError> {
        if rate.0 == 0 {
            return Err(PhysicalError::ZeroRate);
        }
        let check = |name, value: f64, ok: bool, expected| {
            if value.is_finite() && ok {
                Ok(())
            } else {
                Err(PhysicalError::InvalidParameter {
                    name,
                    value,
                    expected,
                })
            }
        };
        check("mass", params.mass, params.mass > 0.0, "positive (kg)")?;
        check(
            "stiffness",
            params.stiffness,
            params.stiffness > 0.0,
            "positive (N/m^alpha)",
        )?;
        check("alpha", params.alpha, params.alpha >= 1.0, "at least 1")?;
        check(
            "damping",
            params.damping,
            params.damping >= 0.0,
            "non-negative",
        )?;
        check_velocity(params.velocity)?;
        let surface = match surface {
            Surface::Rigid => None,
            Surface::Resonant(bank) => {
                if bank.rate() != rate {
                    return Err(PhysicalError::RateMismatch {
                        surface: bank.rate(),
                        impact: rate,
                    });
                }
                Some(bank)
            }
        };
        let period = 1.0 / rate.hz();
        let compliance = match &surface {
            Some(bank) => compliance(period, params.mass, bank),
            None => compliance_of(period, params.mass, 0.0),
        };
        let mut impact = Self {
            params,
            surface,
            period,
            compliance,
            armed: false,
            x: 0.0,
            v: 0.0,
            ys: 0.0,
            stats: StrikeStats::default(),
        };
        if params.velocity > 0.0 {
            impact.arm(params.velocity);
        }
        Ok(impact)
    }

    /// Throws the hammer again: from the next sample it touches the surface where the
    /// surface is now, moving toward it at `velocity` (m/s). The surface keeps ringing.
    ///
    /// # Errors
    /// A velocity that is negative or not finite; the hammer is left as it was.
    pub fn strike(&mut self, velocity: f64) -> Result<(), PhysicalError> {
        check_velocity(velocity)?;
        self.arm(velocity);
        Ok(())
    }

    fn arm(&mut self, velocity: f64) {
        if let Some(bank) = &mut self.surface {
            bank.restore();
        }
        self.armed = true;
        self.x = 0.0;
        self.v = velocity;
        self.stats = StrikeStats::default();
    }

    /// Becomes a copy of `other`. Reuses the surface's buffers when both strike a
    /// resonating surface, so that nothing is allocated when this surface has room for
    /// `other`'s modes ([`ResonatorBank::reserve`]); otherwise the surface is cloned.
    pub fn assign_from(&mut self, other: &Impact) {
        match (&mut self.surface, &other.surface) {
            (Some(mine), Some(theirs)) => mine.assign_from(theirs),
            (None, None) => {}
            (mine, theirs) => mine.clone_from(theirs),
        }
        self.params = other.params;
        self.period = other.period;
        self.compliance = other.compliance;
        self.armed = other.armed;
        self.x = other.x;
        self.v = other.v;
        self.ys = other.ys;
        self.stats = other.stats;
    }

    /// Room for a surface of `modes` modes (see [`assign_from`](Self::assign_from)).
    pub fn reserve(&mut self, modes: usize) {
        if let Some(bank) = &mut self.surface {
            bank.reserve(modes);
        }
    }

    /// Brings the surface to rest and withdraws the hammer.
    pub fn reset(&mut self) {
        if let Some(bank) = &mut self.surface {
            bank.reset();
        }
        self.armed = false;
        self.x = 0.0;
        self.v = 0.0;
        self.ys = 0.0;
        self.stats = StrikeStats::default();
    }

    /// Runs one block. Each sample is, for a resonating surface, its velocity at the
    /// contact point (m/s, with gains in m/(N·s)); for a rigid surface, the contact force
    /// (N) over the sample.
    pub fn process(&mut self, out: &mut [f32]) {
        out.fill(0.0);
        self.process_add(out);
    }

    /// Adds one block to `out` (see [`process`](Self::process)), for a sum of impacts.
    ///
    /// While a hammer may still touch, sample by sample; once it has left for good
    /// ([`withdraw_if_gone`](Self::withdraw_if_gone)), the surface rings on alone
    /// through the bank's free loop, with no contact bookkeeping.
    pub(crate) fn process_add(&mut self, out: &mut [f32]) {
        let mut rest = out;
        while self.armed && !rest.is_empty() {
            // Checked on the strike's own clock (every sample of an armed hammer counts),
            // so that where blocks start or end never changes when it is withdrawn.
            let due = WITHDRAW_CHECK - (self.stats.samples % WITHDRAW_CHECK as u64) as usize;
            let (head, tail) = rest.split_at_mut(rest.len().min(due));
            for o in head.iter_mut() {
                *o += self.step() as f32;
            }
            rest = tail;
            if self.stats.samples.is_multiple_of(WITHDRAW_CHECK as u64) {
                self.withdraw_if_gone();
            }
        }
        if let Some(bank) = &mut self.surface
            && !rest.is_empty()
        {
            bank.add_free_velocity(rest);
            self.ys = bank.displacement();
        }
    }

    /// Culls the surface's modes whose energy is at most `floor` (see
    /// [`ResonatorBank::cull`]), once the hammer has been withdrawn: the free loop then
    /// skips them until the next strike or retune. Nothing to do while a hammer may still
    /// touch.
    pub(crate) fn cull_quiet_modes(&mut self, floor: f64) {
        if !self.armed
            && let Some(bank) = &mut self.surface
        {
            bank.cull(floor);
        }
    }

    /// Withdraws a hammer that can never touch the surface again.
    ///
    /// Out of contact the hammer moves at a constant velocity; moving away (`v ≤ 0`) its
    /// position `y_h = x + y_s` never rises. The surface's modes only decay (`|p_k| < 1`),
    /// so with non-negative gains `y_s ≥ -Σ g_k |z_k|` now and ever after. A hammer below
    /// that bound is gone for good; nothing observable changes when it is withdrawn.
    fn withdraw_if_gone(&mut self) {
        if !self.armed || self.v > 0.0 || self.x > 0.0 {
            return;
        }
        let reach = self
            .surface
            .as_ref()
            .map_or(0.0, ResonatorBank::amplitude_bound);
        if self.x + self.ys < -reach {
            self.armed = false;
        }
    }

    /// Moves the surface's modes to `frequency_scale` times their frequencies as given
    /// (see [`ResonatorBank::retune`]: decay times, gains and the surface's motion are
    /// kept) and updates the contact's compliance to the new `h[1]`. Nothing to do on a
    /// rigid surface. Real time: no allocation.
    ///
    /// Retuning while the hammer is on the surface is allowed (the contact carries on
    /// against the retuned surface) but is not a physical event; retune between strikes.
    ///
    /// # Errors
    /// A scale that is not positive and finite; nothing is changed.
    pub fn retune(&mut self, frequency_scale: f64) -> Result<(), PhysicalError> {
        match &mut self.surface {
            Some(bank) => {
                bank.retune(frequency_scale)?;
                self.compliance = compliance(self.period, self.params.mass, bank);
            }
            None => {
                if !(frequency_scale.is_finite() && frequency_scale > 0.0) {
                    return Err(PhysicalError::InvalidParameter {
                        name: "frequency_scale",
                        value: frequency_scale,
                        expected: "positive and finite",
                    });
                }
            }
        }
        Ok(())
    }

    /// The resonating surface, `None` for a rigid one.
    #[must_use]
    pub fn surface(&self) -> Option<&ResonatorBank> {
        self.surface.as_ref()
    }

    /// Whether the hammer is on the surface or still on its way to it (struck and not yet
    /// rebounded). Once it has left it never comes back unless the surface catches it up.
    #[must_use]
    pub fn is_striking(&self) -> bool {
        self.armed && (self.x > 0.0 || self.v > 0.0)
    }

    /// The hammer's velocity toward the surface now (negative once it has rebounded).
    #[must_use]
    pub fn hammer_velocity(&self) -> f64 {
        self.v
    }

    /// The duration of the last strike's first contact, once the hammer has left the
    /// surface (`None` before), interpolated between samples.
    #[must_use]
    pub fn contact_time(&self) -> Option<Seconds> {
        let (start, end) = (self.stats.start?, self.stats.end?);
        Some(Seconds((end - start) * self.period))
    }

    /// The largest contact force since the last strike.
    #[must_use]
    pub fn peak_force(&self) -> Newtons {
        Newtons(self.stats.peak)
    }

    /// The hammer's kinetic energy plus the energy stored in the contact (J).
    #[must_use]
    pub fn contact_energy(&self) -> f64 {
        0.5 * self.params.mass * self.v * self.v + self.potential(self.x)
    }

    fn potential(&self, x: f64) -> f64 {
        if x <= 0.0 {
            0.0
        } else {
            self.params.stiffness * x.powf(self.params.alpha + 1.0) / (self.params.alpha + 1.0)
        }
    }
}

/// Samples between checks that a hammer has left for good.
const WITHDRAW_CHECK: usize = 16;

fn check_velocity(velocity: f64) -> Result<(), PhysicalError> {
    if velocity.is_finite() && velocity >= 0.0 {
        Ok(())
    } else {
        Err(PhysicalError::InvalidParameter {
            name: "velocity",
            value: velocity,
            expected: "non-negative (m/s toward the surface)",
        })
    }
}

#[cfg(test)]
mod tests;
