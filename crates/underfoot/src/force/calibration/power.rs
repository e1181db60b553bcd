//! The power law's fit: Huber-weighted bounded least squares by
//! [`crate::numeric::trf`], in scaled units, from log-log start points (see the parent
//! module, *Fitting the power law*).

use super::EXPONENT_BOUNDS;
use super::curve::CurveModel;
use super::error::SensorCalibrationError;
use crate::numeric::trf::{FnResiduals, TrfError, TrfOptions, least_squares_bounded};

/// The power law by Huber-weighted bounded least squares in scaled units; returns the
/// model in reading units and the number of samples left with under half weight.
pub(super) fn fit_power(
    name: &str,
    raw: &[f64],
    load: &[f64],
    r_lo: f64,
    r_hi: f64,
) -> Result<(CurveModel, usize), SensorCalibrationError> {
    let span = r_hi - r_lo;
    let scale = load.iter().fold(0.0_f64, |m, l| m.max(l.abs()));
    let x: Vec<f64> = raw.iter().map(|r| (r - r_lo) / span).collect();
    let y: Vec<f64> = load.iter().map(|l| l / scale).collect();
    let m = x.len();
    let (b_lo, b_hi) = EXPONENT_BOUNDS;
    // The offset may lie below every reading (a sensor never seen unloaded), but not
    // above the top one, where the curve would be zero everywhere.
    let lower = [1e-9, b_lo, -1.0];
    let upper = [1e9, b_hi, 0.999];
    let opts = TrfOptions::default();
    let mut w = vec![1.0_f64; m];
    let mut best: Option<[f64; 3]> = None;
    for _round in 0..4 {
        let problem = FnResiduals {
            m,
            f: |p: &[f64], r: &mut [f64]| {
                for i in 0..m {
                    let d = x[i] - p[2];
                    let f = if d > 0.0 { p[0] * d.powf(p[1]) } else { 0.0 };
                    r[i] = w[i].sqrt() * (f - y[i]);
                }
            },
        };
        let starts: Vec<[f64; 3]> = match best {
            Some(p) => vec![p],
            None => start_points(&x, &y),
        };
        let mut round_best: Option<(f64, [f64; 3])> = None;
        let mut last_error = None;
        for s in starts {
            let s = [
                s[0].clamp(lower[0], upper[0]),
                s[1].clamp(lower[1], upper[1]),
                s[2].clamp(lower[2], upper[2]),
            ];
            match least_squares_bounded(&problem, &s, &lower, &upper, &opts) {
                Ok(sol) if round_best.is_none_or(|(c, _)| sol.cost < c) => {
                    round_best = Some((sol.cost, [sol.x[0], sol.x[1], sol.x[2]]));
                }
                Ok(_) => {}
                Err(e) => last_error = Some(e),
            }
        }
        let Some((_, p)) = round_best else {
            return Err(SensorCalibrationError::Fit {
                sensor: name.to_owned(),
                source: last_error.unwrap_or(TrfError::Numerical("no start point converged")),
            });
        };
        best = Some(p);
        // Huber weights from the unweighted residuals, scaled by their MAD.
        let mut res: Vec<f64> = (0..m)
            .map(|i| {
                let d = x[i] - p[2];
                let f = if d > 0.0 { p[0] * d.powf(p[1]) } else { 0.0 };
                (f - y[i]).abs()
            })
            .collect();
        let abs = res.clone();
        let sigma = (1.4826 * crate::numeric::median(&mut res)).max(1e-9);
        let k = 1.345 * sigma;
        for (wi, a) in w.iter_mut().zip(&abs) {
            *wi = if *a <= k { 1.0 } else { k / a };
        }
    }
    let p = best.unwrap_or([1.0, 1.0, 0.0]);
    let downweighted = w.iter().filter(|&&wi| wi < 0.5).count();
    let (a, b, x0) = (p[0], p[1], p[2]);
    Ok((
        CurveModel::Power {
            a: scale * a / span.powf(b),
            b,
            r0: r_lo + x0 * span,
        },
        downweighted,
    ))
}

/// Start points for the power law: a log-log line for a few trial offsets at or below
/// the lowest reading.
fn start_points(x: &[f64], y: &[f64]) -> Vec<[f64; 3]> {
    [-0.2, -0.05, -0.01, 0.0]
        .iter()
        .map(|&x0| {
            let pts: Vec<(f64, f64)> = x
                .iter()
                .zip(y)
                .filter(|&(&xi, &yi)| xi - x0 > 1e-3 && yi > 0.02)
                .map(|(&xi, &yi)| ((xi - x0).ln(), yi.ln()))
                .collect();
            let n = pts.len() as f64;
            if pts.len() < 2 {
                return [1.0, 1.0, x0];
            }
            let (mx, my) = pts
                .iter()
                .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
            let (sxy, sxx) = pts.iter().fold((0.0, 0.0), |(a, b), p| {
                (a + (p.0 - mx) * (p.1 - my), b + (p.0 - mx) * (p.0 - mx))
            });
            let slope = if sxx > 0.0 { sxy / sxx } else { 1.0 };
            let slope = if slope.is_finite() { slope } else { 1.0 };
            let intercept = my - slope * mx;
            [intercept.exp(), slope, x0]
        })
        .collect()
}
