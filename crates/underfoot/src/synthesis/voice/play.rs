//! One playing instance of a material: the [`Voice`] the audio thread runs.
//!
//! A voice copies a [`PreparedMaterial`]'s coefficients into fixed-size arrays (so
//! loading one never allocates) and runs them:
//!
//! ```math
//! s_k[n] = p_k\, s_k[n-1] + \tilde r_k\, x[n], \qquad
//!   y[n] = \tilde d\, x[n] + \sum_k c_k \operatorname{Re} s_k[n]
//! ```
//!
//! with `c_k = 2` for a conjugate pair and 1 for a real pole, then the post filter. The
//! modes run in parallel, each as a complex one-pole: a rotation by `p_k` in the
//! Gold-Rader coupled form. That is a second-order section per mode, but one whose
//! coefficients `Re p, Im p` keep a low resonance's frequency and decay exact in `f32`
//! at 48 kHz, where the direct-form `a1 = -2 r cos θ` of a 20 Hz mode would lose 2% of its
//! frequency to rounding.
//!
//! # The perturbation (the IIR paper's equation 4)
//!
//! At every new step each numerator coefficient is multiplied by `1 + σ n`,
//! `n ~ N(0, 1)`, from a seeded generator, `σ` the material's own (sized from its
//! recordings' spread between steps, [`PreparedMaterial::perturbation`]) or the IIR
//! paper's 0.01 when the engine is set to it: the poles, and so
//! stability, never change, while the zeros move and every step sounds a little
//! different. The IIR paper perturbs the expanded numerator of the analysis-rate filter. At
//! the audio rate the numerator coefficients of a low mode nearly cancel
//! (`b_0 + b_1 ≈ 0` when the pole angle θ is small), and a 1% change in each would
//! change that mode's level by up to `1/θ`, about 200% for a 40 Hz mode at 48 kHz. We
//! perturb the numerator of the modal form instead (the real and imaginary parts of each
//! residue, and the direct term), whose 1% change moves each mode's level and phase by
//! about 1%: the few-percent variation the IIR paper describes. The residue multiplies the
//! input, not the state, so a new step's coefficients never change the ringing of the
//! previous one: no discontinuity at the switch.

use std::sync::atomic::{AtomicU64, Ordering};

use num_complex::Complex64;

use super::{LANES, MAX_MODES, MAX_POST_SECTIONS, PreparedMaterial, Section};
use crate::force::drive::DriveKind;
use crate::signal::noise::SplitMix64;

/// One playing instance of a material: coefficients, perturbed numerators and state,
/// all in fixed-size arrays.
#[derive(Debug, Clone)]
pub struct Voice {
    /// Modes rounded up to a multiple of the SIMD width; the padding lanes are all zero.
    pub(super) lanes: usize,
    pub(super) pole_re: [f32; MAX_MODES],
    pub(super) pole_im: [f32; MAX_MODES],
    pub(super) base_re: [f32; MAX_MODES],
    pub(super) base_im: [f32; MAX_MODES],
    pub(super) res_re: [f32; MAX_MODES],
    pub(super) res_im: [f32; MAX_MODES],
    pub(super) state_re: [f32; MAX_MODES],
    pub(super) state_im: [f32; MAX_MODES],
    pub(super) base_direct: f32,
    pub(super) direct: f32,
    pub(super) sections: [Section; MAX_POST_SECTIONS],
    pub(super) section_count: usize,
    pub(super) gain: f32,
    /// Samples processed since the material was loaded.
    pub(super) clock: u64,
    /// Names the coefficients: a new value at every change, unique in the process (0
    /// for a new voice's zeros), so that [`super::VoiceLanes`] copies them only when
    /// they changed.
    pub(super) generation: u64,
}

/// The source of [`Voice::generation`].
static GENERATIONS: AtomicU64 = AtomicU64::new(1);

fn next_generation() -> u64 {
    GENERATIONS.fetch_add(1, Ordering::Relaxed)
}

impl Default for Voice {
    fn default() -> Self {
        Self::new()
    }
}

/// States below this are flushed to zero at the end of a block: a decayed mode would
/// otherwise go subnormal, where arithmetic is a hundred times slower.
pub(super) const FLUSH: f32 = 1e-20;
/// How many samples run between flushes.
pub(super) const FLUSH_EVERY: usize = 64;

impl Voice {
    /// A silent voice with no material.
    #[must_use]
    pub fn new() -> Self {
        Self {
            lanes: 0,
            pole_re: [0.0; MAX_MODES],
            pole_im: [0.0; MAX_MODES],
            base_re: [0.0; MAX_MODES],
            base_im: [0.0; MAX_MODES],
            res_re: [0.0; MAX_MODES],
            res_im: [0.0; MAX_MODES],
            state_re: [0.0; MAX_MODES],
            state_im: [0.0; MAX_MODES],
            base_direct: 0.0,
            direct: 0.0,
            sections: [Section::IDENTITY; MAX_POST_SECTIONS],
            section_count: 0,
            gain: 0.0,
            clock: 0,
            generation: 0,
        }
    }

    /// Loads a material's coefficients for `drive`, with silent state and unperturbed
    /// numerators. Never allocates.
    pub fn load(&mut self, m: &PreparedMaterial, drive: DriveKind) {
        self.lanes = m.modes.div_ceil(LANES) * LANES;
        self.pole_re = m.pole_re;
        self.pole_im = m.pole_im;
        self.base_re = m.res_re;
        self.base_im = m.res_im;
        self.res_re = m.res_re;
        self.res_im = m.res_im;
        self.base_direct = m.direct;
        self.direct = m.direct;
        self.sections = m.sections;
        self.section_count = m.section_count;
        self.gain = m.drive_gain[drive.index()] * m.level;
        self.clock = 0;
        self.generation = next_generation();
        self.reset();
    }

    /// Silences the voice (zero state) without changing its material.
    pub fn reset(&mut self) {
        self.state_re = [0.0; MAX_MODES];
        self.state_im = [0.0; MAX_MODES];
        for s in &mut self.sections {
            s.s = [0.0; 2];
        }
    }

    /// Puts the voice in the steady state of a constant input `x` (before its gain), as if
    /// it had been driven by `x` forever. A voice that starts mid-stance under a force
    /// drive starts from here instead of from rest, so it does not ring with the step
    /// response of a force that was in fact there all along.
    pub fn settle(&mut self, x: f32) {
        let x = f64::from(x * self.gain);
        let mut v = f64::from(self.direct) * x;
        for k in 0..self.lanes {
            // s = p s + r x  =>  s = r x / (1 - p)
            let p = Complex64::new(self.pole_re[k].into(), self.pole_im[k].into());
            let r = Complex64::new(self.res_re[k].into(), self.res_im[k].into());
            let s = r * x / (1.0 - p);
            self.state_re[k] = s.re as f32;
            self.state_im[k] = s.im as f32;
            v += s.re;
        }
        for sec in &mut self.sections[..self.section_count] {
            let [b0, b1, b2] = sec.b.map(f64::from);
            let [a1, a2] = sec.a.map(f64::from);
            let y = v * (b0 + b1 + b2) / (1.0 + a1 + a2);
            sec.s = [(y - b0 * v) as f32, (b2 * v - a2 * y) as f32];
            v = y;
        }
    }

    /// New numerators for a new step: each coefficient of the modal numerator times
    /// `1 + sigma n`, `n ~ N(0, 1)`. The poles are untouched.
    pub fn perturb(&mut self, rng: &mut SplitMix64, sigma: f32) {
        let mut draw = |base: f32| base * (1.0 + sigma * rng.normal() as f32);
        for k in 0..self.lanes {
            self.res_re[k] = draw(self.base_re[k]);
            self.res_im[k] = draw(self.base_im[k]);
        }
        self.direct = draw(self.base_direct);
        self.generation = next_generation();
    }

    /// The current (perturbed) numerators, for tests: real parts, imaginary parts, direct.
    #[must_use]
    pub fn numerators(&self) -> (&[f32], &[f32], f32) {
        (
            &self.res_re[..self.lanes],
            &self.res_im[..self.lanes],
            self.direct,
        )
    }

    /// The poles, for tests.
    pub fn poles(&self) -> impl Iterator<Item = Complex64> + '_ {
        (0..self.lanes).map(|k| Complex64::new(self.pole_re[k].into(), self.pole_im[k].into()))
    }

    /// Filters `input` into `out` (same length). Never allocates, locks or panics.
    ///
    /// Returns the number of non-finite samples met: each resets the voice's state and
    /// is written as zero, so a bad coefficient or input can never reach the output.
    pub fn process(&mut self, input: &[f32], out: &mut [f32]) -> u32 {
        // In short stretches, flushing tiny states after each: a decayed mode would
        // otherwise go subnormal within a long block, where f32 arithmetic is a hundred
        // times slower.
        // The flushes fall on the voice's own sample clock, not on the caller's blocks, so
        // the output does not depend on how it is cut into blocks.
        let n = input.len().min(out.len());
        let mut resets = 0;
        let mut start = 0;
        while start < n {
            let until_flush = FLUSH_EVERY - (self.clock % FLUSH_EVERY as u64) as usize;
            let len = until_flush.min(n - start);
            resets +=
                self.process_stretch(&input[start..start + len], &mut out[start..start + len]);
            self.clock += len as u64;
            if self.clock.is_multiple_of(FLUSH_EVERY as u64) {
                self.flush_tiny_states();
            }
            start += len;
        }
        resets
    }

    fn process_stretch(&mut self, input: &[f32], out: &mut [f32]) -> u32 {
        // One monomorphised loop per group and post-section count, so that the whole state
        // lives in registers for the block instead of going through memory at every
        // sample. Past four sections, the spare ones pass their input through.
        macro_rules! sections {
            ($g:literal) => {
                match self.section_count {
                    0 => self.run::<$g, 0>(input, out),
                    1 => self.run::<$g, 1>(input, out),
                    2 => self.run::<$g, 2>(input, out),
                    3 => self.run::<$g, 3>(input, out),
                    4 => self.run::<$g, 4>(input, out),
                    _ => self.run::<$g, MAX_POST_SECTIONS>(input, out),
                }
            };
        }
        match self.lanes / LANES {
            0 => sections!(0),
            1 => sections!(1),
            2 => sections!(2),
            3 => sections!(3),
            4 => sections!(4),
            5 => sections!(5),
            6 => sections!(6),
            7 => sections!(7),
            _ => sections!(8),
        }
    }

    fn flush_tiny_states(&mut self) {
        for k in 0..self.lanes.min(MAX_MODES) {
            if self.state_re[k].abs() < FLUSH && self.state_im[k].abs() < FLUSH {
                self.state_re[k] = 0.0;
                self.state_im[k] = 0.0;
            }
        }
        for s in &mut self.sections {
            for v in &mut s.s {
                if v.abs() < FLUSH {
                    *v = 0.0;
                }
            }
        }
    }

    fn run<const G: usize, const S: usize>(&mut self, input: &[f32], out: &mut [f32]) -> u32 {
        let group = |a: &[f32; MAX_MODES]| -> [[f32; LANES]; G] {
            std::array::from_fn(|g| std::array::from_fn(|j| a[g * LANES + j]))
        };
        let (pr, pi, rr, ri) = (
            group(&self.pole_re),
            group(&self.pole_im),
            group(&self.res_re),
            group(&self.res_im),
        );
        let (mut sr, mut si) = (group(&self.state_re), group(&self.state_im));
        let mut sections: [Section; S] = std::array::from_fn(|i| self.sections[i]);
        let (gain, direct) = (self.gain, self.direct);
        let mut resets = 0;
        for (x, y) in input.iter().zip(out.iter_mut()) {
            let x = *x * gain;
            let mut acc = [0.0f32; LANES];
            for g in 0..G {
                for j in 0..LANES {
                    let nr = pr[g][j] * sr[g][j] - pi[g][j] * si[g][j] + rr[g][j] * x;
                    let ni = pr[g][j] * si[g][j] + pi[g][j] * sr[g][j] + ri[g][j] * x;
                    sr[g][j] = nr;
                    si[g][j] = ni;
                    acc[j] += nr;
                }
            }
            let mut v = direct * x + ((acc[0] + acc[1]) + (acc[2] + acc[3]));
            for s in &mut sections {
                v = s.tick(v);
            }
            if v.is_finite() {
                *y = v;
            } else {
                sr = [[0.0; LANES]; G];
                si = [[0.0; LANES]; G];
                for s in &mut sections {
                    s.s = [0.0; 2];
                }
                resets += 1;
                *y = 0.0;
            }
        }
        for g in 0..G {
            for j in 0..LANES {
                self.state_re[g * LANES + j] = sr[g][j];
                self.state_im[g * LANES + j] = si[g][j];
            }
        }
        self.sections[..S].copy_from_slice(&sections);
        resets
    }
}
