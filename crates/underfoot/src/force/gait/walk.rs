//! The walk: the strikes of both feet in one alternating sequence, each step's stance
//! and shape drawn around the nominal, and the steps sampled into a force track (see the
//! parent module, *Strikes*).

use super::config::GaitConfig;
use super::error::GaitError;
use super::step::{PEAK1, PEAK2, Shape, VALLEY, toe_share};
use super::{CLIP, Gait};
use crate::force::SensorReading;
use crate::force::track::{ChannelSensors, ForceRow, ForceTrack};
use crate::signal::noise::SplitMix64;
use crate::units::{Newtons, Seconds};

/// Generates a walk; see the [module docs](super) for the model.
///
/// Row `i` is at `i / sensor_rate` seconds, from zero to the last toe-off plus the tail.
/// The strike instants are exact, between samples: the first non-zero sample of a step
/// is the first one after its strike.
///
/// # Errors
/// What [`GaitConfig::validate`] finds.
pub fn generate(config: &GaitConfig) -> Result<Gait, GaitError> {
    config.validate()?;
    let weight = Newtons::weight_of(config.weight_kg).0;
    let rate = config.sensor_rate;
    let steps: Vec<Step> = plan(config)
        .into_iter()
        .filter(|s| s.foot < config.channels)
        .collect();

    let end = steps.iter().map(Step::toe_off).fold(0.0, f64::max) + config.tail.0;
    // validate bounds the walk by MAX_ROWS, so this fits easily.
    let n_rows = (end * rate).floor() as usize + 1;
    let mut heel = vec![vec![0.0_f64; n_rows]; config.channels];
    let mut toe = heel.clone();
    let mut strikes = vec![Vec::new(); config.channels];
    let mut toe_offs = vec![Vec::new(); config.channels];
    for step in &steps {
        strikes[step.foot].push(Seconds(step.strike));
        toe_offs[step.foot].push(Seconds(step.toe_off()));
        let first = (step.strike * rate).ceil() as usize;
        let last = ((step.toe_off() * rate).floor() as usize).min(n_rows - 1);
        for i in first..=last {
            let u = (i as f64 / rate - step.strike) / step.stance;
            let force = weight * step.scale * step.shape.eval(u);
            let share = toe_share(u);
            heel[step.foot][i] += force * (1.0 - share);
            toe[step.foot][i] += force * share;
        }
    }

    let names = ["left", "right"];
    let channels = names[..config.channels]
        .iter()
        .map(|name| ChannelSensors {
            name: (*name).to_owned(),
            sensors: vec!["heel".to_owned(), "toe".to_owned()],
        })
        .collect();
    let rows = (0..n_rows)
        .map(|i| ForceRow {
            time: Seconds(i as f64 / rate),
            readings: (0..config.channels)
                .map(|c| pair(heel[c][i] as f32, toe[c][i] as f32))
                .collect(),
        })
        .collect();
    Ok(Gait {
        track: ForceTrack { channels, rows },
        strikes,
        toe_offs,
    })
}

/// A reading of a heel and a toe sensor.
fn pair(heel: f32, toe: f32) -> SensorReading {
    // Two sensors always fit; the fallback keeps the total should that ever change.
    SensorReading::new(&[heel, toe]).unwrap_or_else(|| SensorReading::single(heel + toe))
}

/// One step of one foot.
#[derive(Debug, Clone)]
struct Step {
    foot: usize,
    /// Heel strike, seconds.
    strike: f64,
    /// Stance duration, seconds.
    stance: f64,
    /// `k_n` of the module docs.
    scale: f64,
    shape: Shape,
}

impl Step {
    fn toe_off(&self) -> f64 {
        self.strike + self.stance
    }
}

/// The steps of both feet, alternating, left first, each foot's first `steps` of them.
fn plan(config: &GaitConfig) -> Vec<Step> {
    let mut rng = SplitMix64::new(config.seed);
    let v = config.variation;
    let mut draw = move || rng.normal().clamp(-CLIP, CLIP);
    let needed = config.strikes_needed();
    let mut times = Vec::with_capacity(needed);
    let mut t = config.lead_in.0;
    for _ in 0..needed {
        times.push(t);
        t += (1.0 + v * draw()) / config.cadence;
    }
    (0..2 * config.steps)
        .map(|n| {
            let cycle = times[n + 2] - times[n];
            let sigma = (config.stance_fraction * (1.0 + 0.5 * v * draw())).clamp(0.5, 0.85);
            let shape = Shape::new(
                PEAK1 * (1.0 + v * draw()),
                VALLEY * (1.0 + v * draw()),
                PEAK2 * (1.0 + v * draw()),
            );
            Step {
                foot: n % 2,
                strike: times[n],
                stance: sigma * cycle,
                scale: 1.0 / (2.0 * sigma * shape.area()),
                shape,
            }
        })
        .collect()
}
