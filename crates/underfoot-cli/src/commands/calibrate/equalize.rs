//! `underfoot calibrate equalize`: the device equalizer (the compensation paper's equations 4-5), tuned
//! by successive sweeps, each through the weights of the passes before it.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use underfoot::atomic_file::OutputFile;
use underfoot::compensation::equalizer::{
    Capped, Equalization, EqualizerConfig, EqualizerFilter, Realisation, auto_taps, equalize,
};
use underfoot::compensation::files::{EqualizerFile, PassFigures};
use underfoot::document;
use underfoot::io::spec::{self, SpecError};
use underfoot::units::Decibels;

use super::device::{DeviceArg, parse_device};
use super::sweep::{SweepSettings, centred};
use super::{check_outputs, plotted};
use crate::output::emit;
use crate::plot::{Curve, Scale, draw_responses};
use crate::report::{Align, table};

fn parse_passes(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "passes", 1, 50)
}

fn parse_taps(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "taps", 1, 1 << 16)
}

/// `--bins`: the range the equalizer takes, stated as it is enforced.
fn parse_bins(s: &str) -> Result<usize, SpecError> {
    use underfoot::compensation::equalizer::weights::{MAX_BINS, MIN_BINS, bins_are_valid};
    match s.trim().parse::<usize>() {
        Ok(n) if bins_are_valid(n) => Ok(n),
        _ => Err(SpecError::Invalid {
            what: "--bins",
            input: s.to_string(),
            reason: format!("expected a power of two from {MIN_BINS} to {MAX_BINS} (2^20)"),
        }),
    }
}

/// `--taps`: a length, or sized from the band and the weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Taps {
    Auto,
    Fixed(usize),
}

fn parse_taps_arg(s: &str) -> Result<Taps, SpecError> {
    if s == "auto" {
        Ok(Taps::Auto)
    } else {
        parse_taps(s).map(Taps::Fixed)
    }
}

/// `underfoot calibrate equalize`.
#[derive(Debug, Clone, Args)]
pub struct EqualizeArgs {
    /// The device: `simulated`, a measured-response file (from `calibrate sweep`), whose
    /// magnitude is replayed for the passes after the first, or `audio[:DEVICE]` (a sound
    /// card, measured at every pass; see `--output-device`, `--input-device`, `--host`).
    #[arg(long = "device-under-test", visible_alias = "dut", value_name = "DEVICE", value_parser = parse_device)]
    pub device: DeviceArg,
    /// Sweeps (passes); the first is through flat weights.
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = parse_passes)]
    pub passes: usize,
    /// How the weights are applied: low-delay (a minimum-phase filter, no bulk delay) or
    /// bank (the uniform filter bank, N - 1 samples of delay).
    #[arg(long, default_value = "low-delay", value_name = "KIND")]
    pub realisation: String,
    /// Low-delay only: filter length in taps, or `auto`: the power of two at least
    /// 4 fs / (the band's lowest frequency), lengthened while the filter misses the
    /// weights by more than 0.1 dB RMS (up to 32768).
    #[arg(long, default_value = "auto", value_name = "N|auto", value_parser = parse_taps_arg)]
    pub taps: Taps,
    /// Size N of the uniform bank that carries the weights (bins fs/N apart).
    #[arg(long, default_value_t = 4096, value_name = "N", value_parser = parse_bins)]
    pub bins: usize,
    /// Largest boost of any frequency, in dB.
    #[arg(long = "max-boost-db", default_value_t = 12.0, value_name = "DB")]
    pub max_boost_db: f64,
    /// Where to write the equalizer (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also draw every pass against flat (.svg or .png).
    /// Default: no figure.
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub plot_scale: crate::plot::PlotScale,
    #[command(flatten)]
    pub settings: SweepSettings,
}

/// Runs `underfoot calibrate equalize`.
pub(super) fn run(args: &EqualizeArgs) -> anyhow::Result<()> {
    let s = &args.settings;
    let inputs = s.input_files(&args.device);
    let (out, plot_out) = check_outputs(&args.out, args.plot.as_deref(), &inputs)?;
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
    let rate = sweep.config().rate;
    let (realisation, grow) = match (args.realisation.as_str(), args.taps) {
        ("low-delay", Taps::Auto) => (
            Realisation::LowDelay {
                taps: auto_taps(&config, rate),
            },
            true,
        ),
        ("low-delay", Taps::Fixed(taps)) => (Realisation::LowDelay { taps }, false),
        ("bank", _) => (Realisation::Bank, false),
        (other, _) => anyhow::bail!("--realisation {other:?}: expected low-delay or bank"),
    };
    let eq = equalize(
        device.as_mut(),
        &sweep,
        config,
        realisation,
        args.passes,
        grow,
    )
    .context("equalizing")?;
    let passes: Vec<PassFigures> = eq.passes.iter().map(PassFigures::from).collect();
    // What the realisation costs: the bank's bulk delay, or the low-delay filter's group
    // delay at the band's low edge (it has no bulk delay).
    let filter = EqualizerFilter::new(&eq.weights, eq.realisation)?;
    let delay = match eq.realisation {
        Realisation::Bank => format!(
            "{:.1} ms bulk delay",
            (args.bins - 1) as f64 / f64::from(s.rate) * 1e3
        ),
        Realisation::LowDelay { .. } => format!(
            "no bulk delay, {:.1} ms group delay at {} Hz, misses the weights by {:.2} dB RMS",
            filter.group_delay(s.band.lo).map_or(0.0, |d| d.0 * 1e3),
            s.band.lo.0,
            filter.realisation_error(&eq.weights).unwrap_or(0.0)
        ),
    };
    let file = EqualizerFile::new(eq.weights.clone(), eq.realisation, passes, description);
    document::save_to(&out, &file)?;
    let rows: Vec<Vec<String>> = eq
        .passes
        .iter()
        .map(|p| {
            vec![
                p.pass.to_string(),
                format!("{:.2}", p.deviation.0),
                format!("{:.2}", p.peak.0),
                p.taps.map_or_else(|| "-".to_owned(), |t| t.to_string()),
                if p.pass == eq.best {
                    "kept: written".to_owned()
                } else if p.kept {
                    "kept".to_owned()
                } else {
                    format!("worse: not kept, step now {:.2}", p.step)
                },
            ]
        })
        .collect();
    emit(&format!(
        "equalizing {} over {}-{} Hz ({}; {delay})\n{}{}wrote {} (pass {})\n",
        file.description,
        s.band.lo.0,
        s.band.hi.0,
        match eq.realisation {
            Realisation::Bank => format!("filter bank, N = {}", args.bins),
            Realisation::LowDelay { taps } => format!(
                "low-delay minimum-phase filter, {taps} taps{}",
                if grow { ", sized automatically" } else { "" }
            ),
        },
        table(
            &[
                ("pass", Align::Right),
                ("deviation RMS (dB)", Align::Right),
                ("peak (dB)", Align::Right),
                ("taps", Align::Right),
                ("weights", Align::Left),
            ],
            &rows
        ),
        capped_report(&eq.capped, eq.cap_residual, &config),
        args.out.display(),
        eq.best
    ))?;
    if let Some(plot_out) = &plot_out {
        draw_passes(plot_out, args.plot_scale.get(), &eq)?;
    }
    Ok(())
}

/// Where the bounds stopped the correction, and what that leaves.
fn capped_report(capped: &[Capped], residual: Decibels, config: &EqualizerConfig) -> String {
    if capped.is_empty() {
        return String::new();
    }
    let ranges: Vec<String> = capped
        .iter()
        .map(|c| {
            let at = if c.hi.0 > c.lo.0 {
                format!("{:.0}-{:.0} Hz", c.lo.0, c.hi.0)
            } else {
                format!("{:.0} Hz", c.lo.0)
            };
            format!("{at} ({:.1} dB short)", c.short.0)
        })
        .collect();
    let boost = capped.iter().any(|c| c.boost);
    format!(
        "capped by the {} bound at {}: {:.2} dB RMS of the deviation is left there{}\n",
        if boost {
            format!("+{} dB boost", config.max_boost.0)
        } else {
            format!("-{} dB cut", config.max_cut.0)
        },
        ranges.join(", "),
        residual.0,
        if boost {
            " (raise --max-boost-db to correct it, if the actuator has the headroom)"
        } else {
            ""
        }
    )
}

/// Every pass's measured response against flat, where the bounds stopped the
/// correction, and the equalizer itself: the gain of the weights kept, over the band.
fn draw_passes(out: &OutputFile, scale: Scale, eq: &Equalization) -> anyhow::Result<()> {
    let (passes, best, capped) = (&eq.passes, eq.best, &eq.capped);
    let data: Vec<(Vec<f64>, Vec<f64>)> = passes
        .iter()
        .map(|p| {
            (
                p.response.freqs.iter().map(|f| f.0).collect(),
                centred(&p.response),
            )
        })
        .collect();
    // The best pass's measurement where a bound stopped the correction, one segment
    // per range, drawn over it.
    let (best_f, best_db) = &data[best - 1];
    let marks: Vec<(String, Vec<f64>, Vec<f64>)> = capped
        .iter()
        .map(|c| {
            let (f, db): (Vec<f64>, Vec<f64>) = best_f
                .iter()
                .zip(best_db)
                .filter(|(f, _)| **f >= c.lo.0 * 0.97 && **f <= c.hi.0 * 1.03)
                .map(|(f, d)| (*f, *d))
                .unzip();
            (
                format!(
                    "{} capped {:.0}-{:.0} Hz",
                    if c.boost { "boost" } else { "cut" },
                    c.lo.0,
                    c.hi.0
                ),
                f,
                db,
            )
        })
        .filter(|(_, f, _)| f.len() >= 2)
        .collect();
    let (lo, hi) = (best_f[0], best_f[best_f.len() - 1]);
    let (gain_f, gain_db): (Vec<f64>, Vec<f64>) = (0..eq.weights.gains_db.len())
        .map(|k| (eq.weights.bin_frequency(k).0, eq.weights.gains_db[k]))
        .filter(|&(f, _)| f >= lo && f <= hi)
        .unzip();
    let curves: Vec<Curve<'_>> = passes
        .iter()
        .zip(&data)
        .map(|(p, (f, db))| Curve {
            label: format!(
                "pass {} ({:.2} dB){}",
                p.pass,
                p.deviation.0,
                if p.pass == best {
                    ", kept"
                } else if p.kept {
                    ""
                } else {
                    ", worse"
                }
            ),
            freqs_hz: f,
            db,
        })
        .chain(marks.iter().map(|(label, f, db)| Curve {
            label: label.clone(),
            freqs_hz: f,
            db,
        }))
        .chain((gain_f.len() >= 2).then(|| Curve {
            label: format!("the equalizer (pass {best}'s gain)"),
            freqs_hz: &gain_f,
            db: &gain_db,
        }))
        .collect();
    plotted(
        out.path(),
        out.write_with(|p| {
            draw_responses(
                p,
                scale,
                "Equalized device against flat, pass by pass, and the equalizer",
                "magnitude or gain (dB re band mean)",
                &curves,
            )
        })?,
    )
}
