//! Material models and the library file that holds them.
//!
//! A [`MaterialModel`] is one row of the IIR paper's soil-type look-up table (Fig. 3): the
//! fitted filter of one ground material, with the evidence of how well it fits. A
//! [`Library`] is the versioned JSON file of many of them. [`evaluate`] measures how
//! closely a render reproduces a material; [`level`] sets the level it plays at.
pub mod build;
pub mod builtin;
pub mod evaluate;
pub mod level;
pub mod library;
pub mod model;
pub mod quality;

pub use library::{FORMAT, InvalidLibrary, Library, LibraryError};
pub use model::{FilterCoefficients, FitRecord, MaterialModel, SourceFile};
