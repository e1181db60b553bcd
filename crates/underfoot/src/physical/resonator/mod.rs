//! A surface as a bank of damped modes, discretised by impulse invariance.
//!
//! # The continuous model
//!
//! Struck at one point, a linear surface moves there as a sum of independent modes. Mode
//! `k` is a damped oscillator of modal mass `m_k`; a force impulse of `J` newton-seconds
//! at `t = 0` sets its velocity to `J / m_k` and leaves it ringing as
//!
//! ```math
//! y_k(t) = g_k\, J\, e^{-t/\tau_k} \sin(2\pi f_k t), \qquad g_k = \frac{1}{2\pi f_k m_k},
//! ```
//!
//! a damped sine: it starts from rest at zero displacement, which is why the impulse
//! response of a mode to a force is a sine and not a cosine. `f_k` is the frequency one
//! observes (the damped one), `τ_k` the time for the envelope to fall by `e`, and the gain
//! `g_k` (metres per newton-second) the mode's share of the point's mobility. Writing
//! `s_k = -1/τ_k + i 2π f_k`, the displacement is `Im(g_k e^{s_k t})` and the velocity
//! is its derivative `Im(g_k s_k e^{s_k t})`.
//!
//! # Impulse invariance
//!
//! Sampling `y_k` at `t = n / f_s` gives, with the pole
//! `p_k = e^{s_k / f_s} = e^{-1/(τ_k f_s)} e^{i 2π f_k / f_s}`,
//!
//! ```math
//! h[n] = \sum_k g_k \operatorname{Im} p_k^n ,
//! ```
//!
//! so the sampled response passes through the continuous one at every sample: each mode's
//! frequency and decay are exact at any rate, not warped as a bilinear transform would
//! warp them. Each sample of input is taken as the impulse `J[n]` (N·s) delivered during
//! that sample, at its start. One complex one-pole per mode runs it:
//!
//! ```math
//! z_k[n+1] = p_k \left(z_k[n] + J[n]\right), \qquad
//!   y[n] = \sum_k g_k \operatorname{Im} z_k[n], \qquad
//!   \dot y[n] = \sum_k \operatorname{Im}\left(g_k s_k z_k[n]\right).
//! ```
//!
//! `h[0] = 0`: an impulse moves the surface only from the next sample on, so a contact
//! force computed from the surface's position is never in a delay-free loop with it.
//! The velocity is the exact derivative of the continuous response between impulses.
//!
//! # Where it is struck, where it is felt
//!
//! A mode's gain between two points is `φ_k(a) φ_k(b) / m_k`, the product of its shape
//! at both. At the point struck (`a = b`) it is positive: the contact sees the
//! driving-point gains `|g_k|`. The vibration is felt elsewhere (the skin is not the
//! grain, a microphone is not the floor), so its gains may carry a sign. A bank keeps
//! one number per mode: `|g_k|` drives [`displacement`](ResonatorBank::displacement), the
//! contact's side, and the signed `g_k` drives [`velocity`](ResonatorBank::velocity), the
//! side felt. This assumes the mode's shape has the same size at both points and differs
//! at most in sign: all that can be identified from one recorded signal. With
//! non-negative gains both are the same point.
//!
//! # Precision
//!
//! The banks run in f64, in lanes of four (`free.rs`). Single precision would double the
//! lanes, and its error is small: the same recursion with poles, gains and state rounded to
//! f32, over a 4 s walk of every built-in physical model (32 modes each; heel impulses and
//! micro-impulses), differs from this one's velocity by a relative RMS error of 2.5e-6
//! (water) to 1.3e-4 (dirt, whose low modes ring longest), measured by
//! `single_precision_banks_error_per_material` in the library's tests. The banks stay in f64
//! all the same: the contact solve reads the displacement to a few ulps of f64 (its energy
//! bookkeeping is tested to 1e-12), the free loop's cost is the latency of one multiply and
//! add per sample rather than its width for the few modes of most slots, and the targets of
//! issue 33 for the aggregate were met without it.
//!
//! # Files
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the bank: impulse invariance, tuning, the sample-by-sample loop, its energy |
//! | `mode.rs` | a [`SurfaceMode`] and the decay cap every mode is played with ([`LONGEST_DECAY`]) |
//! | `free.rs` | the loops an [`Impact`](super::Impact) runs: free ringing in vector lanes, the contact's delayed impulse |
//! | `cull.rs` | culling modes that have died away (set to exactly zero and skipped until an impulse, retune or reset restores them) |
//! | `sos.rs` | the bank as second-order sections ([`ResonatorBank::to_sos`]) |
//! | `tests.rs` | the tests |

mod cull;
mod free;
mod mode;
mod sos;

pub use mode::{LONGEST_DECAY, SurfaceMode};

use num_complex::Complex64;

use super::PhysicalError;
use crate::units::SampleRate;

/// The highest frequency [`ResonatorBank::retune`] moves a mode to, as a fraction of the
/// sample rate.
const RETUNE_CEILING: f64 = 0.49;

/// A bank of damped modes running in parallel, one complex one-pole each.
///
/// Allocates at construction only; [`tick`](Self::tick) and
/// [`process_in_place`](Self::process_in_place) never allocate.
#[derive(Debug, Clone, PartialEq)]
pub struct ResonatorBank {
    rate: SampleRate,
    modes: Vec<SurfaceMode>,
    /// The factor applied to every frequency of `modes` (see [`ResonatorBank::retune`]).
    scale: f64,
    pole: Vec<Complex64>,
    /// `g_k`, to read the displacement from the state.
    gain: Vec<f64>,
    /// `g_k s_k`: the velocity, from the state.
    gain_slope: Vec<Complex64>,
    /// The state and the coefficients the loops run on, one array per real number, each
    /// padded with silent modes to a whole number of vector lanes (see `free.rs`); boxed,
    /// so that a bank (and a `Surface`) stays small to move.
    lanes: Box<Lanes>,
    /// `h[1]`: the displacement one sample after a unit impulse.
    first_sample: f64,
    /// The modes still computed are the first `live` of the per-mode arrays; the others
    /// were culled ([`cull`](Self::cull)) and their state is exactly zero.
    live: usize,
    /// Which mode of `modes` each position of the per-mode arrays holds: the identity
    /// unless modes were culled (culling swaps the live ones to the front).
    order: Vec<usize>,
}

impl ResonatorBank {
    /// A bank of `modes` running at `rate`, at rest.
    ///
    /// # Errors
    /// No modes, a zero rate, a frequency outside `(0, f_s/2)`, a decay time that is not
    /// positive and finite, or a gain that is not finite.
    pub fn new(modes: &[SurfaceMode], rate: SampleRate) -> Result<Self, PhysicalError> {
        if rate.0 == 0 {
            return Err(PhysicalError::ZeroRate);
        }
        if modes.is_empty() {
            return Err(PhysicalError::NoModes);
        }
        for (index, m) in modes.iter().enumerate() {
            m.check(index, rate.nyquist())?;
        }
        let zero = Complex64::new(0.0, 0.0);
        let mut bank = Self {
            rate,
            modes: modes.to_vec(),
            scale: 1.0,
            pole: vec![zero; modes.len()],
            gain: modes.iter().map(|m| m.gain.abs()).collect(),
            gain_slope: vec![zero; modes.len()],
            lanes: Box::new(Lanes::new(modes.len())),
            first_sample: 0.0,
            live: modes.len(),
            order: (0..modes.len()).collect(),
        };
        bank.tune();
        Ok(bank)
    }

    /// Recomputes every coefficient from the modes and the frequency scale, in place.
    fn tune(&mut self) {
        self.restore();
        let fs = self.rate.hz();
        let ceiling = RETUNE_CEILING * fs;
        self.first_sample = 0.0;
        for (k, m) in self.modes.iter().enumerate() {
            let f = (m.frequency.0 * self.scale).min(ceiling);
            // The cap applies here, where every physical model is played, so a bank built
            // in code is held to it as a loaded one is.
            let slope = Complex64::new(-1.0 / m.played_decay().0, std::f64::consts::TAU * f);
            let pole = (slope / fs).exp();
            self.pole[k] = pole;
            // The contact sees the driving-point gain |g|; the output, the signed one.
            let g = m.gain.abs();
            self.gain_slope[k] = slope * m.gain;
            self.first_sample += g * pole.im;
            self.lanes.set_coefficients(k, pole, g, self.gain_slope[k]);
        }
    }

    /// Moves every mode to `frequency_scale` times its frequency as given, keeping its
    /// decay time and gain and the bank's state (the displacement does not jump; the
    /// ringing carries on at the new pitch). Scales are absolute, not cumulative:
    /// `retune(1.0)` restores the modes as given.
    ///
    /// A frequency pushed to or past the Nyquist frequency cannot be represented; it is
    /// clamped to `0.49 f_s`, where the pole is still complex so the mode still rings
    /// (and `h[1]` stays positive for non-negative gains, which [`Impact`] relies on).
    ///
    /// Real time: no allocation, one complex exponential per mode.
    ///
    /// # Errors
    /// [`PhysicalError::InvalidParameter`] when the scale is not positive and finite; the
    /// bank is left as it was.
    ///
    /// [`Impact`]: super::Impact
    pub fn retune(&mut self, frequency_scale: f64) -> Result<(), PhysicalError> {
        if !(frequency_scale.is_finite() && frequency_scale > 0.0) {
            return Err(PhysicalError::InvalidParameter {
                name: "frequency_scale",
                value: frequency_scale,
                expected: "positive and finite",
            });
        }
        self.scale = frequency_scale;
        self.tune();
        Ok(())
    }

    /// The scale set by [`retune`](Self::retune) (1 when built).
    #[must_use]
    pub fn frequency_scale(&self) -> f64 {
        self.scale
    }

    /// The rate the bank runs at.
    #[must_use]
    pub fn rate(&self) -> SampleRate {
        self.rate
    }

    /// The modes, as given.
    #[must_use]
    pub fn modes(&self) -> &[SurfaceMode] {
        &self.modes
    }

    /// The discrete poles `p_k`, one per mode (the member of each conjugate pair with
    /// positive imaginary part).
    /// In the modes' order, except while modes are culled (see `cull`).
    #[must_use]
    pub fn poles(&self) -> &[Complex64] {
        &self.pole
    }

    /// Reserves room for `modes` modes, so that [`assign_from`](Self::assign_from) a bank
    /// of up to that many never allocates.
    pub fn reserve(&mut self, modes: usize) {
        let more = modes.saturating_sub(self.modes.len());
        self.modes.reserve_exact(more);
        self.pole.reserve_exact(more);
        self.gain.reserve_exact(more);
        self.gain_slope.reserve_exact(more);
        self.lanes.reserve(modes);
        self.order.reserve_exact(more);
    }

    /// Becomes a copy of `other`, state included, reusing this bank's buffers: no
    /// allocation when `other` has no more modes than this bank has room for (see
    /// [`reserve`](Self::reserve)).
    pub fn assign_from(&mut self, other: &ResonatorBank) {
        fn copy<T: Copy>(to: &mut Vec<T>, from: &[T]) {
            to.clear();
            to.extend_from_slice(from);
        }
        self.rate = other.rate;
        self.scale = other.scale;
        self.first_sample = other.first_sample;
        self.live = other.live;
        copy(&mut self.order, &other.order);
        copy(&mut self.modes, &other.modes);
        copy(&mut self.pole, &other.pole);
        copy(&mut self.gain, &other.gain);
        copy(&mut self.gain_slope, &other.gain_slope);
        self.lanes.assign_from(&other.lanes);
    }

    /// Brings the bank to rest.
    pub fn reset(&mut self) {
        self.lanes.zr.fill(0.0);
        self.lanes.zi.fill(0.0);
        self.restore();
    }
    /// The displacement `y[n]` now, before this sample's input.
    #[must_use]
    pub fn displacement(&self) -> f64 {
        let l = &self.lanes;
        l.zi[..self.live]
            .iter()
            .zip(&l.g)
            .map(|(zi, g)| g * zi)
            .sum()
    }

    /// The velocity `ẏ[n]` now, before this sample's input (metres per second when the
    /// gains are in metres per newton-second).
    #[must_use]
    pub fn velocity(&self) -> f64 {
        let l = &self.lanes;
        (0..self.live)
            .map(|k| l.sr[k] * l.zi[k] + l.si[k] * l.zr[k])
            .sum()
    }

    /// Returns the displacement `y[n]`, then takes the impulse `J[n]` (N·s) of this
    /// sample and advances by one sample.
    pub fn tick(&mut self, impulse: f64) -> f64 {
        if impulse != 0.0 && self.live < self.modes.len() {
            self.restore();
        }
        let mut y = 0.0;
        let l = &mut self.lanes;
        for k in 0..self.live {
            y += l.g[k] * l.zi[k];
            // z <- p (z + J)
            let (re, im) = (l.zr[k] + impulse, l.zi[k]);
            l.zr[k] = l.pr[k] * re - l.pi[k] * im;
            l.zi[k] = l.pr[k] * im + l.pi[k] * re;
        }
        y
    }

    /// Runs a block: each sample of `buffer` is an impulse in, replaced by the
    /// displacement out (as [`tick`](Self::tick)).
    pub fn process_in_place(&mut self, buffer: &mut [f64]) {
        for v in buffer.iter_mut() {
            *v = self.tick(*v);
        }
    }

    /// The first `n` samples of the impulse response `h[n]`, from rest, leaving this
    /// bank's state untouched.
    #[must_use]
    pub fn impulse_response(&self, n: usize) -> Vec<f64> {
        let mut bank = self.clone();
        bank.reset();
        let mut x = vec![0.0; n];
        if let Some(first) = x.first_mut() {
            *first = 1.0;
        }
        bank.process_in_place(&mut x);
        x
    }

    /// The vibrational energy the bank holds, `Σ ½ ω_k g_k |z_k|²` (joules when the gains
    /// are in m/(N·s)).
    ///
    /// A mode of modal mass `m_k = 1/(ω_k g_k)` set moving by an impulse `J` holds
    /// `J²/(2 m_k)`; `|z_k|` is the amplitude of its impulse-equivalent state, so this is
    /// the energy of the envelope: it decays smoothly as `e^{-2t/τ_k}` without the
    /// twice-per-period exchange between kinetic and potential energy. With `ω_k` at the
    /// current tuning.
    #[must_use]
    pub fn energy(&self) -> f64 {
        (0..self.live)
            .map(|k| self.lanes.mode_energy(k))
            .sum::<f64>()
    }
}

/// The state and coefficients of a bank as a struct of arrays: `z_k = zr[k] + i zi[k]`,
/// `p_k = pr[k] + i pi[k]`, `|g_k| = g[k]`, `g_k s_k = sr[k] + i si[k]`, in the order of
/// the bank's per-mode arrays, each padded with zeros to a whole number of lanes (a
/// padded mode has zero state and coefficients: it stays zero and adds zero).
#[derive(Debug, Clone, PartialEq, Default)]
struct Lanes {
    zr: Vec<f64>,
    zi: Vec<f64>,
    pr: Vec<f64>,
    pi: Vec<f64>,
    g: Vec<f64>,
    sr: Vec<f64>,
    si: Vec<f64>,
}

impl Lanes {
    fn new(modes: usize) -> Self {
        let n = free::padded(modes);
        let zero = vec![0.0; n];
        Self {
            zr: zero.clone(),
            zi: zero.clone(),
            pr: zero.clone(),
            pi: zero.clone(),
            g: zero.clone(),
            sr: zero.clone(),
            si: zero,
        }
    }

    fn arrays_mut(&mut self) -> [&mut Vec<f64>; 7] {
        [
            &mut self.zr,
            &mut self.zi,
            &mut self.pr,
            &mut self.pi,
            &mut self.g,
            &mut self.sr,
            &mut self.si,
        ]
    }

    fn set_coefficients(&mut self, k: usize, pole: Complex64, g: f64, gain_slope: Complex64) {
        self.pr[k] = pole.re;
        self.pi[k] = pole.im;
        self.g[k] = g;
        self.sr[k] = gain_slope.re;
        self.si[k] = gain_slope.im;
    }

    fn reserve(&mut self, modes: usize) {
        let n = free::padded(modes);
        for a in self.arrays_mut() {
            a.reserve_exact(n.saturating_sub(a.len()));
        }
    }

    fn assign_from(&mut self, other: &Lanes) {
        for (to, from) in self.arrays_mut().into_iter().zip([
            &other.zr, &other.zi, &other.pr, &other.pi, &other.g, &other.sr, &other.si,
        ]) {
            to.clear();
            to.extend_from_slice(from);
        }
    }

    fn swap(&mut self, a: usize, b: usize) {
        for v in self.arrays_mut() {
            v.swap(a, b);
        }
    }

    /// `½ ω_k |g_k| |z_k|²`.
    fn mode_energy(&self, k: usize) -> f64 {
        0.5 * self.si[k].abs() * (self.zr[k] * self.zr[k] + self.zi[k] * self.zi[k])
    }

    /// `z_k` as a complex number.
    #[cfg(test)]
    fn state(&self, k: usize) -> Complex64 {
        Complex64::new(self.zr[k], self.zi[k])
    }
}

#[cfg(test)]
impl ResonatorBank {
    /// The state of each mode, in the per-mode arrays' order.
    fn state(&self) -> Vec<Complex64> {
        (0..self.modes.len()).map(|k| self.lanes.state(k)).collect()
    }
}

#[cfg(test)]
mod tests;
