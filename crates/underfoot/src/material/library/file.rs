//! The library as a [`Document`]: reading it from text or a file, writing it, and editing
//! a file in place under its edit lock.
//!
//! The header and its checks are the document layer's; this file keeps the library's own
//! messages (a missing or unsupported tag names every format this version reads) and its
//! larger size cap ([`MAX_LIBRARY_BYTES`]).

use std::path::Path;

use super::{InvalidLibrary, Library, LibraryError};
use crate::atomic_file::OutputFile;
use crate::document::{self, Document, DocumentError, FileError, TAG_PREFIX};
use crate::limits::{MAX_LIBRARY_BYTES, read_to_string_capped};

impl Document for Library {
    const KIND: &'static str = "library";
    const VERSION: u32 = 3;
    const OLDEST: u32 = 1;
    type Invalid = InvalidLibrary;

    fn validate(&self) -> Result<(), InvalidLibrary> {
        self.check()
    }

    fn upgrade(mut self, from: u32) -> Result<Self, InvalidLibrary> {
        if from == 1 {
            self.upgrade_from_1();
        }
        // Format 2 lacks the excitation, the time statistics and the level, which are
        // optional (a material without an excitation plays one impulse per step, as it
        // did) and default to the recorded level: nothing to change.
        Ok(self)
    }
}

impl Library {
    /// Parses and validates a library from JSON text.
    ///
    /// `origin` names where the text came from (a path, `built-in`, ...) in errors.
    ///
    /// # Errors
    /// [`LibraryError::Json`] for text that is not JSON or not shaped like a library,
    /// [`LibraryError::UnknownFormat`] for a missing or unsupported `format` tag, and
    /// [`LibraryError::Invalid`] for a material that breaks a rule of the format.
    pub fn from_json(text: &str, origin: &str) -> Result<Self, LibraryError> {
        document::from_json(text, origin).map_err(LibraryError::from_document)
    }

    /// Reads and validates a library file.
    ///
    /// # Errors
    /// [`LibraryError::File`] when the file cannot be read, and the errors of
    /// [`Library::from_json`] (with the path as origin).
    pub fn load(path: impl AsRef<Path>) -> Result<Self, LibraryError> {
        let path = path.as_ref();
        let text = read_to_string_capped(path, MAX_LIBRARY_BYTES)
            .map_err(|source| reading(path, source))?;
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
        match read_to_string_capped(path, MAX_LIBRARY_BYTES) {
            Ok(text) => Self::from_json(&text, &path.display().to_string()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Self::new()),
            Err(source) => Err(reading(path, source)),
        }
    }

    /// The library as pretty-printed JSON, with a final newline: the text [`Library::save`]
    /// writes, but not validated, so that a broken library can be written on purpose.
    #[must_use]
    pub fn to_json(&self) -> String {
        // Serialising these types cannot fail: every map key is a string, and serde_json
        // writes non-finite floats as null rather than failing.
        document::to_json_unchecked(self, "library")
            .expect("a library always serialises: its maps have string keys")
    }

    /// Validates the library and writes it to `path` atomically.
    ///
    /// The text goes to a temporary file in the same directory, which is flushed to disk
    /// and then renamed over `path`. On any error the previous file at `path` (if any) is
    /// left exactly as it was and the temporary file is removed.
    ///
    /// # Errors
    /// The errors of [`Library::validate`] (nothing is written), or [`LibraryError::File`].
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LibraryError> {
        self.save_to(&OutputFile::check(path.as_ref(), &[])?)
    }

    /// Validates the library and writes it to an output the caller has already checked
    /// against the output policy ([`crate::atomic_file`]), atomically as [`Library::save`].
    ///
    /// # Errors
    /// As [`Library::save`].
    pub fn save_to(&self, out: &OutputFile) -> Result<(), LibraryError> {
        let origin = format!("library to be saved to {}", out.path().display());
        let text = document::to_json(self, &origin).map_err(LibraryError::from_document)?;
        Ok(out.write(text.as_bytes())?)
    }

    /// Edits the library file `out` in place: read, `edit`, write, all under the file's
    /// edit lock ([`OutputFile::lock`]), so concurrent edits by several processes all
    /// land (each reads what the one before it wrote). With `create`, a missing file is
    /// an empty library; without, it is an error. Nothing is written if `edit` fails.
    ///
    /// # Errors
    /// [`LibraryError::File`] for the lock, the errors of [`Library::load`] /
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
            // Errors name the file as the user gave it.
            LibraryError::File(FileError { action, source, .. }) => LibraryError::File(FileError {
                path: out.path().to_path_buf(),
                action,
                source,
            }),
            e => e,
        })?;
        let value = edit(&mut library)?;
        library.save_to(out)?;
        Ok(value)
    }
}

fn reading(path: &Path, source: std::io::Error) -> LibraryError {
    LibraryError::File(FileError {
        path: path.to_path_buf(),
        action: "reading",
        source,
    })
}

impl LibraryError {
    /// The document layer's error in the library's words: a header that is not a
    /// library's of a version this one reads is an [`LibraryError::UnknownFormat`] naming
    /// the tag found, and a failed validation names the material.
    fn from_document(e: DocumentError) -> Self {
        match e {
            DocumentError::File(e) => Self::File(e),
            DocumentError::Json {
                origin,
                line,
                column,
                message,
                ..
            } => Self::Json {
                origin,
                line,
                column,
                message: strip_position(&message),
            },
            DocumentError::NoTag { origin, .. } => Self::UnknownFormat {
                origin,
                found: None,
            },
            DocumentError::WrongKind { origin, found, .. } => Self::UnknownFormat {
                origin,
                found: Some(found),
            },
            DocumentError::Version { origin, found, .. } => Self::UnknownFormat {
                origin,
                found: Some(format!("{TAG_PREFIX}{}/{found}", Library::KIND)),
            },
            DocumentError::Invalid { origin, reason } => {
                match reason.downcast::<InvalidLibrary>() {
                    Ok(invalid) => invalid.at(&origin),
                    Err(reason) => Self::Document(DocumentError::Invalid { origin, reason }),
                }
            }
            e => Self::Document(e),
        }
    }
}

/// serde_json appends " at line L column C" to its messages; the error variant carries
/// those as fields, so the message drops them to avoid saying it twice.
fn strip_position(message: &str) -> String {
    match message.rfind(" at line ") {
        Some(i) => message[..i].to_string(),
        None => message.to_string(),
    }
}
