//! `fit`: recordings (files or arrays) in, a material out, fitted as `underfoot fit`
//! fits one.

use std::path::PathBuf;

use numpy::PyReadonlyArray1;
use pyo3::prelude::*;
use underfoot::analysis::{MAX_ANALYSIS_RATE, MIN_ANALYSIS_RATE, SavgolSetting};
use underfoot::fit::{MAX_FILTER_ORDER, OrderChoice};
use underfoot::material::build::{BuildConfig, build_material};
use underfoot::recording::{self, CsvSpec, Recording};
use underfoot::units::{Band, Decibels, SampleRate, Seconds};

use crate::errors::{Failure, Outcome, guarded};
use crate::material::Material;

/// One recording as the Python side hands it over: a file, or a named array at a rate.
pub enum Source {
    File(PathBuf),
    Samples(String, SampleRate, Vec<f64>),
}

impl Source {
    /// A file path (`str`), or a tuple `(name, rate, float64 array)`.
    fn extract(item: &Bound<'_, PyAny>) -> Outcome<Self> {
        if let Ok((name, rate, samples)) =
            item.extract::<(String, f64, PyReadonlyArray1<'_, f64>)>()
        {
            let rate = whole_rate(rate, &name)?;
            let limit = underfoot::limits::MAX_RECORDING_FRAMES;
            if samples.as_array().len() > limit {
                return Err(Failure::new(
                    "RecordingError",
                    format!("{name}: too long: more than {limit} samples (split the recording)"),
                ));
            }
            let samples = match samples.as_slice() {
                Ok(s) => s.to_vec(),
                Err(_) => samples.as_array().iter().copied().collect(),
            };
            return Ok(Self::Samples(name, rate, samples));
        }
        item.extract::<PathBuf>()
            .map(Self::File)
            .map_err(|_| Failure::new("InputTypeError", "a recording is a path or an array"))
    }

    /// The recordings it holds (a long file is read as excerpts around its strikes, as
    /// the command line reads it).
    fn read(self, csv: Option<&CsvSpec>) -> Outcome<Vec<Recording>> {
        Ok(match self {
            Self::File(path) => recording::read_for_analysis(&path, csv)?,
            Self::Samples(name, rate, samples) => {
                vec![recording::from_samples(&name, rate, samples)?]
            }
        })
    }
}

/// A sample rate in whole hertz, as a recording's is.
pub fn whole_rate(rate: f64, what: &str) -> Outcome<SampleRate> {
    if rate.is_finite() && rate >= 1.0 && rate <= f64::from(u32::MAX) && rate.fract() == 0.0 {
        Ok(SampleRate(rate as u32))
    } else {
        Err(Failure::input(format!(
            "{what}: rate {rate:?}: need a whole number of hertz, at least 1"
        )))
    }
}

/// A band `(lo, hi)` in Hz, checked as the command line's `--band`.
pub fn band(lo: f64, hi: f64) -> Outcome<Band> {
    format!("{lo}:{hi}").parse::<Band>().map_err(Failure::input)
}

/// The Savitzky-Golay setting: `"auto"`, `"off"`, or `(window, polyorder)`, checked as
/// the command line's `--savgol auto|off|WINDOW:ORDER` is (the library's parser).
pub fn savgol(item: &Bound<'_, PyAny>) -> Outcome<SavgolSetting> {
    let text = match item.extract::<(usize, usize)>() {
        Ok((window, polyorder)) => format!("{window}:{polyorder}"),
        Err(_) => item.extract::<String>().map_err(|_| {
            Failure::new(
                "InputTypeError",
                "savgol: expected \"auto\", \"off\" or (window, polyorder)",
            )
        })?,
    };
    text.parse().map_err(Failure::input)
}

/// The settings of a fit, from the Python side's keyword arguments.
pub struct FitOptions {
    pub analysis_rate: u32,
    pub band: Band,
    pub order: Option<usize>,
    pub max_order: usize,
    pub savgol: SavgolSetting,
    pub target_lsd: f64,
    pub longest_decay: f64,
    pub accept_poor_fit: bool,
}

impl FitOptions {
    /// The library's build settings, each value checked as the command line checks its
    /// flag.
    pub fn config(&self) -> Outcome<BuildConfig> {
        let mut cfg = BuildConfig::default();
        if !(MIN_ANALYSIS_RATE..=MAX_ANALYSIS_RATE).contains(&self.analysis_rate) {
            return Err(Failure::input(format!(
                "analysis_rate {}: need {MIN_ANALYSIS_RATE} to {MAX_ANALYSIS_RATE} Hz",
                self.analysis_rate
            )));
        }
        cfg.analysis.rate = SampleRate(self.analysis_rate);
        cfg.analysis.band = self.band;
        if !self.band.fits(cfg.analysis.rate) {
            return Err(Failure::input(format!(
                "band {} does not fit the analysis rate {}: the upper edge must be below {}",
                self.band,
                cfg.analysis.rate,
                cfg.analysis.rate.nyquist()
            )));
        }
        let order = |n: usize, what: &str| {
            if (1..=MAX_FILTER_ORDER).contains(&n) {
                Ok(n)
            } else {
                Err(Failure::input(format!(
                    "{what} {n}: need 1 to {MAX_FILTER_ORDER}"
                )))
            }
        };
        cfg.fit.order = match self.order {
            Some(n) => OrderChoice::Fixed(order(n, "order")?),
            None => OrderChoice::Auto {
                max: order(self.max_order, "max_order")?,
            },
        };
        cfg.analysis.savgol = self.savgol;
        if !(self.target_lsd.is_finite() && self.target_lsd > 0.0) {
            return Err(Failure::input(format!(
                "target_lsd {}: need a number of dB above 0",
                self.target_lsd
            )));
        }
        cfg.fit.target_lsd = Decibels(self.target_lsd);
        if !(self.longest_decay > 0.0 && self.longest_decay <= 60.0) {
            return Err(Failure::input(format!(
                "longest_decay {}: need seconds in (0, 60]",
                self.longest_decay
            )));
        }
        cfg.fit.longest_decay = Seconds(self.longest_decay);
        cfg.quality.accept_poor_fit = self.accept_poor_fit;
        Ok(cfg)
    }
}

/// Each source as handed over (read later, off the GIL).
pub fn read_sources(sources: &[Bound<'_, PyAny>]) -> Outcome<Vec<Source>> {
    if sources.is_empty() {
        return Err(Failure::input("no recordings given"));
    }
    sources.iter().map(Source::extract).collect()
}

/// The CSV spec of `csv_column` and `csv_rate`.
pub fn csv_spec(column: Option<String>, rate: Option<f64>) -> Outcome<Option<CsvSpec>> {
    match (column, rate) {
        (Some(column), Some(rate)) => Ok(Some(CsvSpec {
            column,
            rate: whole_rate(rate, "csv_rate")?,
        })),
        (None, None) => Ok(None),
        _ => Err(Failure::input(
            "csv_column and csv_rate go together: give both for CSV recordings",
        )),
    }
}

/// Decodes the sources into recordings (off the GIL).
pub fn recordings(sources: Vec<Source>, csv: Option<&CsvSpec>) -> Outcome<Vec<Recording>> {
    let mut all = Vec::new();
    for source in sources {
        all.extend(source.read(csv)?);
    }
    Ok(all)
}

/// Reads one recording as `fit` reads a file: `(samples, rate, name, sha256)`, mixed to
/// mono, whole (a long file is not cut into excerpts here).
#[pyfunction]
#[pyo3(signature = (path, csv_column, csv_rate))]
pub fn read_recording(
    py: Python<'_>,
    path: PathBuf,
    csv_column: Option<String>,
    csv_rate: Option<f64>,
) -> PyResult<(Bound<'_, numpy::PyArray1<f64>>, u32, String, String)> {
    let csv = csv_spec(csv_column, csv_rate)?;
    let r = py.detach(|| guarded(|| Ok(recording::read(&path, csv.as_ref())?)))?;
    Ok((
        numpy::PyArray1::from_vec(py, r.samples),
        r.rate.0,
        r.name,
        r.sha256,
    ))
}

/// Fits a material to recordings (see the Python docstring of `underfoot.fit`).
#[pyfunction]
#[pyo3(signature = (sources, material, analysis_rate, band_lo, band_hi, order, max_order,
    savgol, target_lsd, longest_decay, accept_poor_fit, csv_column, csv_rate))]
#[expect(
    clippy::too_many_arguments,
    reason = "the keyword arguments of underfoot.fit"
)]
pub fn fit(
    py: Python<'_>,
    sources: Vec<Bound<'_, PyAny>>,
    material: String,
    analysis_rate: u32,
    band_lo: f64,
    band_hi: f64,
    order: Option<usize>,
    max_order: usize,
    savgol: Bound<'_, PyAny>,
    target_lsd: f64,
    longest_decay: f64,
    accept_poor_fit: bool,
    csv_column: Option<String>,
    csv_rate: Option<f64>,
) -> PyResult<Material> {
    underfoot::material::library::validate_name(&material)
        .map_err(|e| Failure::input(format!("material {material:?}: {e}")))?;
    let options = FitOptions {
        analysis_rate,
        band: band(band_lo, band_hi)?,
        order,
        max_order,
        savgol: self::savgol(&savgol)?,
        target_lsd,
        longest_decay,
        accept_poor_fit,
    };
    let cfg = options.config()?;
    let csv = csv_spec(csv_column, csv_rate)?;
    let sources = read_sources(&sources)?;
    let model = py.detach(|| {
        guarded(|| {
            let recordings = recordings(sources, csv.as_ref())?;
            Ok(build_material(&material, &recordings, &cfg, &mut |_| {})?)
        })
    })?;
    Ok(Material { model })
}
