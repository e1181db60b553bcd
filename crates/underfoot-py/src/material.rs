//! `Material` and `Library`: a fitted model and a library file of them.

use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use underfoot::atomic_file::OutputFile;
use underfoot::material::library::validate::validate_model;
use underfoot::material::{Library as LibraryModel, MaterialModel};

use crate::errors::{Failure, Outcome, guarded};

/// Three curves on one grid: frequencies, measured, model.
type Curves<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);

/// A material model: the fitted filter, its fit record, the recorded steps' statistics
/// and the physical model (the native half of `underfoot.Material`).
#[pyclass(frozen, module = "underfoot._underfoot")]
pub struct Material {
    pub model: MaterialModel,
}

/// A value as JSON text, for `json.loads` on the Python side: the library's own
/// serialisation, so a dict from Python holds what a library file holds.
fn json<T: serde::Serialize>(value: &T) -> Outcome<String> {
    serde_json::to_string(value).map_err(|e| Failure::new("Error", e))
}

#[pymethods]
impl Material {
    /// The material's name.
    #[getter]
    fn name(&self) -> &str {
        &self.model.name
    }

    /// The filter order.
    #[getter]
    fn order(&self) -> usize {
        self.model.order
    }

    /// The analysis rate the filter was fitted at, Hz.
    #[getter]
    fn analysis_rate(&self) -> u32 {
        self.model.sample_rate.0
    }

    /// The band of interest, Hz.
    #[getter]
    fn band(&self) -> (f64, f64) {
        (self.model.band_hz.lo.0, self.model.band_hz.hi.0)
    }

    /// The playback level, dB.
    #[getter]
    fn level_db(&self) -> f64 {
        self.model.level_db
    }

    /// Whether the fit was kept above the quality bound.
    #[getter]
    fn poor_fit(&self) -> bool {
        self.model.fit.poor_fit
    }

    /// The second-order sections, `(n, 6)`, rows `[b0, b1, b2, 1, a1, a2]`.
    #[getter]
    fn sos<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let rows: Vec<Vec<f64>> = self.model.filter.sos.iter().map(|r| r.to_vec()).collect();
        if rows.is_empty() {
            return Ok(PyArray2::zeros(py, [0, 6], false));
        }
        PyArray2::from_vec2(py, &rows).map_err(|e| Failure::new("Error", e).into())
    }

    /// The fit grid, Hz; the measured magnitude and the filter's on it.
    fn response<'py>(&self, py: Python<'py>) -> PyResult<Curves<'py>> {
        let fit = &self.model.fit;
        let model: Vec<f64> = match self.model.sos() {
            Some(sos) => fit
                .grid_hz
                .iter()
                .map(|f| {
                    sos.response(self.model.sample_rate.omega(underfoot::units::Hz(*f)))
                        .norm()
                })
                .collect(),
            None => vec![f64::NAN; fit.grid_hz.len()],
        };
        Ok((
            PyArray1::from_slice(py, &fit.grid_hz),
            PyArray1::from_slice(py, &fit.measured),
            PyArray1::from_vec(py, model),
        ))
    }

    /// The whole model as the JSON object a library file holds.
    fn to_json(&self) -> PyResult<String> {
        Ok(json(&self.model)?)
    }

    /// The fit record as JSON.
    fn fit_json(&self) -> PyResult<String> {
        Ok(json(&self.model.fit)?)
    }

    /// The recorded steps' statistics as JSON (`null` for a file before format 3).
    fn time_json(&self) -> PyResult<String> {
        Ok(json(&self.model.time)?)
    }

    /// The physical model as JSON (`null` when it could not be estimated).
    fn physical_json(&self) -> PyResult<String> {
        Ok(json(&self.model.physical)?)
    }

    /// A material from the JSON object of one, checked as a library's materials are.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let model: MaterialModel = serde_json::from_str(text)
            .map_err(|e| Failure::new("LibraryError", format!("not a material: {e}")))?;
        validate_model(&model)
            .map_err(|e| Failure::new("LibraryError", format!("material {:?}: {e}", model.name)))?;
        Ok(Self { model })
    }
}

/// A library of materials (the native half of `underfoot.Library`).
#[pyclass(module = "underfoot._underfoot")]
pub struct Library {
    pub library: LibraryModel,
}

#[pymethods]
impl Library {
    #[new]
    fn new() -> Self {
        Self {
            library: LibraryModel::new(),
        }
    }

    /// Reads and validates a library file.
    #[staticmethod]
    fn load(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        let library = py.detach(|| guarded(|| Ok(LibraryModel::load(&path)?)))?;
        Ok(Self { library })
    }

    /// The built-in library.
    #[staticmethod]
    fn builtin() -> Self {
        Self {
            library: underfoot::material::builtin::builtin().clone(),
        }
    }

    /// The material of that name.
    fn get(&self, name: &str) -> PyResult<Material> {
        let model = self.library.get(name).map_err(Failure::from)?;
        Ok(Material {
            model: model.clone(),
        })
    }

    /// The names, in the library's order.
    fn names(&self) -> Vec<String> {
        self.library.names().into_iter().map(String::from).collect()
    }

    /// Adds a material, replacing one of the same name; whether it replaced one.
    fn add(&mut self, material: &Material) -> bool {
        self.library.upsert(material.model.clone()).is_some()
    }

    /// Removes the material of that name and returns it.
    fn remove(&mut self, name: &str) -> PyResult<Material> {
        let model = self.library.remove(name).map_err(Failure::from)?;
        Ok(Material { model })
    }

    /// Validates the library and writes it to `path` atomically, under the file's edit
    /// lock, as the command line writes libraries.
    fn save(&self, py: Python<'_>, path: std::path::PathBuf) -> PyResult<()> {
        let library = &self.library;
        py.detach(|| {
            guarded(|| {
                let out =
                    OutputFile::check(&path, &[]).map_err(|e| Failure::of("LibraryError", &e))?;
                let _lock = out.lock().map_err(|e| Failure::of("LibraryError", &e))?;
                Ok(library.save_to(&out)?)
            })
        })?;
        Ok(())
    }

    /// The library as the JSON text of its file.
    fn to_json(&self) -> String {
        self.library.to_json()
    }
}
