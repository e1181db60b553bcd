//! Fitting one sensor, or every sensor of a session: the checks on the data (enough
//! samples, loads and readings that vary, readings that rise with load), then the model's
//! own fit (`power.rs`, `piecewise.rs`), then how well the curve meets the samples.

use serde::{Deserialize, Serialize};

use super::curve::{CurveModel, SensorCalibration, SensorCurve};
use super::error::SensorCalibrationError;
use super::piecewise::fit_piecewise;
use super::power::fit_power;
use super::session::SensorSamples;
use super::{
    MIN_LOAD_LEVELS, MIN_LOAD_SPAN, MIN_POINTS_PIECEWISE, MIN_POINTS_POWER, MIN_RANK_CORRELATION,
};
use crate::units::Newtons;

/// Which curve to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CurveKind {
    /// `F = a·(r − r0)^b`: the FSR's conductance law; few samples suffice.
    Power,
    /// Monotone piecewise-linear through isotonic group means; needs dense data.
    Piecewise,
}

impl CurveKind {
    /// The fewest samples this kind accepts.
    #[must_use]
    pub fn min_points(self) -> usize {
        match self {
            Self::Power => MIN_POINTS_POWER,
            Self::Piecewise => MIN_POINTS_PIECEWISE,
        }
    }
}

impl std::fmt::Display for CurveKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Power => "power",
            Self::Piecewise => "piecewise",
        })
    }
}

impl std::str::FromStr for CurveKind {
    type Err = SensorCalibrationError;
    fn from_str(s: &str) -> Result<Self, SensorCalibrationError> {
        match s {
            "power" => Ok(Self::Power),
            "piecewise" => Ok(Self::Piecewise),
            other => Err(SensorCalibrationError::UnknownKind {
                found: other.to_owned(),
            }),
        }
    }
}

/// How well a curve fits its samples.
#[derive(Debug, Clone, PartialEq)]
pub struct FitReport {
    /// The sensor.
    pub sensor: String,
    /// The curve kind fitted.
    pub kind: CurveKind,
    /// Samples used.
    pub points: usize,
    /// Root-mean-square of curve minus load over the samples.
    pub rms_error: Newtons,
    /// Largest absolute curve-minus-load over the samples.
    pub max_error: Newtons,
    /// The smallest and largest load.
    pub load_range: (Newtons, Newtons),
    /// Samples the robust fit gave less than half weight (likely mis-recorded loads);
    /// always 0 for the piecewise model.
    pub downweighted: usize,
}

/// Fits one sensor's curve to `(raw reading, known load)` samples; `name` names the sensor
/// in the curve and in errors.
///
/// # Errors
/// [`SensorCalibrationError::TooFewPoints`], [`SensorCalibrationError::NonFinite`],
/// [`SensorCalibrationError::NarrowRange`] (fewer than [`MIN_LOAD_LEVELS`] distinct loads, a
/// span under [`MIN_LOAD_SPAN`], or constant readings), [`SensorCalibrationError::NonMonotone`]
/// (rank correlation under [`MIN_RANK_CORRELATION`]), or [`SensorCalibrationError::Fit`].
pub fn fit_sensor(
    name: &str,
    samples: &[(f64, Newtons)],
    kind: CurveKind,
) -> Result<(SensorCurve, FitReport), SensorCalibrationError> {
    if let Some((index, &(raw, load))) = samples
        .iter()
        .enumerate()
        .find(|(_, (r, l))| !(r.is_finite() && l.0.is_finite()))
    {
        return Err(SensorCalibrationError::NonFinite {
            sensor: name.to_owned(),
            index,
            raw,
            load: load.0,
        });
    }
    if samples.len() < kind.min_points() {
        return Err(SensorCalibrationError::TooFewPoints {
            sensor: name.to_owned(),
            kind,
            found: samples.len(),
            needed: kind.min_points(),
        });
    }
    let raw: Vec<f64> = samples.iter().map(|s| s.0).collect();
    let load: Vec<f64> = samples.iter().map(|s| s.1.0).collect();
    let narrow = |reason: String| SensorCalibrationError::NarrowRange {
        sensor: name.to_owned(),
        reason,
    };
    let (r_lo, r_hi) = min_max(&raw);
    let (l_lo, l_hi) = min_max(&load);
    if r_hi <= r_lo {
        return Err(narrow(format!(
            "every reading is {r_lo}: the sensor did not respond"
        )));
    }
    if l_hi - l_lo < MIN_LOAD_SPAN.0 {
        return Err(narrow(format!(
            "loads span {l_lo} to {l_hi} N, less than {} N",
            MIN_LOAD_SPAN.0
        )));
    }
    let mut levels = load.clone();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    if levels.len() < MIN_LOAD_LEVELS {
        return Err(narrow(format!(
            "{} distinct loads, at least {MIN_LOAD_LEVELS} needed",
            levels.len()
        )));
    }
    let rho = rank_correlation(&raw, &load);
    if rho < MIN_RANK_CORRELATION {
        return Err(SensorCalibrationError::NonMonotone {
            sensor: name.to_owned(),
            rank_correlation: rho,
        });
    }

    let (model, raw_range, downweighted) = match kind {
        CurveKind::Power => {
            let (model, downweighted) = fit_power(name, &raw, &load, r_lo, r_hi)?;
            (model, [r_lo, r_hi], downweighted)
        }
        CurveKind::Piecewise => {
            let knots = fit_piecewise(&raw, &load);
            let range = [knots[0][0], knots[knots.len() - 1][0]];
            if range[1] <= range[0] {
                return Err(narrow("the readings collapse to a single knot".to_owned()));
            }
            (CurveModel::Piecewise { knots }, range, 0)
        }
    };
    let curve = SensorCurve {
        name: name.to_owned(),
        model,
        raw_range,
        drift: 0.0,
    };
    let (mut sum2, mut max) = (0.0_f64, 0.0_f64);
    for (&r, &l) in raw.iter().zip(&load) {
        let f = curve.force(r).map_or(0.0, |(f, _)| f.0);
        sum2 += (f - l) * (f - l);
        max = max.max((f - l).abs());
    }
    let report = FitReport {
        sensor: name.to_owned(),
        kind,
        points: samples.len(),
        rms_error: Newtons((sum2 / samples.len() as f64).sqrt()),
        max_error: Newtons(max),
        load_range: (Newtons(l_lo), Newtons(l_hi)),
        downweighted,
    };
    Ok((curve, report))
}

impl SensorCalibration {
    /// Fits every sensor of a session.
    ///
    /// # Errors
    /// The first sensor's error, see [`fit_sensor`].
    pub fn fit(
        session: &[SensorSamples],
        kind: CurveKind,
    ) -> Result<(Self, Vec<FitReport>), SensorCalibrationError> {
        let mut sensors = Vec::with_capacity(session.len());
        let mut reports = Vec::with_capacity(session.len());
        for s in session {
            let (curve, report) = fit_sensor(&s.name, &s.samples, kind)?;
            sensors.push(curve);
            reports.push(report);
        }
        Ok((Self { sensors }, reports))
    }
}

/// The smallest and largest value.
pub(super) fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        })
}

/// Spearman's rank correlation, ties given their average rank.
fn rank_correlation(x: &[f64], y: &[f64]) -> f64 {
    fn ranks(v: &[f64]) -> Vec<f64> {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        let mut r = vec![0.0; v.len()];
        let mut s = 0;
        while s < idx.len() {
            let mut e = s + 1;
            while e < idx.len() && v[idx[e]] == v[idx[s]] {
                e += 1;
            }
            let avg = (s + e - 1) as f64 / 2.0;
            for &k in &idx[s..e] {
                r[k] = avg;
            }
            s = e;
        }
        r
    }
    let (rx, ry) = (ranks(x), ranks(y));
    let n = x.len() as f64;
    let (mx, my) = (rx.iter().sum::<f64>() / n, ry.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in rx.iter().zip(&ry) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    if sxx == 0.0 || syy == 0.0 {
        0.0
    } else {
        sxy / (sxx * syy).sqrt()
    }
}
