//! `underfoot calibrate equalize`: the device equalizer (the compensation paper's equations 4-5), tuned
//! by successive sweeps, each through the weights of the passes before it.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use underfoot::atomic_file::OutputFile;
use underfoot::compensation::equalizer::{EqualizerConfig, PassReport, Realisation, equalize};
use underfoot::compensation::files::{EqualizerFile, PassFigures};
use underfoot::document;
use underfoot::io::spec::{self, SpecError};
use underfoot::units::Decibels;

use super::device::{DeviceArg, parse_device};
use super::sweep::{SweepSettings, centred};
use super::{check_outputs, plotted};
use crate::output::emit;
use crate::plot::{Curve, draw_responses};
use crate::report::{Align, table};

fn parse_passes(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "passes", 1, 50)
}

fn parse_taps(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "taps", 1, 1 << 16)
}

/// `underfoot calibrate equalize`.
#[derive(Debug, Clone, Args)]
pub struct EqualizeArgs {
    /// The device: `simulated`, a measured-response file (from `calibrate sweep`), whose
    /// magnitude is replayed for the passes after the first, or `audio[:DEVICE]` (a sound
    /// card, measured at every pass; see `--output-device`, `--input-device`, `--host`).
    #[arg(long, value_name = "DEVICE", value_parser = parse_device)]
    pub device: DeviceArg,
    /// Sweeps (passes); the first is through flat weights.
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = parse_passes)]
    pub passes: usize,
    /// How the weights are applied: low-delay (a minimum-phase filter, no bulk delay) or
    /// bank (the uniform filter bank, N - 1 samples of delay).
    #[arg(long, default_value = "low-delay", value_name = "KIND")]
    pub realisation: String,
    /// Low-delay only: filter length in taps.
    #[arg(long, default_value_t = 2048, value_name = "N", value_parser = parse_taps)]
    pub taps: usize,
    /// Size N of the uniform bank that carries the weights (bins fs/N apart).
    #[arg(long, default_value_t = 4096, value_name = "N", value_parser = parse_taps)]
    pub bins: usize,
    /// Largest boost of any frequency, in dB.
    #[arg(long = "max-boost-db", default_value_t = 12.0, value_name = "DB")]
    pub max_boost_db: f64,
    /// Where to write the equalizer (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also draw every pass against flat (.svg or .png).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub settings: SweepSettings,
}

/// Runs `underfoot calibrate equalize`.
pub(super) fn run(args: &EqualizeArgs) -> anyhow::Result<()> {
    let s = &args.settings;
    let inputs: Vec<&Path> = s.input_file().into_iter().collect();
    let (out, plot_out) = check_outputs(&args.out, args.plot.as_deref(), &inputs)?;
    let realisation = match args.realisation.as_str() {
        "low-delay" => Realisation::LowDelay { taps: args.taps },
        "bank" => Realisation::Bank,
        other => anyhow::bail!("--realisation {other:?}: expected low-delay or bank"),
    };
    anyhow::ensure!(
        (1..=10).contains(&args.passes),
        "--passes {}: need 1 to 10",
        args.passes
    );
    let sweep = s.sweep()?;
    let (mut device, description) = s.device(&args.device)?;
    let config = EqualizerConfig {
        band: s.band,
        bins: args.bins,
        max_boost: Decibels(args.max_boost_db),
        ..EqualizerConfig::default()
    };
    let eq = equalize(device.as_mut(), &sweep, config, realisation, args.passes)
        .context("equalizing")?;
    let passes: Vec<PassFigures> = eq.passes.iter().map(PassFigures::from).collect();
    let latency_ms = match realisation {
        Realisation::Bank => (args.bins - 1) as f64 / f64::from(s.rate) * 1e3,
        Realisation::LowDelay { .. } => 0.0,
    };
    let file = EqualizerFile::new(eq.weights, realisation, passes.clone(), description);
    document::save_to(&out, &file)?;
    let rows: Vec<Vec<String>> = passes
        .iter()
        .map(|p| {
            vec![
                p.pass.to_string(),
                format!("{:.2}", p.deviation_db),
                format!("{:.2}", p.peak_db),
            ]
        })
        .collect();
    emit(&format!(
        "equalizing {} over {}-{} Hz ({}, {:.1} ms bulk delay)\n{}wrote {}\n",
        file.description,
        s.band.lo.0,
        s.band.hi.0,
        match realisation {
            Realisation::Bank => format!("filter bank, N = {}", args.bins),
            Realisation::LowDelay { taps } =>
                format!("low-delay minimum-phase filter, {taps} taps"),
        },
        latency_ms,
        table(
            &[
                ("pass", Align::Right),
                ("deviation RMS (dB)", Align::Right),
                ("peak (dB)", Align::Right),
            ],
            &rows
        ),
        args.out.display()
    ))?;
    if let Some(plot_out) = &plot_out {
        draw_passes(plot_out, &eq.passes)?;
    }
    Ok(())
}

fn draw_passes(out: &OutputFile, passes: &[PassReport]) -> anyhow::Result<()> {
    let data: Vec<(Vec<f64>, Vec<f64>)> = passes
        .iter()
        .map(|p| {
            (
                p.response.freqs.iter().map(|f| f.0).collect(),
                centred(&p.response),
            )
        })
        .collect();
    let curves: Vec<Curve<'_>> = passes
        .iter()
        .zip(&data)
        .map(|(p, (f, db))| Curve {
            label: format!("pass {} ({:.2} dB)", p.pass, p.deviation.0),
            freqs_hz: f,
            db,
        })
        .collect();
    plotted(
        out.path(),
        out.write_with(|p| {
            draw_responses(
                p,
                "Equalized device against flat, pass by pass",
                "magnitude (dB re its mean in the band)",
                &curves,
            )
        })?,
    )
}
