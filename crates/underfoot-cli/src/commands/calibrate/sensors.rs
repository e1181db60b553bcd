//! `underfoot calibrate sensors`: each force sensor's curve, fitted to readings under
//! known loads (a lab scale).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use underfoot::force::calibration::{CurveKind, CurveModel, SensorCalibration, read_session};

use super::check_outputs;
use crate::output::emit;
use crate::report::{Align, table};

/// `underfoot calibrate sensors`.
#[derive(Debug, Clone, Args)]
pub struct SensorsArgs {
    /// The calibration session: CSV rows of `sensor,raw,load_n` (raw reading, known load
    /// in newtons).
    #[arg(long, value_name = "FILE.csv")]
    pub readings: PathBuf,
    /// Where to write the sensor calibration (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// The curve: `power` (F = a (r - r0)^b, the FSR conductance law) or `piecewise`
    /// (monotone, for dense data).
    #[arg(long, default_value = "power", value_parser = clap::value_parser!(CurveKind))]
    pub kind: CurveKind,
}

/// Runs `underfoot calibrate sensors`.
pub(super) fn run(args: &SensorsArgs) -> anyhow::Result<()> {
    let (out, _) = check_outputs(&args.out, None, &[&args.readings])?;
    let session = read_session(&args.readings)?;
    let (calibration, reports) = SensorCalibration::fit(&session, args.kind)
        .with_context(|| format!("fitting the sensors of {}", args.readings.display()))?;
    calibration.save_to(&out)?;
    let rows: Vec<Vec<String>> = reports
        .iter()
        .zip(&calibration.sensors)
        .map(|(r, c)| {
            let model = match &c.model {
                CurveModel::Power { a, b, r0 } => format!("{a:.4e} (r - {r0:.1})^{b:.3}"),
                CurveModel::Piecewise { knots } => format!("{} knots", knots.len()),
            };
            vec![
                r.sensor.clone(),
                r.points.to_string(),
                format!("{:.0} to {:.0}", r.load_range.0.0, r.load_range.1.0),
                format!("{:.2}", r.rms_error.0),
                format!("{:.2}", r.max_error.0),
                r.downweighted.to_string(),
                model,
            ]
        })
        .collect();
    let text = table(
        &[
            ("sensor", Align::Left),
            ("points", Align::Right),
            ("load N", Align::Right),
            ("rms N", Align::Right),
            ("max N", Align::Right),
            ("outliers", Align::Right),
            ("curve", Align::Left),
        ],
        &rows,
    );
    emit(&format!(
        "{} curves of {} sensors from {}\n{text}wrote {}\n",
        args.kind,
        reports.len(),
        args.readings.display(),
        args.out.display()
    ))
}
