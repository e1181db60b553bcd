//! Quantising one material: the decay limit, the scaling, and the coefficients in `f32`,
//! Q15 and Q31, each checked ([`mod@super::check`]); and its excitation's tables at its
//! rate, which need no quantising (the generator's own `f64` and `f32` values).
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

use super::check::{Checker, FormatCheck, margin};
use super::{ExportConfig, ExportError, QUIETEST_LEVEL};
use crate::excitation::Tables;
use crate::material::MaterialModel;
use crate::signal::fixed::{
    F32Section, F32State, Q15Section, Q15State, Q31Section, Q31State, f32_cascade, q15_cascade,
    q31_cascade, to_q15, to_q31,
};
use crate::signal::{Biquad, Sos};
use crate::units::{Band, Decibels, SampleRate, Seconds};

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
    /// Its excitation at its rate (the heel impulse alone for a material without one):
    /// the tables the header's generator plays.
    pub excitation: Tables,
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
    let excitation = Tables::new(&model.excitation_or_heel(), model.sample_rate)
        .map_err(|e| bad(e.to_string()))?;
    if !(config.tolerance.0 > 0.0
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
    let n = impulse_length(&reference);
    let mut checker = Checker::new(model, &reference, config, n);
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
    // Each format's check: its coefficients' response, and the impulse responses its
    // own loop computes at every level. A format not asked for is still measured, for
    // the report, but cannot fail the export.
    let mut check = |format: &'static str,
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
        excitation,
    })
}

/// The cascade with every pole pulled in radially to decay within `longest` (the
/// voice's rule, [`crate::synthesis::ModalFilter::limit_decay`]); numerators unchanged.
pub(super) fn limit_decay(sos: &Sos, rate: SampleRate, longest: Seconds) -> Sos {
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
