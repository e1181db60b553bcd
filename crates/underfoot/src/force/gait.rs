//! The vertical ground-reaction force of walking, for demos and tests.
//!
//! [`generate`] makes a [`ForceTrack`] of someone walking, so that every command runs
//! without hardware, and returns the true heel-strike instants with it, so that step
//! detection can be checked against them.
//!
//! # Model
//!
//! **One foot per channel.** A channel is one shoe or insole, or the tiles under one
//! foot; channel 0 is the left foot (`left`), channel 1 the right (`right`). Each has two
//! sensors, `heel` and `toe`. A one-channel track is the left foot of a walker whose
//! right foot is not instrumented: its steps come once per gait cycle.
//!
//! **Strikes.** The heel strikes of both feet form one alternating sequence
//! `t_0 < t_1 < ...`, left on even `n`, right on odd `n`, with cadence `c` (steps per
//! second, both feet together) and relative variation `v`:
//!
//! ```text
//! t_0 = lead_in,    t_(n+1) = t_n + (1 / c) (1 + v z_n),    z_n ~ N(0, 1) clipped to ±2.5
//! ```
//!
//! One sequence for both feet, rather than one per foot, so that the feet stay about half
//! a cycle apart however long the walk: per-foot jitter would let them drift together.
//! Step `n`'s gait cycle is `T_n = t_(n+2) - t_n` (nominally `2 / c`), and its stance
//! (heel strike to toe-off) lasts `sigma_n T_n`, with the stance fraction
//! `sigma_n = sigma (1 + v z / 2)` (nominally `sigma` = 0.62, clamped to 0.5..0.85). Half
//! as much variation as the timing, because the cycle it multiplies varies already.
//! A stance fraction above one half means both feet are down for a while twice per
//! cycle (double support), as in walking.
//!
//! **Shape.** In stance, with `u = (t - t_n) / (sigma_n T_n)` in `0..=1` and body weight
//! `W = weight_kg g`,
//!
//! ```text
//! F_n(t) = W k_n S_n(u),        k_n = 1 / (2 sigma_n ∫_0^1 S_n(u) du)
//! ```
//!
//! and zero outside stance. `S_n` is the piecewise cubic Hermite curve through the knots
//! `(u_i, y_i)` with slopes `m_i`; on `[u_i, u_(i+1)]`, with `h = u_(i+1) - u_i` and
//! `s = (u - u_i) / h`,
//!
//! ```text
//! S(u) = (2s³ - 3s² + 1) y_i + (s³ - 2s² + s) h m_i + (3s² - 2s³) y_(i+1) + (s³ - s²) h m_(i+1)
//! ```
//!
//! | `u` | `y` | slope `m` | meaning |
//! |---|---|---|---|
//! | 0 | 0 | 0 | heel strike |
//! | 0.115 | 0.88 `p1` | `2 (p1 - y) / 0.135` | end of the fast heel-strike rise |
//! | 0.25 | `p1` = 1.15 | 0 | first peak: weight acceptance |
//! | 0.50 | `q` = 0.75 | 0 | mid-stance valley |
//! | 0.75 | `p2` = 1.10 | 0 | second peak: push-off |
//! | 1 | 0 | 0 | toe-off |
//!
//! Each step draws its own `p1`, `q`, `p2` as `(1 + v z)` times the values above.
//! Every segment is monotone (its end slopes are within the Fritsch-Carlson bounds; the
//! second is exactly the parabola that crests at the first peak), so the curve is never
//! negative and its extremes are the knots. It is C1: value and slope are continuous,
//! also at heel strike and toe-off where they meet the zero of swing, because the force
//! is later differentiated and a kink would click. At 1.8 steps/s the rise reaches
//! 0.88 `p1`, about body weight, 80 ms after heel strike, and the first peak at 172 ms.
//! The steepest slope is then about 18 `W`/s, under 4% of body weight per sample at
//! 500 Hz.
//!
//! **Impulse.** `k_n` scales step `n` so that its impulse is `W T_n / 2`. Summed over
//! both feet these impulses tile time, so the mean force over whole cycles is `W`: the
//! body does not accelerate vertically on average. With the nominal knots and
//! `sigma` = 0.62, `k` = 0.994 and the peaks come out at 1.14, 0.75 and 1.09 `W`. The
//! impulse ties the curve to the stance fraction: at `sigma` = 0.6 the same knots are
//! scaled by `k` = 1.027, to peaks of 1.18, 0.77 and 1.13 `W`.
//!
//! **Heel and toe.** The centre of pressure moves from heel to toe over stance. The toe
//! carries the share `phi(u)` of the force, a smoothstep from 0 at `u` = 0.15 to 1 at
//! `u` = 0.70:
//!
//! ```text
//! heel = (1 - phi(u)) F,    toe = phi(u) F,    phi(u) = 3x² - 2x³,  x = clamp((u - 0.15) / 0.55, 0, 1)
//! ```
//!
//! so heel + toe = `F` (to `f32` rounding) and both stay C1.
//!
//! # Example
//!
//! ```
//! use underfoot::force::gait::{generate, GaitConfig};
//!
//! let config = GaitConfig::from_spec("steps=4,cadence=1.8,weight=70,seed=3")?;
//! let gait = generate(&config)?;
//! assert_eq!(gait.track.channel_count(), 2);
//! assert_eq!(gait.strikes[0].len(), 4);
//! assert_eq!(gait.track.sensor_rate().map(f64::round), Some(500.0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use super::SensorReading;
use super::track::{ChannelSensors, ForceRow, ForceTrack};
use crate::signal::noise::SplitMix64;
use crate::units::{Newtons, Seconds};

/// The nominal stance fraction: the part of a gait cycle a foot is on the ground.
///
/// 0.62, in the usual 0.6-0.62 of walking, is where the impulse needs the nominal curve
/// scaled least (`k` = 0.994 in the [module docs](self)), so the nominal peaks are the
/// peaks generated.
pub const DEFAULT_STANCE_FRACTION: f64 = 0.62;

/// The most rows [`generate`] makes, about 67 minutes at 500 Hz, so that a typo in a spec
/// cannot ask for more memory than the machine has.
pub const MAX_ROWS: usize = 2_000_000;

/// The keys [`GaitConfig::from_spec`] accepts.
pub const SPEC_KEYS: &[&str] = &[
    "steps",
    "cadence",
    "weight",
    "channels",
    "variation",
    "rate",
    "seed",
    "stance",
    "lead_in",
    "tail",
];

/// Normal draws are clipped to this many standard deviations, so that even the largest
/// variation keeps every interval and peak positive.
const CLIP: f64 = 2.5;

/// Knot positions (fraction of stance) and nominal heights (fraction of body weight).
const RISE_U: f64 = 0.115;
const RISE_LEVEL: f64 = 0.88;
const PEAK1_U: f64 = 0.25;
const VALLEY_U: f64 = 0.5;
const PEAK2_U: f64 = 0.75;
const PEAK1: f64 = 1.15;
const VALLEY: f64 = 0.75;
const PEAK2: f64 = 1.10;

/// Where the toe's share of the force starts and finishes rising.
const TOE_FROM: f64 = 0.15;
const TOE_TO: f64 = 0.70;

/// What to generate. Build with `..Default::default()` or [`GaitConfig::from_spec`].
#[derive(Debug, Clone, PartialEq)]
pub struct GaitConfig {
    /// Heel strikes per channel (spec key `steps`), at least 1.
    pub steps: usize,
    /// Steps per second, both feet together (`cadence`), 0.5 to 4; 1.8 is a brisk walk.
    pub cadence: f64,
    /// Body mass in kilograms (`weight`), 20 to 300.
    pub weight_kg: f64,
    /// Feet, 1 or 2 (`channels`): channel `k` is foot `k`, left first.
    pub channels: usize,
    /// Relative step-to-step variation of timing and peak heights (`variation`), 0 to 0.3.
    pub variation: f64,
    /// Sensor rate in hertz (`rate`), 50 to 10 000.
    pub sensor_rate: f64,
    /// Seed of the variation (`seed`): the same seed gives the same track.
    pub seed: u64,
    /// Nominal stance fraction (`stance`), 0.55 to 0.75.
    pub stance_fraction: f64,
    /// Silence before the first heel strike (`lead_in`, seconds), 0 to 60.
    pub lead_in: Seconds,
    /// Silence after the last toe-off (`tail`, seconds), 0 to 60.
    pub tail: Seconds,
}

impl Default for GaitConfig {
    fn default() -> Self {
        Self {
            steps: 8,
            cadence: 1.8,
            weight_kg: 70.0,
            channels: 2,
            variation: 0.05,
            sensor_rate: 500.0,
            seed: 1,
            stance_fraction: DEFAULT_STANCE_FRACTION,
            lead_in: Seconds(0.5),
            tail: Seconds(1.0),
        }
    }
}

/// What is wrong with a gait spec or configuration.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GaitError {
    /// A spec item without `=`.
    #[error("gait spec: {item:?} is not key=value")]
    Malformed {
        /// The item as written.
        item: String,
    },
    /// A spec key that is not one of [`SPEC_KEYS`].
    #[error("gait spec: unknown key {key:?} (in {key}={value}); known keys: {}", SPEC_KEYS.join(", "))]
    UnknownKey {
        /// The key.
        key: String,
        /// Its value.
        value: String,
    },
    /// A spec key given twice.
    #[error("gait spec: {key} is given twice")]
    DuplicateKey {
        /// The key.
        key: String,
    },
    /// A spec value that does not parse.
    #[error("gait spec: {key}={value}: {value:?} is not {expected}")]
    BadNumber {
        /// The key.
        key: String,
        /// The value as written.
        value: String,
        /// What it should be, e.g. `a whole number`.
        expected: &'static str,
    },
    /// A setting outside its range.
    #[error("gait {key} = {value} is out of range: {allowed}")]
    OutOfRange {
        /// The setting, by its spec key.
        key: &'static str,
        /// Its value.
        value: String,
        /// The range allowed.
        allowed: &'static str,
    },
    /// A walk of more than [`MAX_ROWS`] rows.
    #[error(
        "gait of {steps} steps at {cadence} steps/s and {rate} Hz needs up to {rows} rows; at \
         most {MAX_ROWS} (fewer steps or a lower rate)"
    )]
    TooLong {
        /// Steps per channel.
        steps: usize,
        /// Cadence in steps per second.
        cadence: f64,
        /// Sensor rate in hertz.
        rate: f64,
        /// Rows needed at most.
        rows: u64,
    },
}

impl GaitConfig {
    /// The default configuration changed by `key=value` items separated by commas, e.g.
    /// `steps=12,cadence=1.8,weight=70`; keys are [`SPEC_KEYS`]. An empty spec gives the
    /// defaults. The result is validated.
    ///
    /// # Errors
    /// [`GaitError`] naming the item, key or value at fault, or the setting out of range.
    pub fn from_spec(spec: &str) -> Result<Self, GaitError> {
        let mut config = Self::default();
        let mut seen: Vec<&str> = Vec::new();
        for item in spec.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let Some((key, value)) = item.split_once('=') else {
                return Err(GaitError::Malformed {
                    item: item.to_owned(),
                });
            };
            let (key, value) = (key.trim(), value.trim());
            if seen.contains(&key) {
                return Err(GaitError::DuplicateKey {
                    key: key.to_owned(),
                });
            }
            seen.push(key);
            let bad = |expected| GaitError::BadNumber {
                key: key.to_owned(),
                value: value.to_owned(),
                expected,
            };
            let whole = || value.parse::<u64>().map_err(|_| bad("a whole number"));
            let real = || value.parse::<f64>().map_err(|_| bad("a number"));
            let count =
                || whole().and_then(|n| usize::try_from(n).map_err(|_| bad("a whole number")));
            match key {
                "steps" => config.steps = count()?,
                "cadence" => config.cadence = real()?,
                "weight" => config.weight_kg = real()?,
                "channels" => config.channels = count()?,
                "variation" => config.variation = real()?,
                "rate" => config.sensor_rate = real()?,
                "seed" => config.seed = whole()?,
                "stance" => config.stance_fraction = real()?,
                "lead_in" => config.lead_in = Seconds(real()?),
                "tail" => config.tail = Seconds(real()?),
                _ => {
                    return Err(GaitError::UnknownKey {
                        key: key.to_owned(),
                        value: value.to_owned(),
                    });
                }
            }
        }
        config.validate()?;
        Ok(config)
    }

    /// Checks every setting against its range (see the fields), and that the walk fits
    /// in [`MAX_ROWS`] rows.
    ///
    /// # Errors
    /// [`GaitError::OutOfRange`] naming the first setting at fault, or
    /// [`GaitError::TooLong`].
    pub fn validate(&self) -> Result<(), GaitError> {
        fn within(
            key: &'static str,
            value: f64,
            lo: f64,
            hi: f64,
            allowed: &'static str,
        ) -> Result<(), GaitError> {
            if (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(GaitError::OutOfRange {
                    key,
                    value: value.to_string(),
                    allowed,
                })
            }
        }
        if self.steps == 0 {
            return Err(GaitError::OutOfRange {
                key: "steps",
                value: "0".to_owned(),
                allowed: "at least 1",
            });
        }
        if !(1..=2).contains(&self.channels) {
            return Err(GaitError::OutOfRange {
                key: "channels",
                value: self.channels.to_string(),
                allowed: "1 or 2 (one foot per channel)",
            });
        }
        within("cadence", self.cadence, 0.5, 4.0, "0.5 to 4 steps/s")?;
        within("weight", self.weight_kg, 20.0, 300.0, "20 to 300 kg")?;
        within("variation", self.variation, 0.0, 0.3, "0 to 0.3")?;
        within("rate", self.sensor_rate, 50.0, 10_000.0, "50 to 10000 Hz")?;
        within("stance", self.stance_fraction, 0.55, 0.75, "0.55 to 0.75")?;
        within("lead_in", self.lead_in.0, 0.0, 60.0, "0 to 60 s")?;
        within("tail", self.tail.0, 0.0, 60.0, "0 to 60 s")?;
        // An upper bound on the walk: every interval at its clipped maximum.
        let strikes = (self.strikes_needed() + 1) as f64;
        let longest =
            self.lead_in.0 + strikes * (1.0 + CLIP * self.variation) / self.cadence + self.tail.0;
        let rows = (longest * self.sensor_rate).ceil();
        if rows > MAX_ROWS as f64 {
            return Err(GaitError::TooLong {
                steps: self.steps,
                cadence: self.cadence,
                rate: self.sensor_rate,
                rows: rows as u64,
            });
        }
        Ok(())
    }

    /// Heel strikes of both feet needed: every kept step's cycle must end at a strike.
    fn strikes_needed(&self) -> usize {
        2 * self.steps.min(MAX_ROWS) + 2
    }
}

/// A generated walk: the force track and the true instants of each step.
#[derive(Debug, Clone, PartialEq)]
pub struct Gait {
    /// The sensor readings: channels `left` (and `right`), sensors `heel` and `toe`.
    pub track: ForceTrack,
    /// Each channel's heel-strike instants, in order: where the force leaves zero.
    pub strikes: Vec<Vec<Seconds>>,
    /// Each channel's toe-off instants, one per strike: where the force returns to zero.
    pub toe_offs: Vec<Vec<Seconds>>,
}

/// Generates a walk; see the [module docs](self) for the model.
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

/// One nominal step's total vertical force in newtons (no variation, stance fraction
/// [`DEFAULT_STANCE_FRACTION`]), sampled at `rate` hertz from heel strike to toe-off,
/// both zeros included.
///
/// For calibrating gains against the force a walker makes. Empty if an argument is not
/// positive and finite.
#[must_use]
pub fn nominal_step(weight_kg: f64, cadence: f64, rate: f64) -> Vec<f64> {
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if !(positive(weight_kg) && positive(cadence) && positive(rate)) {
        return Vec::new();
    }
    let shape = Shape::new(PEAK1, VALLEY, PEAK2);
    let stance = DEFAULT_STANCE_FRACTION * 2.0 / cadence;
    let scale = 1.0 / (2.0 * DEFAULT_STANCE_FRACTION * shape.area());
    let weight = Newtons::weight_of(weight_kg).0;
    let samples = (stance * rate).floor();
    if samples > MAX_ROWS as f64 {
        return Vec::new();
    }
    (0..=samples as usize)
        .map(|i| weight * scale * shape.eval(i as f64 / rate / stance))
        .collect()
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

/// The toe's share of the force at stance fraction `u`: C1, 0 early, 1 late.
fn toe_share(u: f64) -> f64 {
    let x = ((u - TOE_FROM) / (TOE_TO - TOE_FROM)).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// A knot of the Hermite curve: position, value, slope.
#[derive(Debug, Clone, Copy)]
struct Knot {
    u: f64,
    y: f64,
    m: f64,
}

/// The stance curve `S(u)`: a piecewise cubic Hermite through six knots.
#[derive(Debug, Clone)]
struct Shape {
    knots: [Knot; 6],
}

impl Shape {
    fn new(peak1: f64, valley: f64, peak2: f64) -> Self {
        let knot = |u, y, m| Knot { u, y, m };
        let rise = RISE_LEVEL * peak1;
        Self {
            knots: [
                knot(0.0, 0.0, 0.0),
                // Twice the secant to the crest: the segment after it is the parabola
                // with its vertex at the first peak, so the approach is concave.
                knot(RISE_U, rise, 2.0 * (peak1 - rise) / (PEAK1_U - RISE_U)),
                knot(PEAK1_U, peak1, 0.0),
                knot(VALLEY_U, valley, 0.0),
                knot(PEAK2_U, peak2, 0.0),
                knot(1.0, 0.0, 0.0),
            ],
        }
    }

    /// `S(u)`, zero outside `0..=1`.
    fn eval(&self, u: f64) -> f64 {
        if !(0.0..=1.0).contains(&u) {
            return 0.0;
        }
        for w in self.knots.windows(2) {
            let (a, b) = (w[0], w[1]);
            if u <= b.u {
                let h = b.u - a.u;
                let s = (u - a.u) / h;
                let (s2, s3) = (s * s, s * s * s);
                return (2.0 * s3 - 3.0 * s2 + 1.0) * a.y
                    + (s3 - 2.0 * s2 + s) * h * a.m
                    + (3.0 * s2 - 2.0 * s3) * b.y
                    + (s3 - s2) * h * b.m;
            }
        }
        0.0
    }

    /// `∫_0^1 S(u) du`, exactly: a cubic Hermite segment integrates to
    /// `h (y_a + y_b) / 2 + h² (m_a - m_b) / 12`.
    fn area(&self) -> f64 {
        self.knots
            .windows(2)
            .map(|w| {
                let h = w[1].u - w[0].u;
                h * (w[0].y + w[1].y) / 2.0 + h * h * (w[0].m - w[1].m) / 12.0
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn totals(track: &ForceTrack, channel: usize) -> Vec<f64> {
        track
            .rows
            .iter()
            .map(|r| f64::from(r.readings[channel].total()))
            .collect()
    }

    fn weight(config: &GaitConfig) -> f64 {
        Newtons::weight_of(config.weight_kg).0
    }

    #[test]
    fn shape_area_matches_quadrature() {
        let shape = Shape::new(PEAK1, VALLEY, PEAK2);
        let n = 100_000;
        let sum: f64 = (0..n)
            .map(|i| shape.eval((i as f64 + 0.5) / n as f64))
            .sum();
        assert!((sum / n as f64 - shape.area()).abs() < 1e-9);
    }

    #[test]
    fn force_is_zero_outside_stance_and_never_negative() {
        let config = GaitConfig {
            steps: 10,
            variation: 0.2,
            ..GaitConfig::default()
        };
        let gait = generate(&config).unwrap();
        let rate = config.sensor_rate;
        for c in 0..2 {
            let stances: Vec<(f64, f64)> = gait.strikes[c]
                .iter()
                .zip(&gait.toe_offs[c])
                .map(|(a, b)| (a.0, b.0))
                .collect();
            for (row, total) in gait.track.rows.iter().zip(totals(&gait.track, c)) {
                let t = row.time.0;
                assert!(row.readings[c].as_slice().iter().all(|&v| v >= 0.0));
                let in_stance = stances.iter().any(|&(a, b)| t > a && t < b);
                if !in_stance {
                    assert!(total == 0.0, "channel {c} at {t} s: {total} N");
                }
            }
            // Strictly inside a stance, away from its ends, there is load.
            for &(a, b) in &stances {
                let mid = ((a + b) / 2.0 * rate).round() as usize;
                assert!(totals(&gait.track, c)[mid] > 0.25 * weight(&config));
            }
        }
    }

    #[test]
    fn peaks_and_valley_are_near_their_fractions_of_body_weight() {
        let config = GaitConfig {
            steps: 1,
            channels: 1,
            variation: 0.0,
            ..GaitConfig::default()
        };
        let gait = generate(&config).unwrap();
        let w = weight(&config);
        let f = totals(&gait.track, 0);
        let rate = config.sensor_rate;
        let strike = gait.strikes[0][0].0;
        let stance = gait.toe_offs[0][0].0 - strike;
        let at = |u: f64| ((strike + u * stance) * rate).round() as usize;
        let max_in = |a: f64, b: f64| f[at(a)..at(b)].iter().copied().fold(0.0, f64::max);
        let min_in = |a: f64, b: f64| f[at(a)..at(b)].iter().copied().fold(f64::MAX, f64::min);
        let (p1, q, p2) = (max_in(0.0, 0.4), min_in(0.35, 0.65), max_in(0.6, 1.0));
        assert!((1.1..1.2).contains(&(p1 / w)), "first peak {}", p1 / w);
        assert!((0.7..0.8).contains(&(q / w)), "valley {}", q / w);
        assert!((1.05..1.15).contains(&(p2 / w)), "second peak {}", p2 / w);
        // Where they are: at 25%, 50% and 75% of stance, to a sample.
        let argmax = |a: f64, b: f64| {
            (at(a)..at(b))
                .max_by(|&i, &j| f[i].total_cmp(&f[j]))
                .unwrap()
        };
        assert!(argmax(0.0, 0.4).abs_diff(at(0.25)) <= 1);
        assert!(argmax(0.6, 1.0).abs_diff(at(0.75)) <= 1);
        // The heel-strike rise: about body weight within 80 ms.
        let after = |seconds: f64| f[((strike + seconds) * rate).round() as usize] / w;
        assert!(
            after(0.080) > 0.95 && after(0.050) > 0.5,
            "{}",
            after(0.080)
        );
    }

    #[test]
    fn mean_force_over_whole_cycles_is_body_weight() {
        for (seed, cadence, variation) in [(1, 1.8, 0.05), (2, 1.0, 0.2), (3, 3.0, 0.0)] {
            let config = GaitConfig {
                steps: 24,
                cadence,
                variation,
                seed,
                ..GaitConfig::default()
            };
            let gait = generate(&config).unwrap();
            let (left, right) = (totals(&gait.track, 0), totals(&gait.track, 1));
            // Whole cycles away from the ends, where the other foot's steps are all there.
            let rate = config.sensor_rate;
            let from = (gait.strikes[0][2].0 * rate).round() as usize;
            let to = (gait.strikes[0][22].0 * rate).round() as usize;
            let mean = (from..to).map(|i| left[i] + right[i]).sum::<f64>() / (to - from) as f64;
            let ratio = mean / weight(&config);
            assert!((ratio - 1.0).abs() < 0.05, "cadence {cadence}: {ratio}");
            assert!((ratio - 1.0).abs() < 0.01 || variation > 0.0, "{ratio}");
        }
    }

    #[test]
    fn heel_and_toe_add_up_to_the_nominal_step() {
        let config = GaitConfig {
            steps: 1,
            channels: 1,
            variation: 0.0,
            ..GaitConfig::default()
        };
        let gait = generate(&config).unwrap();
        let step = nominal_step(config.weight_kg, config.cadence, config.sensor_rate);
        let first = (config.lead_in.0 * config.sensor_rate).round() as usize;
        let rows = &gait.track.rows[first..first + step.len()];
        for (k, (row, expected)) in rows.iter().zip(&step).enumerate() {
            let [heel, toe] = row.readings[0].as_slice() else {
                panic!("two sensors")
            };
            let total = f64::from(*heel) + f64::from(*toe);
            assert!((total - expected).abs() < 1e-3, "sample {k}");
            let u = k as f64 / (config.sensor_rate * config.stance_fraction * 2.0 / config.cadence);
            if u < TOE_FROM {
                assert_eq!(*toe, 0.0);
            }
            if u > TOE_TO {
                assert_eq!(*heel, 0.0);
            }
        }
        assert_eq!(step.first(), Some(&0.0));
        assert!(step.last().is_some_and(|&f| f < 1.0));
        assert!(nominal_step(70.0, 0.0, 500.0).is_empty());
    }

    #[test]
    fn the_force_is_smooth() {
        let config = GaitConfig {
            steps: 8,
            ..GaitConfig::default()
        };
        let gait = generate(&config).unwrap();
        let w = weight(&config);
        for c in 0..2 {
            let f = totals(&gait.track, c);
            let jump = f
                .windows(2)
                .map(|p| (p[1] - p[0]).abs())
                .fold(0.0, f64::max);
            // A kink (slope jump) of 10 W/s would give a second difference of 0.02 W at
            // 500 Hz; the curve's own curvature stays well below that.
            let bend = f
                .windows(3)
                .map(|p| (p[2] - 2.0 * p[1] + p[0]).abs())
                .fold(0.0, f64::max);
            assert!(jump < 0.05 * w, "jump {}", jump / w);
            assert!(bend < 0.008 * w, "bend {}", bend / w);
        }
    }

    #[test]
    fn strikes_keep_the_cadence_and_alternate() {
        let config = GaitConfig {
            steps: 40,
            cadence: 2.0,
            ..GaitConfig::default()
        };
        let gait = generate(&config).unwrap();
        let (left, right) = (&gait.strikes[0], &gait.strikes[1]);
        assert_eq!((left.len(), right.len()), (40, 40));
        assert_eq!(left[0], config.lead_in);
        let cycle = (left[39].0 - left[0].0) / 39.0;
        assert!((cycle - 1.0).abs() < 0.03, "cycle {cycle}");
        for (l, r) in left.iter().zip(right) {
            let offset = r.0 - l.0;
            assert!((0.3..0.7).contains(&offset), "offset {offset}");
        }
        let end = gait.track.rows.last().unwrap().time.0;
        assert!((end - gait.toe_offs[1][39].0 - config.tail.0).abs() < 0.003);
        gait.track.validate("gait").unwrap();

        let one = generate(&GaitConfig {
            channels: 1,
            ..config
        })
        .unwrap();
        assert_eq!(one.track.channels[0].name, "left");
        assert_eq!(one.strikes, vec![left.clone()]);
    }

    #[test]
    fn the_seed_decides_the_walk() {
        let config = GaitConfig::default();
        let a = generate(&config).unwrap();
        assert_eq!(a, generate(&config).unwrap());
        let b = generate(&GaitConfig { seed: 2, ..config }).unwrap();
        assert_ne!(a.strikes, b.strikes);
        assert_ne!(a.track, b.track);
    }

    #[test]
    fn generated_tracks_survive_the_file_format() {
        let gait = generate(&GaitConfig::from_spec("steps=2,rate=200").unwrap()).unwrap();
        let back = ForceTrack::from_csv_str(&gait.track.to_csv(), "gait").unwrap();
        assert_eq!(back, gait.track);
        assert!((back.sensor_rate().unwrap() - 200.0).abs() < 1e-6);
    }

    #[test]
    fn specs_parse_and_faults_are_named() {
        let config = GaitConfig::from_spec(
            " steps=12, cadence=1.6,weight=82.5,channels=1,variation=0,rate=1000,seed=9,\
             stance=0.62,lead_in=0,tail=2 ",
        )
        .unwrap();
        assert_eq!(
            config,
            GaitConfig {
                steps: 12,
                cadence: 1.6,
                weight_kg: 82.5,
                channels: 1,
                variation: 0.0,
                sensor_rate: 1000.0,
                seed: 9,
                stance_fraction: 0.62,
                lead_in: Seconds(0.0),
                tail: Seconds(2.0),
            }
        );
        assert_eq!(GaitConfig::from_spec("").unwrap(), GaitConfig::default());

        let fault = |spec: &str| GaitConfig::from_spec(spec).unwrap_err();
        assert!(matches!(fault("steps"), GaitError::Malformed { .. }));
        assert!(matches!(
            fault("speed=3"),
            GaitError::UnknownKey { ref key, ref value } if key == "speed" && value == "3"
        ));
        assert!(matches!(
            fault("steps=1.5"),
            GaitError::BadNumber { ref key, ref value, .. } if key == "steps" && value == "1.5"
        ));
        assert!(matches!(fault("weight=heavy"), GaitError::BadNumber { .. }));
        assert!(matches!(fault("seed=-1"), GaitError::BadNumber { .. }));
        assert!(matches!(
            fault("steps=2,steps=3"),
            GaitError::DuplicateKey { .. }
        ));
        for (spec, key) in [
            ("steps=0", "steps"),
            ("cadence=0.4", "cadence"),
            ("cadence=4.5", "cadence"),
            ("weight=19", "weight"),
            ("weight=301", "weight"),
            ("weight=NaN", "weight"),
            ("channels=3", "channels"),
            ("channels=0", "channels"),
            ("variation=0.31", "variation"),
            ("variation=-0.1", "variation"),
            ("rate=49", "rate"),
            ("rate=10001", "rate"),
            ("stance=0.5", "stance"),
            ("lead_in=-1", "lead_in"),
            ("tail=inf", "tail"),
        ] {
            let e = fault(spec);
            assert!(
                matches!(e, GaitError::OutOfRange { key: k, .. } if k == key),
                "{spec}: {e}"
            );
        }
        assert!(matches!(
            fault("steps=100000000000,rate=10000"),
            GaitError::TooLong { .. }
        ));
        let message = fault("cadence=9").to_string();
        assert!(
            message.contains("cadence") && message.contains('9'),
            "{message}"
        );
    }
}
