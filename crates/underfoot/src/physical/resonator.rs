//! A surface as a bank of damped modes, discretised by impulse invariance.
//!
//! # The continuous model
//!
//! Struck at one point, a linear surface moves there as a sum of independent modes. Mode
//! `k` is a damped oscillator of modal mass `m_k`; a force impulse of `J` newton-seconds
//! at `t = 0` sets its velocity to `J / m_k` and leaves it ringing as
//!
//! $$ y_k(t) = g_k\, J\, e^{-t/\tau_k} \sin(2\pi f_k t), \qquad g_k = \frac{1}{2\pi f_k m_k}, $$
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
//! $$ h\[n\] = \sum_k g_k \operatorname{Im} p_k^n , $$
//!
//! so the sampled response passes through the continuous one at every sample: each mode's
//! frequency and decay are exact at any rate, not warped as a bilinear transform would
//! warp them. Each sample of input is taken as the impulse `J[n]` (N·s) delivered during
//! that sample, at its start. One complex one-pole per mode runs it:
//!
//! $$ z_k\[n+1\] = p_k \left(z_k\[n\] + J\[n\]\right), \qquad
//!    y\[n\] = \sum_k g_k \operatorname{Im} z_k\[n\], \qquad
//!    \dot y\[n\] = \sum_k \operatorname{Im}\left(g_k s_k z_k\[n\]\right). $$
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
//! # Second-order sections
//!
//! Mode `k` alone is the section `g_k r_k \sin θ_k z^{-1} / (1 - 2 r_k \cos θ_k z^{-1} + r_k^2 z^{-2})`
//! (`p_k = r_k e^{iθ_k}`). The bank is their sum; [`ResonatorBank::to_sos`] brings it
//! over a common denominator and factors the numerator, giving a cascade with the same
//! impulse response, for firmware and interchange. The poles are kept exactly as
//! computed; only the zeros come from a root finder, whose accuracy falls as the number
//! of modes grows (the numerator has degree `2K - 1`). For real-time use, the parallel
//! form here is both cheaper and exact.
//!
//! # Culling
//!
//! Without input each mode only decays (`|p_k| < 1`), so once a mode's share of the
//! energy, `½ ω_k |g_k| |z_k|²`, is negligible it stays negligible: a caller that knows
//! the scale of what matters (an [`Aggregate`](super::Aggregate) voice, from its peak
//! energy) may cull it (`ResonatorBank::cull`): its state is set to exactly zero and
//! every loop skips it. The live modes are kept at the front of the per-mode arrays (a
//! culled one is swapped with the last live one), so the loops run over one contiguous
//! prefix with the arithmetic of each live mode unchanged. Any impulse, retune or reset
//! restores all the modes (at rest, as they were culled) and the modes' order. Culling
//! is a decision, so it must be taken on a sample clock of the caller's, never at a block
//! boundary, to keep the output independent of the block size.

use num_complex::Complex64;

use super::PhysicalError;
use crate::signal::{Biquad, Sos};
use crate::units::{Hz, SampleRate, Seconds};

/// The longest e-fold decay a mode plays, the physical counterpart of the IIR voice's
/// [`VoiceConfig::longest_decay`](crate::synthesis::VoiceConfig::longest_decay) and the
/// calibration's `max_decay` (both 0.5 s): no ground rings for seconds, and an actuator on
/// skin must not. A library refuses a stored mode beyond it
/// ([`PhysicalModel::validate`](super::PhysicalModel::validate)); a bank built in code
/// plays any longer mode at this decay ([`Mode::played_decay`]).
pub const LONGEST_DECAY: Seconds = Seconds(0.5);

/// One damped mode of a surface at the point struck.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mode {
    /// The (damped) frequency of the ringing.
    pub frequency: Hz,
    /// The time for the ringing's envelope to decay by a factor `e`.
    pub decay: Seconds,
    /// Displacement per unit impulse, in metres per newton-second: `1 / (2π f m)` for a
    /// mode of modal mass `m` at the point struck. Its magnitude is the driving-point gain
    /// the contact sees; its sign is the mode shape's at the point the vibration is felt
    /// relative to the point struck (see the module documentation).
    pub gain: f64,
}

impl Mode {
    /// The decay the mode is played with: its own, at most [`LONGEST_DECAY`].
    #[must_use]
    pub fn played_decay(&self) -> Seconds {
        Seconds(self.decay.0.min(LONGEST_DECAY.0))
    }

    /// Checks mode `index`: a frequency in `(0, below)`, a positive and finite decay time,
    /// a finite gain.
    ///
    /// # Errors
    /// [`PhysicalError::FrequencyOutOfRange`], [`PhysicalError::BadDecay`] or
    /// [`PhysicalError::BadGain`].
    pub fn check(&self, index: usize, below: Hz) -> Result<(), PhysicalError> {
        let f = self.frequency.0;
        if !(f.is_finite() && f > 0.0 && f < below.0) {
            return Err(PhysicalError::FrequencyOutOfRange {
                index,
                frequency: self.frequency,
                nyquist: below,
            });
        }
        if !(self.decay.0.is_finite() && self.decay.0 > 0.0) {
            return Err(PhysicalError::BadDecay {
                index,
                decay: self.decay,
            });
        }
        if !self.gain.is_finite() {
            return Err(PhysicalError::BadGain {
                index,
                gain: self.gain,
            });
        }
        Ok(())
    }
}

/// The highest frequency [`ResonatorBank::retune`] moves a mode to, as a fraction of the
/// sample rate.
const RETUNE_CEILING: f64 = 0.49;

/// Modes summed side by side in the free loop.
const LANES: usize = 4;

/// The most live modes the free loop copies to arrays on the stack to run them as vectors.
const SOA_MODES: usize = 64;

/// A bank of damped modes running in parallel, one complex one-pole each.
///
/// Allocates at construction only; [`tick`](Self::tick) and
/// [`process_in_place`](Self::process_in_place) never allocate.
#[derive(Debug, Clone, PartialEq)]
pub struct ResonatorBank {
    rate: SampleRate,
    modes: Vec<Mode>,
    /// The factor applied to every frequency of `modes` (see [`ResonatorBank::retune`]).
    scale: f64,
    pole: Vec<Complex64>,
    /// `g_k`, to read the displacement from the state.
    gain: Vec<f64>,
    /// `g_k p_k`: the displacement one sample ahead, from the state before the input.
    gain_pole: Vec<Complex64>,
    /// `g_k s_k`: the velocity, from the state.
    gain_slope: Vec<Complex64>,
    state: Vec<Complex64>,
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
    pub fn new(modes: &[Mode], rate: SampleRate) -> Result<Self, PhysicalError> {
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
            gain_pole: vec![zero; modes.len()],
            gain_slope: vec![zero; modes.len()],
            state: vec![zero; modes.len()],
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
            self.gain_pole[k] = pole * g;
            self.gain_slope[k] = slope * m.gain;
            self.first_sample += g * pole.im;
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
    pub fn modes(&self) -> &[Mode] {
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
        self.gain_pole.reserve_exact(more);
        self.gain_slope.reserve_exact(more);
        self.state.reserve_exact(more);
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
        copy(&mut self.gain_pole, &other.gain_pole);
        copy(&mut self.gain_slope, &other.gain_slope);
        copy(&mut self.state, &other.state);
    }

    /// Brings the bank to rest.
    pub fn reset(&mut self) {
        self.state.fill(Complex64::new(0.0, 0.0));
        self.restore();
    }

    /// Culls every live mode whose energy `½ ω_k |g_k| |z_k|²` (its share of
    /// [`energy`](Self::energy)) is at most `floor`: its state is set to exactly zero and
    /// the free loops skip it until [`restore`](Self::restore) (which a retune, a reset or
    /// an impulse bring). Each mode only decays without input, so a culled mode would
    /// have stayed at most that small. The live modes are swapped to the front of the
    /// per-mode arrays; their own arithmetic is unchanged.
    ///
    /// Real time: no allocation, one pass over the live modes.
    pub(crate) fn cull(&mut self, floor: f64) {
        let mut k = 0;
        while k < self.live {
            let energy = 0.5 * self.gain_slope[k].im.abs() * self.state[k].norm_sqr();
            if energy <= floor {
                self.state[k] = Complex64::new(0.0, 0.0);
                self.live -= 1;
                self.swap(k, self.live);
            } else {
                k += 1;
            }
        }
    }

    /// Brings every culled mode back into the loops (at rest, as it was culled) and the
    /// per-mode arrays back to the modes' order. Real time: at most one swap per mode.
    pub(crate) fn restore(&mut self) {
        self.live = self.modes.len();
        for k in 0..self.order.len() {
            while self.order[k] != k {
                let j = self.order[k];
                self.swap(k, j);
            }
        }
    }

    /// The number of modes computed (not culled).
    #[must_use]
    #[cfg(test)]
    pub(crate) fn live_modes(&self) -> usize {
        self.live
    }

    fn swap(&mut self, a: usize, b: usize) {
        self.pole.swap(a, b);
        self.gain.swap(a, b);
        self.gain_pole.swap(a, b);
        self.gain_slope.swap(a, b);
        self.state.swap(a, b);
        self.order.swap(a, b);
    }

    /// The displacement `y[n]` now, before this sample's input.
    #[must_use]
    pub fn displacement(&self) -> f64 {
        self.state[..self.live]
            .iter()
            .zip(&self.gain)
            .map(|(z, g)| g * z.im)
            .sum()
    }

    /// The velocity `ẏ[n]` now, before this sample's input (metres per second when the
    /// gains are in metres per newton-second).
    #[must_use]
    pub fn velocity(&self) -> f64 {
        self.state[..self.live]
            .iter()
            .zip(&self.gain_slope)
            .map(|(z, gs)| gs.re * z.im + gs.im * z.re)
            .sum()
    }

    /// Returns the displacement `y[n]`, then takes the impulse `J[n]` (N·s) of this
    /// sample and advances by one sample.
    pub fn tick(&mut self, impulse: f64) -> f64 {
        if impulse != 0.0 && self.live < self.modes.len() {
            self.restore();
        }
        let mut y = 0.0;
        for ((z, p), g) in self.state[..self.live]
            .iter_mut()
            .zip(&self.pole)
            .zip(&self.gain)
        {
            y += g * z.im;
            *z = p * (*z + impulse);
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
        0.5 * self.state[..self.live]
            .iter()
            .zip(&self.gain_slope)
            .map(|(z, gs)| gs.im.abs() * z.norm_sqr())
            .sum::<f64>()
    }

    /// Advances one sample with no impulse and returns the velocity before the step and
    /// the displacement after it: [`velocity`](Self::velocity), `tick(0.0)` and
    /// [`displacement`](Self::displacement) in one pass over the modes.
    /// [`add_delayed_impulse`](Self::add_delayed_impulse) then adds the step's impulse.
    pub(crate) fn advance_free(&mut self) -> (f64, f64) {
        let (mut velocity, mut displacement) = (0.0, 0.0);
        for (((z, p), g), gs) in self.state[..self.live]
            .iter_mut()
            .zip(&self.pole)
            .zip(&self.gain)
            .zip(&self.gain_slope)
        {
            velocity += gs.re * z.im + gs.im * z.re;
            *z *= p;
            displacement += g * z.im;
        }
        (velocity, displacement)
    }

    /// Rings freely over `out`, adding the velocity of each sample to it (as
    /// [`velocity`](Self::velocity) then `tick(0.0)`, sample by sample).
    pub(crate) fn add_free_velocity(&mut self, out: &mut [f32]) {
        let live = self.live;
        if live > SOA_MODES {
            self.add_free_velocity_aos(out);
            return;
        }
        // The live modes go into separate arrays of real and imaginary parts (a struct of
        // arrays, on the stack), padded with silent modes to a whole number of lanes, so
        // that the compiler can run the lanes of the sample loop as vector operations.
        // The arithmetic of each mode is that of the complex loop.
        let padded = live.div_ceil(LANES) * LANES;
        let mut zr = [0.0; SOA_MODES];
        let mut zi = [0.0; SOA_MODES];
        let mut pr = [0.0; SOA_MODES];
        let mut pi = [0.0; SOA_MODES];
        let mut sr = [0.0; SOA_MODES];
        let mut si = [0.0; SOA_MODES];
        for k in 0..live {
            zr[k] = self.state[k].re;
            zi[k] = self.state[k].im;
            pr[k] = self.pole[k].re;
            pi[k] = self.pole[k].im;
            sr[k] = self.gain_slope[k].re;
            si[k] = self.gain_slope[k].im;
        }
        let (zr, zi) = (&mut zr[..padded], &mut zi[..padded]);
        let (pr, pi, sr, si) = (&pr[..padded], &pi[..padded], &sr[..padded], &si[..padded]);
        for o in out.iter_mut() {
            let mut lanes = [0.0; LANES];
            for ((((zr, zi), pr), pi), (sr, si)) in zr
                .chunks_exact_mut(LANES)
                .zip(zi.chunks_exact_mut(LANES))
                .zip(pr.chunks_exact(LANES))
                .zip(pi.chunks_exact(LANES))
                .zip(sr.chunks_exact(LANES).zip(si.chunks_exact(LANES)))
            {
                for l in 0..LANES {
                    lanes[l] += sr[l] * zi[l] + si[l] * zr[l];
                    let re = zr[l] * pr[l] - zi[l] * pi[l];
                    zi[l] = zr[l] * pi[l] + zi[l] * pr[l];
                    zr[l] = re;
                }
            }
            *o += ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3])) as f32;
        }
        for (k, z) in self.state[..live].iter_mut().enumerate() {
            *z = Complex64::new(zr[k], zi[k]);
        }
    }

    /// [`add_free_velocity`](Self::add_free_velocity) for banks of more than
    /// [`SOA_MODES`] live modes, on the complex arrays in place.
    fn add_free_velocity_aos(&mut self, out: &mut [f32]) {
        // Modes go four at a time into separate partial sums, so that a sample's sum is
        // not one long chain of additions. Every sample is computed the same way wherever
        // a block starts or ends, which keeps the engine's output independent of its
        // block size, bit for bit.
        let live = self.live;
        let split = live / LANES * LANES;
        let (state, state_tail) = self.state[..live].split_at_mut(split);
        let (pole, pole_tail) = self.pole.split_at(split);
        let (slope, slope_tail) = self.gain_slope.split_at(split);
        for o in out.iter_mut() {
            let mut lanes = [0.0; LANES];
            for ((z, p), gs) in state
                .chunks_exact_mut(LANES)
                .zip(pole.chunks_exact(LANES))
                .zip(slope.chunks_exact(LANES))
            {
                for l in 0..LANES {
                    lanes[l] += gs[l].re * z[l].im + gs[l].im * z[l].re;
                    z[l] *= p[l];
                }
            }
            let mut velocity = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
            for ((z, p), gs) in state_tail
                .iter_mut()
                .zip(&pole_tail[..live - split])
                .zip(slope_tail)
            {
                velocity += gs.re * z.im + gs.im * z.re;
                *z *= p;
            }
            *o += velocity as f32;
        }
    }

    /// `Σ |g_k| |z_k|`: no displacement, now or later without input, exceeds it in size
    /// (each `|z_k|` only decays).
    pub(crate) fn amplitude_bound(&self) -> f64 {
        self.state[..self.live]
            .iter()
            .zip(&self.gain)
            .map(|(z, g)| g.abs() * z.norm())
            .sum()
    }

    /// Adds the impulse `J` (N·s) of the sample just advanced by
    /// [`advance_free`](Self::advance_free): `z_k += p_k J`, so that together they are
    /// `z_k ← p_k (z_k + J)` as in [`tick`](Self::tick), and the displacement grows by
    /// `h[1] J`.
    pub(crate) fn add_delayed_impulse(&mut self, impulse: f64) {
        if impulse != 0.0 && self.live < self.modes.len() {
            self.restore();
        }
        for (z, p) in self.state[..self.live].iter_mut().zip(&self.pole) {
            *z += p * impulse;
        }
    }

    /// `h[1]`: how much the next displacement moves per unit impulse now.
    pub(crate) fn first_sample_gain(&self) -> f64 {
        self.first_sample
    }

    /// The bank as a cascade of second-order sections with the same impulse response.
    ///
    /// # Errors
    /// [`PhysicalError::Factorisation`] when the numerator cannot be factored: its leading
    /// coefficient `h[1]` is zero (gains that cancel), or the root finder fails.
    pub fn to_sos(&self) -> Result<Sos, PhysicalError> {
        let denominators: Vec<[f64; 3]> = self
            .pole
            .iter()
            .map(|p| [1.0, -2.0 * p.re, p.norm_sqr()])
            .collect();
        // H(w) = w N(w) / Π A_j(w) with N(w) = Σ_k g_k Im(p_k) Π_{j≠k} A_j(w), w = z^-1.
        let mut numerator = vec![0.0; 2 * self.pole.len() - 1];
        for (k, (p, g)) in self.pole.iter().zip(&self.gain).enumerate() {
            let mut term = vec![g * p.im];
            for (j, a) in denominators.iter().enumerate() {
                if j != k {
                    term = crate::signal::sos::poly_mul(&term, a);
                }
            }
            for (n, t) in numerator.iter_mut().zip(&term) {
                *n += t;
            }
        }
        let lead = numerator[0];
        if lead == 0.0 || !lead.is_finite() {
            return Err(PhysicalError::Factorisation(
                "the first sample of the impulse response is zero",
            ));
        }
        let zeros = crate::numeric::roots(&numerator).ok_or(PhysicalError::Factorisation(
            "the root finder did not converge",
        ))?;
        let mut sections = crate::signal::zpk::sections_from_roots(&zeros, &self.pole, lead);
        // The numerator has one degree fewer than the denominator: the z^-1 of h[0] = 0.
        // It goes into a section with a spare numerator degree.
        let spare = sections
            .iter_mut()
            .filter(|s| s.b[2] == 0.0)
            .min_by_key(|s| usize::from(s.b[1] != 0.0))
            .ok_or(PhysicalError::Factorisation(
                "no section can take the delay",
            ))?;
        *spare = Biquad {
            b: [0.0, spare.b[0], spare.b[1]],
            a: spare.a,
        };
        Ok(Sos::new(sections))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    fn three_modes() -> [Mode; 3] {
        [
            Mode {
                frequency: Hz(60.0),
                decay: Seconds(0.2),
                gain: 1.0,
            },
            Mode {
                frequency: Hz(250.0),
                decay: Seconds(0.08),
                gain: 0.5,
            },
            Mode {
                frequency: Hz(1200.0),
                decay: Seconds(0.03),
                gain: 0.2,
            },
        ]
    }

    /// Prony's method: the modes of a sum of damped sinusoids from its samples alone, by
    /// the least-squares linear recursion `y[n] = -Σ a_i y[n-i]` and its roots.
    fn prony(y: &[f64], modes: usize, rate: SampleRate) -> Vec<(f64, f64)> {
        let order = 2 * modes;
        let rows = y.len() - order;
        let m = DMatrix::from_fn(rows, order, |r, c| y[r + order - 1 - c]);
        let rhs = DVector::from_fn(rows, |r, _| -y[r + order]);
        let a = m.svd(true, true).solve(&rhs, 1e-300).unwrap();
        let mut poly = vec![1.0];
        poly.extend(a.iter());
        let mut found: Vec<(f64, f64)> = crate::numeric::roots(&poly)
            .unwrap()
            .into_iter()
            .filter(|p| p.im > 0.0)
            .map(|p| {
                (
                    p.arg() * rate.hz() / std::f64::consts::TAU,
                    -1.0 / (rate.hz() * p.norm().ln()),
                )
            })
            .collect();
        found.sort_by(|a, b| a.0.total_cmp(&b.0));
        found
    }

    #[test]
    fn impulse_response_has_the_requested_frequencies_and_decays() {
        for rate in [SampleRate(48_000), SampleRate(8_000)] {
            let bank = ResonatorBank::new(&three_modes(), rate).unwrap();
            // Long enough for the slowest mode, short of the fastest one's underflow.
            let h = bank.impulse_response(rate.samples_in(Seconds(0.5)));
            let found = prony(&h, 3, rate);
            assert_eq!(found.len(), 3, "at {rate}");
            for (m, (f, tau)) in three_modes().iter().zip(&found) {
                let df = (f / m.frequency.0 - 1.0).abs();
                let dtau = (tau / m.decay.0 - 1.0).abs();
                eprintln!(
                    "{rate}: {} -> f err {df:.2e}, tau err {dtau:.2e}",
                    m.frequency
                );
                assert!(
                    df < 0.01 && dtau < 0.01,
                    "{rate}: {m:?} measured {f} Hz, {tau} s"
                );
            }
        }
    }

    #[test]
    fn one_mode_zero_crossings_and_log_envelope() {
        for rate in [SampleRate(48_000), SampleRate(8_000)] {
            for m in three_modes() {
                let bank = ResonatorBank::new(&[m], rate).unwrap();
                let h = bank.impulse_response(rate.samples_in(Seconds(4.0 * m.decay.0)));
                // Upward zero crossings, interpolated: one per period.
                let ups: Vec<f64> = (1..h.len())
                    .filter(|&n| h[n - 1] < 0.0 && h[n] >= 0.0)
                    .map(|n| (n - 1) as f64 + h[n - 1] / (h[n - 1] - h[n]))
                    .collect();
                let periods = (ups.len() - 1) as f64;
                let f = periods * rate.hz() / (ups[ups.len() - 1] - ups[0]);
                // Log-envelope: the RMS over each whole period falls as e^{-t/tau}; the
                // slope of its logarithm, by least squares, is -1/tau.
                let (mut t, mut l) = (Vec::new(), Vec::new());
                for w in ups.windows(2) {
                    let (a, b) = (w[0].ceil() as usize, w[1].ceil() as usize);
                    let ms: f64 = h[a..b].iter().map(|v| v * v).sum::<f64>() / (b - a) as f64;
                    t.push(0.5 * (w[0] + w[1]) / rate.hz());
                    l.push(0.5 * ms.ln());
                }
                let n = t.len() as f64;
                let (mt, ml) = (t.iter().sum::<f64>() / n, l.iter().sum::<f64>() / n);
                let slope = t
                    .iter()
                    .zip(&l)
                    .map(|(a, b)| (a - mt) * (b - ml))
                    .sum::<f64>()
                    / t.iter().map(|a| (a - mt).powi(2)).sum::<f64>();
                let tau = -1.0 / slope;
                let df = (f / m.frequency.0 - 1.0).abs();
                let dtau = (tau / m.decay.0 - 1.0).abs();
                eprintln!(
                    "{rate}: {} -> crossings f err {df:.2e}, envelope tau err {dtau:.2e}",
                    m.frequency
                );
                assert!(df < 0.01, "{rate}: {m:?} measured {f} Hz");
                assert!(dtau < 0.01, "{rate}: {m:?} measured {tau} s");
            }
        }
    }

    #[test]
    fn sections_give_the_same_impulse_response() {
        for rate in [SampleRate(48_000), SampleRate(8_000)] {
            let bank = ResonatorBank::new(&three_modes(), rate).unwrap();
            let sos = bank.to_sos().unwrap();
            assert!(sos.is_stable());
            assert_eq!(sos.sections.len(), 3);
            let n = rate.samples_in(Seconds(0.3));
            let a = bank.impulse_response(n);
            let b = sos.impulse_response(n);
            let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let err = a
                .iter()
                .zip(&b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            eprintln!("{rate}: sos max error {:.2e} of peak", err / peak);
            assert!(err < 1e-8 * peak, "{rate}: {err} against {peak}");
        }
    }

    #[test]
    fn tick_and_block_agree_and_velocity_is_the_derivative() {
        let rate = SampleRate(48_000);
        let mut a = ResonatorBank::new(&three_modes(), rate).unwrap();
        let mut b = a.clone();
        let mut x: Vec<f64> = (0..500).map(|n| ((n * 7919) % 13) as f64 - 6.0).collect();
        let ticked: Vec<f64> = x.iter().map(|&v| a.tick(v)).collect();
        for chunk in x.chunks_mut(37) {
            b.process_in_place(chunk);
        }
        assert_eq!(ticked, x);
        // After an impulse the bank rings freely: its velocity is the slope of its path.
        let mut c = ResonatorBank::new(&three_modes(), rate).unwrap();
        c.tick(1.0);
        for _ in 0..100 {
            c.tick(0.0);
        }
        let (y0, v0) = (c.displacement(), c.velocity());
        let y1 = c.tick(0.0);
        let _ = y1;
        let y2 = c.displacement();
        let slope = (y2 - y0) * rate.hz();
        assert!(
            (slope - v0).abs() < 0.02 * v0.abs().max(1e-3),
            "{slope} vs {v0}"
        );
    }

    #[test]
    fn retune_gives_exact_frequencies_and_keeps_the_state() {
        let rate = SampleRate(8000);
        let mut bank = ResonatorBank::new(&three_modes(), rate).unwrap();
        bank.tick(1.0);
        for _ in 0..37 {
            bank.tick(0.0);
        }
        let (y, state) = (bank.displacement(), bank.state.clone());
        let scale = 1.37;
        bank.retune(scale).unwrap();
        assert_eq!(bank.frequency_scale(), scale);
        assert_eq!(bank.state, state);
        assert_eq!(bank.displacement(), y);
        assert_eq!(bank.modes(), three_modes());
        // The same coefficients as a bank built at the scaled frequencies.
        let scaled: Vec<Mode> = three_modes()
            .iter()
            .map(|m| Mode {
                frequency: Hz(m.frequency.0 * scale),
                ..*m
            })
            .collect();
        let fresh = ResonatorBank::new(&scaled, rate).unwrap();
        for (p, q) in bank.poles().iter().zip(fresh.poles()) {
            assert!((p - q).norm() < 1e-14, "{p} vs {q}");
        }
        for (p, m) in bank.poles().iter().zip(&scaled) {
            let f = p.arg() * rate.hz() / std::f64::consts::TAU;
            assert!(
                (f / m.frequency.0 - 1.0).abs() < 1e-12,
                "{f} vs {}",
                m.frequency
            );
        }
        assert!((bank.first_sample_gain() / fresh.first_sample_gain() - 1.0).abs() < 1e-12);
        // And the impulse response's modes are there (Prony).
        let h = bank.impulse_response(rate.samples_in(Seconds(0.5)));
        for (m, (f, tau)) in scaled.iter().zip(prony(&h, 3, rate)) {
            assert!(
                (f / m.frequency.0 - 1.0).abs() < 0.01,
                "{f} vs {}",
                m.frequency
            );
            assert!((tau / m.decay.0 - 1.0).abs() < 0.01, "{tau} vs {}", m.decay);
        }
        // Absolute, not cumulative.
        bank.retune(1.0).unwrap();
        let original = ResonatorBank::new(&three_modes(), rate).unwrap();
        for (p, q) in bank.poles().iter().zip(original.poles()) {
            assert!((p - q).norm() < 1e-15);
        }
    }

    #[test]
    fn retune_clamps_below_nyquist_and_rejects_bad_scales() {
        let rate = SampleRate(8000);
        let mut bank = ResonatorBank::new(&three_modes(), rate).unwrap();
        // 1200 Hz * 4 = 4800 Hz, past Nyquist: clamped to 0.49 f_s = 3920 Hz.
        bank.retune(4.0).unwrap();
        let top = bank.poles()[2];
        let f = top.arg() * rate.hz() / std::f64::consts::TAU;
        assert!((f - 3920.0).abs() < 1e-9, "{f}");
        assert!(top.im > 0.0 && bank.first_sample_gain() > 0.0);
        let before = bank.clone();
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(matches!(
                bank.retune(bad),
                Err(PhysicalError::InvalidParameter { .. })
            ));
        }
        assert_eq!(bank, before);
    }

    #[test]
    fn energy_is_the_modal_kinetic_energy_and_decays() {
        let rate = SampleRate(48_000);
        let m = three_modes()[1];
        let mut bank = ResonatorBank::new(&[m], rate).unwrap();
        let impulse = 0.3;
        bank.tick(impulse);
        // J^2 / (2 m_k) with m_k = 1 / (2π f g).
        let expected = impulse * impulse * std::f64::consts::TAU * m.frequency.0 * m.gain / 2.0;
        let e0 = bank.energy();
        // One sample of decay has passed.
        let decayed = expected * (-2.0 / (m.decay.0 * rate.hz())).exp();
        assert!((e0 / decayed - 1.0).abs() < 1e-12, "{e0} vs {decayed}");
        let n = rate.samples_in(m.decay);
        for _ in 0..n {
            bank.tick(0.0);
        }
        let ratio = bank.energy() / e0;
        let theory = (-2.0 * n as f64 / (m.decay.0 * rate.hz())).exp();
        assert!((ratio / theory - 1.0).abs() < 1e-9, "{ratio} vs {theory}");
    }

    #[test]
    fn the_fused_free_step_matches_tick() {
        let rate = SampleRate(48_000);
        let mut a = ResonatorBank::new(&three_modes(), rate).unwrap();
        let mut b = a.clone();
        for n in 0..300 {
            let j = if n % 50 < 3 { 0.1 * n as f64 } else { 0.0 };
            // The velocity is a sum of large terms that cancel: compare to their size.
            let size: f64 = a
                .state
                .iter()
                .zip(&a.gain_slope)
                .map(|(z, gs)| z.norm() * gs.norm())
                .sum();
            let v = a.velocity();
            a.tick(j);
            let (vb, free) = b.advance_free();
            b.add_delayed_impulse(j);
            assert!((v - vb).abs() <= 1e-12 * size.max(1.0), "{v} vs {vb}");
            let y = b.displacement();
            assert!((free + b.first_sample_gain() * j - y).abs() <= 1e-12 * y.abs().max(1e-9));
            assert!((a.displacement() - y).abs() <= 1e-12 * y.abs().max(1e-9));
        }
    }

    #[test]
    fn the_free_loop_matches_tick_for_any_number_of_modes() {
        let rate = SampleRate(48_000);
        for count in [1, 3, 4, 6, 9] {
            let modes: Vec<Mode> = (0..count)
                .map(|k| Mode {
                    frequency: Hz(70.0 * 1.6f64.powi(k)),
                    decay: Seconds(0.05),
                    gain: 1e-3,
                })
                .collect();
            let mut a = ResonatorBank::new(&modes, rate).unwrap();
            a.tick(0.01);
            let mut b = a.clone();
            let expected: Vec<f32> = (0..201)
                .map(|_| {
                    let v = a.velocity();
                    a.tick(0.0);
                    0.5 + v as f32
                })
                .collect();
            let mut out = vec![0.5f32; 201];
            b.add_free_velocity(&mut out);
            for (x, y) in expected.iter().zip(&out) {
                assert!(
                    (x - y).abs() <= 1e-6 * x.abs().max(1.0),
                    "{count} modes: {x} vs {y}"
                );
            }
            assert!((a.displacement() - b.displacement()).abs() <= 1e-12 * a.amplitude_bound());
        }
    }

    #[test]
    fn culling_drops_only_quiet_modes_and_restoring_brings_them_back() {
        let rate = SampleRate(48_000);
        // Decays from 1 ms to 40 ms: after 20 ms the fastest are far below the slowest.
        let modes: Vec<Mode> = (0..9)
            .map(|k| Mode {
                frequency: Hz(90.0 * 1.5f64.powi(k)),
                decay: Seconds(if k % 3 == 0 {
                    0.04
                } else {
                    0.0005 * (k + 1) as f64
                }),
                gain: 1e-3 / (k + 1) as f64,
            })
            .collect();
        let mut full = ResonatorBank::new(&modes, rate).unwrap();
        full.tick(0.01);
        let mut warm = vec![0.0f32; 960];
        full.add_free_velocity(&mut warm);
        let peak = full.energy();
        let mut culled = full.clone();
        let floor = 1e-12 * peak;
        culled.cull(floor);
        let live = culled.live_modes();
        assert!(live > 0 && live < modes.len(), "{live} live");
        // Every mode kept is above the floor; every mode dropped was at most at it.
        let share =
            |b: &ResonatorBank, k: usize| 0.5 * b.gain_slope[k].im.abs() * b.state[k].norm_sqr();
        assert!((0..live).all(|k| share(&culled, k) > floor));
        assert!(
            culled.state[live..]
                .iter()
                .all(|z| *z == Complex64::new(0.0, 0.0))
        );
        let dropped = full.energy() - culled.energy();
        assert!(dropped >= 0.0 && dropped <= (modes.len() - live) as f64 * floor);
        // The free loop carries on as before, but for the dropped modes' tiny share.
        let (mut a, mut b) = (vec![0.0f32; 2000], vec![0.0f32; 2000]);
        full.add_free_velocity(&mut a);
        culled.add_free_velocity(&mut b);
        let size = a.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let err = a
            .iter()
            .zip(&b)
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
        assert!(err <= 1e-5 * size, "{err} of {size}");
        // A retune (or an impulse) restores every mode, in the modes' order.
        culled.retune(1.0).unwrap();
        assert_eq!(culled.live_modes(), modes.len());
        assert_eq!(
            culled.poles(),
            ResonatorBank::new(&modes, rate).unwrap().poles()
        );
        culled.cull(f64::INFINITY);
        assert_eq!(culled.live_modes(), 0);
        assert_eq!(culled.velocity(), 0.0);
        culled.tick(0.01);
        assert_eq!(culled.live_modes(), modes.len());
        let fresh = ResonatorBank::new(&modes, rate)
            .unwrap()
            .impulse_response(50);
        assert_eq!(culled.impulse_response(50), fresh);
    }

    #[test]
    fn bad_modes_are_errors() {
        let rate = SampleRate(8000);
        let good = three_modes()[0];
        let with = |f: f64, tau: f64, g: f64| {
            ResonatorBank::new(
                &[
                    good,
                    Mode {
                        frequency: Hz(f),
                        decay: Seconds(tau),
                        gain: g,
                    },
                ],
                rate,
            )
        };
        assert!(matches!(
            with(4000.0, 0.1, 1.0),
            Err(PhysicalError::FrequencyOutOfRange { index: 1, .. })
        ));
        assert!(matches!(
            with(0.0, 0.1, 1.0),
            Err(PhysicalError::FrequencyOutOfRange { .. })
        ));
        assert!(matches!(
            with(f64::NAN, 0.1, 1.0),
            Err(PhysicalError::FrequencyOutOfRange { .. })
        ));
        assert!(matches!(
            with(100.0, 0.0, 1.0),
            Err(PhysicalError::BadDecay { .. })
        ));
        assert!(matches!(
            with(100.0, f64::INFINITY, 1.0),
            Err(PhysicalError::BadDecay { .. })
        ));
        assert!(matches!(
            with(100.0, 0.1, f64::NAN),
            Err(PhysicalError::BadGain { .. })
        ));
        assert_eq!(ResonatorBank::new(&[], rate), Err(PhysicalError::NoModes));
        assert_eq!(
            ResonatorBank::new(&[good], SampleRate(0)),
            Err(PhysicalError::ZeroRate)
        );
    }
}
