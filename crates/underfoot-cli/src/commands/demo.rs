//! `underfoot demo`: a walk across every material of the built-in library (or another),
//! rendered by the engine, then checked with the fitting pipeline.
//!
//! Writes into `--out-dir`:
//! - `walk.wav`: the vibration of the walk, one channel (float);
//! - `walk-force.csv`: the force track that drove it;
//! - `walk.svg`: its spectrogram, materials marked (`.png` with `--plot-format png`, as
//!   the other two figures);
//! - `spectra.svg`: each material's measured response against its fitted model (Fig. 4);
//! - `steps.svg`: each material's steps in time, its recorded steps' decay envelope and
//!   micro-events against those of its stretch of the walk;
//! - `walk.json`: where each material's stretch is, and how closely it reproduces the
//!   material (log-spectral distance between the stretch, analysed like a recording, and
//!   the response measured from the material's recordings; in time, the recorded steps'
//!   figures beside the stretch's, each step measured from where its sound starts after
//!   its strike, as the recordings' steps were).
//!
//! Every material plays at its library level (`underfoot::material::level`), which keeps a
//! nominal step 3 dB under the default ceiling: the walk is not limited, so its stretches
//! keep the materials' spectra.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use serde::Serialize;
use underfoot::analysis::steps::StepSummary;
use underfoot::atomic_file::OutputFile;
use underfoot::engine::offline::{render, walk_across};
use underfoot::force::gait::GaitConfig;
use underfoot::io::wav::{WavFormat, WavSink};
use underfoot::material::evaluate::{StepComparison, compare_steps, segment_lsd};
use underfoot::synthesis::SynthModel;
use underfoot::units::{Decibels, Seconds};

use crate::commands::synth::SynthArgs;
use crate::output::emit;
use crate::plot::{self, Panel, Segment, StepPanel};
use crate::report::{Align, fit_table, table};
use crate::steps::{RenderRow, render_time_table};

/// Arguments of `underfoot demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Directory to write into (created if missing).
    #[arg(long, value_name = "DIR", default_value = ".")]
    out_dir: PathBuf,
    /// Heel strikes on each material.
    #[arg(long, default_value_t = 4, value_name = "N")]
    steps: usize,
    /// The walk, e.g. "cadence=1.8,weight=70,variation=0.05,seed=1" (steps and channels
    /// are set by the demo).
    #[arg(long, default_value = "", value_name = "SPEC")]
    gait: String,
    /// The dB axis of the spectra figure: one for every material (`shared`: compare
    /// materials at a glance) or each material its own (`own`: the most detail).
    #[arg(long, value_enum, default_value_t = plot::YRange::Shared, value_name = "RANGE")]
    y_range: plot::YRange,
    /// Image format of the plots.
    #[arg(long, value_name = "svg|png", default_value = "svg", value_parser = ["svg", "png"])]
    plot_format: String,
    #[command(flatten)]
    plot_scale: crate::plot::PlotScale,
    #[command(flatten)]
    synth: SynthArgs,
}

#[derive(Serialize)]
struct WalkReport {
    wav: String,
    rate: u32,
    gain_db: f64,
    ceiling_db: f64,
    strikes: u64,
    limited_samples: u64,
    segments: Vec<SegmentReport>,
}

#[derive(Serialize)]
struct SegmentReport {
    material: String,
    start_s: f64,
    end_s: f64,
    strikes: usize,
    lsd_db: f64,
    /// `None` for a material without recorded steps (a library file before format 3).
    time: Option<TimeReport>,
}

/// A stretch's steps in time beside the material's recorded steps.
#[derive(Serialize)]
struct TimeReport {
    recorded: StepFigures,
    rendered: StepFigures,
    /// Gain-aligned log-spectral distance between the two average step spectra.
    spectrum_db: Option<f64>,
    /// The rendered steps' level over the recorded ones, output gain and playback level
    /// taken out.
    level_db: Option<f64>,
}

/// A step summary's figures (`underfoot::analysis::steps::StepSummary`).
#[derive(Serialize)]
struct StepFigures {
    steps: usize,
    duration_ms: f64,
    events: f64,
    event_rate_hz: f64,
    crest_db: f64,
    spread_db: Option<f64>,
}

impl StepFigures {
    fn of(s: &StepSummary) -> Self {
        Self {
            steps: s.steps,
            duration_ms: s.duration_ms,
            events: s.events,
            event_rate_hz: s.event_rate_hz,
            crest_db: s.crest_db,
            spread_db: s.spread_db,
        }
    }
}

impl TimeReport {
    fn of(recorded: &StepSummary, c: &StepComparison) -> Self {
        let finite = |v: f64| Some(v).filter(|v| v.is_finite());
        Self {
            recorded: StepFigures::of(recorded),
            rendered: StepFigures::of(&c.rendered),
            spectrum_db: finite(c.spectrum_db),
            level_db: finite(c.level_db),
        }
    }
}

/// Runs `underfoot demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        (1..=50).contains(&args.steps),
        "--steps {}: need 1 to 50",
        args.steps
    );
    let setup = args.synth.setup(1)?;
    let which = setup.origin.clone();
    emit(&format!(
        "Fit of the materials of {which} (cf. Table I)\n\n{}",
        fit_table(&setup.library.materials)
    ))?;
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating output directory {}", args.out_dir.display()))?;
    // The six files against the output policy (underfoot::atomic_file) before any is
    // written: never the library or compensation files the demo reads, never a device.
    let inputs = args.synth.input_files();
    let inputs: Vec<&std::path::Path> = inputs.iter().map(PathBuf::as_path).collect();
    let ext = &args.plot_format;
    let names = [
        "walk.wav".to_owned(),
        "walk-force.csv".to_owned(),
        "walk.json".to_owned(),
        format!("walk.{ext}"),
        format!("spectra.{ext}"),
        format!("steps.{ext}"),
    ];
    let paths: Vec<PathBuf> = names.iter().map(|n| args.out_dir.join(n)).collect();
    let outs = OutputFile::check_all(
        &paths.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
        &inputs,
    )?;
    let [
        wav_out,
        force_out,
        json_out,
        spectrogram_out,
        spectra_out,
        steps_out,
    ] = <[OutputFile; 6]>::try_from(outs).map_err(|_| anyhow::anyhow!("six outputs"))?;

    let gait = if args.gait.is_empty() {
        GaitConfig::default()
    } else {
        GaitConfig::from_spec(&args.gait)?
    };
    let names: Vec<&str> = setup
        .library
        .materials
        .iter()
        .map(|m| m.name.as_str())
        .collect();
    let rate = setup.config.rate;
    let walk = walk_across(&setup.bank, &names, args.steps, &gait, rate)?;
    let first = walk.segments[0].slot;
    let out = render(
        &setup.config,
        setup.bank.clone(),
        &[first],
        &walk.events,
        walk.frames,
        256,
    )?;

    let wav = wav_out.path().to_path_buf();
    let mut sink = WavSink::to_output(wav_out, rate, 1, WavFormat::Float32)?;
    sink.write_interleaved(&out.samples)?;
    sink.finish()?;
    walk.track.save_to(&force_out)?;

    let mut segments = Vec::new();
    let mut in_time = Vec::new();
    for seg in &walk.segments {
        let (a, b) = (
            rate.samples_in(seg.start),
            rate.samples_in(seg.end).min(walk.frames),
        );
        let model = setup.library.get(&seg.material)?;
        let lsd = segment_lsd(&out.samples[a..b], rate, model, setup.config.gain)
            .with_context(|| format!("analysing the {} stretch of the walk", seg.material))?;
        // At the strikes the walk was generated with, as the engine knows them: found in
        // the signal, a quiet step could be missed or a loud ring taken for one.
        let onsets: Vec<Seconds> = seg
            .strikes
            .iter()
            .map(|t| Seconds(t.0 - a as f64 / rate.hz()))
            .collect();
        let steps = compare_steps(
            &out.samples[a..b],
            rate,
            Some(&onsets),
            model,
            setup.config.gain,
        )
        .with_context(|| format!("measuring the {} stretch's steps", seg.material))?;
        segments.push(SegmentReport {
            material: seg.material.clone(),
            start_s: seg.start.0,
            end_s: seg.end.0,
            strikes: seg.strikes.len(),
            lsd_db: lsd,
            time: model
                .time
                .as_ref()
                .zip(steps.as_ref())
                .map(|(recorded, c)| TimeReport::of(recorded, c)),
        });
        in_time.push((model, steps));
    }
    let rows: Vec<Vec<String>> = segments
        .iter()
        .map(|s| {
            vec![
                s.material.clone(),
                format!("{:.1}-{:.1} s", s.start_s, s.end_s),
                s.strikes.to_string(),
                format!("{:.2}", s.lsd_db),
            ]
        })
        .collect();
    let t = out.telemetry;
    emit(&format!(
        "\nA walk across {} material(s), {} steps each: {} strike(s) detected, gain {:.1} dB, \
         peak {:.1} dBFS, {} sample(s) limited.\nEach stretch analysed like a recording, \
         against the material's measured response:\n\n{}",
        segments.len(),
        args.steps,
        t.strikes,
        setup.config.gain.0,
        Decibels::from_amplitude(f64::from(t.peak).max(1e-12)).0,
        t.limited,
        table(
            &[
                ("material", Align::Left),
                ("stretch", Align::Right),
                ("strikes", Align::Right),
                ("LSD dB", Align::Right),
            ],
            &rows
        )
    ))?;
    let time_rows: Vec<RenderRow<'_>> = in_time
        .iter()
        .map(|(model, steps)| RenderRow {
            name: &model.name,
            model,
            rendered: steps.as_ref(),
        })
        .collect();
    emit(&format!(
        "\nThe steps in time: recorded / rendered in the walk (each stretch's steps, measured \
         from where each starts after its strike, as the recordings are):\n\n{}",
        render_time_table(&time_rows, "walk")
    ))?;

    let report = WalkReport {
        wav: "walk.wav".into(),
        rate: rate.0,
        gain_db: setup.config.gain.0,
        ceiling_db: setup.config.ceiling.0,
        strikes: t.strikes,
        limited_samples: t.limited,
        segments,
    };
    let json = serde_json::to_string_pretty(&report)? + "\n";
    json_out.write(json.as_bytes())?;

    let labels: Vec<Segment<'_>> = walk
        .segments
        .iter()
        .map(|s| Segment {
            label: &s.material,
            start_s: s.start.0,
            end_s: s.end.0,
        })
        .collect();
    let top = walk_top(&setup.library);
    let spectrogram = spectrogram_out.path();
    spectrogram_out
        .write_with(|p| {
            plot::draw_spectrogram(
                p,
                args.plot_scale.get(),
                &format!(
                    "A walk across {which}, played by {}",
                    match args.synth.model {
                        SynthModel::Iir => "the fitted filters",
                        SynthModel::Physical => "the physical models",
                    }
                ),
                &out.samples,
                rate.0,
                top,
                walk_band(&setup.library),
                &labels,
            )
        })?
        .report(spectrogram);

    let path = spectra_out.path();
    let panels: Vec<Panel<'_>> = setup
        .library
        .materials
        .iter()
        .map(|m| Panel {
            title: format!("{}: order {}, LSD {:.2} dB", m.name, m.order, m.fit.lsd_db),
            fit: &m.fit,
            physical: None,
            recordings: &[],
        })
        .collect();
    spectra_out
        .write_with(|p| plot::draw_spectra(p, args.plot_scale.get(), &panels, args.y_range))?
        .report(path);

    let steps_path = steps_out.path().to_path_buf();
    let step_panels: Vec<StepPanel<'_>> = in_time
        .iter()
        .map(|(model, steps)| {
            let (recorded, rendered) = (model.time.as_ref(), steps.as_ref().map(|c| &c.rendered));
            let title = match (recorded, rendered) {
                (Some(r), Some(w)) => format!(
                    "{}: D90 {:.0} ms recorded, {:.0} ms rendered",
                    model.name, r.duration_ms, w.duration_ms
                ),
                // compare_steps measures nothing without recorded steps to compare with.
                _ => format!("{}: no recorded steps in the library", model.name),
            };
            StepPanel {
                title,
                recorded,
                rendered,
            }
        })
        .collect();
    steps_out
        .write_with(|p| plot::draw_steps(p, args.plot_scale.get(), &step_panels))?
        .report(&steps_path);
    emit(&format!(
        "\nwalk: {}\nforce: {}\nspectrogram: {}\nspectra: {}\nsteps: {}\nreport: {}\n",
        wav.display(),
        args.out_dir.join("walk-force.csv").display(),
        spectrogram.display(),
        path.display(),
        steps_path.display(),
        args.out_dir.join("walk.json").display(),
    ))
}

/// The spectrogram's top: the highest band edge of the materials, plus a little.
/// The band the walk's materials were fitted over: from the lowest lower edge to the
/// highest upper one.
fn walk_band(library: &underfoot::material::Library) -> (f64, f64) {
    library
        .materials
        .iter()
        .fold((f64::INFINITY, 0.0), |(lo, hi), m| {
            (lo.min(m.band_hz.lo.0), hi.max(m.band_hz.hi.0))
        })
}

fn walk_top(library: &underfoot::material::Library) -> f64 {
    library
        .materials
        .iter()
        .map(|m| m.band_hz.hi.0)
        .fold(0.0, f64::max)
        .max(100.0)
        * 1.1
}
