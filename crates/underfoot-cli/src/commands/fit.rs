//! `underfoot fit`: recordings in, one material model out, stored in a library file.
//!
//! Everything that can be checked without the recordings (arguments, the `--out` library,
//! output directories) is checked before the slow fit, and the library is only ever
//! replaced atomically after a successful fit: a failed run leaves `--out` as it was.
//!
//! The quality gate (`underfoot::material::quality`) refuses recordings at a rate too low
//! for the band, a band above a recording's Nyquist frequency, recordings with no strike
//! clearly above their noise, and a fit above the distance bound; `--accept-poor-fit` keeps
//! the last, marked in the library. Recordings that disagree are a warning on stderr.
//! `--report` adds the leave-one-recording-out check, printed and in the report file.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use underfoot::analysis::{MAX_ANALYSIS_RATE, MIN_ANALYSIS_RATE};
use underfoot::analysis::{SavgolSetting, measure_each_file};
use underfoot::atomic_file::OutputFile;
use underfoot::fit::{MAX_FILTER_ORDER, OrderChoice};
use underfoot::io::spec::{self, SpecError};
use underfoot::material::Library;
use underfoot::material::MaterialModel;
use underfoot::material::build::{BuildConfig, BuildError, Progress, build_material_with_report};
use underfoot::material::evaluate::StepComparison;
use underfoot::material::library::validate_name;
use underfoot::material::quality::{Disagreement, HeldOut, QualityError, refit_each};
use underfoot::recording::{self, CsvSpec};
use underfoot::synthesis::SynthModel;
use underfoot::units::{Band, Decibels, Hz, SampleRate};

use crate::output::emit;
use crate::plot::{self, Panel};
use crate::report::{
    FitReport, FitReportEntry, LeaveOneOutReport, RecordingFigure, RenderedSteps, TimeScore,
    leave_one_out_table,
};
use crate::steps::{TimeRow, render_and_compare, time_table};

/// Arguments of `underfoot fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    /// Name of the material (letters, digits, '-', '_', '.'); replaces a material of the
    /// same name in the library.
    #[arg(long = "name", value_name = "NAME")]
    material: String,
    /// Library file to add the material to (created if missing).
    #[arg(long = "library", value_name = "LIB.json")]
    out: PathBuf,
    /// Also write a JSON summary of the fit here, and check how the model generalises:
    /// fit on all recordings but one, measure on the one left out, for each in turn
    /// (printed as a table, and in the summary).
    /// Default: no summary, and leave-one-out only for 12 recordings or fewer.
    #[arg(long, value_name = "R.json")]
    report: Option<PathBuf>,
    /// Also draw measured vs model magnitude here (.svg or .png).
    /// Default: no figure.
    #[arg(long, value_name = "P.svg|P.png")]
    plot: Option<PathBuf>,
    #[command(flatten)]
    plot_scale: crate::plot::PlotScale,
    /// Analysis sample rate in Hz [default: 2000].
    #[arg(long = "analysis-rate", value_name = "HZ", value_parser = parse_analysis_rate)]
    rate: Option<SampleRate>,
    /// Band of interest in Hz [default: 20:900].
    #[arg(long, value_name = "LO:HI")]
    band: Option<Band>,
    /// Fit exactly this filter order.
    /// Default: the lowest order up to --max-order that meets --target-lsd.
    #[arg(long, value_name = "N", value_parser = parse_order, conflicts_with = "max_order")]
    order: Option<usize>,
    /// Search orders up to N and keep the lowest that meets the targets [default: 16].
    #[arg(long, value_name = "N", value_parser = parse_order)]
    max_order: Option<usize>,
    /// Savitzky-Golay denoising at each recording's rate: `auto` (the widest window of
    /// polynomial order 3 within 0.1 dB up to the band's top), `off`, or `WINDOW:ORDER`
    /// (odd window in samples, polynomial order) [default: auto].
    #[arg(long, value_name = "auto|off|W:P")]
    savgol: Option<SavgolSetting>,
    /// Target log-spectral distance of the order search, in dB [default: 0.5].
    #[arg(long, value_name = "DB", value_parser = parse_positive)]
    target_lsd: Option<f64>,
    /// The longest e-fold decay any pole of the fitted filter may have, in seconds; the
    /// search never leaves it and the library stores it [default: 0.5].
    #[arg(long, value_name = "S", value_parser = parse_decay)]
    longest_decay: Option<f64>,
    /// Keep a fit whose distance is above the quality bound (LSD above 2 dB, or NRMSE above
    /// 0.5 with LSD above 1 dB) instead of refusing it; it is marked as poor in the library.
    #[arg(long)]
    accept_poor_fit: bool,
    /// For CSV recordings: the column holding the signal (header name or 0-based index).
    /// Default: none; needed for a CSV recording.
    #[arg(long, value_name = "C", requires = "csv_rate")]
    csv_column: Option<String>,
    /// For CSV recordings: the rate the data was logged at, in Hz.
    /// Default: none; needed for a CSV recording.
    #[arg(long, value_name = "HZ", value_parser = parse_csv_rate, requires = "csv_column")]
    csv_rate: Option<SampleRate>,
    /// Recordings of heel strikes on the material (WAV, FLAC, Ogg Vorbis, CSV).
    #[arg(required = true, value_name = "FILES")]
    files: Vec<PathBuf>,
}

fn parse_analysis_rate(s: &str) -> Result<SampleRate, SpecError> {
    spec::parse_rate(s, "analysis rate", MIN_ANALYSIS_RATE, MAX_ANALYSIS_RATE)
}

fn parse_csv_rate(s: &str) -> Result<SampleRate, SpecError> {
    spec::parse_rate(s, "CSV rate", 1, 1_000_000)
}

fn parse_decay(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(t) if t > 0.0 && t <= 60.0 => Ok(t),
        _ => Err(format!(
            "{s:?} is not a decay limit: expected seconds in (0, 60], e.g. 0.5"
        )),
    }
}

fn parse_order(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "filter order", 1, MAX_FILTER_ORDER)
}

fn parse_positive(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s:?}: expected a number above 0")),
    }
}

impl FitArgs {
    fn config(&self) -> anyhow::Result<BuildConfig> {
        let mut cfg = BuildConfig::default();
        if let Some(rate) = self.rate {
            cfg.analysis.rate = rate;
        }
        if let Some(band) = self.band {
            cfg.analysis.band = band;
        }
        if !cfg.analysis.band.fits(cfg.analysis.rate) {
            bail!(
                "band {} does not fit the analysis rate {}: the upper edge must be below {} \
                 (use --band or --analysis-rate)",
                cfg.analysis.band,
                cfg.analysis.rate,
                cfg.analysis.rate.nyquist()
            );
        }
        match (self.order, self.max_order) {
            (Some(n), _) => cfg.fit.order = OrderChoice::Fixed(n),
            (None, Some(max)) => cfg.fit.order = OrderChoice::Auto { max },
            (None, None) => {}
        }
        if let Some(sg) = self.savgol {
            cfg.analysis.savgol = sg;
        }
        if let Some(t) = self.longest_decay {
            cfg.fit.longest_decay = underfoot::units::Seconds(t);
        }
        if let Some(t) = self.target_lsd {
            cfg.fit.target_lsd = Decibels(t);
        }
        cfg.quality.accept_poor_fit = self.accept_poor_fit;
        Ok(cfg)
    }

    fn csv(&self) -> Option<CsvSpec> {
        match (&self.csv_column, self.csv_rate) {
            (Some(column), Some(rate)) => Some(CsvSpec {
                column: column.clone(),
                rate,
            }),
            _ => None,
        }
    }
}

/// The directory a file will be written in, which must exist before the fit starts.
fn check_parent_dir(file: &Path, what: &str) -> anyhow::Result<()> {
    let dir = match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "{what} {}: directory {} does not exist",
            file.display(),
            dir.display()
        );
    }
    Ok(())
}

fn bar(len: u64, template: &str) -> ProgressBar {
    // Bars are for people watching; in logs and pipes they are noise.
    let target = if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(len), target);
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style);
    }
    bar
}

/// The library's refusal, with the option that changes it where there is one.
fn with_flag_hint(e: BuildError) -> anyhow::Error {
    let hint = match &e {
        BuildError::Quality(QualityError::PoorFit { .. }) => {
            Some(" (--order or --max-order, --band, or --accept-poor-fit)".to_string())
        }
        BuildError::Quality(
            QualityError::BandAboveNyquist { suggested, .. }
            | QualityError::BandAboveAnalysisNyquist { suggested, .. },
        ) => Some(format!(" (--band {}:{})", suggested.lo.0, suggested.hi.0)),
        _ => None,
    };
    match hint {
        Some(h) => anyhow::anyhow!("{e}{h}"),
        None => e.into(),
    }
}

/// Runs `underfoot fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    validate_name(&args.material).map_err(|e| anyhow::anyhow!("--name: {e}"))?;
    let cfg = args.config()?;
    check_parent_dir(&args.out, "library")?;
    if let Some(report) = &args.report {
        check_parent_dir(report, "report")?;
    }
    if let Some(p) = &args.plot {
        plot::Format::of(p)?;
        check_parent_dir(p, "plot")?;
    }
    // Every output against the output policy, with the recordings as inputs: none of
    // them is ever an output, and no two outputs are one file.
    let inputs: Vec<&Path> = args.files.iter().map(PathBuf::as_path).collect();
    let library_out = OutputFile::check(&args.out, &inputs)?;
    let report_out = match &args.report {
        Some(p) => {
            let o = OutputFile::check(p, &inputs)?;
            o.distinct_from(&library_out)?;
            Some(o)
        }
        None => None,
    };
    let plot_out = match &args.plot {
        Some(p) => {
            let o = OutputFile::check(p, &inputs)?;
            o.distinct_from(&library_out)?;
            if let Some(r) = &report_out {
                o.distinct_from(r)?;
            }
            Some(o)
        }
        None => None,
    };
    // Before the slow part: a broken library must not cost a fit to find out about. It
    // is read again under the edit lock when the material is added, so that fits into
    // one library at the same time all land.
    Library::load_or_new(&args.out)?;

    let csv = args.csv();
    let reading = bar(
        args.files.len() as u64,
        "reading  [{bar:30}] {pos}/{len} {msg}",
    );
    let mut recordings = Vec::with_capacity(args.files.len());
    for path in &args.files {
        reading.set_message(path.display().to_string());
        // Every RecordingError names its file.
        let read = recording::read_for_analysis(path, csv.as_ref())?;
        if let Some(e) = read.first().and_then(|r| r.excerpt) {
            let seconds = e.file_frames as f64 / read[0].rate.hz();
            let how = match e.strikes {
                0 => "around its loudest moment: no strike stands above its noise".into(),
                found if e.kept < e.cut => format!(
                    "(of {}) around its {found} strikes, spread evenly over it",
                    e.cut
                ),
                found => format!("around its {found} strikes"),
            };
            reading.suspend(|| {
                eprintln!(
                    "underfoot: {}: {seconds:.0} s long, read as {} excerpt{} {how} \
                     (see underfoot::recording::excerpts)",
                    path.display(),
                    e.kept,
                    if e.kept == 1 { "" } else { "s" },
                );
            });
        }
        recordings.extend(read);
        reading.inc(1);
    }
    reading.finish_and_clear();

    // The generalisation check, computed for every fit of a few recordings (one refit each,
    // without the physical calibration): a set that mixes materials fits well in-sample
    // and only this shows it. The warning needs the spectra only: without --report (which
    // renders the left-out models' steps), the refits skip fitting the excitation, most of
    // their time. The refits need nothing of the model fitted on all recordings, so they
    // run on a thread of their own beside its fit, whose stages leave a core idle at times
    // (reading its result is left for after the fit, below).
    let check_cfg = (args.report.is_some()
        || recording::by_file(&recordings).len() <= MAX_LOO_RECORDINGS)
        .then(|| {
            if args.report.is_some() {
                cfg.clone()
            } else {
                BuildConfig {
                    excitation: None,
                    ..cfg.clone()
                }
            }
        });

    // The order search bisects, so orders arrive out of sequence: count fits, not orders.
    let fitting = bar(0, "fitting  {spinner} {pos} orders tried {msg}");
    let started = Instant::now();
    let mut checked = None;
    let mut progress = |p: &Progress| match p {
        Progress::Checked(c) => {
            if let Some(w) = c.disagreement.as_ref().and_then(Disagreement::warning) {
                fitting.suspend(|| eprintln!("underfoot: warning: {:?}: {w}", args.material));
            }
            checked = Some(c.clone());
        }
        Progress::Measured { strikes, .. } => fitting.set_message(format!("{strikes} strikes")),
        Progress::OrderTried {
            order,
            lsd_db,
            nrmse,
            ..
        } => {
            fitting.inc(1);
            fitting.set_message(format!(
                "(last: order {order}, LSD {lsd_db:.2} dB, NRMSE {nrmse:.4})"
            ));
        }
        Progress::PhysicalFailed { reason } => {
            fitting.suspend(|| {
                eprintln!(
                    "underfoot: warning: no physical model for {:?} (the filter is kept): {reason}",
                    args.material
                );
            });
        }
        _ => {}
    };
    let (built, elapsed, refits) = std::thread::scope(|scope| {
        let refits = check_cfg
            .as_ref()
            .map(|c| scope.spawn(|| refit_each(&recordings, c, &args.material)));
        let built = build_material_with_report(&args.material, &recordings, &cfg, &mut progress);
        let elapsed = started.elapsed().as_secs_f64();
        let refits = refits.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
        (built, elapsed, refits)
    });
    let (model, built) = built
        .map_err(with_flag_hint)
        .with_context(|| format!("fitting material {:?}", args.material))?;
    fitting.finish_and_clear();
    if model.fit.poor_fit {
        eprintln!(
            "underfoot: warning: {:?} is a poor fit (LSD {:.2} dB, NRMSE {:.3}, above the quality \
             bound), kept because of --accept-poor-fit and marked as poor in {}",
            model.name,
            model.fit.lsd_db,
            model.fit.nrmse,
            args.out.display()
        );
    }
    // The generalisation check runs before anything is written: a failure here leaves
    // --out as it was, like any other.
    let left_out = match refits {
        Some(refits) => Some(
            refits
                .map(|r| r.map(|r| r.score(&model)))
                .with_context(|| format!("leave-one-out check of {:?}", args.material))?,
        ),
        None => None,
    };
    if let Some(Some(loo)) = &left_out
        && let Some(warning) = crate::report::generalisation_warning(&model, loo)
    {
        eprintln!("underfoot: warning: {warning}");
    }
    // Printed and reported with --report.
    let loo = if args.report.is_some() {
        left_out
    } else {
        None
    };

    let replaced = Library::edit(&library_out, true, |library| {
        Ok(library.upsert(model.clone()).is_some())
    })?;
    let physical = model.physical.as_ref().map_or(String::new(), |p| {
        format!(
            "; physical: {}, {} modes, LSD {:.2} dB (calibration render)",
            p.kind.name(),
            p.modes.len(),
            p.record.lsd_db
        )
    });
    emit(&format!(
        "{}: order {}, NRMSE {:.4}, LSD {:.2} dB, {} strikes{physical}, {:.0} ms -> {} ({})\n",
        model.name,
        model.order,
        model.fit.nrmse,
        model.fit.lsd_db,
        model.fit.strikes,
        elapsed * 1e3,
        args.out.display(),
        if replaced { "replaced" } else { "added" }
    ))?;
    emit(&step_line(&model, built.excitation.as_ref()))?;

    // The library is saved by now; what follows is extra, and its errors say so.
    let saved = || format!("(the material was saved to {})", args.out.display());
    if let Some(loo) = &loo {
        match loo {
            Some(loo) => emit(&format!(
                "leave one recording out ({}: fitted on the others, gain-aligned LSD on the one \
                 left out; in-sample: the model fitted on all):\n{}",
                model.name,
                leave_one_out_table(loo)
            ))?,
            None => emit(&format!(
                "leave one recording out: not possible for {} with a single recording; fit \
                 two or more to see how the model generalises\n",
                model.name
            ))?,
        }
    }
    // In time: the model's steps rendered beside the recordings', and each recording left
    // out against steps of the model fitted on the others.
    let mut time = None;
    let mut held_out_time = Vec::new();
    if report_out.is_some() || loo.is_some() {
        let iir = render_and_compare(&model, SynthModel::Iir, REPORT_STEPS).with_context(saved)?;
        let physical =
            render_and_compare(&model, SynthModel::Physical, REPORT_STEPS).with_context(saved)?;
        emit(&format!(
            "the steps in time: recorded / rendered by the filter / by the physical model \
             ({REPORT_STEPS} steps of a generated walk, measured as the recordings are):\n{}",
            time_table(&[TimeRow {
                name: &model.name,
                model: &model,
                iir: iir.as_ref(),
                physical: physical.as_ref(),
            }])
        ))?;
        time = Some(TimeScore::of(&model, iir.as_ref(), physical.as_ref()));
        if let Some(Some(loo)) = &loo {
            let mut rows = Vec::new();
            for h in &loo.held_out {
                let rendered = match &h.recorded {
                    Some(recorded) => {
                        let against = MaterialModel {
                            time: Some(recorded.clone()),
                            ..h.model.clone()
                        };
                        render_and_compare(&against, SynthModel::Iir, REPORT_STEPS)
                            .with_context(saved)?
                    }
                    None => None,
                };
                rows.push((h, rendered));
            }
            emit(&format!(
                "leave one recording out, in time (each recording's steps against steps of the \
                 model fitted on the others):\n{}",
                held_out_time_table(&rows)
            ))?;
            held_out_time = rows.into_iter().map(|(_, r)| r).collect();
        }
    }
    if let Some(out) = &report_out {
        let mut entry = FitReportEntry::of(&model);
        entry.time = time;
        entry.strike_to_noise_db = checked
            .iter()
            .flat_map(|c| &c.strike_to_noise)
            .map(|s| RecordingFigure {
                file: s.file.clone(),
                db: s.snr.0,
            })
            .collect();
        entry.leave_one_out = loo.flatten().as_ref().map(|l| {
            let mut r = LeaveOneOutReport::of(l);
            for (h, rendered) in r.held_out.iter_mut().zip(&held_out_time) {
                h.rendered = rendered.as_ref().map(RenderedSteps::of);
            }
            r
        });
        let report = FitReport {
            materials: vec![entry],
        };
        let mut json = serde_json::to_string_pretty(&report)?;
        json.push('\n');
        out.write(json.as_bytes()).with_context(saved)?;
    }
    if let (Some(path), Some(out)) = (&args.plot, &plot_out) {
        // The physical model as calibrated: its calibration render's spectrum, the one
        // its printed figures are of.
        let physical = model.physical.as_ref().map(|p| &p.record);
        let title = match physical {
            Some(p) => format!(
                "{}: IIR order {}, LSD {:.2} dB; physical LSD {:.2} dB",
                model.name, model.order, model.fit.lsd_db, p.lsd_db
            ),
            None => format!(
                "{}: order {}, NRMSE {:.4}, LSD {:.2} dB",
                model.name, model.order, model.fit.nrmse, model.fit.lsd_db
            ),
        };
        let grid: Vec<Hz> = model.fit.grid_hz.iter().map(|&f| Hz(f)).collect();
        let each = measure_each_file(&recordings, &cfg.analysis, &grid);
        let drawn = out
            .write_with(|p| {
                plot::draw_spectra(
                    p,
                    args.plot_scale.get(),
                    &[Panel {
                        title,
                        fit: &model.fit,
                        physical: physical.map(|p| &p.model[..]),
                        // One file is its own mean: nothing to draw behind it.
                        recordings: if each.len() > 1 { &each } else { &[] },
                    }],
                    plot::YRange::Own,
                )
            })
            .with_context(saved)?;
        drawn.report(path);
    }
    Ok(())
}

/// Fits of up to this many recordings are checked by leaving each out, without
/// `--report`: a refit each, a few tens of milliseconds.
const MAX_LOO_RECORDINGS: usize = 12;

/// Steps of a generated walk rendered per model for `--report`'s tables in time.
const REPORT_STEPS: usize = 48;

/// What a step of the material is made of, as fitted: its heel, its train, its level, and
/// the recordings' figures beside the calibration render's.
fn step_line(
    model: &MaterialModel,
    estimate: Option<&underfoot::excitation::estimate::Estimate>,
) -> String {
    let level = format!("level {:+.1} dB re the recordings", model.level_db);
    match (&model.excitation, estimate) {
        (Some(e), Some(est)) if e.energy.is_empty() => format!(
            "  step: one impact (a solid: the recordings hold no train); D90 {:.0} ms; {level}\n",
            est.recorded.duration_ms
        ),
        (Some(e), Some(est)) => format!(
            "  step: heel {:.0}% of its energy, then about {:.0} micro-impacts over {:.0} ms of step \
             clock; recorded / calibration render: D90 {:.0} / {:.0} ms, {:.0} / {:.0} micro-events, \
             crest {:.1} / {:.1} dB, spread {} / {} dB; {level}\n",
            100.0 * e.heel,
            e.expected_events(),
            1e3 * e.span_s(),
            est.target.duration_ms,
            est.rendered.duration_ms,
            est.target.events,
            est.rendered.events,
            est.target.crest_db,
            est.rendered.crest_db,
            est.target
                .spread_db
                .map_or("-".into(), |v| format!("{v:.2}")),
            est.rendered
                .spread_db
                .map_or("-".into(), |v| format!("{v:.2}")),
        ),
        _ => format!("  step: one impulse (no excitation was fitted); {level}\n"),
    }
}

/// The leave-one-out table in time.
fn held_out_time_table(rows: &[(&HeldOut, Option<StepComparison>)]) -> String {
    use crate::report::{Align, table};
    let pair = |a: Option<f64>, b: Option<f64>, f: &dyn Fn(f64) -> String| {
        format!("{} / {}", a.map_or("-".into(), f), b.map_or("-".into(), f))
    };
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|(h, c)| {
            let rec = h.recorded.as_ref();
            let ren = c.as_ref().map(|c| &c.rendered);
            vec![
                h.file.clone(),
                pair(
                    rec.map(|s| s.duration_ms),
                    ren.map(|s| s.duration_ms),
                    &|v| format!("{v:.0}"),
                ),
                pair(rec.map(|s| s.events), ren.map(|s| s.events), &|v| {
                    format!("{v:.0}")
                }),
                pair(rec.map(|s| s.crest_db), ren.map(|s| s.crest_db), &|v| {
                    format!("{v:.1}")
                }),
                c.as_ref()
                    .map_or("-".into(), |c| format!("{:.2}", c.spectrum_db)),
            ]
        })
        .collect();
    table(
        &[
            ("left out", Align::Left),
            ("D90 ms rec/model", Align::Right),
            ("micro-events", Align::Right),
            ("crest dB", Align::Right),
            ("spectrum dB", Align::Right),
        ],
        &cells,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parsers_accept_good_and_reject_bad_values() {
        assert_eq!("20:900".parse::<Band>(), Ok(Band::new(20.0, 900.0)));
        assert!("900:20".parse::<Band>().is_err());
        assert!("20-900".parse::<Band>().is_err());
        assert!("0:10".parse::<Band>().is_err());
        assert!("1e-200:900".parse::<Band>().is_err());
        assert_eq!(parse_analysis_rate("2000"), Ok(SampleRate(2000)));
        assert!(parse_analysis_rate("0").is_err() && parse_analysis_rate("2k").is_err());
        assert!(parse_analysis_rate("4000000000").is_err());
        assert_eq!(parse_csv_rate("50"), Ok(SampleRate(50)));
        assert_eq!(parse_order("8"), Ok(8));
        assert!(parse_order("0").is_err() && parse_order("65").is_err());
        let parse_savgol = |s: &str| s.parse::<SavgolSetting>();
        assert!(parse_savgol("100001:3").is_err() && parse_savgol("17:13").is_err());
        assert!(parse_positive("nan").is_err() && parse_positive("-1").is_err());
        assert_eq!(
            parse_savgol("17:3"),
            Ok(SavgolSetting::Fixed {
                window: 17,
                polyorder: 3
            })
        );
        assert_eq!(parse_savgol("off"), Ok(SavgolSetting::Off));
        assert!(parse_savgol("16:3").is_err() && parse_savgol("5:5").is_err());
    }
}
