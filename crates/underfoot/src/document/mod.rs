//! One way to store a document: every JSON file the project writes (a material
//! library, a sensor calibration, a measured response, an equalizer, a limb model, a
//! table of users) goes through this layer, and every CSV table it reads (force tracks,
//! sensor-calibration sessions, data-logger recordings) through its [`csv`] reader.
//!
//! # The header
//!
//! A document is a JSON object whose first key is its format tag,
//!
//! ```json
//! { "format": "underfoot.<kind>/<version>", ...the body's fields... }
//! ```
//!
//! so a reader knows what it holds before it looks at anything else: handing one
//! command another command's file, or a file from a newer version, gets a message that
//! says so rather than a complaint about a missing field. The body is the
//! [`Document`]'s own serde shape; the tag is added on save and taken off on load, so a
//! document type does not carry it as a field.
//!
//! Files written before this layer existed used `"kind"` and `"version"` keys; a
//! document that names its old kind ([`Document::LEGACY_KIND`]) still loads from them,
//! and is written back with the one header.
//!
//! # Loading and saving
//!
//! [`load`] reads at most [`MAX_DOCUMENT_BYTES`],
//! checks the tag, deserializes the body, brings an older version up to date
//! ([`Document::upgrade`]) and checks what serde cannot ([`Document::validate`]).
//! [`save`] validates first and writes through the [output policy](crate::atomic_file):
//! a temporary file renamed over the target, so a failed save leaves the old file as
//! it was.
//!
//! ```
//! use serde::{Deserialize, Serialize};
//! use underfoot::document::{self, Document};
//!
//! #[derive(Debug, PartialEq, Serialize, Deserialize)]
//! struct Note { text: String }
//!
//! #[derive(Debug, thiserror::Error)]
//! #[error("the note is empty")]
//! struct EmptyNote;
//!
//! impl Document for Note {
//!     const KIND: &'static str = "note";
//!     const VERSION: u32 = 1;
//!     type Invalid = EmptyNote;
//!     fn validate(&self) -> Result<(), EmptyNote> {
//!         if self.text.is_empty() { Err(EmptyNote) } else { Ok(()) }
//!     }
//! }
//!
//! let json = document::to_json(&Note { text: "gravel".into() }, "a note")?;
//! assert!(json.starts_with("{\n  \"format\": \"underfoot.note/1\""));
//! let back: Note = document::from_json(&json, "a note")?;
//! assert_eq!(back.text, "gravel");
//! assert!(document::from_json::<Note>(r#"{"format": "underfoot.note/2", "text": "x"}"#, "new")
//!     .unwrap_err().to_string().contains("version 2"));
//! # Ok::<(), underfoot::document::DocumentError>(())
//! ```

mod body;
pub mod csv;
mod error;

use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;

pub use error::{DocumentError, FileError};

use crate::atomic_file::OutputFile;
use crate::limits::{MAX_DOCUMENT_BYTES, read_to_string_capped};

/// The prefix of every format tag.
pub const TAG_PREFIX: &str = "underfoot.";

/// The key of the format tag.
pub const TAG_KEY: &str = "format";

/// A file type stored through this layer.
pub trait Document: Serialize + DeserializeOwned {
    /// The kind in the tag, `underfoot.<KIND>/<VERSION>`.
    const KIND: &'static str;
    /// The version this build writes.
    const VERSION: u32;
    /// The oldest version this build reads; [`upgrade`](Document::upgrade) brings an
    /// older body up to [`VERSION`](Document::VERSION).
    const OLDEST: u32 = Self::VERSION;
    /// The `"kind"` of files written before the one header (read with their
    /// `"version"`), if this type had any.
    const LEGACY_KIND: Option<&'static str> = None;
    /// What the file is, for people, in messages ("library", "sensor calibration").
    const DESCRIPTION: &'static str = Self::KIND;

    /// What [`validate`](Document::validate) reports.
    type Invalid: std::error::Error + Send + Sync + 'static;

    /// Checks what serde cannot: lengths, finiteness, ranges, stability.
    ///
    /// # Errors
    /// What is wrong, naming the field.
    fn validate(&self) -> Result<(), Self::Invalid>;

    /// Brings a document read as version `from` (older than
    /// [`VERSION`](Document::VERSION)) up to date. The default changes nothing.
    ///
    /// # Errors
    /// When the old document cannot be brought up to date.
    fn upgrade(self, from: u32) -> Result<Self, Self::Invalid> {
        let _ = from;
        Ok(self)
    }
}

/// The tag this build writes for `T`: `underfoot.<kind>/<version>`.
#[must_use]
pub fn tag<T: Document>() -> String {
    format!("{TAG_PREFIX}{}/{}", T::KIND, T::VERSION)
}

#[derive(Serialize)]
struct Tagged<'a, T> {
    format: String,
    #[serde(flatten)]
    body: &'a T,
}

/// The document as file text: validated, pretty JSON with the tag first, ending in a
/// newline.
///
/// # Errors
/// [`DocumentError::Invalid`] when the document fails [`Document::validate`];
/// [`DocumentError::Encode`] when serde cannot write it (a non-string map key).
pub fn to_json<T: Document>(doc: &T, origin: &str) -> Result<String, DocumentError> {
    doc.validate()
        .map_err(|e| DocumentError::invalid(origin, e))?;
    to_json_unchecked(doc, origin)
}

/// [`to_json`] without [`Document::validate`]: the text of whatever is in memory, for a
/// digest of it, or for a test or a fuzzer that writes a broken file on purpose. Files
/// are written with [`save`], which validates.
///
/// # Errors
/// [`DocumentError::Encode`] when serde cannot write it (a non-string map key).
pub fn to_json_unchecked<T: Document>(doc: &T, origin: &str) -> Result<String, DocumentError> {
    let mut text = serde_json::to_string_pretty(&Tagged {
        format: tag::<T>(),
        body: doc,
    })
    .map_err(|e| DocumentError::Encode {
        origin: origin.to_string(),
        message: e.to_string(),
    })?;
    text.push('\n');
    Ok(text)
}

/// Reads a document from text; `origin` names it in errors (a path, or a description).
///
/// # Errors
/// [`DocumentError::Json`] for text that is not JSON or a body serde refuses,
/// [`DocumentError::NoTag`], [`DocumentError::WrongKind`] or [`DocumentError::Version`]
/// for a header that is not `T`'s, and
/// [`DocumentError::Invalid`] for one that fails [`Document::validate`] or
/// [`Document::upgrade`].
pub fn from_json<T: Document>(text: &str, origin: &str) -> Result<T, DocumentError> {
    let mut value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| DocumentError::json(origin, T::DESCRIPTION, &e))?;
    let (version, legacy) = take_header::<T>(&mut value, origin)?;
    drop(value);
    // The body is read again from the text, not from the value, so that its errors keep
    // their line and column.
    let mut deserializer = serde_json::Deserializer::from_str(text);
    let doc: T = serde::Deserializer::deserialize_map(&mut deserializer, body::Body::new(legacy))
        .and_then(|doc| deserializer.end().map(|()| doc))
        .map_err(|e| DocumentError::json(origin, T::DESCRIPTION, &e))?;
    let doc = if version < T::VERSION {
        doc.upgrade(version)
            .map_err(|e| DocumentError::invalid(origin, e))?
    } else {
        doc
    };
    doc.validate()
        .map_err(|e| DocumentError::invalid(origin, e))?;
    Ok(doc)
}

/// The version a tag names, if it is `T`'s kind.
fn parse_tag<T: Document>(tag: &str) -> Option<Result<u32, String>> {
    let rest = tag.strip_prefix(TAG_PREFIX)?;
    let (kind, version) = rest.rsplit_once('/')?;
    (kind == T::KIND).then(|| version.parse::<u32>().map_err(|_| version.to_string()))
}

/// Checks and removes the header (the tag, or a legacy kind and version), returning
/// the version and whether the header was the legacy one.
fn take_header<T: Document>(
    value: &mut serde_json::Value,
    origin: &str,
) -> Result<(u32, bool), DocumentError> {
    let no_tag = || DocumentError::NoTag {
        origin: origin.to_string(),
        description: T::DESCRIPTION,
        expected: tag::<T>(),
    };
    let wrong_kind = |found: &serde_json::Value| DocumentError::WrongKind {
        origin: origin.to_string(),
        found: found
            .as_str()
            .map_or_else(|| found.to_string(), str::to_string),
        expected: tag::<T>(),
    };
    let version_error = |found: String| DocumentError::Version {
        origin: origin.to_string(),
        description: T::DESCRIPTION,
        found,
        oldest: T::OLDEST,
        newest: T::VERSION,
    };
    let object = value.as_object_mut().ok_or_else(no_tag)?;
    let (version, legacy) = if let Some(found) = object.remove(TAG_KEY) {
        match found.as_str().and_then(parse_tag::<T>) {
            Some(Ok(v)) => (v, false),
            Some(Err(v)) => return Err(version_error(v)),
            None => return Err(wrong_kind(&found)),
        }
    } else if let Some(kind) = object.remove("kind") {
        if T::LEGACY_KIND.is_none() || kind.as_str() != T::LEGACY_KIND {
            return Err(wrong_kind(&kind));
        }
        let found = object.remove("version");
        let version = found
            .as_ref()
            .and_then(serde_json::Value::as_u64)
            .and_then(|v| u32::try_from(v).ok())
            .ok_or_else(|| {
                version_error(found.map_or_else(|| "missing".to_string(), |v| v.to_string()))
            })?;
        (version, true)
    } else {
        return Err(no_tag());
    };
    if !(T::OLDEST..=T::VERSION).contains(&version) {
        return Err(version_error(version.to_string()));
    }
    Ok((version, legacy))
}

/// Reads a document from a file.
///
/// # Errors
/// [`DocumentError::File`] for a missing, unreadable or oversized file; otherwise as
/// [`from_json`], with the path as the origin.
pub fn load<T: Document>(path: &Path) -> Result<T, DocumentError> {
    let text = read_to_string_capped(path, MAX_DOCUMENT_BYTES).map_err(|source| FileError {
        path: path.to_path_buf(),
        action: "reading",
        source,
    })?;
    from_json(&text, &path.display().to_string())
}

/// Writes a document atomically to `path`, after checking it against the output policy.
///
/// # Errors
/// As [`to_json`], and [`DocumentError::File`] when the policy refuses the path or the
/// write fails (the old file is kept).
pub fn save<T: Document>(path: &Path, doc: &T) -> Result<(), DocumentError> {
    save_to(&OutputFile::check(path, &[])?, doc)
}

/// [`save`] to an output the caller checked together with its inputs.
///
/// # Errors
/// As [`save`].
pub fn save_to<T: Document>(out: &OutputFile, doc: &T) -> Result<(), DocumentError> {
    let text = to_json(doc, &out.path().display().to_string())?;
    out.write(text.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests;
