//! A material's steps in time, rendered beside its recorded ones: what `fit --report`,
//! `compare` and `demo` print.
//!
//! Steps are rendered by the engine exactly as `render` renders them (48 kHz, the default
//! settings, the material at its playback level) from a generated walk of nominal steps on
//! one channel, and measured by [`underfoot::analysis::steps`] at their strikes, as the
//! recordings' steps were measured when the material was fitted (the library's `time`).

use anyhow::Context;
use underfoot::analysis::steps::StepSummary;
use underfoot::engine::offline::{render, walk_across};
use underfoot::engine::{EngineConfig, MaterialBank};
use underfoot::force::gait::{GaitConfig, nominal_step};
use underfoot::material::evaluate::{StepComparison, compare_steps};
use underfoot::material::{Library, MaterialModel};
use underfoot::synthesis::{SynthModel, VoiceConfig};
use underfoot::units::{Decibels, Newtons, SampleRate, Seconds};

use crate::report::{Align, table};

/// The rate steps are rendered at.
const RATE: SampleRate = SampleRate(48_000);

/// `steps` nominal steps of `model` played by `synth`, rendered and compared with its
/// recorded steps; `None` when the material has no recorded time statistics (a library
/// file before format 3) or no model of that kind.
pub fn render_and_compare(
    model: &MaterialModel,
    synth: SynthModel,
    steps: usize,
) -> anyhow::Result<Option<StepComparison>> {
    if model.time.is_none() || (synth == SynthModel::Physical && model.physical.is_none()) {
        return Ok(None);
    }
    let mut library = Library::new();
    library.upsert(model.clone());
    let voice = VoiceConfig {
        model: synth,
        ..VoiceConfig::default()
    };
    let bank = MaterialBank::prepare(
        &library,
        RATE,
        &voice,
        &nominal_step(70.0, 1.8, RATE.hz()),
        Newtons::weight_of(70.0),
    )
    .with_context(|| format!("preparing {:?}", model.name))?;
    let walk = walk_across(
        &bank,
        &[model.name.as_str()],
        steps,
        &GaitConfig::default(),
        RATE,
    )?;
    let config = EngineConfig {
        rate: RATE,
        ..EngineConfig::default()
    };
    let out = render(&config, bank, &[0], &walk.events, walk.frames, 256)?;
    let onsets: Vec<Seconds> = walk.segments[0].strikes.clone();
    Ok(compare_steps(
        &out.samples,
        RATE,
        Some(&onsets),
        model,
        Decibels(0.0),
    )?)
}

/// One material's row of a time table.
pub struct TimeRow<'a> {
    /// The material.
    pub name: &'a str,
    /// Its recorded steps' figures (from its library entry).
    pub model: &'a MaterialModel,
    /// Rendered with its fitted filter and excitation.
    pub iir: Option<&'a StepComparison>,
    /// Rendered with its physical model.
    pub physical: Option<&'a StepComparison>,
}

/// One material's row of a table of one render against its recordings (the demo's walk).
pub struct RenderRow<'a> {
    /// The material.
    pub name: &'a str,
    /// Its recorded steps' figures (from its library entry).
    pub model: &'a MaterialModel,
    /// Its render, measured.
    pub rendered: Option<&'a StepComparison>,
}

/// `recorded / render / render...`, each formatted by `f`, `-` where absent.
fn figures(recorded: Option<f64>, renders: &[Option<f64>], f: impl Fn(f64) -> String) -> String {
    std::iter::once(recorded)
        .chain(renders.iter().copied())
        .map(|v| v.filter(|v| v.is_finite()).map_or("-".to_string(), &f))
        .collect::<Vec<_>>()
        .join(" / ")
}

/// The table of steps in time: per material, recorded / IIR / physical duration (`D90`),
/// micro-events, crest factor and spread between steps, and how far each render's average
/// spectrum and level are from the recordings'.
pub fn time_table(rows: &[TimeRow<'_>]) -> String {
    let rows: Vec<(&str, &MaterialModel, Vec<Option<&StepComparison>>)> = rows
        .iter()
        .map(|r| (r.name, r.model, vec![r.iir, r.physical]))
        .collect();
    renders_table(&rows, &["IIR", "phys"])
}

/// [`time_table`] with one render, named `label` in the headers, in place of the IIR and
/// physical ones.
pub fn render_time_table(rows: &[RenderRow<'_>], label: &str) -> String {
    let rows: Vec<(&str, &MaterialModel, Vec<Option<&StepComparison>>)> = rows
        .iter()
        .map(|r| (r.name, r.model, vec![r.rendered]))
        .collect();
    renders_table(&rows, &[label])
}

/// The time table of any number of renders per material, named by `labels` in the
/// headers.
fn renders_table(
    rows: &[(&str, &MaterialModel, Vec<Option<&StepComparison>>)],
    labels: &[&str],
) -> String {
    use Align::{Left, Right};
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|(name, model, renders)| {
            let rec = model.time.as_ref();
            let column = |f: &dyn Fn(&StepSummary) -> Option<f64>| -> Vec<Option<f64>> {
                renders
                    .iter()
                    .map(|c| c.and_then(|c| f(&c.rendered)))
                    .collect()
            };
            let compared = |f: &dyn Fn(&StepComparison) -> f64, fmt: &dyn Fn(f64) -> String| {
                renders
                    .iter()
                    .map(|c| c.map(f).filter(|v| v.is_finite()).map_or("-".into(), fmt))
                    .collect::<Vec<_>>()
                    .join(" / ")
            };
            vec![
                (*name).to_string(),
                figures(
                    rec.map(|s| s.duration_ms),
                    &column(&|s| Some(s.duration_ms)),
                    |v| format!("{v:.0}"),
                ),
                figures(rec.map(|s| s.events), &column(&|s| Some(s.events)), |v| {
                    format!("{v:.0}")
                }),
                figures(
                    rec.map(|s| s.crest_db),
                    &column(&|s| Some(s.crest_db)),
                    |v| format!("{v:.1}"),
                ),
                figures(
                    rec.and_then(|s| s.spread_db),
                    &column(&|s| s.spread_db),
                    |v| format!("{v:.2}"),
                ),
                compared(&|c| c.spectrum_db, &|v| format!("{v:.2}")),
                compared(&|c| c.level_db, &|v| format!("{v:+.1}")),
            ]
        })
        .collect();
    let names = labels.join("/");
    let d90 = format!("D90 ms rec/{names}");
    let spectrum = format!("spectrum dB {names}");
    let level = format!("level dB {names}");
    table(
        &[
            ("material", Left),
            (&d90, Right),
            ("micro-events", Right),
            ("crest dB", Right),
            ("spread dB", Right),
            (&spectrum, Right),
            (&level, Right),
        ],
        &cells,
    )
}
