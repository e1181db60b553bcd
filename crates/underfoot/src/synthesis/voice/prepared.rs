//! A material made ready for one audio rate, off the audio thread: [`PreparedMaterial`].
//!
//! Its modal form ([`crate::synthesis::modal`]) resampled by impulse invariance, its
//! longest decay limited (a fit can park a pole at the edge of stability; no ground rings
//! for seconds, and an actuator on skin must not), its residues re-solved so that modes
//! and post filter together have the model's response across the band, and one
//! normalised gain per drive ([`PreparedMaterial::normalise_drives`]). A [`Voice`]
//! copies those coefficients (see [`mod@super::play`]). Beside them: the material's
//! excitation at the audio rate ([`crate::excitation::Tables`]), its playback level
//! ([`crate::material::level`]), and the size of its per-step perturbation.
//!
//! # Modes for the aliases
//!
//! A fit at 2 kHz may place broad modes (a few samples of decay) whose response in the
//! band owes much to their images around the 1 kHz Nyquist frequency. Impulse invariance
//! keeps a mode's frequency and decay, not its images, and with the poles fixed the residue
//! solve cannot always make up for them: the shared `wood` was 1.2 dB (gain-aligned RMS
//! over the band, 2.4 dB at worst) from its model at 48 kHz, `glass` 0.7 dB. Where the
//! misfit is over [`ALIAS_MODES_ABOVE`] (0.5 dB), two broad pairs above the band (at 1.2
//! and 2 times its top, bandwidths 0.6 and 1 times it), whose tails across the band are
//! smooth as the images' are, are solved with the rest and kept if they bring the voice
//! closer: `wood` 0.23 dB, `glass` 0.02 dB. They cost a voice two modes, nothing for a
//! material whose modes leave room in their last group of lanes.
//!
//! # The perturbation's size
//!
//! The IIR paper perturbs each numerator coefficient by 1% at every step. Real steps on
//! one material differ by far more (4-5.5 dB of gain-aligned log-spectral distance between
//! two steps, 1/6-octave bands, on the shared recordings), most of it from what the
//! excitation's random train already varies. What the train leaves,
//! [`ExcitationModel::perturbation_db`](crate::excitation::ExcitationModel::perturbation_db),
//! is given to the perturbation: `σ` is found (bisection on `[0, 0.5]`) so that two
//! independently perturbed copies of this voice's response, `d + Σ_k ½(r̃_k/(1 - p_k
//! e^{-iω}) + r̃_k^*/(1 - p_k^* e^{-iω}))` times the post filter, with every real and
//! imaginary part of a residue and the direct term multiplied by `1 + σ n`, differ by that
//! distance on average (48 seeded pairs, power averaged over the sixth-octave bands of
//! the model's band, 4 frequencies a band). Two independent contributions add in
//! quadrature, which is how the train's and the perturbation's were split. A material
//! without an excitation (a file before format 3) keeps the paper's 1%.
//!
//! A perturbation is not free: `E|H + δH|² = |H|² + E|δH|²`, so on average it adds power,
//! most where the modes cancel (below the lowest resonance, between two), and fills in
//! the response's valleys. `σ` is therefore held, if need be, to where the draws' average
//! power spectrum stays within [`MAX_PERTURBATION_BIAS`] (0.5 dB, gain-aligned, the same
//! bands) of the unperturbed one: the steps may then differ a little less than the
//! recordings', but on average they keep the fitted spectrum. (Measured on the shared
//! `sand`: sized for its 2.5 dB alone, the perturbation lifted 21-30 Hz by 3-8 dB and
//! moved the rendered steps' average spectrum from 1.2 to 2.4 dB off the recordings'.)
//!
//! # Post filter
//!
//! The IIR paper adds a low-pass to remove the artefacts of fitting above the band (its
//! 250-500 Hz peaks). Here it is a Butterworth low-pass at the top of the band (order
//! 4 by default), and a second-order Butterworth high-pass at half the bottom of the band:
//! the fit says nothing about the response below the band, and an actuator pressed on
//! skin must not be fed the DC and sub-sonic drift of a force signal.

use num_complex::Complex64;

use super::{
    ExcitationChoice, MAX_MODES, MAX_POST_SECTIONS, Section, SynthModel, Voice, VoiceConfig,
    VoiceError,
};
use crate::analysis::steps::{StepConfig, band_centres};
use crate::excitation::{ExcitationModel, Tables};
use crate::fit::metrics::gain_aligned_lsd_db;
use crate::force::drive::DriveKind;
use crate::material::MaterialModel;
use crate::physical::{Ground, PhysicalModel};
use crate::signal::noise::SplitMix64;
use crate::signal::{Sos, butterworth};
use crate::synthesis::modal::{ModalFilter, PoleResidue};
use crate::units::{Band, Decibels, Hz, SampleRate, Seconds};

/// How far, at most, the per-step perturbation may move the average spectrum of a
/// material's steps (gain-aligned, sixth-octave bands; see the module documentation).
pub const MAX_PERTURBATION_BIAS: Decibels = Decibels(0.5);

/// The in-band misfit (gain-aligned RMS, dB) of the rate change above which two broad
/// modes are added above the band (see the module documentation).
pub const ALIAS_MODES_ABOVE: Decibels = Decibels(0.5);

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
    /// The physical model at the audio rate (its output at the playback level), when
    /// [`VoiceConfig::model`] asks for it.
    pub ground: Option<Ground>,
    /// What drives each step, at the audio rate.
    pub excitation: Tables,
    /// The playback level (amplitude re the recorded level): the voice's gain includes it.
    pub level: f32,
    /// The standard deviation of the per-step numerator perturbation sized for this
    /// material (see the module documentation).
    pub perturbation: f32,
    pub(super) modes: usize,
    pub(super) pole_re: [f32; MAX_MODES],
    pub(super) pole_im: [f32; MAX_MODES],
    pub(super) res_re: [f32; MAX_MODES],
    pub(super) res_im: [f32; MAX_MODES],
    pub(super) direct: f32,
    pub(super) sections: [Section; MAX_POST_SECTIONS],
    pub(super) section_count: usize,
}

/// The perturbation of a material fitted before its steps' spread was measured: the IIR
/// paper's.
pub const PAPER_PERTURBATION: f32 = 0.01;

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
        let solve = |modal: &mut ModalFilter| -> Result<(), VoiceError> {
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
            Ok(())
        };
        let grid = model.band_hz.log_grid(192);
        let wanted: Vec<f64> = grid.iter().map(|f| target(*f).norm()).collect();
        let misfit = |modal: &ModalFilter| -> f64 {
            let got: Vec<f64> = grid
                .iter()
                .map(|f| modal.response(rate.omega(*f)).norm())
                .collect();
            gain_aligned_lsd_db(&wanted, &got)
        };
        solve(&mut modal)?;
        // Fixed poles cannot make up for a fit that leans on the aliases of broad modes
        // near its Nyquist frequency: two broad modes above the band, solved with the
        // rest, stand in for them (see the module documentation).
        let alone = misfit(&modal);
        if alone > ALIAS_MODES_ABOVE.0 && modal.modes.len() + 2 <= MAX_MODES {
            let mut wider = modal.clone();
            let top = model.band_hz.hi.0;
            for (f, bandwidth) in [(1.2 * top, 0.6 * top), (2.0 * top, top)] {
                wider.modes.push(PoleResidue {
                    pole: Complex64::from_polar(
                        (-std::f64::consts::PI * bandwidth / rate.hz()).exp(),
                        rate.omega(Hz(f)),
                    ),
                    residue: Complex64::new(0.0, 0.0),
                    pair: true,
                });
            }
            solve(&mut wider)?;
            if misfit(&wider) < alone {
                modal = wider;
            }
        }

        let fitted = match config.excitation {
            ExcitationChoice::Fitted => model.excitation.as_ref(),
            ExcitationChoice::Heel => None,
        };
        let excitation = Tables::new(
            &fitted.cloned().unwrap_or_else(ExcitationModel::heel_only),
            rate,
        )
        .map_err(|source| VoiceError::Excitation {
            name: name.clone(),
            source,
        })?;
        let level = Decibels(model.level_db).to_amplitude();
        let ground = match config.model {
            SynthModel::Iir => None,
            SynthModel::Physical => {
                let physical = model
                    .physical
                    .as_ref()
                    .ok_or_else(|| VoiceError::NoPhysicalModel { name: name.clone() })?;
                let levelled = PhysicalModel {
                    output_gain: physical.output_gain * level,
                    ..physical.clone()
                };
                let ground = Ground::new(&levelled, rate, 0, excitation.mean_impulse_energy())
                    .map_err(|source| VoiceError::Physical {
                        name: name.clone(),
                        source,
                    })?;
                Some(ground)
            }
        };
        let mut prepared = Self {
            name,
            limited_modes,
            drive_gain: [1.0; DriveKind::COUNT],
            ground,
            excitation,
            level: level as f32,
            perturbation: PAPER_PERTURBATION,
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
        if let Some(e) = fitted {
            prepared.perturbation = prepared.perturbation_for(e.perturbation_db, model.band_hz);
        } else if model.excitation.is_some() {
            // One impulse asked for, of a material that has an excitation: its fitted size.
            let e = model.excitation.as_ref().map_or(0.0, |e| e.perturbation_db);
            prepared.perturbation = prepared.perturbation_for(e, model.band_hz);
        }
        Ok(prepared)
    }

    /// The perturbation `σ` whose two independent draws differ by `spread_db` on average,
    /// or less where that would move the average spectrum by more than
    /// [`MAX_PERTURBATION_BIAS`] (see the module documentation); 0 for a spread of 0, at
    /// most 0.5.
    #[must_use]
    pub fn perturbation_for(&self, spread_db: f64, band: Band) -> f32 {
        if !(spread_db.is_finite() && spread_db > 0.0) {
            return 0.0;
        }
        let rate = self.modal.rate;
        let steps_cfg = StepConfig {
            band,
            ..StepConfig::default()
        };
        let centres = band_centres(&steps_cfg);
        let half = 2f64.powf(0.5 / steps_cfg.spectrum_fraction);
        let omegas: Vec<Vec<Complex64>> = centres
            .iter()
            .map(|c| {
                (0..4)
                    .map(|i| {
                        let f = c / half * half.powf(2.0 * (f64::from(i) + 0.5) / 4.0);
                        Complex64::from_polar(1.0, -rate.omega(Hz(f)))
                    })
                    .collect()
            })
            .collect();
        let post: Vec<Vec<f64>> = omegas
            .iter()
            .map(|zs| {
                zs.iter()
                    .map(|z| self.post.response(-z.arg()).norm_sqr())
                    .collect()
            })
            .collect();
        // The band powers of one draw: every residue part and the direct term times
        // `1 + σ n`.
        let draw = |sigma: f64, rng: &mut SplitMix64| -> Vec<f64> {
            let mut g = |v: f32| f64::from(v) * (1.0 + sigma * rng.normal());
            let d = g(self.direct);
            let residues: Vec<Complex64> = (0..self.modes)
                .map(|k| Complex64::new(g(self.res_re[k]), g(self.res_im[k])))
                .collect();
            omegas
                .iter()
                .zip(&post)
                .map(|(zs, ps)| {
                    let power: f64 = zs
                        .iter()
                        .zip(ps)
                        .map(|(z, p)| {
                            let mut h = Complex64::new(d, 0.0);
                            for (k, r) in residues.iter().enumerate() {
                                let pole = Complex64::new(
                                    f64::from(self.pole_re[k]),
                                    f64::from(self.pole_im[k]),
                                );
                                h += 0.5
                                    * (r / (1.0 - pole * z) + r.conj() / (1.0 - pole.conj() * z));
                            }
                            h.norm_sqr() * p
                        })
                        .sum();
                    power / zs.len() as f64
                })
                .collect()
        };
        let db = |power: &[f64]| -> Vec<f64> {
            power.iter().map(|p| 10.0 * p.max(1e-300).log10()).collect()
        };
        let aligned = |a: &[f64], b: &[f64]| {
            let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
        };
        let plain = db(&draw(0.0, &mut SplitMix64::new(0)));
        let pairs = 48;
        // The mean distance between two draws, and the draws' average spectrum's from the
        // plain one.
        let stats_at = |sigma: f64| {
            let mut rng = SplitMix64::new(0x5EED_5EED);
            let mut total = 0.0;
            let mut average = vec![0.0; plain.len()];
            for _ in 0..pairs {
                let (a, b) = (draw(sigma, &mut rng), draw(sigma, &mut rng));
                for (m, (x, y)) in average.iter_mut().zip(a.iter().zip(&b)) {
                    *m += x + y;
                }
                total += aligned(&db(&a), &db(&b));
            }
            (total / f64::from(pairs), aligned(&db(&average), &plain))
        };
        // The largest σ in [0, 0.5] at which `within(σ)` holds, by bisection.
        let largest = |within: &dyn Fn(f64) -> bool| {
            let (mut lo, mut hi) = (0.0f64, 0.5f64);
            if within(hi) {
                return hi;
            }
            for _ in 0..24 {
                let mid = 0.5 * (lo + hi);
                if within(mid) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        };
        let sigma = largest(&|s| stats_at(s).0 < spread_db);
        if stats_at(sigma).1 <= MAX_PERTURBATION_BIAS.0 {
            return sigma as f32;
        }
        largest(&|s| s <= sigma && stats_at(s).1 <= MAX_PERTURBATION_BIAS.0) as f32
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
