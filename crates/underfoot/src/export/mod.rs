//! Firmware export: a library's materials as second-order sections in `f32`, Q15 and Q31,
//! checked, and written as one C99 header with a portable reference of the per-sample
//! loop ([`c::header`]).
//!
//! # Rate
//!
//! The filters are exported at each model's own rate (2 kHz for the built-ins), the rate
//! they were fitted at: no re-design, so the exported float filter *is* the model. A
//! device that plays at a higher rate upsamples the filter's output (or the drive), as the
//! acquisition board of the paper samples at the analysis rate anyway. At 2 kHz the
//! lowest resonances (20 Hz) sit at `θ = 0.063` rad, 24 times further from `z = 1` than
//! at 48 kHz, which is what lets a 16-bit direct form hold them at all.
//!
//! # Design of the fixed-point cascade
//!
//! * **Ordering and pairing**: the fit's own sections, in its order: each pairs its
//!   poles with the zeros the fit placed next to them, which keeps every section's gain
//!   moderate.
//! * **Decay limit**: poles are first pulled in radially so that none rings longer
//!   than [`ExportConfig::longest_decay`] (0.5 s), the voice's own rule: several fits
//!   park a pole within `1e-7` of the unit circle, which no 16- or 32-bit direct form
//!   keeps inside it, and an actuator on skin must not ring for seconds anyway. The
//!   float reference of the check is this decay-limited filter.
//! * **Scaling**: by powers of two, for the drive the filter actually gets (a step's
//!   force pulse: impulse-like). Section `i` shifts its numerator sum right by the
//!   smallest `m_i` that keeps the peak of the impulse response from the cascade input to
//!   its output, `2^-(m_1+...+m_i) max_n |h_{1..i}\[n\]|`, at or below 1/2 (a factor 2 of
//!   headroom). L∞ scaling in frequency (no full-scale sinusoid ever overflows) was
//!   measured too: it costs 20-40 dB of signal level on the resonant built-ins (dirt:
//!   a gain of 128 instead of 1), which would bury the band edges in rounding noise. A
//!   sustained full-scale sinusoid at a resonance saturates instead, and saturation
//!   never wraps. The cascade's output is the model's times `2^-M`, `M = Σ m_i`;
//!   [`Exported::gain`] is `2^M`. (Q15 folds `2^-m_i` into its numerator's exponent.)
//! * **Quantisation**: Q31 coefficients rounded to nearest in Q(k).(31-k) with the
//!   smallest post-shift `k` that holds them; Q15 coefficients split into integer parts
//!   applied exactly and 16-bit remainders with their own exponents (see
//!   [`crate::signal::fixed`]), each rounded to nearest.
//! * **Error feedback** (Q31 only): per section, `[0, 0]` or `[round(-a1), round(-a2)]`,
//!   whichever gives the smaller output noise power (the error through
//!   `(1 - f_1 z^{-1} - f_2 z^{-2}) / A_i(z)` and every later section). The Q15 format
//!   needs none: its sections round to 32 bits.
//!
//! # The check
//!
//! A format passes when, for the quantised cascade:
//!
//! 1. every pole is strictly inside the unit circle and keeps at least half of the float
//!    filter's distance to it (`1 - |p|`), and
//! 2. its response, times the gain, is within [`ExportConfig::tolerance`] (0.5 dB) of the
//!    float (f64) model at [`ExportConfig::grid_points`] log-spaced frequencies over the
//!    band: from the quantised coefficients, and from the DFT of the impulse responses
//!    the fixed-point loop actually computes (until they have decayed by 120 dB), which
//!    adds the data path's rounding to the coefficients'. The impulses are fed at every
//!    one of [`ExportConfig::levels`] (0, -6, ..., -30 dBFS by default; rounded to the
//!    input format, and each response divided by the impulse actually fed), because
//!    rounding noise does not scale with the signal: a loop that is exact at full scale
//!    can be decibels off for a quiet step. `f32` is checked at full scale only (its
//!    rounding scales with the signal).
//!
//! The exporter refuses a library in which any material fails for a format it was asked
//! for, naming the material, the format, the worst frequency and the level of the
//! impulse that failed (or that the coefficients did).
//!
//! # Figures
//!
//! On the built-in library (2 kHz, 3 to 8 sections each), over impulses from 0 to
//! -30 dBFS: Q31 comes within 2e-3 dB of the float model on every material (5e-5 dB
//! from its coefficients), with pole margins unchanged to 1e-5; `f32` within 2e-3 dB.
//! Q15 comes within 0.15 dB from its coefficients and 0.18 dB from its computed impulse
//! responses at every level (worst: ice, 0.14 / 0.18 dB at -18 dBFS; sand 0.14 / 0.15
//! dB), and keeps at least 99.8 % of every pole margin: its 32-bit output is within
//! 0.05 dB of its own full-scale figure at every level.
//!
//! Before, the Q15 cascade rounded its output to 16 bits: 0.06-0.35 dB at 0 dBFS, but
//! 0.4-6.9 dB at -30 dBFS (sand 6.9, ice 5.0, hard 3.8), the same as the float model's
//! own impulse response rounded to 16 bits (sand 6.9, hard 3.8, ice 3.7 dB): a 16-bit
//! output cannot hold a quiet step's response at the band edges whatever computes it,
//! so the rounding is left to the DAC (see [`crate::signal::fixed`]).
//!
//! Synthetic cascades with every pole at the decay limit (radius `exp(-1/1000)` at
//! 20, 50 and 200 Hz) pass too: 0.02 dB with zeros pairing each pole, up to 0.24 dB
//! (Q15, a bare 20 Hz resonance falling 76 dB to 900 Hz, at -24 dBFS) without.
//!
//! Both fixed-point formats are exported by default ([`ExportConfig::q15`],
//! [`ExportConfig::q31`]). Q15 is the one for a 16-bit microcontroller: 16-bit
//! coefficients and 16 x 32-bit products (two 16 x 16 multiplies each) into a 64-bit
//! accumulator, against Q31's 32 x 32-bit products. `underfoot export` prints the
//! figures per material.

pub mod c;

use std::path::Path;

use crate::atomic_file::{AtomicWriteError, OutputFile, write_atomic};
use crate::material::{Library, MaterialModel};
use crate::numeric::dtft;
use crate::signal::fixed::{
    F32Section, F32State, Q15Section, Q15State, Q31Section, Q31State, f32_cascade, q15_cascade,
    q31_cascade, to_q15, to_q31,
};
use crate::signal::{Biquad, Sos};
use crate::units::{Band, Decibels, Hz, SampleRate, Seconds};

/// What can go wrong exporting a library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExportError {
    /// A material asked for is not in the library.
    #[error("material {name:?} is not in the library (it has: {available})")]
    UnknownMaterial {
        /// The name asked for.
        name: String,
        /// The names it has, comma-separated.
        available: String,
    },
    /// Nothing to export.
    #[error("the library has no materials to export")]
    Empty,
    /// A model's filter cannot be run (malformed rows, unstable, or its band does not fit).
    #[error("material {name:?}: {reason}")]
    BadModel {
        /// The material.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A fixed-point format fails the check.
    #[error(
        "material {name:?}: the {format} filter fails the check: {reason} \
         (worst deviation {worst_db:.3} dB at {worst_hz:.1} Hz, {}, tolerance {tolerance_db} dB)",
        where_text(.level)
    )]
    CheckFailed {
        /// The material.
        name: String,
        /// `Q15`, `Q31` or `f32`.
        format: &'static str,
        /// What failed.
        reason: String,
        /// The worst deviation over the band, in dB.
        worst_db: f64,
        /// Where it is.
        worst_hz: f64,
        /// The impulse level (dBFS) of the worst deviation; `None` when it is the
        /// coefficients' own response (or the poles) that fails.
        level: Option<Decibels>,
        /// The tolerance.
        tolerance_db: f64,
    },
    /// The header could not be written.
    #[error("writing the header")]
    Write(#[from] AtomicWriteError),
}

fn where_text(level: &Option<Decibels>) -> String {
    level.map_or_else(
        || "from the coefficients".to_string(),
        |l| format!("impulse at {} dBFS", l.0),
    )
}

/// How to export.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportConfig {
    /// Largest deviation from the float response allowed over the band (default 0.5 dB).
    pub tolerance: Decibels,
    /// Log-spaced frequencies over the band the check uses (default 256).
    pub grid_points: usize,
    /// The smallest fraction of the float filter's pole margin `1 - |p|` a quantised
    /// filter must keep (default 0.5).
    pub margin_fraction: f64,
    /// No pole rings longer than this (time to decay by `e`; default 0.5 s, the
    /// voice's [`longest_decay`](crate::synthesis::VoiceConfig::longest_decay)).
    pub longest_decay: Seconds,
    /// Export (and enforce the check for) Q15 (default true).
    pub q15: bool,
    /// Export (and enforce the check for) Q31 (default true).
    pub q31: bool,
    /// The impulse levels the fixed-point loops are checked at, in dBFS (default 0,
    /// -6, ..., -30): the range the exported figures hold for.
    pub levels: Vec<Decibels>,
}

/// The impulse levels checked by default: 0 to -30 dBFS in steps of 6 dB.
pub const DEFAULT_LEVELS: [f64; 6] = [0.0, -6.0, -12.0, -18.0, -24.0, -30.0];

/// The quietest level the check accepts: a Q15 impulse of at least one step.
pub const QUIETEST_LEVEL: Decibels = Decibels(-90.0);

impl Default for ExportConfig {
    fn default() -> Self {
        Self {
            tolerance: Decibels(0.5),
            grid_points: 256,
            margin_fraction: 0.5,
            longest_decay: Seconds(0.5),
            q15: true,
            q31: true,
            levels: DEFAULT_LEVELS.iter().map(|&l| Decibels(l)).collect(),
        }
    }
}

/// How close one format comes to the float model.
#[derive(Debug, Clone, PartialEq)]
pub struct FormatCheck {
    /// Worst deviation over the band of the quantised coefficients' response, in dB.
    pub coefficients_db: f64,
    /// Worst deviation over the band of the DFT of the computed impulse response, in
    /// dB, over every level checked.
    pub impulse_db: f64,
    /// Where the larger of the two is.
    pub worst_hz: Hz,
    /// The impulse level of the worst impulse deviation.
    pub worst_level: Decibels,
    /// Per level checked, in the order of [`ExportConfig::levels`].
    pub levels: Vec<LevelCheck>,
    /// `1 - |p|` of the pole nearest the unit circle.
    pub pole_margin: f64,
}

/// The computed impulse response at one level against the float model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelCheck {
    /// The impulse's level, in dBFS.
    pub level: Decibels,
    /// Worst deviation over the band, in dB.
    pub impulse_db: f64,
    /// Where it is.
    pub worst_hz: Hz,
}

impl FormatCheck {
    /// The larger of the two deviations.
    #[must_use]
    pub fn worst_db(&self) -> f64 {
        self.coefficients_db.max(self.impulse_db)
    }
}

/// One material ready for firmware.
#[derive(Debug, Clone, PartialEq)]
pub struct Exported {
    /// Its name in the library.
    pub name: String,
    /// The rate the filter runs at.
    pub rate: SampleRate,
    /// The band it was fitted in.
    pub band: Band,
    /// The model's output is `gain` times the cascade's (`2^M`, see the module doc).
    pub gain: f64,
    /// The scaled float sections (the reference every format is checked against).
    pub sections: Vec<Biquad>,
    /// In `f32`.
    pub f32: Vec<F32Section>,
    /// In Q15.
    pub q15: Vec<Q15Section>,
    /// In Q31.
    pub q31: Vec<Q31Section>,
    /// `1 - |p|` of the float model's pole nearest the unit circle.
    pub pole_margin: f64,
    /// The `f32` cascade against the model.
    pub f32_check: FormatCheck,
    /// The Q15 cascade against the model.
    pub q15_check: FormatCheck,
    /// The Q31 cascade against the model.
    pub q31_check: FormatCheck,
    /// Length of the impulse responses the check computed (until a 120 dB decay).
    pub impulse_samples: usize,
    /// Whether the Q15 sections are exported (asked for, and so checked).
    pub with_q15: bool,
    /// Whether the Q31 sections are exported.
    pub with_q31: bool,
}

/// A library ready for firmware: what [`c::header`] writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Export {
    /// Where the library came from (a path, or `built-in`).
    pub origin: String,
    /// SHA-256 of the library's JSON, lower-case hex: its identity.
    pub library_sha256: String,
    /// The materials, in library order.
    pub materials: Vec<Exported>,
}

/// Prepares and checks `names` (all materials when empty) of `library`.
///
/// # Errors
/// [`ExportError::UnknownMaterial`], [`ExportError::Empty`], and the errors of
/// [`prepare`] for the first material that fails.
pub fn export_library(
    library: &Library,
    origin: &str,
    names: &[String],
    config: &ExportConfig,
) -> Result<Export, ExportError> {
    let models: Vec<&MaterialModel> = if names.is_empty() {
        library.materials.iter().collect()
    } else {
        names
            .iter()
            .map(|n| {
                library
                    .materials
                    .iter()
                    .find(|m| &m.name == n)
                    .ok_or_else(|| ExportError::UnknownMaterial {
                        name: n.clone(),
                        available: library.names().join(", "),
                    })
            })
            .collect::<Result<_, _>>()?
    };
    if models.is_empty() {
        return Err(ExportError::Empty);
    }
    let materials = models
        .into_iter()
        .map(|m| prepare(m, config))
        .collect::<Result<_, _>>()?;
    Ok(Export {
        origin: origin.to_string(),
        library_sha256: sha256_hex(library.to_json().as_bytes()),
        materials,
    })
}

/// Writes `text` to `path` atomically (temporary file and rename).
///
/// # Errors
/// [`ExportError::Write`].
pub fn write(path: &Path, text: &str) -> Result<(), ExportError> {
    Ok(write_atomic(path, text.as_bytes())?)
}

/// Writes `text` to an output the caller checked against the output policy
/// ([`crate::atomic_file`]; `-` is standard output there).
///
/// # Errors
/// [`ExportError::Write`].
pub fn write_to(out: &OutputFile, text: &str) -> Result<(), ExportError> {
    Ok(out.write(text.as_bytes())?)
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Quantises one model in every format and checks each (see the module doc).
///
/// # Errors
/// [`ExportError::BadModel`] for a filter that cannot run, [`ExportError::CheckFailed`]
/// for a format that fails the check.
pub fn prepare(model: &MaterialModel, config: &ExportConfig) -> Result<Exported, ExportError> {
    let bad = |reason: String| ExportError::BadModel {
        name: model.name.clone(),
        reason,
    };
    let sos = model
        .sos()
        .ok_or_else(|| bad("a section has a0 = 0 or a non-finite coefficient".into()))?;
    if sos.sections.is_empty() {
        return Err(bad("the filter has no sections".into()));
    }
    if !sos.is_stable() {
        return Err(bad("the filter is unstable".into()));
    }
    if !model.band_hz.fits(model.sample_rate) {
        return Err(bad(format!(
            "band {} does not fit rate {}",
            model.band_hz, model.sample_rate
        )));
    }
    if !(config.grid_points >= 2
        && config.tolerance.0 > 0.0
        && config.margin_fraction >= 0.0
        && config.longest_decay.0 > 0.0
        && !config.levels.is_empty()
        && config
            .levels
            .iter()
            .all(|l| (QUIETEST_LEVEL.0..=0.0).contains(&l.0)))
    {
        return Err(bad(format!("invalid export settings {config:?}")));
    }

    let sos = limit_decay(&sos, model.sample_rate, config.longest_decay);
    let shifts = peak_shifts(&sos).ok_or_else(|| bad("its gain is not finite".into()))?;
    let total: u32 = shifts.iter().map(|&m| u32::from(m)).sum();
    let gain = 2f64.powi(total as i32);
    let scaled: Vec<Biquad> = sos
        .sections
        .iter()
        .zip(&shifts)
        .map(|(s, &m)| Biquad {
            b: s.b.map(|c| c / 2f64.powi(i32::from(m))),
            a: s.a,
        })
        .collect();
    let feedback = error_feedback(&scaled);

    let quantise_fail = |format: &'static str| ExportError::CheckFailed {
        name: model.name.clone(),
        format,
        reason: "a coefficient does not fit the format".into(),
        worst_db: f64::INFINITY,
        worst_hz: f64::NAN,
        level: None,
        tolerance_db: config.tolerance.0,
    };
    let q15 = sos
        .sections
        .iter()
        .zip(&shifts)
        .map(|(s, &m)| Q15Section::quantize(s.b, [s.a[1], s.a[2]], m))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| quantise_fail("Q15"))?;
    let q31 = sos
        .sections
        .iter()
        .zip(&shifts)
        .zip(&feedback)
        .map(|((s, &m), &f)| Q31Section::quantize(s.b, [s.a[1], s.a[2]], f, m))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| quantise_fail("Q31"))?;
    let f32: Vec<F32Section> = scaled
        .iter()
        .map(|s| F32Section::new(s.b, [s.a[1], s.a[2]]))
        .collect();

    let reference = Sos::new(scaled.clone());
    let pole_margin = margin(&reference);
    let checker = Checker::new(model, &reference, config);
    let represented = |pairs: Vec<([f64; 3], [f64; 2])>| {
        Sos::new(
            pairs
                .into_iter()
                .map(|(b, a)| Biquad {
                    b,
                    a: [1.0, a[0], a[1]],
                })
                .collect(),
        )
    };
    let n = impulse_length(&reference);
    // Each format's check: its coefficients' response, and the impulse responses its
    // own loop computes at every level. A format not asked for is still measured, for
    // the report, but cannot fail the export.
    let check = |format: &'static str,
                 coefficients: Vec<([f64; 3], [f64; 2])>,
                 impulses: Vec<(Decibels, Vec<f64>)>,
                 enforced: bool| {
        match checker.check(&model.name, format, &represented(coefficients), &impulses) {
            (_, Some(e)) if enforced => Err(e),
            (check, _) => Ok(check),
        }
    };

    // Each response is divided by the impulse actually fed (its level rounded to the
    // input format), so that it estimates the filter's, not the input's rounding.
    let q15_check = check(
        "Q15",
        q15.iter().map(Q15Section::coefficients).collect(),
        config
            .levels
            .iter()
            .map(|&level| {
                let x = to_q15(level.to_amplitude() as f32);
                let unit = f64::from(x) * 65536.0;
                let mut states = vec![Q15State::default(); q15.len()];
                let ir = impulse_response(n, |first| {
                    f64::from(q15_cascade(&q15, &mut states, if first { x } else { 0 })) / unit
                });
                (level, ir)
            })
            .collect(),
        config.q15,
    )?;
    let q31_check = check(
        "Q31",
        q31.iter().map(Q31Section::coefficients).collect(),
        config
            .levels
            .iter()
            .map(|&level| {
                let x = to_q31(level.to_amplitude());
                let mut states = vec![Q31State::default(); q31.len()];
                let ir = impulse_response(n, |first| {
                    f64::from(q31_cascade(&q31, &mut states, if first { x } else { 0 }))
                        / f64::from(x)
                });
                (level, ir)
            })
            .collect(),
        config.q31,
    )?;
    // Floating point scales with the level (up to its own rounding, 2^-24 relative):
    // one full-scale impulse tells it all.
    let mut states = vec![F32State::default(); f32.len()];
    let f32_check = check(
        "f32",
        f32.iter()
            .map(|s| (s.b.map(f64::from), [f64::from(s.a[0]), f64::from(s.a[1])]))
            .collect(),
        vec![(
            Decibels(0.0),
            impulse_response(n, |first| {
                f64::from(f32_cascade(
                    &f32,
                    &mut states,
                    if first { 1.0 } else { 0.0 },
                ))
            }),
        )],
        true,
    )?;

    Ok(Exported {
        name: model.name.clone(),
        rate: model.sample_rate,
        band: model.band_hz,
        gain,
        sections: scaled,
        f32,
        q15,
        q31,
        pole_margin,
        f32_check,
        q15_check,
        q31_check,
        impulse_samples: n,
        with_q15: config.q15,
        with_q31: config.q31,
    })
}

/// The cascade with every pole pulled in radially to decay within `longest` (the
/// voice's rule, [`crate::synthesis::ModalFilter::limit_decay`]); numerators unchanged.
fn limit_decay(sos: &Sos, rate: SampleRate, longest: Seconds) -> Sos {
    let max_radius = (-1.0 / (rate.hz() * longest.0)).exp();
    Sos::new(
        sos.sections
            .iter()
            .map(|s| {
                if s.poles().iter().all(|p| p.norm() <= max_radius) {
                    return *s;
                }
                let [p, q] = s.poles().map(|p| {
                    let r = p.norm();
                    if r > max_radius {
                        p * (max_radius / r)
                    } else {
                        p
                    }
                });
                Biquad {
                    b: s.b,
                    a: [1.0, -(p + q).re, (p * q).re],
                }
            })
            .collect(),
    )
}

/// `n` samples of a loop's impulse response; `tick(first)` runs one sample, `first` for
/// the impulse.
fn impulse_response(n: usize, mut tick: impl FnMut(bool) -> f64) -> Vec<f64> {
    (0..n).map(|i| tick(i == 0)).collect()
}

/// Samples of impulse response the check computes: until the slowest pole has decayed
/// by 120 dB, within `[4096, 2^17]`.
fn impulse_length(sos: &Sos) -> usize {
    let r = sos.poles().iter().map(|p| p.norm()).fold(0.0, f64::max);
    let n = if r > 0.0 && r < 1.0 {
        (1e-6f64.ln() / r.ln()).ceil()
    } else {
        0.0
    };
    (n as usize).clamp(4096, 1 << 17)
}

fn margin(sos: &Sos) -> f64 {
    1.0 - sos.poles().iter().map(|p| p.norm()).fold(0.0, f64::max)
}

/// The scaling shifts: see the module doc.
fn peak_shifts(sos: &Sos) -> Option<Vec<u8>> {
    let n = impulse_length(sos);
    let mut signal = vec![0.0; n];
    signal[0] = 1.0;
    let mut total = 0i32;
    let mut shifts = Vec::with_capacity(sos.sections.len());
    for s in &sos.sections {
        Sos::new(vec![*s]).filter_in_place(&mut signal);
        let peak = signal.iter().fold(0.0f64, |p, v| p.max(v.abs()));
        if !peak.is_finite() {
            return None;
        }
        // The smallest m with peak 2^-(total + m) <= 1/2 (a factor 2 of headroom for
        // drives that are not quite impulses); a section that attenuates does not shift
        // left (that would amplify its rounding instead of saving headroom).
        let needed = (2.0 * peak).log2().ceil() as i32 - total;
        let m = needed.clamp(0, 24);
        total += m;
        shifts.push(m as u8);
    }
    Some(shifts)
}

/// Per section, the error-feedback weights with the smaller output noise power.
fn error_feedback(sections: &[Biquad]) -> Vec<[i8; 2]> {
    const GRID: usize = 2048;
    let omegas: Vec<f64> = (0..GRID)
        .map(|i| std::f64::consts::PI * (i as f64 + 0.5) / GRID as f64)
        .collect();
    (0..sections.len())
        .map(|i| {
            let s = &sections[i];
            let shaped = [
                (-s.a[1]).round().clamp(-2.0, 2.0) as i8,
                (-s.a[2]).round().clamp(-2.0, 2.0) as i8,
            ];
            let power = |f: [i8; 2]| {
                let noise = Biquad {
                    b: [1.0, -f64::from(f[0]), -f64::from(f[1])],
                    a: s.a,
                };
                omegas
                    .iter()
                    .map(|&w| {
                        let later = sections[i + 1..]
                            .iter()
                            .fold(noise.response(w), |h, t| h * t.response(w));
                        later.norm_sqr()
                    })
                    .sum::<f64>()
            };
            if power(shaped) < power([0, 0]) {
                shaped
            } else {
                [0, 0]
            }
        })
        .collect()
}

/// The band grid and the float reference on it.
struct Checker {
    rate: SampleRate,
    grid: Vec<Hz>,
    reference: Vec<f64>,
    reference_margin: f64,
    tolerance: f64,
    margin_fraction: f64,
}

impl Checker {
    fn new(model: &MaterialModel, reference: &Sos, config: &ExportConfig) -> Self {
        let grid = model.band_hz.log_grid(config.grid_points);
        let rate = model.sample_rate;
        let reference_values = grid
            .iter()
            .map(|&f| reference.response(rate.omega(f)).norm())
            .collect();
        Self {
            rate,
            grid,
            reference: reference_values,
            reference_margin: margin(reference),
            tolerance: config.tolerance.0,
            margin_fraction: config.margin_fraction,
        }
    }

    /// Worst deviation (dB) and where, of magnitudes on the grid.
    fn worst(&self, magnitudes: impl Iterator<Item = f64>) -> (f64, Hz) {
        magnitudes
            .zip(&self.reference)
            .zip(&self.grid)
            .map(|((m, r), &f)| {
                let d = (20.0 * (m / r).log10()).abs();
                (if d.is_nan() { f64::INFINITY } else { d }, f)
            })
            .fold((0.0, Hz(f64::NAN)), |a, b| if b.0 > a.0 { b } else { a })
    }

    /// The check of one format: `impulses` are its computed impulse responses, each
    /// with its level, divided by the impulse fed.
    fn check(
        &self,
        name: &str,
        format: &'static str,
        coefficients: &Sos,
        impulses: &[(Decibels, Vec<f64>)],
    ) -> (FormatCheck, Option<ExportError>) {
        let (coefficients_db, coef_hz) = self.worst(
            self.grid
                .iter()
                .map(|&f| coefficients.response(self.rate.omega(f)).norm()),
        );
        let levels: Vec<LevelCheck> = impulses
            .iter()
            .map(|(level, ir)| {
                let (impulse_db, worst_hz) = self.worst(
                    self.grid
                        .iter()
                        .map(|&f| dtft(ir, self.rate.omega(f)).norm()),
                );
                LevelCheck {
                    level: *level,
                    impulse_db,
                    worst_hz,
                }
            })
            .collect();
        // The worst level; a NaN deviation (already mapped to infinity) wins.
        let worst_level = levels.iter().fold(None::<&LevelCheck>, |w, l| match w {
            Some(w) if w.impulse_db >= l.impulse_db => Some(w),
            _ => Some(l),
        });
        let (impulse_db, ir_hz, level) = worst_level
            .map_or((f64::NAN, Hz(f64::NAN), Decibels(0.0)), |l| {
                (l.impulse_db, l.worst_hz, l.level)
            });
        let impulse_worse = impulse_db > coefficients_db;
        let worst_hz = if impulse_worse { ir_hz } else { coef_hz };
        let check = FormatCheck {
            coefficients_db,
            impulse_db,
            worst_hz,
            worst_level: level,
            levels,
            pole_margin: margin(coefficients),
        };
        let fail = |reason: String, at_level: bool| ExportError::CheckFailed {
            name: name.to_string(),
            format,
            reason,
            worst_db: check.worst_db(),
            worst_hz: worst_hz.0,
            level: at_level.then_some(level),
            tolerance_db: self.tolerance,
        };
        if !(check.pole_margin > 0.0
            && check.pole_margin >= self.margin_fraction * self.reference_margin)
        {
            let e = fail(
                format!(
                    "a pole moved to {:.6} from the unit circle (the float filter's is {:.6})",
                    check.pole_margin, self.reference_margin
                ),
                false,
            );
            return (check, Some(e));
        }
        if check.worst_db().is_nan() || check.worst_db() > self.tolerance {
            let e = fail(
                "its response is too far from the float filter's".into(),
                impulse_worse,
            );
            return (check, Some(e));
        }
        (check, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::builtin::builtin;

    #[test]
    fn every_format_of_every_builtin_passes_and_gain_undoes_the_scaling() {
        // The figures first, whatever they are (the module doc quotes them).
        let loose = ExportConfig {
            tolerance: Decibels(1e3),
            margin_fraction: 0.0,
            ..ExportConfig::default()
        };
        let e = export_library(builtin(), "built-in", &[], &loose).unwrap();
        for m in &e.materials {
            let (q15, q31) = (&m.q15_check, &m.q31_check);
            let per_level = |c: &FormatCheck| {
                c.levels
                    .iter()
                    .map(|l| format!("{:.3}", l.impulse_db))
                    .collect::<Vec<_>>()
                    .join(" ")
            };
            eprintln!(
                "{:<8} impulse dB at {:?} dBFS: Q15 {}; Q31 {}; 16-bit output of the float model {}",
                m.name,
                DEFAULT_LEVELS,
                per_level(q15),
                per_level(q31),
                rounded_float_figures(builtin().get(&m.name).unwrap(), m)
            );
            eprintln!(
                "{:<8} Q15 {:.3e}/{:.3e} dB margin {:.3e}; Q31 {:.1e}/{:.1e} dB; \
                 f32 {:.1e}/{:.1e} dB; float margin {:.3e}",
                m.name,
                q15.coefficients_db,
                q15.impulse_db,
                q15.pole_margin,
                q31.coefficients_db,
                q31.impulse_db,
                m.f32_check.coefficients_db,
                m.f32_check.impulse_db,
                m.pole_margin
            );
        }
        let e = export_library(builtin(), "built-in", &[], &ExportConfig::default()).unwrap();
        assert_eq!(e.materials.len(), builtin().materials.len());
        for m in &e.materials {
            assert!(m.with_q15 && m.with_q31);
            for check in [&m.q15_check, &m.q31_check, &m.f32_check] {
                assert!(check.worst_db() <= 0.5 && check.pole_margin > 0.0);
            }
            // Every level of 0..-30 dBFS, each within the tolerance.
            for check in [&m.q15_check, &m.q31_check] {
                let levels: Vec<f64> = check.levels.iter().map(|l| l.level.0).collect();
                assert_eq!(levels, DEFAULT_LEVELS, "{}", m.name);
                assert!(
                    check.levels.iter().all(|l| l.impulse_db <= 0.5),
                    "{}",
                    m.name
                );
            }
            // The scaled sections times the gain are the (decay-limited) model.
            let model = builtin().get(&m.name).unwrap();
            let f = model.band_hz.log_grid(3)[1];
            let w = model.sample_rate.omega(f);
            let limited = limit_decay(&model.sos().unwrap(), model.sample_rate, Seconds(0.5));
            let ratio = Sos::new(m.sections.clone()).response(w).norm() * m.gain
                / limited.response(w).norm();
            assert!((ratio - 1.0).abs() < 1e-12, "{}: {ratio}", m.name);
        }
    }

    #[test]
    fn a_failing_format_is_refused_naming_material_and_frequency() {
        // Q15 of a 16th-order fit at a tolerance no 16-bit output can meet.
        let config = ExportConfig {
            q15: true,
            tolerance: Decibels(1e-3),
            ..ExportConfig::default()
        };
        let err = prepare(builtin().get("gravel").unwrap(), &config).unwrap_err();
        let ExportError::CheckFailed {
            name,
            format,
            worst_db,
            worst_hz,
            ..
        } = &err
        else {
            panic!("{err}");
        };
        assert_eq!((name.as_str(), *format), ("gravel", "Q15"));
        assert!(*worst_db > 1e-3 && (20.0..=900.0).contains(worst_hz));
        let text = err.to_string();
        assert!(text.contains("gravel") && text.contains("Q15") && text.contains(" Hz"));
    }

    /// The worst deviation (dB) at each default level of the float model's own impulse
    /// response, scaled as exported and rounded to Q15: what a 16-bit output costs any
    /// filter (the reason the Q15 cascade's output stays 32-bit).
    fn rounded_float_figures(model: &MaterialModel, m: &Exported) -> String {
        let reference = Sos::new(m.sections.clone());
        let checker = Checker::new(model, &reference, &ExportConfig::default());
        let mut unit = vec![0.0; m.impulse_samples];
        unit[0] = 1.0;
        reference.filter_in_place(&mut unit);
        DEFAULT_LEVELS
            .iter()
            .map(|&l| {
                let x = f64::from(to_q15(Decibels(l).to_amplitude() as f32));
                let ir: Vec<f64> = unit.iter().map(|h| (h * x).round() / x).collect();
                let (d, _) = checker.worst(
                    checker
                        .grid
                        .iter()
                        .map(|&f| dtft(&ir, checker.rate.omega(f)).norm()),
                );
                format!("{d:.2}")
            })
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// A built-in model with its filter replaced: poles at the decay limit (radius
    /// `exp(-1/(0.5 s 2 kHz))`) at each of `hz`; zeros at DC and Nyquist (`floor`
    /// `None`: a bare resonance) or at the poles' angles and radius `floor` (a
    /// resonance over a flat floor, as the fits pair them).
    fn at_the_decay_limit(hz: &[f64], floor: Option<f64>) -> MaterialModel {
        let mut model = builtin().get("hard").unwrap().clone();
        assert_eq!(model.sample_rate, SampleRate(2000));
        let r = (-1.0f64 / 1000.0).exp();
        let sos = Sos::new(
            hz.iter()
                .map(|&f| {
                    let th = std::f64::consts::TAU * f / 2000.0;
                    let b = match floor {
                        // About unit peak gain.
                        None => [1.0 - r, 0.0, r - 1.0],
                        Some(z) => [1.0, -2.0 * z * th.cos(), z * z],
                    };
                    Biquad {
                        b,
                        a: [1.0, -2.0 * r * th.cos(), r * r],
                    }
                })
                .collect(),
        );
        model.order = sos.order();
        model.filter = crate::material::FilterCoefficients::from_sos(&sos);
        model.name = format!("limit-{hz:?}");
        model
    }

    #[test]
    fn cascades_with_poles_at_the_decay_limit_pass_at_every_level() {
        // Not the built-ins' particular coefficients: the slowest poles any model may
        // hold, low in the band where the 16-bit remainders are the finest.
        // A cascade of the bare resonances spans some 170 dB over the band (each falls
        // 60-76 dB from its peak to 900 Hz), beyond any 32-bit format; the fits pair
        // each resonance with zeros, as `floor` does (peaks of 26-34 dB over it).
        let cases = [
            (&[20.0][..], None),
            (&[50.0], None),
            (&[200.0], None),
            (&[20.0], Some(0.95)),
            (&[20.0, 50.0, 200.0], Some(0.95)),
            (&[200.0, 20.0, 50.0], Some(0.9)),
        ];
        for (hz, floor) in cases {
            let model = at_the_decay_limit(hz, floor);
            let m =
                prepare(&model, &ExportConfig::default()).unwrap_or_else(|e| panic!("{hz:?}: {e}"));
            for check in [&m.q15_check, &m.q31_check] {
                assert_eq!(check.levels.len(), DEFAULT_LEVELS.len());
                eprintln!(
                    "{hz:?}: coefficients {:.4} dB, impulses {:?}",
                    check.coefficients_db,
                    check
                        .levels
                        .iter()
                        .map(|l| l.impulse_db)
                        .collect::<Vec<_>>()
                );
                assert!(check.worst_db() <= 0.5 && check.pole_margin > 0.0, "{hz:?}");
            }
        }
    }

    #[test]
    fn a_level_that_fails_is_named() {
        // An oracle: the reference's own impulse response passes at every level; one
        // level doubled (+6 dB) must fail, and the error names that level.
        let model = builtin().get("hard").unwrap();
        let config = ExportConfig::default();
        let m = prepare(model, &config).unwrap();
        let reference = Sos::new(m.sections.clone());
        let checker = Checker::new(model, &reference, &config);
        let mut ir = vec![0.0; m.impulse_samples];
        ir[0] = 1.0;
        reference.filter_in_place(&mut ir);
        let mut impulses: Vec<(Decibels, Vec<f64>)> =
            config.levels.iter().map(|&l| (l, ir.clone())).collect();
        let (ok, err) = checker.check("hard", "Q15", &reference, &impulses);
        assert!(err.is_none() && ok.impulse_db < 1e-3, "{ok:?}");
        impulses[3].1.iter_mut().for_each(|v| *v *= 2.0);
        let (bad, err) = checker.check("hard", "Q15", &reference, &impulses);
        assert_eq!(bad.worst_level, Decibels(-18.0));
        assert!((bad.impulse_db - 20.0 * 2f64.log10()).abs() < 1e-3);
        let err = err.unwrap();
        assert!(
            matches!(&err, ExportError::CheckFailed { level: Some(l), format: "Q15", .. } if l.0 == -18.0),
            "{err}"
        );
        let text = err.to_string();
        assert!(
            text.contains("hard") && text.contains("-18 dBFS") && text.contains(" Hz"),
            "{text}"
        );
    }

    #[test]
    fn levels_outside_the_range_are_refused() {
        for levels in [
            vec![],
            vec![Decibels(3.0)],
            vec![Decibels(-100.0)],
            vec![Decibels(f64::NAN)],
        ] {
            let config = ExportConfig {
                levels,
                ..ExportConfig::default()
            };
            let err = prepare(builtin().get("hard").unwrap(), &config).unwrap_err();
            assert!(matches!(err, ExportError::BadModel { .. }), "{err}");
        }
    }

    #[test]
    fn unknown_material_and_bad_model_are_errors() {
        let names = vec!["lava".to_string()];
        let err = export_library(builtin(), "built-in", &names, &ExportConfig::default());
        assert!(matches!(err, Err(ExportError::UnknownMaterial { .. })));
        let mut model = builtin().get("sand").unwrap().clone();
        model.filter.sos[0][4] = -2.5; // a pole outside the unit circle
        model.filter.sos[0][5] = 1.5;
        let err = prepare(&model, &ExportConfig::default()).unwrap_err();
        assert!(matches!(err, ExportError::BadModel { .. }), "{err}");
        let empty = crate::material::Library::new();
        assert!(matches!(
            export_library(&empty, "x", &[], &ExportConfig::default()),
            Err(ExportError::Empty)
        ));
    }
}
