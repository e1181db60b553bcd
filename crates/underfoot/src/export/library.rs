//! The export of a library: its materials prepared and checked, with the library's
//! identity, and the header written.

use std::path::Path;

use super::{ExportConfig, ExportError, Exported, prepare};
use crate::atomic_file::{OutputFile, write_atomic};
use crate::material::{Library, MaterialModel};

/// A library ready for firmware: what [`c::header`](super::c::header) writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Export {
    /// Where the library came from (a path, or `built-in`).
    pub origin: String,
    /// SHA-256 of the library's JSON, lower-case hex: its identity.
    pub library_sha256: String,
    /// The materials, in library order.
    pub materials: Vec<Exported>,
}

/// Prepares and checks `names` (all materials when empty) of `library`.
///
/// # Errors
/// [`ExportError::UnknownMaterial`], [`ExportError::Empty`], and the errors of
/// [`prepare`] for the first material that fails.
pub fn export_library(
    library: &Library,
    origin: &str,
    names: &[String],
    config: &ExportConfig,
) -> Result<Export, ExportError> {
    let models: Vec<&MaterialModel> = if names.is_empty() {
        library.materials.iter().collect()
    } else {
        names
            .iter()
            .map(|n| {
                library
                    .materials
                    .iter()
                    .find(|m| &m.name == n)
                    .ok_or_else(|| ExportError::UnknownMaterial {
                        name: n.clone(),
                        available: library.names().join(", "),
                    })
            })
            .collect::<Result<_, _>>()?
    };
    if models.is_empty() {
        return Err(ExportError::Empty);
    }
    let materials = prepare_all(&models, config)?;
    Ok(Export {
        origin: origin.to_string(),
        library_sha256: sha256_hex(library.to_json().as_bytes()),
        materials,
    })
}

/// [`prepare`] of every model, on as many threads as the machine has (each material's
/// check is independent, and an export of a large library is that check's time), in
/// order; the first failure in library order is the error, as one at a time.
fn prepare_all(
    models: &[&MaterialModel],
    config: &ExportConfig,
) -> Result<Vec<Exported>, ExportError> {
    let threads = std::thread::available_parallelism()
        .map_or(1, std::num::NonZeroUsize::get)
        .min(models.len())
        .max(1);
    if threads == 1 {
        return models.iter().map(|m| prepare(m, config)).collect();
    }
    let chunk = models.len().div_ceil(threads);
    let results: Vec<Vec<Result<Exported, ExportError>>> = std::thread::scope(|scope| {
        let workers: Vec<_> = models
            .chunks(chunk)
            .map(|part| scope.spawn(move || part.iter().map(|m| prepare(m, config)).collect()))
            .collect();
        workers
            .into_iter()
            .map(|w| w.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    results.into_iter().flatten().collect()
}

/// Writes `text` to `path` atomically (temporary file and rename).
///
/// # Errors
/// [`ExportError::Write`].
pub fn write(path: &Path, text: &str) -> Result<(), ExportError> {
    Ok(write_atomic(path, text.as_bytes())?)
}

/// Writes `text` to an output the caller checked against the output policy
/// ([`crate::atomic_file`]; `-` is standard output there).
///
/// # Errors
/// [`ExportError::Write`].
pub fn write_to(out: &OutputFile, text: &str) -> Result<(), ExportError> {
    Ok(out.write(text.as_bytes())?)
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}
