//! The event-based voice of the paper's Fig. 3: one material filter per channel, driven
//! by force, with new numerator coefficients at every step.
//!
//! # Structure
//!
//! A [`PreparedMaterial`] is a library model made ready for one audio rate, off the
//! audio thread: its modal form ([`super::modal`]) resampled by impulse invariance, its
//! longest decay limited (a fit can park a pole at the edge of stability; no ground rings
//! for seconds, and an actuator on skin must not), its residues re-solved so that modes
//! and post filter together have the model's response across the band, and one
//! calibrated gain per drive. A [`Voice`]
//! copies those coefficients into fixed-size arrays (so loading one never allocates) and
//! runs them:
//!
//! $$ s_k\[n\] = p_k\, s_k\[n-1\] + \tilde r_k\, x\[n\], \qquad
//!    y\[n\] = \tilde d\, x\[n\] + \sum_k c_k \operatorname{Re} s_k\[n\] $$
//!
//! with `c_k = 2` for a conjugate pair and 1 for a real pole, then the post filter. The
//! modes run in parallel, each as a complex one-pole: a rotation by `p_k` in the
//! Gold-Rader coupled form. That is a second-order section per mode, but one whose
//! coefficients `Re p, Im p` keep a low resonance's frequency and decay exact in `f32`
//! at 48 kHz, where the direct-form `a1 = -2 r cos θ` of a 20 Hz mode would lose 2% of its
//! frequency to rounding.
//!
//! # The perturbation (paper's equation 4)
//!
//! At every new step each numerator coefficient is multiplied by `1 + σ n`,
//! `n ~ N(0, 1)`, `σ = 0.01` by default, from a seeded generator: the poles, and so
//! stability, never change, while the zeros move and every step sounds a little
//! different. The paper perturbs the expanded numerator of the analysis-rate filter. At
//! the audio rate the numerator coefficients of a low mode nearly cancel
//! (`b_0 + b_1 ≈ 0` when the pole angle θ is small), and a 1% change in each would
//! change that mode's level by up to `1/θ`, about 200% for a 40 Hz mode at 48 kHz. We
//! perturb the numerator of the modal form instead (the real and imaginary parts of each
//! residue, and the direct term), whose 1% change moves each mode's level and phase by
//! about 1%: the few-percent variation the paper describes. The residue multiplies the
//! input, not the state, so a new step's coefficients never change the ringing of the
//! previous one: no discontinuity at the switch.
//!
//! # Post filter
//!
//! The paper adds a low-pass to remove the artefacts of fitting above the band (its
//! 250-500 Hz peaks). Here it is a Butterworth low-pass at the top of the band (order
//! 4 by default), and a second-order Butterworth high-pass at half the bottom of the band:
//! the fit says nothing about the response below the band, and an actuator pressed on
//! skin must not be fed the DC and sub-sonic drift of a force signal.

use num_complex::Complex64;

use super::modal::{ModalError, ModalFilter};
use crate::force::drive::DriveKind;
use crate::material::MaterialModel;
use crate::physical::Ground;
use crate::signal::noise::SplitMix64;
use crate::signal::{Sos, butterworth};
use crate::units::{Hz, SampleRate, Seconds};

/// The most modes a voice runs (a model of order up to 32).
pub const MAX_MODES: usize = 32;
/// The most second-order sections in the post filter.
pub const MAX_POST_SECTIONS: usize = 8;
const LANES: usize = 4;

/// How a model is prepared for playback.
#[derive(Debug, Clone, PartialEq)]
pub struct VoiceConfig {
    /// Order of the low-pass that removes fitting artefacts; 0 for none (default 4).
    pub lowpass_order: usize,
    /// Its cutoff; `None` for the top of the model's band (the default).
    pub lowpass_cutoff: Option<Hz>,
    /// Cutoff of the second-order high-pass; `None` for half the bottom of the band,
    /// `Some(Hz(0.0))` for none.
    pub highpass_cutoff: Option<Hz>,
    /// No mode rings longer than this (time to decay by `e`; default 0.5 s, i.e. a
    /// 60 dB decay in 3.5 s).
    pub longest_decay: Seconds,
    /// Frequencies (log-spaced over the band) the residues are re-solved on (default 256).
    pub fit_points: usize,
    /// Pull of the residue solve towards the impulse-invariant residues (default 1e-4).
    pub regularisation: f64,
    /// Rounds of the magnitude-only residue solve (default 10).
    pub magnitude_iterations: usize,
    /// Which model plays: the fitted filter (default) or the calibrated physical model.
    pub model: SynthModel,
}

/// Which of a material's models the engine plays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SynthModel {
    /// The fitted IIR filter, perturbed at every step ([`Voice`]).
    #[default]
    Iir,
    /// The physical model calibrated from the same recordings
    /// ([`crate::physical::Ground`]): one Hunt-Crossley impact per step on a solid, a
    /// Poisson stream of micro-impacts driven by the loading rate on an aggregate.
    Physical,
}

impl Default for VoiceConfig {
    fn default() -> Self {
        Self {
            lowpass_order: 4,
            lowpass_cutoff: None,
            highpass_cutoff: None,
            longest_decay: Seconds(0.5),
            fit_points: 256,
            regularisation: 0.0,
            magnitude_iterations: 40,
            model: SynthModel::Iir,
        }
    }
}

/// Why a model cannot be played.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum VoiceError {
    /// The model's filter has malformed sections.
    #[error("material {name:?}: the filter has malformed sections")]
    MalformedFilter {
        /// The material.
        name: String,
    },
    /// The filter has no modal form.
    #[error("material {name:?}: {source}")]
    Modal {
        /// The material.
        name: String,
        /// Why.
        source: ModalError,
    },
    /// The filter has more modes than a voice runs.
    #[error("material {name:?} has {modes} modes; a voice runs at most {MAX_MODES}")]
    TooManyModes {
        /// The material.
        name: String,
        /// How many.
        modes: usize,
    },
    /// The physical model was asked for and the material has none.
    #[error("material {name:?} has no physical model (refit it with `underfoot fit`)")]
    NoPhysicalModel {
        /// The material.
        name: String,
    },
    /// The material's physical model cannot run at this rate.
    #[error("material {name:?}: physical model: {source}")]
    Physical {
        /// The material.
        name: String,
        /// Why.
        source: crate::physical::PhysicalError,
    },
    /// A setting of the [`VoiceConfig`] is out of range.
    #[error("voice setting {name} = {value} is out of range: {expected}")]
    InvalidConfig {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The range it must lie in.
        expected: &'static str,
    },
    /// A post-filter setting does not fit the rate.
    #[error("material {name:?}: post filter: {reason}")]
    PostFilter {
        /// The material.
        name: String,
        /// Why.
        reason: String,
    },
}

/// A transposed direct-form II biquad in `f32`, for the post filter.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Section {
    b: [f32; 3],
    a: [f32; 2],
    s: [f32; 2],
}

impl Section {
    /// Passes its input through: what the unused sections hold.
    const IDENTITY: Self = Self {
        b: [1.0, 0.0, 0.0],
        a: [0.0, 0.0],
        s: [0.0, 0.0],
    };

    #[inline]
    fn tick(&mut self, x: f32) -> f32 {
        let y = self.b[0] * x + self.s[0];
        self.s[0] = self.b[1] * x - self.a[0] * y + self.s[1];
        self.s[1] = self.b[2] * x - self.a[1] * y;
        y
    }
}

/// A material ready for one audio rate. Built off the audio thread; a [`Voice`] copies it.
#[derive(Debug, Clone)]
pub struct PreparedMaterial {
    /// The material's name.
    pub name: String,
    /// The modal filter at the audio rate, decay-limited, in `f64` (for inspection).
    pub modal: ModalFilter,
    /// The post filter at the audio rate.
    pub post: Sos,
    /// How many modes had their decay limited.
    pub limited_modes: usize,
    /// Gain per drive ([`DriveKind::index`]) that makes a nominal step reproduce the
    /// recorded level.
    pub drive_gain: [f32; DriveKind::COUNT],
    /// The physical model at the audio rate, when [`VoiceConfig::model`] asks for it.
    pub ground: Option<Ground>,
    modes: usize,
    pole_re: [f32; MAX_MODES],
    pole_im: [f32; MAX_MODES],
    res_re: [f32; MAX_MODES],
    res_im: [f32; MAX_MODES],
    direct: f32,
    sections: [Section; MAX_POST_SECTIONS],
    section_count: usize,
}

/// The scratch block of a physical model's runtime; longer blocks run in pieces.
const GROUND_BLOCK: usize = 256;

impl PreparedMaterial {
    /// Prepares `model` for playback at `rate`. Every drive's gain is 1 until
    /// [`calibrate`](Self::calibrate) is called; for [`DriveKind::Impulse`] that is
    /// already right (impulse invariance keeps the recorded level).
    ///
    /// # Errors
    /// A malformed or unstable filter, more than [`MAX_MODES`] modes, or a post filter
    /// that does not fit the rate.
    pub fn prepare(
        model: &MaterialModel,
        rate: SampleRate,
        config: &VoiceConfig,
    ) -> Result<Self, VoiceError> {
        let longest = config.longest_decay.0;
        // No "unlimited": an infinite or absent limit would let a fitted pole at the edge
        // of stability ring for hours (the fit's own limits are at most 60 s too).
        if !(longest.is_finite() && longest > 0.0 && longest <= 60.0) {
            return Err(VoiceError::InvalidConfig {
                name: "longest_decay",
                value: longest,
                expected: "a decay time in (0, 60] s",
            });
        }
        let name = model.name.clone();
        let sos = model
            .sos()
            .ok_or_else(|| VoiceError::MalformedFilter { name: name.clone() })?;
        let mut modal = ModalFilter::from_sos(&sos, model.sample_rate)
            .map_err(|source| VoiceError::Modal {
                name: name.clone(),
                source,
            })?
            .at_rate(rate);
        let limited_modes = modal.limit_decay(config.longest_decay);
        if modal.modes.len() > MAX_MODES {
            return Err(VoiceError::TooManyModes {
                name,
                modes: modal.modes.len(),
            });
        }

        let post_error = |reason: String| VoiceError::PostFilter {
            name: name.clone(),
            reason,
        };
        let mut post = Vec::new();
        if config.lowpass_order > 0 {
            let cutoff = config.lowpass_cutoff.unwrap_or(model.band_hz.hi);
            let lp = butterworth::lowpass(config.lowpass_order, cutoff, rate)
                .map_err(|e| post_error(e.to_string()))?;
            post.extend(lp.sections);
        }
        let hp_cutoff = config
            .highpass_cutoff
            .unwrap_or(Hz(model.band_hz.lo.0 / 2.0));
        if hp_cutoff.0 > 0.0 {
            let hp =
                butterworth::highpass(2, hp_cutoff, rate).map_err(|e| post_error(e.to_string()))?;
            post.extend(hp.sections);
        }
        if post.len() > MAX_POST_SECTIONS {
            return Err(post_error(format!(
                "{} sections; at most {MAX_POST_SECTIONS}",
                post.len()
            )));
        }
        let post = Sos::new(post);

        // In the band, the voice (modes and post filter) is the model's response scaled by
        // the rate ratio (see `modal`): solve the residues for exactly that.
        let ratio = rate.hz() / model.sample_rate.hz();
        let target =
            |f: Hz| sos.response(model.sample_rate.omega(f)) * ratio / post.response(rate.omega(f));
        for _ in 0..config.magnitude_iterations {
            let current = modal.clone();
            let magnitude_target = |f: Hz| {
                let h = current.response(rate.omega(f));
                let phase = if h.norm() > 0.0 {
                    h / h.norm()
                } else {
                    Complex64::new(1.0, 0.0)
                };
                phase * target(f).norm()
            };
            modal
                .fit_residues(
                    model.band_hz,
                    &magnitude_target,
                    config.fit_points,
                    config.regularisation,
                )
                .map_err(|source| VoiceError::Modal {
                    name: name.clone(),
                    source,
                })?;
        }

        let ground = match config.model {
            SynthModel::Iir => None,
            SynthModel::Physical => {
                let physical = model
                    .physical
                    .as_ref()
                    .ok_or_else(|| VoiceError::NoPhysicalModel { name: name.clone() })?;
                let ground = Ground::new(physical, rate, 0, GROUND_BLOCK).map_err(|source| {
                    VoiceError::Physical {
                        name: name.clone(),
                        source,
                    }
                })?;
                Some(ground)
            }
        };
        let mut prepared = Self {
            name,
            limited_modes,
            drive_gain: [1.0; DriveKind::COUNT],
            ground,
            modes: modal.modes.len(),
            pole_re: [0.0; MAX_MODES],
            pole_im: [0.0; MAX_MODES],
            res_re: [0.0; MAX_MODES],
            res_im: [0.0; MAX_MODES],
            direct: modal.direct as f32,
            sections: [Section::IDENTITY; MAX_POST_SECTIONS],
            section_count: post.sections.len(),
            post,
            modal,
        };
        for (k, m) in prepared.modal.modes.iter().enumerate() {
            let c = if m.pair { 2.0 } else { 1.0 };
            prepared.pole_re[k] = m.pole.re as f32;
            prepared.pole_im[k] = m.pole.im as f32;
            prepared.res_re[k] = (c * m.residue.re) as f32;
            prepared.res_im[k] = (c * m.residue.im) as f32;
        }
        for (slot, s) in prepared.sections.iter_mut().zip(&prepared.post.sections) {
            *slot = Section {
                b: s.b.map(|v| v as f32),
                a: [s.a[1] as f32, s.a[2] as f32],
                s: [0.0; 2],
            };
        }
        Ok(prepared)
    }

    /// Sets the gain of the force-driven drives so that `nominal_step` (total force of
    /// one nominal step at this material's audio rate, in newtons) under each drive gives
    /// the energy that a unit impulse gives, i.e. the recorded strike's.
    ///
    /// `weight` is the nominal body weight the drives normalise force by.
    pub fn calibrate(&mut self, nominal_step: &[f64], weight: crate::units::Newtons) {
        let rate = self.modal.rate;
        let tail = rate.samples_in(Seconds(1.0));
        let energy_of = |prepared: &Self, input: &[f32]| {
            prepared
                .render(input, tail)
                .iter()
                .map(|v| f64::from(*v).powi(2))
                .sum::<f64>()
        };
        let reference = energy_of(self, &[1.0]);
        for kind in [DriveKind::Force, DriveKind::ForceRate] {
            let drive = kind.offline(nominal_step, rate, weight);
            let e = energy_of(self, &drive);
            self.drive_gain[kind.index()] = if e > 0.0 && reference > 0.0 {
                (reference / e).sqrt() as f32
            } else {
                1.0
            };
        }
    }

    /// The largest absolute sample of a unit step under the impulse drive (one second of
    /// its response): what a nominal step peaks at before the output gain.
    #[must_use]
    pub fn impulse_peak(&self) -> f32 {
        let tail = self.modal.rate.samples_in(Seconds(1.0)).max(1) - 1;
        self.render(&[1.0], tail)
            .iter()
            .fold(0.0, |m, v| m.max(v.abs()))
    }

    /// A fresh voice of this material under the impulse drive's gain, run on `input`
    /// followed by `tail` samples of silence. For set-up, not for the audio thread.
    fn render(&self, input: &[f32], tail: usize) -> Vec<f32> {
        let mut voice = Voice::new();
        voice.load(self, DriveKind::Impulse);
        let mut x = input.to_vec();
        x.resize(input.len() + tail, 0.0);
        let mut y = vec![0.0; x.len()];
        voice.process(&x, &mut y);
        y
    }

    /// The response of the voice (modes and post filter) at `omega` radians per sample.
    #[must_use]
    pub fn response(&self, omega: f64) -> Complex64 {
        self.modal.response(omega) * self.post.response(omega)
    }

    /// Number of modes.
    #[must_use]
    pub fn mode_count(&self) -> usize {
        self.modes
    }
}

/// One playing instance of a material: coefficients, perturbed numerators and state,
/// all in fixed-size arrays.
#[derive(Debug, Clone)]
pub struct Voice {
    /// Modes rounded up to a multiple of the SIMD width; the padding lanes are all zero.
    lanes: usize,
    pole_re: [f32; MAX_MODES],
    pole_im: [f32; MAX_MODES],
    base_re: [f32; MAX_MODES],
    base_im: [f32; MAX_MODES],
    res_re: [f32; MAX_MODES],
    res_im: [f32; MAX_MODES],
    state_re: [f32; MAX_MODES],
    state_im: [f32; MAX_MODES],
    base_direct: f32,
    direct: f32,
    sections: [Section; MAX_POST_SECTIONS],
    section_count: usize,
    gain: f32,
    /// Samples processed since the material was loaded.
    clock: u64,
}

impl Default for Voice {
    fn default() -> Self {
        Self::new()
    }
}

/// States below this are flushed to zero at the end of a block: a decayed mode would
/// otherwise go subnormal, where arithmetic is a hundred times slower.
const FLUSH: f32 = 1e-20;
/// How many samples run between flushes.
const FLUSH_EVERY: usize = 64;

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
        self.gain = m.drive_gain[drive.index()];
        self.clock = 0;
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
            if self.clock % FLUSH_EVERY as u64 == 0 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::builtin::builtin;

    fn prepared(name: &str) -> PreparedMaterial {
        let model = builtin().get(name).unwrap();
        PreparedMaterial::prepare(model, SampleRate(48_000), &VoiceConfig::default()).unwrap()
    }

    #[test]
    fn voice_runs_its_prepared_response() {
        let m = prepared("gravel");
        let mut voice = Voice::new();
        voice.load(&m, DriveKind::Impulse);
        let n = 1 << 16;
        let mut x = vec![0.0f32; n];
        x[0] = 1.0;
        let mut y = vec![0.0f32; n];
        assert_eq!(voice.process(&x, &mut y), 0);
        // A naive DFT of the impulse response at a few frequencies against the model.
        for f in [40.0, 100.0, 250.0, 500.0] {
            let omega = SampleRate(48_000).omega(Hz(f));
            let dft: Complex64 = y
                .iter()
                .enumerate()
                .map(|(k, v)| f64::from(*v) * Complex64::from_polar(1.0, -omega * k as f64))
                .sum();
            let want = m.response(omega);
            let err = (dft - want).norm() / want.norm();
            assert!(err < 5e-3, "{f} Hz: {dft} vs {want} ({err})");
        }
    }

    /// The rate change and the post filter together: every built-in material's voice at
    /// 48 kHz has its model's response (times the rate ratio) across the band.
    #[test]
    fn every_builtin_voice_matches_its_model_in_the_band() {
        let rate = SampleRate(48_000);
        for model in &builtin().materials {
            let m = PreparedMaterial::prepare(model, rate, &VoiceConfig::default()).unwrap();
            let sos = model.sos().unwrap();
            let ratio = rate.hz() / model.sample_rate.hz();
            let grid = model.band_hz.log_grid(96);
            let db: Vec<f64> = grid
                .iter()
                .map(|f| {
                    let want = sos.response(model.sample_rate.omega(*f)).norm() * ratio;
                    20.0 * (m.response(rate.omega(*f)).norm() / want).log10()
                })
                .collect();
            let lsd = (db.iter().map(|d| d * d).sum::<f64>() / db.len() as f64).sqrt();
            // The low-pass sits on the band's top edge; below 80% of it the match is close.
            let inner = grid
                .iter()
                .zip(&db)
                .filter(|(f, _)| f.0 < 0.8 * model.band_hz.hi.0)
                .map(|(_, d)| d.abs())
                .fold(0.0, f64::max);
            println!("{}: lsd {lsd:.2} dB, worst {inner:.2} dB", model.name);
            // Most are within 0.5 dB. Two fits lean on the aliases of broad modes near the
            // 1 kHz Nyquist frequency more than the residue solve can make up for at
            // 48 kHz (impulse invariance alone is 10 dB off for wood): glass 0.72 dB and
            // wood 1.26 dB RMS (2.4 dB worst), a known gap of the rate change.
            assert!(
                lsd < 1.3 && inner < 2.5,
                "{}: lsd {lsd:.2} dB, worst {inner:.2} dB",
                model.name
            );
        }
    }

    /// Every step sounds a little different: the magnitude spectrum of each perturbed
    /// step differs from the unperturbed one by a few percent (RMS over the band), and
    /// no two steps are alike.
    #[test]
    fn each_step_has_its_own_spectrum_a_few_percent_off() {
        let rate = SampleRate(48_000);
        let model = builtin().get("gravel").unwrap();
        let m = PreparedMaterial::prepare(model, rate, &VoiceConfig::default()).unwrap();
        let grid = model.band_hz.log_grid(48);
        let n = rate.samples_in(Seconds(0.5));
        let spectrum = |voice: &mut Voice| -> Vec<f64> {
            let mut x = vec![0.0f32; n];
            x[0] = 1.0;
            let mut y = vec![0.0f32; n];
            voice.reset();
            voice.process(&x, &mut y);
            grid.iter()
                .map(|f| {
                    let omega = rate.omega(*f);
                    y.iter()
                        .enumerate()
                        .map(|(k, v)| f64::from(*v) * Complex64::from_polar(1.0, -omega * k as f64))
                        .sum::<Complex64>()
                        .norm()
                })
                .collect()
        };
        let mut voice = Voice::new();
        voice.load(&m, DriveKind::Impulse);
        let base = spectrum(&mut voice);
        let mut rng = SplitMix64::new(11);
        let mut steps = Vec::new();
        for _ in 0..20 {
            voice.perturb(&mut rng, 0.01);
            steps.push(spectrum(&mut voice));
        }
        let rel = |a: &[f64], b: &[f64]| {
            (a.iter()
                .zip(b)
                .map(|(x, y)| ((x - y) / y).powi(2))
                .sum::<f64>()
                / a.len() as f64)
                .sqrt()
        };
        let changes: Vec<f64> = steps.iter().map(|s| rel(s, &base)).collect();
        let mean = changes.iter().sum::<f64>() / changes.len() as f64;
        assert!(
            changes.iter().all(|c| (0.002..0.1).contains(c)),
            "{changes:?}"
        );
        assert!((0.005..0.05).contains(&mean), "mean change {mean}");
        for i in 0..steps.len() {
            for j in i + 1..steps.len() {
                assert!(rel(&steps[i], &steps[j]) > 1e-3, "steps {i} and {j} alike");
            }
        }
        println!(
            "per-step spectral change: mean {:.2}%, max {:.2}%",
            100.0 * mean,
            100.0 * changes.iter().fold(0.0f64, |m, c| m.max(*c))
        );
    }

    #[test]
    fn perturbation_keeps_poles_and_changes_numerators_by_about_one_percent() {
        let m = prepared("snow");
        let mut voice = Voice::new();
        voice.load(&m, DriveKind::Impulse);
        let poles: Vec<_> = voice.poles().collect();
        let mut rng = SplitMix64::new(3);
        let mut ratios = Vec::new();
        for _ in 0..200 {
            voice.perturb(&mut rng, 0.01);
            assert_eq!(voice.poles().collect::<Vec<_>>(), poles);
            let (re, _, _) = voice.numerators();
            for (k, r) in re.iter().enumerate() {
                if m.res_re[k] != 0.0 {
                    ratios.push(f64::from(r / m.res_re[k]) - 1.0);
                }
            }
        }
        let sd = (ratios.iter().map(|r| r * r).sum::<f64>() / ratios.len() as f64).sqrt();
        assert!((sd - 0.01).abs() < 0.001, "{sd}");
    }
}
