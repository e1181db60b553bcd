//! The errors of the document layer: one for files, one for documents.

pub use crate::atomic_file::FileError;

/// What is wrong with a document, or with reading or writing its file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DocumentError {
    /// The file could not be read or written.
    #[error(transparent)]
    File(#[from] FileError),
    /// The text is not JSON, or not JSON of the document's shape.
    #[error("{origin}: not a valid {description} file at line {line}, column {column}: {message}")]
    Json {
        /// Where the text came from (a path, or a description).
        origin: String,
        /// What the file should be ([`Document::DESCRIPTION`](super::Document::DESCRIPTION)).
        description: &'static str,
        /// 1-based line of the error.
        line: usize,
        /// 1-based column of the error.
        column: usize,
        /// What the parser objected to.
        message: String,
    },
    /// No header at all.
    #[error(
        "{origin}: no \"format\" tag (is this an underfoot {description} file?); expected {expected:?}"
    )]
    NoTag {
        /// Where the text came from.
        origin: String,
        /// What the file should be.
        description: &'static str,
        /// The tag expected.
        expected: String,
    },
    /// A header for another kind of document.
    #[error("{origin}: a file of format {found:?}, expected {expected:?}")]
    WrongKind {
        /// Where the text came from.
        origin: String,
        /// The tag (or legacy kind) found.
        found: String,
        /// The tag expected.
        expected: String,
    },
    /// The right kind, in a version this build does not read.
    #[error("{origin}: {description} format version {found} is not supported; this version of underfoot reads {}",
        if oldest == newest { format!("version {newest}") } else { format!("versions {oldest} to {newest}") })]
    Version {
        /// Where the text came from.
        origin: String,
        /// What the file is.
        description: &'static str,
        /// The version found, as written (`missing` when absent).
        found: String,
        /// The oldest version this build reads.
        oldest: u32,
        /// The version this build writes.
        newest: u32,
    },
    /// The document breaks a rule serde cannot check.
    #[error("{origin}: {reason}")]
    Invalid {
        /// Where the document came from or is going to.
        origin: String,
        /// What is wrong ([`Document::Invalid`](super::Document::Invalid)).
        reason: Box<dyn std::error::Error + Send + Sync>,
    },
    /// serde could not write the document.
    #[error("{origin}: cannot encode: {message}")]
    Encode {
        /// Where the document is going.
        origin: String,
        /// serde's message.
        message: String,
    },
}

impl DocumentError {
    pub(super) fn json(origin: &str, description: &'static str, e: &serde_json::Error) -> Self {
        Self::Json {
            origin: origin.to_string(),
            description,
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        }
    }

    pub(super) fn invalid(origin: &str, e: impl std::error::Error + Send + Sync + 'static) -> Self {
        Self::Invalid {
            origin: origin.to_string(),
            reason: Box::new(e),
        }
    }

    /// The document's own validation error, if that is what this is.
    #[must_use]
    pub fn reason(&self) -> Option<&(dyn std::error::Error + Send + Sync + 'static)> {
        match self {
            Self::Invalid { reason, .. } => Some(reason.as_ref()),
            _ => None,
        }
    }
}
