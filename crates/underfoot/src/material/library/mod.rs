//! The versioned JSON library file: many [`MaterialModel`]s under one format tag.
//!
//! # File format
//!
//! A library is one UTF-8 JSON object, a [document](crate::document) of kind `library`:
//!
//! ```json
//! {
//!   "format": "underfoot.library/3",
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
//!       "sources": [{ "file": "gravel-01.wav", "sha256": "<64 lower-case hex digits>" }],
//!       "excitation": {
//!         "heel": 0.001, "bin_s": 0.005, "rate_hz": [6400.0, "..."], "energy": [0.004, "..."],
//!         "duration_spread": 0.35, "perturbation_db": 1.7
//!       },
//!       "time": { "steps": 3, "duration_ms": 262.0, "events": 43.0, "crest_db": 14.3, "...": "..." },
//!       "level_db": -12.0
//!     }
//!   ]
//! }
//! ```
//!
//! * `format` comes first in meaning: a reader checks it before it looks at anything else,
//!   so that a file from a newer version is reported as such rather than as a pile of
//!   field errors. This version writes [`FORMAT`] and reads it, [`FORMAT_2`] and
//!   [`FORMAT_1`].
//! * **The step in time** (format 3). `excitation` is what drives a step, fitted from the
//!   recordings ([`crate::excitation::ExcitationModel`]); `time` is the recordings' steps
//!   measured in time ([`crate::analysis::steps::StepSummary`]), what renders are compared
//!   with; `level_db` is the playback level re the recorded level
//!   ([`crate::material::level`]). **Format 2** files lack all three and are read as what
//!   they played: one impulse per step (the IIR paper's drive) at the recorded level;
//!   refitting gives them the rest. Saving writes format 3.
//! * **Decay limit.** `fit.longest_decay_s` is the longest e-fold decay any pole may have;
//!   the fit searched only inside it, and every load checks it. So the filter stored is
//!   the filter the voice plays: the voice's own limit (the same 0.5 s by default) finds
//!   nothing to change.
//! * **Format 1** files were written before the limit was part of the fit; they are read
//!   as what the voice played ([`mod@upgrade`]), then as format 2.
//! * Every material follows the rules of [`mod@validate`]: sections stable and within the
//!   decay limit, `b`/`a` agreeing with `sos`, a well-formed fit record, a valid name.
//!
//! Every load validates the whole file, and every save validates before it writes, so a
//! file written by this module is always readable by it. Saves are atomic: a crash or an
//! error part-way leaves the previous file as it was.
//!
//! | file | what |
//! |---|---|
//! | `mod.rs` | the [`Library`], its errors, and finding materials in it |
//! | `file.rs` | the library as a [`Document`](crate::document::Document): reading, writing, the locked edit |
//! | [`validate`](mod@validate) | the rules of the format for one material, and for names |
//! | [`upgrade`](mod@upgrade) | format 1 to 2 (2 to 3 adds nothing to upgrade) |

mod file;
pub mod upgrade;
pub mod validate;

use std::fmt;

use serde::{Deserialize, Serialize};

use super::MaterialModel;
use crate::document::{DocumentError, FileError};

pub use validate::{
    BA_TOLERANCE, MAX_NAME_LEN, ModelError, NameError, validate_model, validate_name,
};

/// The format tag of the library files this version reads and writes
/// (`underfoot.<KIND>/<VERSION>` of the [`Document`](crate::document::Document)).
pub const FORMAT: &str = "underfoot.library/3";

/// The format before a step's time structure was stored; read as it is (see
/// [`mod@upgrade`]).
pub const FORMAT_2: &str = "underfoot.library/2";

/// The format before the decay limit was stored; read and upgraded (see [`mod@upgrade`]).
pub const FORMAT_1: &str = "underfoot.library/1";

/// Every format tag this version can read.
pub const SUPPORTED_FORMATS: &[&str] = &[FORMAT, FORMAT_2, FORMAT_1];

/// A library of material models.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Library {
    /// Always [`FORMAT`]: the document layer writes the tag and upgrades an older file on
    /// load, so the tag is not part of the body.
    #[serde(skip, default = "current_format")]
    pub format: String,
    /// The materials, in insertion order, names unique.
    pub materials: Vec<MaterialModel>,
}

fn current_format() -> String {
    FORMAT.to_string()
}

/// What is wrong with a library file or a library operation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LibraryError {
    /// The file could not be read or written.
    #[error(transparent)]
    File(#[from] FileError),
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
    /// Any other error of the document layer.
    #[error(transparent)]
    Document(DocumentError),
}

/// What [`Document::validate`](crate::document::Document::validate) finds wrong with a
/// library: the first material that breaks a rule of the format.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum InvalidLibrary {
    /// [`Library::format`] is not [`FORMAT`].
    #[error("unsupported library format {0:?}")]
    Format(String),
    /// A material breaks a rule of [`mod@validate`].
    #[error("material {material:?}: materials[{index}]: {reason}")]
    Material {
        /// Its place in the library.
        index: usize,
        /// Its name.
        material: String,
        /// What is wrong.
        reason: ModelError,
    },
    /// Two materials of one name.
    #[error(
        "material {material:?}: materials[{index}]: duplicate name (also materials[{first}]); \
         names must be unique"
    )]
    Duplicate {
        /// The place of the second.
        index: usize,
        /// The name.
        material: String,
        /// The place of the first.
        first: usize,
    },
}

impl InvalidLibrary {
    /// The library's error for this problem, with where the library came from.
    fn at(self, origin: &str) -> LibraryError {
        let origin = origin.to_string();
        match self {
            Self::Format(found) => LibraryError::UnknownFormat {
                origin,
                found: Some(found),
            },
            Self::Material {
                index,
                material,
                reason,
            } => LibraryError::Invalid {
                origin,
                material,
                reason: format!("materials[{index}]: {reason}"),
            },
            Self::Duplicate {
                index,
                material,
                first,
            } => LibraryError::Invalid {
                origin,
                material,
                reason: format!(
                    "materials[{index}]: duplicate name (also materials[{first}]); names must \
                     be unique"
                ),
            },
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

/// The most names a not-found message lists.
const LISTED_NAMES: usize = 24;

struct AvailableList<'a>(&'a [String]);

impl fmt::Display for AvailableList<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            f.write_str("the library is empty")
        } else {
            // A library of thousands would bury the message under its names.
            let shown = self.0.len().min(LISTED_NAMES);
            write!(f, "available: {}", self.0[..shown].join(", "))?;
            match self.0.len() - shown {
                0 => Ok(()),
                more => write!(f, " and {more} more (`underfoot library list` shows all)"),
            }
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
        self.check().map_err(|e| e.at("library"))
    }

    /// The rules of [`Library::validate`], as the document layer's error.
    fn check(&self) -> Result<(), InvalidLibrary> {
        if self.format != FORMAT {
            return Err(InvalidLibrary::Format(self.format.clone()));
        }
        for (index, m) in self.materials.iter().enumerate() {
            validate_model(m).map_err(|reason| InvalidLibrary::Material {
                index,
                material: m.name.clone(),
                reason,
            })?;
            if let Some(first) = self.materials[..index]
                .iter()
                .position(|o| o.name == m.name)
            {
                return Err(InvalidLibrary::Duplicate {
                    index,
                    material: m.name.clone(),
                    first,
                });
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

#[cfg(test)]
mod tests;
