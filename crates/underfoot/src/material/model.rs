//! One material model: a fitted IIR filter and the record of its fit.

use serde::{Deserialize, Serialize};

use crate::analysis::steps::StepSummary;
use crate::excitation::ExcitationModel;
use crate::fit::metrics::WorstDeviation;
use crate::signal::{Biquad, Sos};
use crate::units::{Band, SampleRate, Seconds};

/// A fitted ground material, as stored in a library file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaterialModel {
    /// Unique name in its library (e.g. `gravel`).
    pub name: String,
    /// The analysis rate the filter runs at.
    pub sample_rate: SampleRate,
    /// The band the response was measured and fitted in.
    pub band_hz: Band,
    /// Filter order (number of poles).
    pub order: usize,
    /// The filter.
    pub filter: FilterCoefficients,
    /// How well it fits.
    pub fit: FitRecord,
    /// The recordings it was fitted from.
    pub sources: Vec<SourceFile>,
    /// The physical model calibrated from the same recordings, when there is one
    /// (`--model physical`). Files written before it existed simply lack it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physical: Option<crate::physical::PhysicalModel>,
    /// What drives a step: the heel impact and its train of micro-impacts, fitted from the
    /// recordings ([`crate::excitation`]). Absent in files before format 3, whose
    /// materials play one impulse per step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excitation: Option<ExcitationModel>,
    /// The recordings' steps measured in time (duration, micro-events, crest factor,
    /// decay, spread between steps), for comparison with what plays. Format 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<StepSummary>,
    /// The playback level relative to the recorded level, in dB
    /// ([`super::level`]): 0 in files before format 3.
    #[serde(default)]
    pub level_db: f64,
}

/// A filter both as second-order sections (what runs) and expanded (for interchange).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FilterCoefficients {
    /// Rows `[b0, b1, b2, a0, a1, a2]`, cascaded.
    pub sos: Vec<[f64; 6]>,
    /// Expanded numerator, coefficients of `z^0, z^-1, ...`.
    pub b: Vec<f64>,
    /// Expanded denominator, `a[0] = 1`.
    pub a: Vec<f64>,
}

impl FilterCoefficients {
    /// The coefficients of a cascade.
    #[must_use]
    pub fn from_sos(sos: &Sos) -> Self {
        let (b, a) = sos.to_ba();
        Self {
            sos: sos.sections.iter().map(Biquad::to_row).collect(),
            b,
            a,
        }
    }

    /// The cascade, or `None` when a row has `a0 = 0` or a non-finite coefficient.
    #[must_use]
    pub fn to_sos(&self) -> Option<Sos> {
        self.sos
            .iter()
            .map(|r| Biquad::from_row(*r))
            .collect::<Option<Vec<_>>>()
            .map(Sos::new)
    }
}

/// The evidence of a fit, on the 96-point log-frequency grid of the band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FitRecord {
    /// The grid, in hertz.
    pub grid_hz: Vec<f64>,
    /// Measured magnitude on the grid.
    pub measured: Vec<f64>,
    /// Model magnitude on the grid.
    pub model: Vec<f64>,
    /// Normalised RMS error of equation (3) on the magnitude (lower is better; 0 is exact).
    pub nrmse: f64,
    /// RMS log-spectral distance in decibels.
    pub lsd_db: f64,
    /// How the winning fit was found (e.g. `vector-fit+gauss-newton(log)`).
    #[serde(default)]
    pub method: String,
    /// The fit is above the quality bound ([`super::quality`]) and was kept on request
    /// (`fit --accept-poor-fit`). Absent, and false, for every fit that passed.
    #[serde(default, skip_serializing_if = "is_false")]
    pub poor_fit: bool,
    /// Number of heel strikes averaged into the measured response.
    #[serde(default)]
    pub strikes: usize,
    /// Wall-clock time of the fit, order search included, in seconds.
    #[serde(default)]
    pub fit_seconds: f64,
    /// The longest e-fold decay any pole of the filter may have: the fit searched only
    /// inside it, so the voice plays the filter as stored. Files of format 1 lack it and
    /// are read as 0.5 s, the limit their voice applied (see [`super::library`]).
    #[serde(rename = "longest_decay_s", default = "legacy_decay")]
    pub longest_decay: Seconds,
    /// The worst deviation of the model from the measured response in the band, on a dense
    /// grid ([`crate::fit::metrics::worst_deviation`]); absent in files of format 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst: Option<WorstDeviation>,
}

/// The decay limit the voice applied to every model before it was stored with the model.
pub const LEGACY_DECAY: Seconds = Seconds(0.5);

fn legacy_decay() -> Seconds {
    LEGACY_DECAY
}

// By reference because serde's `skip_serializing_if` passes one.
fn is_false(b: &bool) -> bool {
    !*b
}

/// One recording a model was fitted from.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SourceFile {
    /// File name.
    pub file: String,
    /// SHA-256 of its bytes, lower-case hex.
    pub sha256: String,
}

impl MaterialModel {
    /// The material's excitation, or one impulse per step for a material fitted before
    /// the excitation existed.
    #[must_use]
    pub fn excitation_or_heel(&self) -> ExcitationModel {
        self.excitation
            .clone()
            .unwrap_or_else(ExcitationModel::heel_only)
    }

    /// The filter as a runnable cascade.
    ///
    /// A model that passed [`Library`](super::Library) validation always has one; `None`
    /// only for a hand-built model with malformed rows.
    #[must_use]
    pub fn sos(&self) -> Option<Sos> {
        self.filter.to_sos()
    }

    /// The slowest e-fold decay among the filter's poles (infinite for a malformed filter).
    #[must_use]
    pub fn slowest_decay(&self) -> Seconds {
        let radius = self.sos().map_or(f64::INFINITY, |s| {
            s.poles().iter().map(|p| p.norm()).fold(0.0, f64::max)
        });
        crate::fit::decay_time(self.sample_rate, radius)
    }
}
