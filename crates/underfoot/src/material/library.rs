//! TODO(helper): the versioned JSON library.

/// The format tag of the library files this version reads and writes.
pub const FORMAT: &str = "underfoot.library/1";

/// A library of material models.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Library {
    /// Always [`FORMAT`].
    pub format: String,
    /// The materials, in insertion order, names unique.
    pub materials: Vec<super::MaterialModel>,
}

/// What is wrong with a library file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LibraryError {
    /// Placeholder.
    #[error("todo")]
    Todo,
}
