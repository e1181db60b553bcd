//! The rules of the format for one material, checked on every load and save.
//!
//! * `filter.sos` is what runs; `b`/`a` are the same filter expanded, for interchange with
//!   other tools, and must agree with `sos` (relative tolerance [`BA_TOLERANCE`]).
//! * `order` is the number of poles: two per section, one per first-order section
//!   (`a2 = b2 = 0`).
//! * Every section must be stable (both poles strictly inside the unit circle): a library
//!   is played back on a device, and an unstable filter there is a loud, growing tone.
//! * **Decay limit.** No pole may ring longer than `fit.longest_decay_s`: a pole of
//!   radius `r` at rate `f_s` decays by `e` in `-1 / (f_s ln r)` seconds.
//! * `fit` holds the evidence of the fit on a log-frequency grid: three arrays of one
//!   length, and finite, non-negative metrics.
//! * Names are 1 to [`MAX_NAME_LEN`] ASCII letters, digits, `-`, `_` and `.`
//!   ([`validate_name`]).

use crate::material::{FitRecord, MaterialModel};
use crate::physical::PhysicalError;
use crate::signal::{Biquad, Sos};
use crate::units::{Hz, SampleRate};

/// How closely the expanded `b`/`a` must match the expansion of `sos`, relative to the
/// largest coefficient of each polynomial.
///
/// Loose enough for an expansion done by another tool in another order of operations,
/// tight enough that a hand-edited or stale coefficient is caught.
pub const BA_TOLERANCE: f64 = 1e-8;

/// The longest material name, in bytes.
pub const MAX_NAME_LEN: usize = 64;

/// What is wrong with a material name ([`validate_name`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum NameError {
    /// No characters at all.
    #[error("name is empty")]
    Empty,
    /// Longer than [`MAX_NAME_LEN`] bytes.
    #[error("name is {len} bytes long, more than {MAX_NAME_LEN}")]
    TooLong {
        /// Its length in bytes.
        len: usize,
    },
    /// A character outside the allowed set.
    #[error("name contains {0:?}: use letters, digits, '-', '_' or '.'")]
    Character(char),
}

/// What is wrong with one material ([`validate_model`]): the first rule of the format it
/// breaks, naming the field.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// The name breaks [`validate_name`].
    #[error(transparent)]
    Name(#[from] NameError),
    /// The physical model is invalid.
    #[error("physical model: {0}")]
    Physical(#[source] PhysicalError),
    /// The excitation is invalid.
    #[error("{0}")]
    Excitation(#[source] crate::excitation::ExcitationError),
    /// The playback level is not a finite number of decibels in range.
    #[error("level_db {0} must be between -120 and +40 dB")]
    Level(f64),
    /// `sample_rate` is zero.
    #[error("sample_rate is 0")]
    ZeroRate,
    /// The band does not fit below the Nyquist frequency.
    #[error("band_hz [{}, {}] does not fit sample_rate {rate} (need 0 < lo < hi < {})",
        lo.0, hi.0, rate.nyquist())]
    Band {
        /// The band's lower edge.
        lo: Hz,
        /// The band's upper edge.
        hi: Hz,
        /// The model's rate.
        rate: SampleRate,
    },
    /// `filter.sos` is empty.
    #[error("filter.sos has no sections")]
    NoSections,
    /// A coefficient is NaN or infinite.
    #[error("filter.sos[{section}][{coefficient}] is not finite")]
    NotFinite {
        /// The row.
        section: usize,
        /// The column.
        coefficient: usize,
    },
    /// A row's `a0` is zero.
    #[error("filter.sos[{section}] has a0 = 0")]
    ZeroA0 {
        /// The row.
        section: usize,
    },
    /// A section with a pole on or outside the unit circle.
    #[error("filter.sos[{section}] is an unstable section: pole radius {radius:.6} (must be < 1)")]
    Unstable {
        /// The row.
        section: usize,
        /// The largest pole radius.
        radius: f64,
    },
    /// `order` is not the number of poles of `filter.sos`.
    #[error("order is {order} but filter.sos has {poles} poles ({sections} sections)")]
    Order {
        /// The order stored.
        order: usize,
        /// The poles of the sections.
        poles: usize,
        /// The number of sections.
        sections: usize,
    },
    /// `fit.longest_decay_s` is out of range.
    #[error("fit.longest_decay_s = {0} must be in (0, 60] s")]
    DecayLimit(f64),
    /// A pole rings longer than `fit.longest_decay_s`.
    #[error(
        "filter.sos[{section}] has a pole at {frequency:.1} Hz that decays by e in {decay:.3} s, \
         longer than the model's limit fit.longest_decay_s = {limit} s (refit it)"
    )]
    BeyondDecayLimit {
        /// The row.
        section: usize,
        /// The pole's frequency in hertz.
        frequency: f64,
        /// Its e-fold decay in seconds.
        decay: f64,
        /// The limit in seconds.
        limit: f64,
    },
    /// `filter.b` or `filter.a` is not as long as the expansion of `sos`.
    #[error("{field} has {stored} coefficients but filter.sos expands to {expected}")]
    ExpandedLength {
        /// `filter.b` or `filter.a`.
        field: &'static str,
        /// Its length.
        stored: usize,
        /// The length of the expansion.
        expected: usize,
    },
    /// A coefficient of `filter.b` or `filter.a` differs from the expansion of `sos`.
    #[error("{field}[{index}] is {stored} but filter.sos expands to {expected} (they must agree)")]
    Expanded {
        /// `filter.b` or `filter.a`.
        field: &'static str,
        /// The coefficient.
        index: usize,
        /// Its value.
        stored: f64,
        /// The expansion's.
        expected: f64,
    },
    /// The fit record's arrays differ in length.
    #[error("fit arrays differ in length: grid_hz {grid}, measured {measured}, model {model}")]
    FitLengths {
        /// `grid_hz`'s length.
        grid: usize,
        /// `measured`'s length.
        measured: usize,
        /// `model`'s length.
        model: usize,
    },
    /// A grid frequency is not positive and finite.
    #[error("fit.grid_hz[{index}] = {value} is not a positive frequency")]
    FitFrequency {
        /// The point.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// The grid is not strictly increasing.
    #[error("fit.grid_hz is not increasing at index {0}")]
    FitNotIncreasing(usize),
    /// A magnitude is negative or not finite.
    #[error("fit.{field}[{index}] = {value} is not a finite, non-negative magnitude")]
    FitMagnitude {
        /// `measured` or `model`.
        field: &'static str,
        /// The point.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A metric is negative or not finite.
    #[error("fit.{field} = {value} is not finite and non-negative")]
    FitMetric {
        /// `nrmse`, `lsd_db` or `fit_seconds`.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A source names no file.
    #[error("sources[{0}].file is empty")]
    SourceFile(usize),
    /// A source's digest is not a SHA-256 in lower-case hex.
    #[error("sources[{index}].sha256 {sha256:?} is not 64 lower-case hex digits")]
    SourceDigest {
        /// The source.
        index: usize,
        /// The digest stored.
        sha256: String,
    },
}

/// Checks one material against the rules of the format (see the [module docs](self)).
///
/// Used by [`Library`](super::Library) on every load and save, and usable on a freshly
/// built model.
///
/// # Errors
/// The first problem found, naming the field, e.g.
/// `filter.sos[1]: unstable section: pole radius 1.02 (must be < 1)`.
pub fn validate_model(m: &MaterialModel) -> Result<(), ModelError> {
    validate_name(&m.name)?;
    if let Some(p) = &m.physical {
        p.validate().map_err(ModelError::Physical)?;
    }
    if let Some(e) = &m.excitation {
        e.validate().map_err(ModelError::Excitation)?;
    }
    if !(m.level_db.is_finite() && (-120.0..=40.0).contains(&m.level_db)) {
        return Err(ModelError::Level(m.level_db));
    }
    if m.sample_rate.0 == 0 {
        return Err(ModelError::ZeroRate);
    }
    if !m.band_hz.fits(m.sample_rate) {
        return Err(ModelError::Band {
            lo: m.band_hz.lo,
            hi: m.band_hz.hi,
            rate: m.sample_rate,
        });
    }
    let sos = validate_sections(&m.filter.sos)?;
    if m.order != sos.order() {
        return Err(ModelError::Order {
            order: m.order,
            poles: sos.order(),
            sections: sos.sections.len(),
        });
    }
    let limit = m.fit.longest_decay;
    if !(limit.0 > 0.0 && limit.0 <= 60.0) {
        return Err(ModelError::DecayLimit(limit.0));
    }
    // The coefficients round-trip exactly through JSON; the slack is for a file written by
    // another tool.
    let rho = crate::fit::decay_radius(m.sample_rate, limit);
    for (i, s) in sos.sections.iter().enumerate() {
        if let Some(p) = s.poles().iter().find(|p| p.norm() > rho * (1.0 + 1e-12)) {
            return Err(ModelError::BeyondDecayLimit {
                section: i,
                frequency: p.arg().abs() * m.sample_rate.hz() / std::f64::consts::TAU,
                decay: crate::fit::decay_time(m.sample_rate, p.norm()).0,
                limit: limit.0,
            });
        }
    }
    let (b, a) = sos.to_ba();
    check_expanded("filter.b", &m.filter.b, &b)?;
    check_expanded("filter.a", &m.filter.a, &a)?;
    validate_fit(&m.fit)?;
    for (i, s) in m.sources.iter().enumerate() {
        if s.file.is_empty() {
            return Err(ModelError::SourceFile(i));
        }
        let hex = |c: char| c.is_ascii_digit() || ('a'..='f').contains(&c);
        if s.sha256.len() != 64 || !s.sha256.chars().all(hex) {
            return Err(ModelError::SourceDigest {
                index: i,
                sha256: s.sha256.clone(),
            });
        }
    }
    Ok(())
}

/// Checks a material name: 1 to [`MAX_NAME_LEN`] ASCII letters, digits, `-`, `_` and `.`.
///
/// The one rule for names, whether they come from `fit`, a library file or the API.
///
/// # Errors
/// What is wrong with the name.
pub fn validate_name(name: &str) -> Result<(), NameError> {
    if name.is_empty() {
        return Err(NameError::Empty);
    }
    if name.len() > MAX_NAME_LEN {
        return Err(NameError::TooLong { len: name.len() });
    }
    // Names end up as command-line arguments and file names; keep them to characters
    // that need no quoting anywhere.
    if let Some(c) = name
        .chars()
        .find(|&c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        return Err(NameError::Character(c));
    }
    Ok(())
}

fn validate_sections(rows: &[[f64; 6]]) -> Result<Sos, ModelError> {
    if rows.is_empty() {
        return Err(ModelError::NoSections);
    }
    let mut sections = Vec::with_capacity(rows.len());
    for (i, row) in rows.iter().enumerate() {
        if let Some(k) = row.iter().position(|c| !c.is_finite()) {
            return Err(ModelError::NotFinite {
                section: i,
                coefficient: k,
            });
        }
        let Some(s) = Biquad::from_row(*row) else {
            return Err(ModelError::ZeroA0 { section: i });
        };
        if !s.is_stable() {
            let radius = s.poles().iter().map(|p| p.norm()).fold(0.0, f64::max);
            return Err(ModelError::Unstable { section: i, radius });
        }
        sections.push(s);
    }
    Ok(Sos::new(sections))
}

fn check_expanded(field: &'static str, stored: &[f64], expected: &[f64]) -> Result<(), ModelError> {
    if stored.len() != expected.len() {
        return Err(ModelError::ExpandedLength {
            field,
            stored: stored.len(),
            expected: expected.len(),
        });
    }
    let scale = expected
        .iter()
        .fold(0.0f64, |m, c| m.max(c.abs()))
        .max(f64::MIN_POSITIVE);
    for (k, (s, e)) in stored.iter().zip(expected).enumerate() {
        let close = (s - e).abs() <= BA_TOLERANCE * scale;
        // A NaN compares false, so it fails here too.
        if !close {
            return Err(ModelError::Expanded {
                field,
                index: k,
                stored: *s,
                expected: *e,
            });
        }
    }
    Ok(())
}

fn validate_fit(fit: &FitRecord) -> Result<(), ModelError> {
    let n = fit.grid_hz.len();
    if fit.measured.len() != n || fit.model.len() != n {
        return Err(ModelError::FitLengths {
            grid: n,
            measured: fit.measured.len(),
            model: fit.model.len(),
        });
    }
    if let Some(k) = fit
        .grid_hz
        .iter()
        .position(|f| !(f.is_finite() && *f > 0.0))
    {
        return Err(ModelError::FitFrequency {
            index: k,
            value: fit.grid_hz[k],
        });
    }
    if let Some(k) = fit.grid_hz.windows(2).position(|w| w[1] <= w[0]) {
        return Err(ModelError::FitNotIncreasing(k + 1));
    }
    for (field, values) in [("measured", &fit.measured), ("model", &fit.model)] {
        if let Some(k) = values.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(ModelError::FitMagnitude {
                field,
                index: k,
                value: values[k],
            });
        }
    }
    for (field, v) in [
        ("nrmse", fit.nrmse),
        ("lsd_db", fit.lsd_db),
        ("fit_seconds", fit.fit_seconds),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(ModelError::FitMetric { field, value: v });
        }
    }
    Ok(())
}
