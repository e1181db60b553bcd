//! `underfoot calibrate limb`: a user's rheological limb model (the compensation paper's equations
//! 1-3) fitted to sweeps measured with the user standing on the device.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use underfoot::compensation::files::{LimbFile, ResponseFile};
use underfoot::compensation::limb::{LimbFitConfig, fit_limb};
use underfoot::document;
use underfoot::units::Hz;

use super::{check_outputs, plotted};
use crate::output::emit;
use crate::plot::{Curve, draw_responses};

/// `underfoot calibrate limb`.
#[derive(Debug, Clone, Args)]
pub struct LimbArgs {
    /// Responses measured with the user standing on the device (`calibrate sweep` files),
    /// averaged in dB. Measured through the equalizer, or divided by `--unloaded`.
    #[arg(long, value_name = "FILE", num_args = 1.., required = true)]
    pub sweeps: Vec<PathBuf>,
    /// The unloaded device's response, measured the same way, to divide by.
    /// Default: none, for sweeps measured through the equalizer.
    #[arg(long, value_name = "FILE")]
    pub unloaded: Option<PathBuf>,
    /// Where to write the limb model (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also draw the model against the measurement (.svg or .png).
    /// Default: no figure.
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub plot_scale: crate::plot::PlotScale,
}

/// Runs `underfoot calibrate limb`.
pub(super) fn run(args: &LimbArgs) -> anyhow::Result<()> {
    let mut inputs: Vec<&Path> = args.sweeps.iter().map(PathBuf::as_path).collect();
    inputs.extend(args.unloaded.as_deref());
    let (out, plot_out) = check_outputs(&args.out, args.plot.as_deref(), &inputs)?;
    let loaded: Vec<ResponseFile> = args
        .sweeps
        .iter()
        .map(|p| document::load(p))
        .collect::<Result<_, _>>()?;
    let first = &loaded[0];
    for (file, path) in loaded.iter().zip(&args.sweeps) {
        anyhow::ensure!(
            file.freqs_hz == first.freqs_hz,
            "{} is on another frequency grid than {}; measure with the same sweep settings",
            path.display(),
            args.sweeps[0].display()
        );
    }
    let mut db: Vec<f64> = (0..first.freqs_hz.len())
        .map(|i| loaded.iter().map(|f| f.magnitude_db[i]).sum::<f64>() / loaded.len() as f64)
        .collect();
    let mut description = format!(
        "{} loaded sweep(s): {}",
        loaded.len(),
        args.sweeps
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let Some(path) = &args.unloaded {
        let unloaded: ResponseFile = document::load(path)?;
        anyhow::ensure!(
            unloaded.freqs_hz == first.freqs_hz,
            "{} is on another frequency grid than the loaded sweeps",
            path.display()
        );
        for (d, u) in db.iter_mut().zip(&unloaded.magnitude_db) {
            *d -= u;
        }
        description.push_str(&format!(", over unloaded {}", path.display()));
    }
    let freqs: Vec<Hz> = first.freqs_hz.iter().map(|&f| Hz(f)).collect();
    let started = std::time::Instant::now();
    let fit = fit_limb(&freqs, &db, &LimbFitConfig::default()).context("fitting the limb model")?;
    let seconds = started.elapsed().as_secs_f64();
    let p = fit.model.params;
    let file = LimbFile::new(fit.model, first.band, fit.rms_error_db, description);
    document::save_to(&out, &file)?;
    let pct = |i: usize| {
        let s = fit.relative_std[i];
        if s.is_finite() {
            format!("±{:.1}%", 100.0 * s)
        } else {
            "-".to_string()
        }
    };
    emit(&format!(
        "limb model of {} ({:.2} s, {} starts)\n  b3/k3 = {:.5} s ({}; leg corner {:.1} Hz)\n  k2/m2 = {:.4e} s^-2 ({}; skin resonance {:.0} Hz)\n  b2/m2 = {:.1} s^-1 ({})\n  level {:.2} dB, residual {:.3} dB RMS\nwrote {}\n",
        file.description,
        seconds,
        fit.starts,
        p.b3_k3,
        pct(0),
        p.leg_corner().0,
        p.k2_m2,
        pct(1),
        p.skin_resonance().0,
        p.b2_m2,
        pct(2),
        20.0 * fit.model.level.log10(),
        fit.rms_error_db,
        args.out.display()
    ))?;
    if let Some(plot_out) = &plot_out {
        let plot = plot_out.path();
        let f: Vec<f64> = first.freqs_hz.clone();
        let model: Vec<f64> = freqs
            .iter()
            .map(|&x| 20.0 * fit.model.response(x).norm().log10())
            .collect();
        let curves = [
            Curve {
                label: "measured".into(),
                freqs_hz: &f,
                db: &db,
            },
            Curve {
                label: "limb model".into(),
                freqs_hz: &f,
                db: &model,
            },
        ];
        plotted(
            plot,
            plot_out.write_with(|p| {
                draw_responses(
                    p,
                    args.plot_scale.get(),
                    "Loaded response and the limb model H_u",
                    if args.unloaded.is_some() {
                        "magnitude (dB re unloaded device)"
                    } else {
                        "magnitude (dB re equalized device)"
                    },
                    &curves,
                )
            })?,
        )?;
    }
    Ok(())
}
