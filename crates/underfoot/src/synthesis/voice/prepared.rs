//! A material made ready for one audio rate, off the audio thread: [`PreparedMaterial`].
//!
//! Its modal form ([`crate::synthesis::modal`]) resampled by impulse invariance, its
//! longest decay limited (a fit can park a pole at the edge of stability; no ground rings
//! for seconds, and an actuator on skin must not), its residues re-solved so that modes
//! and post filter together have the model's response across the band, and one
//! normalised gain per drive ([`PreparedMaterial::normalise_drives`]). A [`Voice`]
//! copies those coefficients (see [`mod@super::play`]).
//!
//! # Post filter
//!
//! The IIR paper adds a low-pass to remove the artefacts of fitting above the band (its
//! 250-500 Hz peaks). Here it is a Butterworth low-pass at the top of the band (order
//! 4 by default), and a second-order Butterworth high-pass at half the bottom of the band:
//! the fit says nothing about the response below the band, and an actuator pressed on
//! skin must not be fed the DC and sub-sonic drift of a force signal.

use num_complex::Complex64;

use super::{MAX_MODES, MAX_POST_SECTIONS, Section, SynthModel, Voice, VoiceConfig, VoiceError};
use crate::force::drive::DriveKind;
use crate::material::MaterialModel;
use crate::physical::Ground;
use crate::signal::{Sos, butterworth};
use crate::synthesis::modal::ModalFilter;
use crate::units::{Hz, SampleRate, Seconds};

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
    pub(super) modes: usize,
    pub(super) pole_re: [f32; MAX_MODES],
    pub(super) pole_im: [f32; MAX_MODES],
    pub(super) res_re: [f32; MAX_MODES],
    pub(super) res_im: [f32; MAX_MODES],
    pub(super) direct: f32,
    pub(super) sections: [Section; MAX_POST_SECTIONS],
    pub(super) section_count: usize,
}

/// The scratch block of a physical model's runtime; longer blocks run in pieces.
const GROUND_BLOCK: usize = 256;

impl PreparedMaterial {
    /// Prepares `model` for playback at `rate`. Every drive's gain is 1 until
    /// [`normalise_drives`](Self::normalise_drives) is called; for [`DriveKind::Impulse`] that is
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
    pub fn normalise_drives(&mut self, nominal_step: &[f64], weight: crate::units::Newtons) {
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
