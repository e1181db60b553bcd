//! Firmware export: a library's materials as second-order sections in `f32`, Q15 and Q31,
//! checked, with the excitation that drives them, written as one C99 header with a
//! portable reference of the per-sample loops ([`c::header`]).
//!
//! # Rate
//!
//! The filters are exported at each model's own rate (2 kHz for the built-ins), the rate
//! they were fitted at: no re-design, so the exported float filter *is* the model. A
//! device that plays at a higher rate upsamples the filter's output (or the drive), as the
//! acquisition board of the IIR paper samples at the analysis rate anyway. At 2 kHz the
//! lowest resonances (20 Hz) sit at `θ = 0.063` rad, 24 times further from `z = 1` than
//! at 48 kHz, which is what lets a 16-bit direct form hold them at all.
//!
//! # The pipeline
//!
//! Each material is [quantised](mod@quantise): its poles pulled in to the decay limit,
//! its sections scaled by powers of two, its coefficients rounded to each format; then
//! each format is [checked](mod@check) against the float model, and the exporter refuses a
//! library in which any material fails for a format it was asked for. The
//! [library's export](mod@library) bundles the materials with the library's identity for
//! [`c::header`]. Each material also takes its excitation's [`Tables`](crate::excitation::Tables)
//! at its rate (the heel impulse alone for a material without one), which the header's
//! generator plays bit for bit as [`crate::excitation::Generator`] does (see [`c`]).
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
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the settings ([`ExportConfig`]) and the errors ([`ExportError`]) |
//! | [`quantise`](mod@quantise) | one material in `f32`, Q15 and Q31: decay limit, scaling, rounding, error feedback; its excitation's tables |
//! | [`check`](mod@check) | the check of a quantised cascade against the float model |
//! | [`library`](mod@library) | the export of a library, and writing the header |
//! | [`c`](mod@c) | the C99 header, the excitation's generator included |

pub mod c;
pub mod check;
pub mod library;
pub mod quantise;

pub use check::{FormatCheck, LevelCheck};
pub use library::{Export, export_library, write, write_to};
pub use quantise::{Exported, prepare};

use crate::atomic_file::AtomicWriteError;
use crate::units::{Decibels, Seconds};

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
            margin_fraction: 0.5,
            longest_decay: Seconds(0.5),
            q15: true,
            q31: true,
            levels: DEFAULT_LEVELS.iter().map(|&l| Decibels(l)).collect(),
        }
    }
}

#[cfg(test)]
mod tests;
