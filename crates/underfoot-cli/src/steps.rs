//! A material's steps in time, rendered beside its recorded ones: what `fit --report`,
//! `compare` and `demo` print.
//!
//! Steps are rendered by the engine exactly as `render` renders them (48 kHz, the default
//! settings, the material at its playback level) from a generated walk of nominal steps on
//! one channel, and measured by [`underfoot::analysis::steps`] at their strikes, as the
//! recordings' steps were measured when the material was fitted (the library's `time`).

use anyhow::Context;
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

/// `recorded / iir / physical`, each formatted by `f`, `-` where absent.
fn trio(
    recorded: Option<f64>,
    iir: Option<f64>,
    physical: Option<f64>,
    f: impl Fn(f64) -> String,
) -> String {
    [recorded, iir, physical]
        .iter()
        .map(|v| v.filter(|v| v.is_finite()).map_or("-".to_string(), &f))
        .collect::<Vec<_>>()
        .join(" / ")
}

/// The table of steps in time: per material, recorded / IIR / physical duration (`D90`),
/// micro-events, crest factor and spread between steps, and how far each render's average
/// spectrum and level are from the recordings'.
pub fn time_table(rows: &[TimeRow<'_>]) -> String {
    use Align::{Left, Right};
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            let rec = r.model.time.as_ref();
            let (i, p) = (r.iir.map(|c| &c.rendered), r.physical.map(|c| &c.rendered));
            vec![
                r.name.to_string(),
                trio(
                    rec.map(|s| s.duration_ms),
                    i.map(|s| s.duration_ms),
                    p.map(|s| s.duration_ms),
                    |v| format!("{v:.0}"),
                ),
                trio(
                    rec.map(|s| s.events),
                    i.map(|s| s.events),
                    p.map(|s| s.events),
                    |v| format!("{v:.0}"),
                ),
                trio(
                    rec.map(|s| s.crest_db),
                    i.map(|s| s.crest_db),
                    p.map(|s| s.crest_db),
                    |v| format!("{v:.1}"),
                ),
                trio(
                    rec.and_then(|s| s.spread_db),
                    i.and_then(|s| s.spread_db),
                    p.and_then(|s| s.spread_db),
                    |v| format!("{v:.2}"),
                ),
                [r.iir, r.physical]
                    .iter()
                    .map(|c| {
                        c.filter(|c| c.spectrum_db.is_finite())
                            .map_or("-".into(), |c| format!("{:.2}", c.spectrum_db))
                    })
                    .collect::<Vec<_>>()
                    .join(" / "),
                [r.iir, r.physical]
                    .iter()
                    .map(|c| {
                        c.filter(|c| c.level_db.is_finite())
                            .map_or("-".into(), |c| format!("{:+.1}", c.level_db))
                    })
                    .collect::<Vec<_>>()
                    .join(" / "),
            ]
        })
        .collect();
    table(
        &[
            ("material", Left),
            ("D90 ms rec/IIR/phys", Right),
            ("micro-events", Right),
            ("crest dB", Right),
            ("spread dB", Right),
            ("spectrum dB IIR/phys", Right),
            ("level dB IIR/phys", Right),
        ],
        &cells,
    )
}
