//! `underfoot compare`: the IIR paper's Table I for any set of materials and recordings.
//!
//! Each `NAME=FOLDER` is fitted from the recordings in the folder exactly as `underfoot
//! fit` fits them: the IIR filter and the physical model, estimated with no hand tuning
//! ([`underfoot::physical::estimate()`]). Every figure is one of
//! [`underfoot::fit::metrics`]'s, against the measured response on the fit's grid of 96
//! log-spaced frequencies of the band:
//!
//! - **IIR**: the filter's magnitude (the `fit` record, the figure `fit` prints);
//! - **physical**: the calibration render, nominal steps rendered at the model's stored
//!   output gain and analysed exactly as the recordings were (the `fit` record, the figure
//!   `fit` prints);
//! - **physical, held out**: the same render with another random stream of
//!   micro-impacts ([`underfoot::physical::estimate::held_out_seed`]), which the
//!   estimation has not seen; for an aggregate it is a little worse, and it is the fairer
//!   figure for how the model sounds in use. A solid's render has no randomness, so both
//!   figures agree.
//!
//! The table goes to stdout; `--json` writes
//!
//! ```json
//! { "materials": [ { "name": "gravel",
//!                    "iir": { "nrmse": 0.05, "lsd_db": 0.4, "order": 16 },
//!                    "physical": { "nrmse": 0.6, "lsd_db": 1.3,
//!                                  "held_out_nrmse": 0.7, "held_out_lsd_db": 1.6,
//!                                  "kind": "aggregate", "modes": 32 } } ] }
//! ```
//!
//! and `--plot DIR` draws `DIR/NAME.svg` (or `.png` with `--plot-format png`): measured,
//! IIR and physical (held-out render) spectra in one panel, the IIR paper's Fig. 4.
//!
//! A second table gives the steps in time ([`underfoot::analysis::steps`]): per material,
//! the recordings' median duration (`D90`), micro-event count, crest factor and spread
//! between steps, beside those of `--steps` (48) steps of a generated walk rendered at
//! 48 kHz by the IIR filter and by the physical model, each played by the material's
//! fitted excitation at its playback level; and how far each render's average step
//! spectrum (gain-aligned) and level are from the recordings'. The JSON holds them under
//! `time` (`recorded`, `iir`, `physical`).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use serde::Serialize;
use underfoot::analysis::measure_each_file;
use underfoot::atomic_file::OutputFile;
use underfoot::material::build::{BuildConfig, build_material};
use underfoot::material::library::validate_name;
use underfoot::physical::estimate::{held_out_seed, score_render};
use underfoot::recording;
use underfoot::synthesis::SynthModel;
use underfoot::units::Hz;

use crate::output::emit;
use crate::plot::{self, Panel};
use crate::report::TimeScore;
use crate::steps::{TimeRow, render_and_compare, time_table};

/// Arguments of `underfoot compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// Also write the table as JSON here (`-`: standard output, after the table).
    /// Default: the table only.
    #[arg(long = "json-out", value_name = "FILE.json")]
    json: Option<PathBuf>,
    /// Draw one spectrum plot per material into this directory (created if missing).
    /// Default: no figures.
    #[arg(long = "plot-dir", value_name = "DIR")]
    plot: Option<PathBuf>,
    /// Image format of the plots.
    #[arg(long, value_name = "svg|png", default_value = "svg", value_parser = ["svg", "png"])]
    plot_format: String,
    #[command(flatten)]
    plot_scale: crate::plot::PlotScale,
    /// Steps of a generated walk rendered per material and model for the table in time.
    #[arg(long, default_value_t = 48, value_name = "N", value_parser = clap::value_parser!(u32).range(2..=200))]
    steps: u32,
    /// Materials and their recordings, e.g. `gravel=recordings/gravel`.
    #[arg(required = true, value_name = "NAME=FOLDER", value_parser = parse_pair)]
    materials: Vec<(String, PathBuf)>,
}

fn parse_pair(s: &str) -> Result<(String, PathBuf), String> {
    let (name, folder) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?}: expected NAME=FOLDER, e.g. gravel=recordings/gravel"))?;
    validate_name(name).map_err(|e| format!("{s:?}: {e}"))?;
    if folder.is_empty() {
        return Err(format!("{s:?}: the folder is empty"));
    }
    Ok((name.to_string(), PathBuf::from(folder)))
}

/// One material's row.
#[derive(Debug, Serialize)]
struct Row {
    name: String,
    iir: IirScore,
    physical: PhysicalScore,
    time: TimeScore,
}

#[derive(Debug, Serialize)]
struct IirScore {
    nrmse: f64,
    lsd_db: f64,
    order: usize,
}

#[derive(Debug, Serialize)]
struct PhysicalScore {
    /// The calibration render's, as `fit` records and prints them.
    nrmse: f64,
    lsd_db: f64,
    /// A render with another seed.
    held_out_nrmse: f64,
    held_out_lsd_db: f64,
    kind: &'static str,
    modes: usize,
}

#[derive(Debug, Serialize)]
struct Table {
    materials: Vec<Row>,
}

/// The audio files of a folder, sorted by name.
fn recordings_in(folder: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(folder)
        .with_context(|| format!("reading folder {}", folder.display()))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry
            .with_context(|| format!("reading folder {}", folder.display()))?
            .path();
        let audio = path.extension().and_then(|e| e.to_str()).is_some_and(|e| {
            ["wav", "flac", "ogg", "oga"]
                .iter()
                .any(|x| e.eq_ignore_ascii_case(x))
        });
        if audio && path.is_file() {
            files.push(path);
        }
    }
    files.sort();
    if files.is_empty() {
        bail!(
            "{} holds no recording (.wav, .flac, .ogg)",
            folder.display()
        );
    }
    Ok(files)
}

/// Runs `underfoot compare`.
pub fn run(args: &CompareArgs) -> anyhow::Result<()> {
    if let Some(json) = &args.json {
        let dir = json.parent().filter(|d| !d.as_os_str().is_empty());
        if let Some(d) = dir.filter(|d| !d.is_dir()) {
            bail!(
                "--json {}: directory {} does not exist",
                json.display(),
                d.display()
            );
        }
    }
    // Every output against the output policy (underfoot::atomic_file) before the slow
    // part: never a recording, never a device, no two outputs one file.
    let mut recordings_of = Vec::with_capacity(args.materials.len());
    for (_, folder) in &args.materials {
        recordings_of.push(recordings_in(folder)?);
    }
    let inputs: Vec<&std::path::Path> = recordings_of
        .iter()
        .flatten()
        .map(PathBuf::as_path)
        .collect();
    let json_out = match &args.json {
        Some(p) => Some(OutputFile::check_or_stdout(p, &inputs)?),
        None => None,
    };
    let mut plot_outs = Vec::new();
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating plot directory {}", dir.display()))?;
        for (name, _) in &args.materials {
            let o = OutputFile::check(&dir.join(format!("{name}.{}", args.plot_format)), &inputs)?;
            for other in plot_outs.iter().chain(json_out.as_ref()) {
                o.distinct_from(other)?;
            }
            plot_outs.push(o);
        }
    }
    let cfg = BuildConfig::default();
    let cal = cfg.physical.clone().unwrap_or_default();
    let mut rows = Vec::new();
    let mut in_time = Vec::new();
    emit(&format!(
        "{:<12} {:>10} {:>9} {:>6} | {:>10} {:>9} {:>12} {:>9} {:>5}\n",
        "material",
        "IIR NRMSE",
        "LSD dB",
        "order",
        "phys NRMSE",
        "LSD dB",
        "held-out dB",
        "kind",
        "modes"
    ))?;
    for (i, (name, folder)) in args.materials.iter().enumerate() {
        let files = &recordings_of[i];
        let mut recordings = Vec::with_capacity(files.len());
        for f in files {
            recordings.extend(recording::read_for_analysis(f, None)?);
        }
        let model = build_material(name, &recordings, &cfg, &mut |_| {})
            .with_context(|| format!("fitting {name} from {}", folder.display()))?;
        let Some(physical) = &model.physical else {
            bail!(
                "{name}: the physical model could not be calibrated from {}",
                folder.display()
            );
        };
        // The calibration's own figure is the record's, as `fit` prints it; the held-out
        // one renders other micro-impacts.
        let grid: Vec<Hz> = model.fit.grid_hz.iter().map(|f| Hz(*f)).collect();
        let (curve, held_out) = score_render(
            physical,
            &model.excitation_or_heel(),
            &cal,
            &grid,
            &model.fit.measured,
            held_out_seed(&cal),
        )
        .with_context(|| format!("rendering the physical model of {name}"))?;
        let row = Row {
            name: name.clone(),
            iir: IirScore {
                nrmse: model.fit.nrmse,
                lsd_db: model.fit.lsd_db,
                order: model.order,
            },
            physical: PhysicalScore {
                nrmse: physical.record.nrmse,
                lsd_db: physical.record.lsd_db,
                held_out_nrmse: held_out.nrmse,
                held_out_lsd_db: held_out.lsd_db,
                kind: physical.kind.name(),
                modes: physical.modes.len(),
            },
            time: TimeScore {
                recorded: None,
                iir: None,
                physical: None,
            },
        };
        let steps = args.steps as usize;
        let iir = render_and_compare(&model, SynthModel::Iir, steps)
            .with_context(|| format!("rendering the steps of {name}"))?;
        let physical_steps = render_and_compare(&model, SynthModel::Physical, steps)
            .with_context(|| format!("rendering the physical model's steps of {name}"))?;
        let mut row = row;
        row.time = TimeScore::of(&model, iir.as_ref(), physical_steps.as_ref());
        emit(&format!(
            "{:<12} {:>10.4} {:>9.2} {:>6} | {:>10.4} {:>9.2} {:>12.2} {:>9} {:>5}\n",
            row.name,
            row.iir.nrmse,
            row.iir.lsd_db,
            row.iir.order,
            row.physical.nrmse,
            row.physical.lsd_db,
            row.physical.held_out_lsd_db,
            row.physical.kind,
            row.physical.modes
        ))?;
        if let Some(out) = plot_outs.get(i) {
            let path = out.path();
            let each = measure_each_file(&recordings, &cfg.analysis, &grid);
            let title = format!(
                "{name}: IIR LSD {:.2} dB, physical LSD {:.2} dB (held-out render)",
                row.iir.lsd_db, row.physical.held_out_lsd_db
            );
            let drawn = out.write_with(|p| {
                plot::draw_spectra(
                    p,
                    args.plot_scale.get(),
                    &[Panel {
                        title,
                        fit: &model.fit,
                        physical: Some(&curve),
                        recordings: &each,
                    }],
                    plot::YRange::Own,
                )
            })?;
            drawn.report(path);
        }
        rows.push(row);
        in_time.push((model, iir, physical_steps));
    }
    let time_rows: Vec<TimeRow<'_>> = in_time
        .iter()
        .map(|(model, iir, physical)| TimeRow {
            name: &model.name,
            model,
            iir: iir.as_ref(),
            physical: physical.as_ref(),
        })
        .collect();
    emit(&format!(
        "\nThe steps in time: recorded / rendered by the IIR filter / by the physical model \
         ({} steps each of a generated walk at 48 kHz, measured as the recordings are):\n\n{}",
        args.steps,
        time_table(&time_rows)
    ))?;
    if let Some(out) = &json_out {
        let mut json = serde_json::to_string_pretty(&Table { materials: rows })?;
        json.push('\n');
        out.write(json.as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pairs_parse_and_bad_ones_are_refused() {
        assert_eq!(
            parse_pair("gravel=rec/gravel"),
            Ok(("gravel".to_string(), PathBuf::from("rec/gravel")))
        );
        assert!(parse_pair("gravel").is_err());
        assert!(parse_pair("gravel=").is_err());
        assert!(parse_pair("bad name=x").is_err());
    }
}
