//! The native half of the `underfoot` Python package: the library's fit, libraries,
//! renders, analysis and session records, called from Python.
//!
//! The public API is the Python package in `python/underfoot/`, which checks and
//! normalises its arguments (paths, dtypes, shapes, keyword defaults) and calls the
//! functions here with plain types: `float64` arrays, strings, numbers. This crate only
//! translates: every computation is the library's, called as the command line calls it,
//! so the same input gives the same coefficients and the same samples from both.
//!
//! - Errors: each stage's error becomes the Python exception of that stage
//!   (`underfoot._errors`), with the library's message ([`errors`]).
//! - No panic reaches Python: each entry point runs under [`errors::guarded`], which
//!   turns one into `underfoot.Error` naming it a bug.
//! - The GIL is released around the work (fits, renders, analysis), so other Python
//!   threads run meanwhile.
//! - Arrays come in without a copy when contiguous, and a render's output goes out
//!   without one (the engine's interleaved frames, which the Python side transposes).

mod analysis;
mod errors;
mod fit;
mod material;
mod render;
mod session;

use pyo3::prelude::*;

/// The extension module `underfoot._underfoot`.
#[pymodule]
fn _underfoot(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // Which cargo profile built the module: a speed comparison with the command line
    // takes the binary of the same profile.
    m.add(
        "BUILD_PROFILE",
        if cfg!(debug_assertions) {
            "dev"
        } else {
            "release"
        },
    )?;
    m.add_class::<material::Material>()?;
    m.add_class::<material::Library>()?;
    m.add_function(wrap_pyfunction!(fit::fit, m)?)?;
    m.add_function(wrap_pyfunction!(fit::read_recording, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(analysis::measure, m)?)?;
    m.add_function(wrap_pyfunction!(analysis::steps, m)?)?;
    m.add_function(wrap_pyfunction!(analysis::summarize_steps, m)?)?;
    m.add_function(wrap_pyfunction!(analysis::compare_steps, m)?)?;
    m.add_function(wrap_pyfunction!(session::read_session, m)?)?;
    Ok(())
}
