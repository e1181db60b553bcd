//! The versioned JSON library file: many [`MaterialModel`]s under one format tag.
//!
//! # File format
//!
//! A library is one UTF-8 JSON object:
//!
//! ```json
//! {
//!   "format": "underfoot.library/2",
//!   "materials": [
//!     {
//!       "name": "gravel",
//!       "sample_rate": 2000,
//!       "band_hz": [20.0, 900.0],
//!       "order": 2,
//!       "filter": {
//!         "sos": [[0.1, 0.0, -0.1, 1.0, -1.6, 0.81]],
//!         "b": [0.1, 0.0, -0.1],
//!         "a": [1.0, -1.6, 0.81]
//!       },
//!       "fit": {
//!         "grid_hz": [20.0, "..."], "measured": ["..."], "model": ["..."],
//!         "nrmse": 0.05, "lsd_db": 0.4,
//!         "method": "vector-fit+gauss-newton(log)", "strikes": 12, "fit_seconds": 3.1,
//!         "longest_decay_s": 0.5, "worst": { "db": 1.2, "at_hz": 31.5 }
//!       },
//!       "sources": [{ "file": "gravel-01.wav", "sha256": "<64 lower-case hex digits>" }]
//!     }
//!   ]
//! }
//! ```
//!
//! * `format` comes first in meaning: a reader checks it before it looks at anything else,
//!   so that a file from a newer version is reported as such rather than as a pile of
//!   field errors. This version writes [`FORMAT`] and reads it and [`FORMAT_1`].
//! * **Decay limit.** `fit.longest_decay_s` is the longest e-fold decay any pole may have;
//!   the fit searched only inside it, and every load checks it (a pole of radius `r` at
//!   rate `f_s` decays by `e` in `-1 / (f_s ln r)` seconds). So the filter stored is the
//!   filter the voice plays: the voice's own limit (the same 0.5 s by default) finds
//!   nothing to change.
//! * **Format 1** files were written before the limit was part of the fit, and some hold
//!   poles that ring for minutes, which the voice always pulled in to 0.5 s when it
//!   played them. They are read as what they played: each such pole is moved radially to
//!   the 0.5 s radius, and the record's model magnitude and metrics are recomputed for
//!   the filter that results. Saving writes format 2.
//! * `filter.sos` is what runs; `b`/`a` are the same filter expanded, for interchange with
//!   other tools, and must agree with `sos` (relative tolerance [`BA_TOLERANCE`]).
//! * `order` is the number of poles: two per section, one per first-order section
//!   (`a2 = b2 = 0`).
//! * Every section must be stable (both poles strictly inside the unit circle): a library
//!   is played back on a device, and an unstable filter there is a loud, growing tone.
//! * `fit` holds the evidence of the fit on a log-frequency grid: three arrays of one
//!   length, and finite, non-negative metrics.
//!
//! Every load validates the whole file, and every save validates before it writes, so a
//! file written by this module is always readable by it. Saves are atomic: a crash or an
//! error part-way leaves the previous file as it was.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::MaterialModel;
use crate::atomic_file::{AtomicWriteError, OutputFile};

/// The format tag of the library files this version reads and writes.
pub const FORMAT: &str = "underfoot.library/2";

/// The format before the decay limit was stored; read and upgraded (see the module docs).
pub const FORMAT_1: &str = "underfoot.library/1";

/// Every format tag this version can read.
pub const SUPPORTED_FORMATS: &[&str] = &[FORMAT, FORMAT_1];

/// How closely the expanded `b`/`a` must match the expansion of `sos`, relative to the
/// largest coefficient of each polynomial.
///
/// Loose enough for an expansion done by another tool in another order of operations,
/// tight enough that a hand-edited or stale coefficient is caught.
pub const BA_TOLERANCE: f64 = 1e-8;

/// A library of material models.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Library {
    /// Always [`FORMAT`].
    pub format: String,
    /// The materials, in insertion order, names unique.
    pub materials: Vec<MaterialModel>,
}

/// What is wrong with a library file or a library operation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LibraryError {
    /// The file could not be read or written.
    #[error("{path}: {action}: {source}", path = path.display())]
    Io {
        /// The file (or, for a save, the temporary file next to it).
        path: PathBuf,
        /// What was being done, e.g. `reading` or `renaming the temporary file over it`.
        action: &'static str,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The text is not JSON, or not JSON of the shape of a library.
    #[error("{origin}: not a valid library file at line {line}, column {column}: {message}")]
    Json {
        /// Where the text came from (file path or a description).
        origin: String,
        /// 1-based line of the error.
        line: usize,
        /// 1-based column of the error.
        column: usize,
        /// What the JSON parser objected to.
        message: String,
    },
    /// The `format` tag is missing or names a version this one cannot read.
    #[error("{origin}: {}; this version of underfoot reads {}",
        match found {
            Some(f) => format!("unsupported library format {f:?}"),
            None => "no \"format\" tag (is this an underfoot library file?)".to_string(),
        },
        supported_list())]
    UnknownFormat {
        /// Where the text came from.
        origin: String,
        /// The tag found, if any (non-string tags are shown as JSON).
        found: Option<String>,
    },
    /// A material in the library breaks a rule of the format.
    #[error("{origin}: material {material:?}: {reason}")]
    Invalid {
        /// Where the library came from or is going to.
        origin: String,
        /// The material's name (empty when the name itself is the problem).
        material: String,
        /// What is wrong, naming the field.
        reason: String,
    },
    /// No material of that name.
    #[error(
        "no material named {name:?} in the library; {}",
        AvailableList(available)
    )]
    NotFound {
        /// The name asked for.
        name: String,
        /// The names the library does hold.
        available: Vec<String>,
    },
}

impl From<AtomicWriteError> for LibraryError {
    fn from(e: AtomicWriteError) -> Self {
        Self::Io {
            path: e.path,
            action: e.action,
            source: e.source,
        }
    }
}

fn supported_list() -> String {
    SUPPORTED_FORMATS
        .iter()
        .map(|f| format!("{f:?}"))
        .collect::<Vec<_>>()
        .join(", ")
}

struct AvailableList<'a>(&'a [String]);

impl fmt::Display for AvailableList<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            f.write_str("the library is empty")
        } else {
            write!(f, "available: {}", self.0.join(", "))
        }
    }
}

impl Default for Library {
    fn default() -> Self {
        Self::new()
    }
}

impl Library {
    /// An empty library of the current format.
    #[must_use]
    pub fn new() -> Self {
        Self {
            format: FORMAT.to_string(),
            materials: Vec::new(),
        }
    }

    /// Parses and validates a library from JSON text.
    ///
    /// `origin` names where the text came from (a path, `built-in`, ...) in errors.
    ///
    /// # Errors
    /// [`LibraryError::Json`] for text that is not JSON or not shaped like a library,
    /// [`LibraryError::UnknownFormat`] for a missing or unsupported `format` tag, and
    /// [`LibraryError::Invalid`] for a material that breaks a rule of the format.
    pub fn from_json(text: &str, origin: &str) -> Result<Self, LibraryError> {
        let json_error = |e: serde_json::Error| LibraryError::Json {
            origin: origin.to_string(),
            line: e.line(),
            column: e.column(),
            message: strip_position(&e.to_string()),
        };
        // The tag is checked on an untyped parse first, so that a file of another version
        // is reported as such and not as whatever field it happens to lack.
        let value: serde_json::Value = serde_json::from_str(text).map_err(json_error)?;
        let found = match value.get("format") {
            None => None,
            Some(serde_json::Value::String(s)) => Some(s.clone()),
            Some(other) => Some(other.to_string()),
        };
        if !SUPPORTED_FORMATS.contains(&found.as_deref().unwrap_or_default()) {
            return Err(LibraryError::UnknownFormat {
                origin: origin.to_string(),
                found,
            });
        }
        // Parsed again from the text rather than from `value`: only the text parser knows
        // line and column, which is what a person fixing the file needs.
        let mut library: Library = serde_json::from_str(text).map_err(json_error)?;
        if library.format == FORMAT_1 {
            library.upgrade_from_1();
        }
        library.validate_as(origin)?;
        Ok(library)
    }

    /// Reads and validates a library file.
    ///
    /// # Errors
    /// [`LibraryError::Io`] when the file cannot be read, and the errors of
    /// [`Library::from_json`] (with the path as origin).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LibraryError> {
        let path = path.as_ref();
        let text = crate::limits::read_to_string_capped(path, crate::limits::MAX_LIBRARY_BYTES)
            .map_err(|source| LibraryError::Io {
                path: path.to_path_buf(),
                action: "reading",
                source,
            })?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// Reads a library file, or returns an empty library when there is no file yet.
    ///
    /// Only a missing file counts as empty: a file that exists but cannot be read or is
    /// broken is an error, so that a later save never overwrites a library by accident.
    ///
    /// # Errors
    /// As [`Library::load`], except for a missing file.
    pub fn load_or_new(path: impl AsRef<Path>) -> Result<Self, LibraryError> {
        let path = path.as_ref();
        match crate::limits::read_to_string_capped(path, crate::limits::MAX_LIBRARY_BYTES) {
            Ok(text) => Self::from_json(&text, &path.display().to_string()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Self::new()),
            Err(source) => Err(LibraryError::Io {
                path: path.to_path_buf(),
                action: "reading",
                source,
            }),
        }
    }

    /// The library as pretty-printed JSON, with a final newline.
    #[must_use]
    pub fn to_json(&self) -> String {
        // Serialising these types cannot fail: every map key is a string, and serde_json
        // writes non-finite floats as null rather than failing.
        let mut s = serde_json::to_string_pretty(self)
            .expect("a library always serialises: its maps have string keys");
        s.push('\n');
        s
    }

    /// Validates the library and writes it to `path` atomically.
    ///
    /// The text goes to a temporary file in the same directory, which is flushed to disk
    /// and then renamed over `path`. On any error the previous file at `path` (if any) is
    /// left exactly as it was and the temporary file is removed.
    ///
    /// # Errors
    /// The errors of [`Library::validate`] (nothing is written), or [`LibraryError::Io`].
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LibraryError> {
        self.save_to(&OutputFile::check(path.as_ref(), &[])?)
    }

    /// Validates the library and writes it to an output the caller has already checked
    /// against the output policy ([`crate::atomic_file`]), atomically as [`Library::save`].
    ///
    /// # Errors
    /// As [`Library::save`].
    pub fn save_to(&self, out: &OutputFile) -> Result<(), LibraryError> {
        self.validate_as(&format!("library to be saved to {}", out.path().display()))?;
        Ok(out.write(self.to_json().as_bytes())?)
    }

    /// Edits the library file `out` in place: read, `edit`, write, all under the file's
    /// edit lock ([`OutputFile::lock`]), so concurrent edits by several processes all
    /// land (each reads what the one before it wrote). With `create`, a missing file is
    /// an empty library; without, it is an error. Nothing is written if `edit` fails.
    ///
    /// # Errors
    /// [`LibraryError::Io`] for the lock, the errors of [`Library::load`] /
    /// [`Library::load_or_new`], `edit`'s own, and those of [`Library::save_to`].
    pub fn edit<T>(
        out: &OutputFile,
        create: bool,
        edit: impl FnOnce(&mut Self) -> Result<T, LibraryError>,
    ) -> Result<T, LibraryError> {
        let _lock = out.lock()?;
        // Read through the resolved target: the name the lock and the rename are for.
        let mut library = if create {
            Self::load_or_new(out.target())
        } else {
            Self::load(out.target())
        }
        .map_err(|e| match e {
            LibraryError::Io { action, source, .. } => LibraryError::Io {
                path: out.path().to_path_buf(),
                action,
                source,
            },
            e => e,
        })?;
        let value = edit(&mut library)?;
        library.save_to(out)?;
        Ok(value)
    }

    /// Inserts `model`, replacing (in place) a material of the same name.
    ///
    /// Returns the replaced material. The model is not validated here; [`Library::save`]
    /// does that before anything reaches a file.
    pub fn upsert(&mut self, model: MaterialModel) -> Option<MaterialModel> {
        match self.materials.iter_mut().find(|m| m.name == model.name) {
            Some(slot) => Some(std::mem::replace(slot, model)),
            None => {
                self.materials.push(model);
                None
            }
        }
    }

    /// Removes and returns the material called `name`.
    ///
    /// # Errors
    /// [`LibraryError::NotFound`] listing the names the library does hold.
    pub fn remove(&mut self, name: &str) -> Result<MaterialModel, LibraryError> {
        match self.materials.iter().position(|m| m.name == name) {
            Some(i) => Ok(self.materials.remove(i)),
            None => Err(self.not_found(name)),
        }
    }

    /// The material called `name`.
    ///
    /// # Errors
    /// [`LibraryError::NotFound`] listing the names the library does hold.
    pub fn get(&self, name: &str) -> Result<&MaterialModel, LibraryError> {
        self.materials
            .iter()
            .find(|m| m.name == name)
            .ok_or_else(|| self.not_found(name))
    }

    /// The names of the materials, in library order.
    #[must_use]
    pub fn names(&self) -> Vec<&str> {
        self.materials.iter().map(|m| m.name.as_str()).collect()
    }

    /// Checks the format tag, that names are unique, and every material
    /// (see [`validate_model`]).
    ///
    /// # Errors
    /// [`LibraryError::UnknownFormat`] or [`LibraryError::Invalid`] for the first problem found.
    pub fn validate(&self) -> Result<(), LibraryError> {
        self.validate_as("library")
    }

    /// Format 1 to 2: pull every pole beyond the legacy 0.5 s decay in to it, as the voice
    /// did when it played the file, and describe the resulting filter in the record.
    fn upgrade_from_1(&mut self) {
        for m in &mut self.materials {
            m.fit.longest_decay = super::model::LEGACY_DECAY;
            let Some(sos) = m.sos() else { continue };
            let rho = crate::fit::decay_radius(m.sample_rate, m.fit.longest_decay);
            let Some(limited) = limit_radius(&sos, rho) else {
                continue;
            };
            m.filter = super::FilterCoefficients::from_sos(&limited);
            m.fit.model = m
                .fit
                .grid_hz
                .iter()
                .map(|&f| {
                    limited
                        .response(m.sample_rate.omega(crate::units::Hz(f)))
                        .norm()
                })
                .collect();
            m.fit.nrmse = crate::fit::metrics::nrmse(&m.fit.measured, &m.fit.model);
            m.fit.lsd_db = crate::fit::metrics::lsd_db(&m.fit.measured, &m.fit.model);
            m.fit.worst = None;
            m.fit.method = format!("{} + decay-limited on upgrade from format 1", m.fit.method);
        }
        self.format = FORMAT.to_string();
    }

    fn validate_as(&self, origin: &str) -> Result<(), LibraryError> {
        if self.format != FORMAT {
            return Err(LibraryError::UnknownFormat {
                origin: origin.to_string(),
                found: Some(self.format.clone()),
            });
        }
        for (i, m) in self.materials.iter().enumerate() {
            let invalid = |reason: String| LibraryError::Invalid {
                origin: origin.to_string(),
                material: m.name.clone(),
                reason,
            };
            validate_model(m).map_err(|r| invalid(format!("materials[{i}]: {r}")))?;
            if let Some(j) = self.materials[..i].iter().position(|o| o.name == m.name) {
                return Err(invalid(format!(
                    "materials[{i}]: duplicate name (also materials[{j}]); names must be unique"
                )));
            }
        }
        Ok(())
    }

    fn not_found(&self, name: &str) -> LibraryError {
        LibraryError::NotFound {
            name: name.to_string(),
            available: self.names().into_iter().map(str::to_string).collect(),
        }
    }
}

/// Checks one material against the rules of the format (see the module docs).
///
/// Used by [`Library`] on every load and save, and usable on a freshly built model.
///
/// # Errors
/// The first problem found, as a sentence naming the field, e.g.
/// `filter.sos[1]: unstable section: pole radius 1.02 (must be < 1)`.
pub fn validate_model(m: &MaterialModel) -> Result<(), String> {
    validate_name(&m.name)?;
    if let Some(p) = &m.physical {
        p.validate().map_err(|e| format!("physical model: {e}"))?;
    }
    if m.sample_rate.0 == 0 {
        return Err("sample_rate is 0".to_string());
    }
    if !m.band_hz.fits(m.sample_rate) {
        return Err(format!(
            "band_hz [{}, {}] does not fit sample_rate {} (need 0 < lo < hi < {})",
            m.band_hz.lo.0,
            m.band_hz.hi.0,
            m.sample_rate,
            m.sample_rate.nyquist()
        ));
    }
    let sos = validate_sections(&m.filter.sos)?;
    if m.order != sos.order() {
        return Err(format!(
            "order is {} but filter.sos has {} poles ({} sections)",
            m.order,
            sos.order(),
            sos.sections.len()
        ));
    }
    let limit = m.fit.longest_decay;
    if !(limit.0 > 0.0 && limit.0 <= 60.0) {
        return Err(format!(
            "fit.longest_decay_s = {} must be in (0, 60] s",
            limit.0
        ));
    }
    // The coefficients round-trip exactly through JSON; the slack is for a file written by
    // another tool.
    let rho = crate::fit::decay_radius(m.sample_rate, limit);
    for (i, s) in sos.sections.iter().enumerate() {
        if let Some(p) = s.poles().iter().find(|p| p.norm() > rho * (1.0 + 1e-12)) {
            return Err(format!(
                "filter.sos[{i}] has a pole at {:.1} Hz that decays by e in {:.3} s, longer than \
                 the model's limit fit.longest_decay_s = {} s (refit it)",
                p.arg().abs() * m.sample_rate.hz() / std::f64::consts::TAU,
                crate::fit::decay_time(m.sample_rate, p.norm()).0,
                limit.0
            ));
        }
    }
    let (b, a) = sos.to_ba();
    check_expanded("filter.b", &m.filter.b, &b)?;
    check_expanded("filter.a", &m.filter.a, &a)?;
    validate_fit(&m.fit)?;
    for (i, s) in m.sources.iter().enumerate() {
        if s.file.is_empty() {
            return Err(format!("sources[{i}].file is empty"));
        }
        let hex = |c: char| c.is_ascii_digit() || ('a'..='f').contains(&c);
        if s.sha256.len() != 64 || !s.sha256.chars().all(hex) {
            return Err(format!(
                "sources[{i}].sha256 {:?} is not 64 lower-case hex digits",
                s.sha256
            ));
        }
    }
    Ok(())
}

/// The longest material name, in bytes.
pub const MAX_NAME_LEN: usize = 64;

/// Checks a material name: 1 to [`MAX_NAME_LEN`] ASCII letters, digits, `-`, `_` and `.`.
///
/// The one rule for names, whether they come from `fit`, a library file or the API.
///
/// # Errors
/// What is wrong with the name, as a sentence.
pub fn validate_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("name is empty".to_string());
    }
    if name.len() > MAX_NAME_LEN {
        return Err(format!(
            "name is {} bytes long, more than {MAX_NAME_LEN}",
            name.len()
        ));
    }
    // Names end up as command-line arguments and file names; keep them to characters
    // that need no quoting anywhere.
    if let Some(c) = name
        .chars()
        .find(|&c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.')))
    {
        return Err(format!(
            "name contains {c:?}: use letters, digits, '-', '_' or '.'"
        ));
    }
    Ok(())
}

fn validate_sections(rows: &[[f64; 6]]) -> Result<crate::signal::Sos, String> {
    if rows.is_empty() {
        return Err("filter.sos has no sections".to_string());
    }
    let mut sections = Vec::with_capacity(rows.len());
    for (i, row) in rows.iter().enumerate() {
        if let Some(k) = row.iter().position(|c| !c.is_finite()) {
            return Err(format!("filter.sos[{i}][{k}] is not finite"));
        }
        let Some(s) = crate::signal::Biquad::from_row(*row) else {
            return Err(format!("filter.sos[{i}] has a0 = 0"));
        };
        if !s.is_stable() {
            let radius = s.poles().iter().map(|p| p.norm()).fold(0.0, f64::max);
            return Err(format!(
                "filter.sos[{i}] is an unstable section: pole radius {radius:.6} (must be < 1)"
            ));
        }
        sections.push(s);
    }
    Ok(crate::signal::Sos::new(sections))
}

/// `sos` with every pole beyond `rho` moved radially onto it (numerators kept), or `None`
/// when no pole lies beyond it. An unstable section is left as it is, so that validation
/// refuses it: the upgrade reproduces what the voice played, it does not repair a file.
fn limit_radius(sos: &crate::signal::Sos, rho: f64) -> Option<crate::signal::Sos> {
    use crate::signal::Biquad;
    let mut changed = false;
    let sections = sos
        .sections
        .iter()
        .map(|s| {
            let [p, q] = s.poles();
            if (p.norm() <= rho && q.norm() <= rho) || !s.is_stable() {
                return *s;
            }
            changed = true;
            let pull = |z: num_complex::Complex64| {
                if z.norm() > rho {
                    z * (rho / z.norm())
                } else {
                    z
                }
            };
            let (p, q) = (pull(p), pull(q));
            // The monic quadratic with roots p, q (real coefficients: a conjugate pair or two
            // real poles); a first-order section's one pole is -a1.
            let a = if s.a[2] == 0.0 {
                [1.0, s.a[1].clamp(-rho, rho), 0.0]
            } else {
                [1.0, -(p + q).re, (p * q).re]
            };
            Biquad { b: s.b, a }
        })
        .collect();
    changed.then(|| crate::signal::Sos::new(sections))
}

fn check_expanded(field: &str, stored: &[f64], expected: &[f64]) -> Result<(), String> {
    if stored.len() != expected.len() {
        return Err(format!(
            "{field} has {} coefficients but filter.sos expands to {}",
            stored.len(),
            expected.len()
        ));
    }
    let scale = expected
        .iter()
        .fold(0.0f64, |m, c| m.max(c.abs()))
        .max(f64::MIN_POSITIVE);
    for (k, (s, e)) in stored.iter().zip(expected).enumerate() {
        let close = (s - e).abs() <= BA_TOLERANCE * scale;
        // A NaN compares false, so it fails here too.
        if !close {
            return Err(format!(
                "{field}[{k}] is {s} but filter.sos expands to {e} (they must agree)"
            ));
        }
    }
    Ok(())
}

fn validate_fit(fit: &super::FitRecord) -> Result<(), String> {
    let n = fit.grid_hz.len();
    if fit.measured.len() != n || fit.model.len() != n {
        return Err(format!(
            "fit arrays differ in length: grid_hz {n}, measured {}, model {}",
            fit.measured.len(),
            fit.model.len()
        ));
    }
    if let Some(k) = fit
        .grid_hz
        .iter()
        .position(|f| !(f.is_finite() && *f > 0.0))
    {
        return Err(format!(
            "fit.grid_hz[{k}] = {} is not a positive frequency",
            fit.grid_hz[k]
        ));
    }
    if let Some(k) = fit.grid_hz.windows(2).position(|w| w[1] <= w[0]) {
        return Err(format!("fit.grid_hz is not increasing at index {}", k + 1));
    }
    for (field, values) in [("measured", &fit.measured), ("model", &fit.model)] {
        if let Some(k) = values.iter().position(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(format!(
                "fit.{field}[{k}] = {} is not a finite, non-negative magnitude",
                values[k]
            ));
        }
    }
    for (field, v) in [
        ("nrmse", fit.nrmse),
        ("lsd_db", fit.lsd_db),
        ("fit_seconds", fit.fit_seconds),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(format!("fit.{field} = {v} is not finite and non-negative"));
        }
    }
    Ok(())
}

/// serde_json appends " at line L column C" to its messages; the error variant carries
/// those as fields, so the message drops them to avoid saying it twice.
fn strip_position(message: &str) -> String {
    match message.rfind(" at line ") {
        Some(i) => message[..i].to_string(),
        None => message.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{FilterCoefficients, FitRecord, SourceFile};
    use crate::signal::{Biquad, Sos};
    use crate::units::{Band, SampleRate};
    use std::fs;

    /// A valid model: one resonant section whose fit record is its own response.
    fn model(name: &str) -> MaterialModel {
        let rate = SampleRate(2000);
        let band = Band::new(20.0, 900.0);
        let sos = Sos::new(vec![Biquad {
            b: [0.1, 0.0, -0.1],
            a: [1.0, -1.6, 0.81],
        }]);
        let grid: Vec<f64> = band.log_grid(16).iter().map(|f| f.0).collect();
        let mag: Vec<f64> = grid
            .iter()
            .map(|&f| sos.response(rate.omega(crate::units::Hz(f))).norm())
            .collect();
        MaterialModel {
            name: name.to_string(),
            sample_rate: rate,
            band_hz: band,
            order: sos.order(),
            filter: FilterCoefficients::from_sos(&sos),
            fit: FitRecord {
                grid_hz: grid,
                measured: mag.clone(),
                model: mag,
                nrmse: 0.0,
                lsd_db: 0.0,
                method: "hand".to_string(),
                poor_fit: false,
                strikes: 3,
                fit_seconds: 0.5,
                longest_decay: crate::units::Seconds(0.5),
                worst: None,
            },
            sources: vec![SourceFile {
                file: "a.wav".to_string(),
                sha256: "ab".repeat(32),
            }],
            physical: None,
        }
    }

    fn library(names: &[&str]) -> Library {
        Library {
            format: FORMAT.to_string(),
            materials: names.iter().map(|n| model(n)).collect(),
        }
    }

    fn invalid_reason(m: MaterialModel) -> String {
        let lib = Library {
            format: FORMAT.to_string(),
            materials: vec![m],
        };
        match Library::from_json(&lib.to_json(), "test.json") {
            Err(LibraryError::Invalid { origin, reason, .. }) => {
                assert_eq!(origin, "test.json");
                reason
            }
            other => panic!("expected Invalid, got {other:?}"),
        }
    }

    #[test]
    fn round_trips_through_json() {
        let lib = library(&["gravel", "snow"]);
        let back = Library::from_json(&lib.to_json(), "mem").expect("valid");
        assert_eq!(back, lib);
        assert_eq!(back.names(), ["gravel", "snow"]);
        assert!(Library::new().validate().is_ok());
    }

    #[test]
    fn json_syntax_error_gives_line_and_column() {
        let text = "{\n  \"format\": \"underfoot.library/1\",\n  \"materials\": [,]\n}";
        match Library::from_json(text, "bad.json") {
            Err(e @ LibraryError::Json { line: 3, .. }) => {
                let msg = e.to_string();
                assert!(msg.starts_with("bad.json:"), "{msg}");
                assert!(msg.contains("line 3, column"), "{msg}");
            }
            other => panic!("expected Json at line 3, got {other:?}"),
        }
    }

    #[test]
    fn wrong_shape_is_a_json_error() {
        let text = r#"{"format": "underfoot.library/1", "materials": [{"name": "x"}]}"#;
        match Library::from_json(text, "o") {
            Err(LibraryError::Json { message, .. }) => assert!(message.contains("missing field")),
            other => panic!("expected Json, got {other:?}"),
        }
    }

    /// `model` with its section's poles moved to radius `r` (same angle), record updated.
    fn ringing(name: &str, r: f64) -> MaterialModel {
        let mut m = model(name);
        let w: f64 = 0.3;
        let sos = Sos::new(vec![Biquad {
            b: [0.1, 0.0, -0.1],
            a: [1.0, -2.0 * r * w.cos(), r * r],
        }]);
        m.filter = FilterCoefficients::from_sos(&sos);
        m.fit.model = m
            .fit
            .grid_hz
            .iter()
            .map(|&f| {
                sos.response(m.sample_rate.omega(crate::units::Hz(f)))
                    .norm()
            })
            .collect();
        m.fit.measured = m.fit.model.clone();
        m
    }

    /// A pole that rings longer than the stored limit is refused on load, naming the
    /// section, the decay and the limit.
    #[test]
    fn a_pole_beyond_the_decay_limit_is_refused() {
        let slow = ringing("slow", 0.999_99); // 50 s at 2 kHz
        let reason = invalid_reason(slow);
        assert!(
            reason.contains("filter.sos[0]") && reason.contains("longest_decay_s = 0.5"),
            "{reason}"
        );
        // Just inside it is fine.
        let rho = crate::fit::decay_radius(SampleRate(2000), crate::units::Seconds(0.5));
        let lib = Library {
            format: FORMAT.to_string(),
            materials: vec![ringing("edge", rho * (1.0 - 1e-12))],
        };
        Library::from_json(&lib.to_json(), "edge").unwrap();
    }

    /// A format-1 file is read as what it played: its slow pole pulled in to the 0.5 s
    /// radius, the record recomputed for that filter, and written back as format 2.
    #[test]
    fn format_1_is_upgraded_to_what_the_voice_played() {
        let old = Library {
            format: FORMAT_1.to_string(),
            materials: vec![ringing("old", 0.999_99), model("fine")],
        };
        let mut value: serde_json::Value = serde_json::from_str(&old.to_json()).unwrap();
        for m in value["materials"].as_array_mut().unwrap() {
            m["fit"].as_object_mut().unwrap().remove("longest_decay_s");
        }
        let text = value.to_string();
        assert!(!text.contains("longest_decay_s"), "{text}");
        let lib = Library::from_json(&text, "old.json").unwrap();
        assert_eq!(lib.format, FORMAT);
        let m = lib.get("old").unwrap();
        let rho = crate::fit::decay_radius(SampleRate(2000), crate::units::Seconds(0.5));
        let radius = m.sos().unwrap().poles()[0].norm();
        assert!((radius - rho).abs() < 1e-12, "{radius} vs {rho}");
        assert!(m.fit.lsd_db > 0.0 && m.fit.method.contains("format 1"));
        let sos = m.sos().unwrap();
        for (f, v) in m.fit.grid_hz.iter().zip(&m.fit.model) {
            let now = sos
                .response(m.sample_rate.omega(crate::units::Hz(*f)))
                .norm();
            assert!((now / v - 1.0).abs() < 1e-12);
        }
        // The model that was inside the limit is untouched.
        assert_eq!(lib.get("fine").unwrap(), &model("fine"));
        assert!(lib.to_json().contains(FORMAT));
    }

    /// The upgrade does not repair a format-1 file: an unstable filter is still refused.
    #[test]
    fn format_1_with_an_unstable_filter_is_still_refused() {
        let old = Library {
            format: FORMAT_1.to_string(),
            materials: vec![ringing("bad", 1.01)],
        };
        let mut value: serde_json::Value = serde_json::from_str(&old.to_json()).unwrap();
        value["materials"][0]["fit"]
            .as_object_mut()
            .unwrap()
            .remove("longest_decay_s");
        let e = Library::from_json(&value.to_string(), "old.json").expect_err("unstable");
        assert!(e.to_string().contains("unstable"), "{e}");
    }

    #[test]
    fn unknown_or_missing_format_is_reported_with_supported_versions() {
        let v3 = r#"{"format": "underfoot.library/3", "materials": [{"whatever": 1}]}"#;
        let e = Library::from_json(v3, "new.json").expect_err("v3");
        assert!(
            matches!(&e, LibraryError::UnknownFormat { found: Some(f), .. } if f == "underfoot.library/3")
        );
        let msg = e.to_string();
        assert!(
            msg.contains("underfoot.library/3") && msg.contains(FORMAT),
            "{msg}"
        );

        let none = Library::from_json(r#"{"materials": []}"#, "o").expect_err("no tag");
        assert!(matches!(
            none,
            LibraryError::UnknownFormat { found: None, .. }
        ));
        let num = Library::from_json(r#"{"format": 1, "materials": []}"#, "o").expect_err("num");
        assert!(matches!(num, LibraryError::UnknownFormat { found: Some(f), .. } if f == "1"));
        let arr = Library::from_json("[]", "o").expect_err("array");
        assert!(matches!(
            arr,
            LibraryError::UnknownFormat { found: None, .. }
        ));
    }

    #[test]
    fn invalid_names_are_rejected() {
        assert!(invalid_reason(model("")).contains("name is empty"));
        assert!(invalid_reason(model("a b")).contains("name contains ' '"));
        assert!(invalid_reason(model("grès")).contains("name contains 'è'"));
        assert!(invalid_reason(model(&"g".repeat(65))).contains("more than 64"));
        let lib = library(&["a", "b", "a"]);
        match Library::from_json(&lib.to_json(), "o") {
            Err(LibraryError::Invalid {
                material, reason, ..
            }) => {
                assert_eq!(material, "a");
                assert!(
                    reason.contains("duplicate") && reason.contains("materials[0]"),
                    "{reason}"
                );
            }
            other => panic!("expected duplicate, got {other:?}"),
        }
    }

    #[test]
    fn rate_and_band_are_checked() {
        let mut m = model("m");
        m.sample_rate = SampleRate(0);
        assert!(invalid_reason(m).contains("sample_rate is 0"));
        let mut m = model("m");
        m.band_hz = Band::new(20.0, 1000.0);
        assert!(invalid_reason(m).contains("band_hz"));
        let mut m = model("m");
        m.band_hz = Band::new(500.0, 100.0);
        assert!(invalid_reason(m).contains("band_hz"));
    }

    #[test]
    fn malformed_sections_are_rejected() {
        let mut m = model("m");
        m.filter.sos.clear();
        assert!(invalid_reason(m).contains("no sections"));
        let mut m = model("m");
        m.filter.sos[0][3] = 0.0;
        assert!(invalid_reason(m).contains("a0 = 0"));
        // NaN cannot be written as JSON, so check the in-memory path too.
        let mut m = model("m");
        m.filter.sos[0][1] = f64::NAN;
        let r = validate_model(&m).expect_err("nan");
        assert!(r.contains("filter.sos[0][1] is not finite"), "{r}");
        let lib = Library {
            format: FORMAT.to_string(),
            materials: vec![m],
        };
        assert!(matches!(lib.validate(), Err(LibraryError::Invalid { .. })));
    }

    #[test]
    fn unstable_section_is_rejected() {
        let mut m = model("m");
        // Poles at radius sqrt(1.0201) = 1.01: just outside the unit circle.
        let sos = Sos::new(vec![Biquad {
            b: [0.1, 0.0, -0.1],
            a: [1.0, -1.6, 1.0201],
        }]);
        m.filter = FilterCoefficients::from_sos(&sos);
        let r = invalid_reason(m);
        assert!(r.contains("unstable") && r.contains("1.01"), "{r}");
        // On the circle is unstable too.
        let mut m = model("m");
        m.filter.sos[0][5] = 1.0;
        m.filter.a[2] = 1.0;
        assert!(invalid_reason(m).contains("unstable"));
    }

    #[test]
    fn order_must_match_sections() {
        let mut m = model("m");
        m.order = 4;
        let r = invalid_reason(m);
        assert!(r.contains("order is 4") && r.contains("2 poles"), "{r}");
    }

    #[test]
    fn expanded_coefficients_must_match_sections() {
        let mut m = model("m");
        m.filter.a[1] *= 1.0 + 1e-6;
        assert!(invalid_reason(m).contains("filter.a[1]"));
        let mut m = model("m");
        m.filter.b.push(0.0);
        assert!(invalid_reason(m).contains("filter.b has 4 coefficients"));
        // Rounding noise well inside the tolerance is accepted.
        let mut m = model("m");
        m.filter.a[1] *= 1.0 + 1e-12;
        assert!(validate_model(&m).is_ok());
    }

    #[test]
    fn fit_record_is_checked() {
        let mut m = model("m");
        m.fit.model.pop();
        assert!(invalid_reason(m).contains("fit arrays differ in length"));
        let mut m = model("m");
        m.fit.grid_hz.swap(0, 1);
        assert!(invalid_reason(m).contains("not increasing"));
        let mut m = model("m");
        m.fit.measured[2] = -1.0;
        assert!(invalid_reason(m).contains("fit.measured[2]"));
        let mut m = model("m");
        m.fit.lsd_db = f64::INFINITY;
        assert!(validate_model(&m).expect_err("inf").contains("fit.lsd_db"));
        let mut m = model("m");
        m.fit.nrmse = -0.1;
        assert!(invalid_reason(m).contains("fit.nrmse"));
        let mut m = model("m");
        m.sources[0].sha256 = "XYZ".to_string();
        assert!(invalid_reason(m).contains("sources[0].sha256"));
    }

    #[test]
    fn upsert_replaces_in_place_and_get_remove_report_missing_names() {
        let mut lib = library(&["a", "b", "c"]);
        let mut b2 = model("b");
        b2.fit.strikes = 99;
        let old = lib.upsert(b2).expect("replaced");
        assert_eq!(old.fit.strikes, 3);
        assert_eq!(lib.names(), ["a", "b", "c"]);
        assert_eq!(lib.get("b").expect("b").fit.strikes, 99);
        assert!(lib.upsert(model("d")).is_none());
        assert_eq!(lib.names(), ["a", "b", "c", "d"]);

        assert_eq!(lib.remove("a").expect("a").name, "a");
        match lib.remove("a") {
            Err(e @ LibraryError::NotFound { .. }) => {
                let LibraryError::NotFound {
                    ref name,
                    ref available,
                } = e
                else {
                    unreachable!()
                };
                assert_eq!(name, "a");
                assert_eq!(available, &["b", "c", "d"]);
                assert!(e.to_string().contains("available: b, c, d"));
            }
            other => panic!("expected NotFound, got {other:?}"),
        }
        let empty = Library::new();
        assert!(
            empty
                .get("x")
                .expect_err("empty")
                .to_string()
                .contains("library is empty")
        );
    }

    fn dir_entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .expect("read dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn save_and_load_round_trip_without_leftovers() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("lib.json");
        let lib = library(&["gravel"]);
        lib.save(&path).expect("save");
        assert_eq!(Library::load(&path).expect("load"), lib);
        // Overwrite an existing file.
        let lib2 = library(&["gravel", "sand"]);
        lib2.save(&path).expect("save again");
        assert_eq!(Library::load(&path).expect("load"), lib2);
        assert_eq!(dir_entries(dir.path()), ["lib.json"]);
    }

    #[test]
    fn saving_an_invalid_library_leaves_the_old_file_untouched() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("lib.json");
        library(&["gravel"]).save(&path).expect("save");
        let before = fs::read(&path).expect("read");

        let mut bad = library(&["gravel"]);
        bad.materials[0].filter.sos[0][5] = 1.5;
        let e = bad.save(&path).expect_err("unstable");
        assert!(matches!(e, LibraryError::Invalid { .. }));
        assert!(e.to_string().contains("library to be saved to"), "{e}");
        assert_eq!(fs::read(&path).expect("read"), before);
        assert_eq!(dir_entries(dir.path()), ["lib.json"]);
    }

    #[test]
    fn failed_write_leaves_target_and_no_temp_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        // The target is a non-empty directory: renaming a file over it must fail, after
        // the temporary file has been written.
        let target = dir.path().join("lib.json");
        fs::create_dir(&target).expect("mkdir");
        fs::write(target.join("keep"), b"x").expect("write");
        match library(&["a"]).save(&target) {
            // The output policy refuses a directory before anything is written.
            Err(LibraryError::Io { path, action, .. }) => {
                assert_eq!(path, target);
                assert_eq!(action, crate::atomic_file::REFUSED);
            }
            other => panic!("expected Io, got {other:?}"),
        }
        assert_eq!(dir_entries(dir.path()), ["lib.json"]);
        assert_eq!(fs::read(target.join("keep")).expect("kept"), b"x");
    }

    #[test]
    fn concurrent_edits_all_land() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("lib.json");
        let names = ["a", "b", "c", "d", "e", "f"];
        std::thread::scope(|s| {
            for name in names {
                let path = &path;
                s.spawn(move || {
                    let out = OutputFile::check(path, &[]).expect("check");
                    let model = library(&[name]).materials.remove(0);
                    Library::edit(&out, true, |lib| {
                        // Widen the window between the read and the write.
                        std::thread::sleep(std::time::Duration::from_millis(20));
                        Ok(lib.upsert(model))
                    })
                    .expect("edit");
                });
            }
        });
        let mut got = Library::load(&path).expect("load").names().join(",");
        got = got
            .split(',')
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect::<Vec<_>>()
            .join(",");
        assert_eq!(got, names.join(","));
        // Without create, a missing library is an error and nothing is written.
        let missing = OutputFile::check(&dir.path().join("none.json"), &[]).expect("check");
        assert!(Library::edit(&missing, false, |_| Ok(())).is_err());
        assert!(!dir.path().join("none.json").exists());
    }

    #[test]
    fn load_reports_io_and_load_or_new_accepts_only_a_missing_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let missing = dir.path().join("none.json");
        match Library::load(&missing) {
            Err(e @ LibraryError::Io { .. }) => {
                assert!(e.to_string().contains("none.json"), "{e}");
            }
            other => panic!("expected Io, got {other:?}"),
        }
        assert_eq!(
            Library::load_or_new(&missing).expect("empty"),
            Library::new()
        );

        let broken = dir.path().join("broken.json");
        fs::write(&broken, "{").expect("write");
        assert!(matches!(
            Library::load_or_new(&broken),
            Err(LibraryError::Json { .. })
        ));
        // A directory exists but is not a readable file.
        assert!(matches!(
            Library::load_or_new(dir.path()),
            Err(LibraryError::Io { .. })
        ));
    }
}
