//! The library's errors as Python exceptions, one class per stage.
//!
//! The classes are defined in Python (`underfoot/_errors.py`), where an exception can
//! derive from two bases (`InputError` is also a `ValueError`, a missing material's
//! `LibraryError` also a `KeyError`); here each error is sorted into its class, its
//! message kept as the command line prints it.

use std::error::Error;
use std::fmt::Display;
use std::panic::{AssertUnwindSafe, catch_unwind};

use pyo3::prelude::*;
use pyo3::types::PyType;
use underfoot::analysis::AnalysisError;
use underfoot::engine::{EngineError, PlayError};
use underfoot::force::gait::GaitError;
use underfoot::force::track::TrackError;
use underfoot::live::record::RecordError;
use underfoot::material::LibraryError;
use underfoot::material::build::BuildError;
use underfoot::material::quality::QualityError;
use underfoot::recording::RecordingError;

/// An error on its way to Python: its class in `underfoot._errors`, its message, and
/// attributes set on the exception.
#[derive(Debug)]
pub struct Failure {
    class: &'static str,
    message: String,
    attributes: Vec<(&'static str, f64)>,
}

/// What the native functions return; `?` turns any library error into its class.
pub type Outcome<T> = Result<T, Failure>;

impl Failure {
    /// A failure of class `class` (a name in `underfoot._errors`).
    pub fn new(class: &'static str, message: impl Display) -> Self {
        Self {
            class,
            message: message.to_string(),
            attributes: Vec::new(),
        }
    }

    /// A bad argument from Python.
    pub fn input(message: impl Display) -> Self {
        Self::new("InputError", message)
    }

    /// A failure of class `class` for `error`, said with its causes as the command line
    /// says them.
    pub fn of(class: &'static str, error: &dyn Error) -> Self {
        Self::new(class, chain(error))
    }
}

/// An error and its causes on one line, "what we did: why it failed", each said once:
/// many of the library's errors already end with their source (`"{path}: {source}"`),
/// and a cause whose text the line holds is left out (the command line's rule, so that
/// Python gets the message a terminal shows).
fn chain(error: &dyn Error) -> String {
    let mut out = String::new();
    let mut link = Some(error);
    while let Some(e) = link {
        let text = e.to_string();
        if !text.is_empty() && !out.contains(&text) {
            if !out.is_empty() {
                out.push_str(": ");
            }
            out.push_str(&text);
        }
        link = e.source();
    }
    out
}

impl From<Failure> for PyErr {
    fn from(f: Failure) -> Self {
        Python::attach(|py| {
            let raise = || -> PyResult<PyErr> {
                let class = py.import("underfoot._errors")?.getattr(f.class)?;
                let class = class.cast_into::<PyType>()?;
                let exception = class.call1((f.message.as_str(),))?;
                for (name, value) in &f.attributes {
                    exception.setattr(*name, *value)?;
                }
                Ok(PyErr::from_value(exception))
            };
            // The classes ship with the package: a failure here is a broken install, and
            // the message still says what went wrong.
            raise().unwrap_or_else(|e| {
                pyo3::exceptions::PyRuntimeError::new_err(format!(
                    "{} (and underfoot._errors.{} could not be raised: {e})",
                    f.message, f.class
                ))
            })
        })
    }
}

/// Runs `work`, turning a panic into `underfoot.Error` so that none reaches Python as a
/// `PanicException` (which no `except Exception` catches).
pub fn guarded<T>(work: impl FnOnce() -> Outcome<T>) -> Outcome<T> {
    catch_unwind(AssertUnwindSafe(work)).unwrap_or_else(|panic| {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown".into());
        Err(Failure::new(
            "Error",
            format!("internal error in underfoot (a bug; please report it): {what}"),
        ))
    })
}

macro_rules! stage {
    ($error:ty => $class:literal) => {
        impl From<$error> for Failure {
            fn from(e: $error) -> Self {
                Self::of($class, &e)
            }
        }
    };
}

stage!(RecordingError => "RecordingError");
stage!(AnalysisError => "AnalysisError");
stage!(TrackError => "ForceError");
stage!(GaitError => "ForceError");
stage!(EngineError => "EngineError");
stage!(RecordError => "SessionError");

impl From<LibraryError> for Failure {
    fn from(e: LibraryError) -> Self {
        // A name the library does not hold is a lookup that failed: Python's KeyError.
        let class = if matches!(e, LibraryError::NotFound { .. }) {
            "MaterialNotFound"
        } else {
            "LibraryError"
        };
        Self::of(class, &e)
    }
}

impl From<PlayError> for Failure {
    fn from(e: PlayError) -> Self {
        match e {
            PlayError::Library(e) => e.into(),
            PlayError::Engine(e) => e.into(),
            e => Self::of("EngineError", &e),
        }
    }
}

impl From<BuildError> for Failure {
    fn from(e: BuildError) -> Self {
        match e {
            BuildError::InvalidName { .. } => Self::of("InputError", &e),
            BuildError::Analysis(e) => e.into(),
            BuildError::Quality(QualityError::PoorFit { lsd_db, nrmse, .. }) => Self {
                attributes: vec![("lsd_db", lsd_db), ("nrmse", nrmse)],
                ..Self::new(
                    "PoorFitError",
                    format!(
                        "{} (accept_poor_fit=True keeps it, marked as poor)",
                        chain(&e)
                    ),
                )
            },
            e => Self::of("FitError", &e),
        }
    }
}
