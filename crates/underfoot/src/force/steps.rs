//! Heel-strike detection: a Schmitt trigger on the total force.
//!
//! A strike is the total force rising through `on`; the detector re-arms only when the
//! force has fallen below `off < on` (the foot has left the ground), and ignores strikes
//! closer than `refractory` to the previous one. The gap between the thresholds keeps
//! sensor noise and the double hump of a stance from counting as new steps.
//!
//! Each strike has an *intensity*: the loading rate at the crossing over a nominal loading
//! rate, clamped to `[min_intensity, max_intensity]`. A foot that comes down hard excites
//! the ground more; the clamp keeps one glitchy reading from making a step ten times louder.
//!
//! # Time
//!
//! The loading rate is the slope between the two readings around the crossing,
//! `(F_k - F_{k-1}) / (t_k - t_{k-1})`, and the refractory period is measured between
//! crossing times. What `t` is depends on what the reading knows ([`ReadingTime`]):
//!
//! - **Sensor time** (a track's `time_s`, a replay's clock, a sensor's timestamp): used as
//!   it is. The intensity is then a property of the force signal alone, the same offline
//!   and live whatever the audio block size: two readings that reach the audio thread in
//!   the same block are still `t_k - t_{k-1}` apart.
//! - **Arrival time** (the engine frame a reading without a sensor time was applied at,
//!   over the audio rate): quantised to the block grid, and readings queued behind a late
//!   poll arrive together. Such a source is taken to deliver one reading per nominal
//!   sensor period `T` in order, so `Δt = T` unless the gap is longer than `1.5 T` (a real
//!   pause, or a slower sensor), in which case the gap is used. This keeps the block grid
//!   out of the slope of a steady stream; the onset itself stays on the block grid.
//!
//! A time that goes back (a sensor clock that restarted) forgets the past, as
//! [`reset`](StepDetector::reset) does.

use crate::units::{Hz, Newtons, SampleRate, Seconds};

/// The default rising threshold: well above a force-sensing resistor's ±10 N.
pub const DEFAULT_THRESHOLD: Newtons = Newtons(60.0);

/// Where the detector re-arms, as a fraction of the rising threshold (30 N under 60 N):
/// far enough under it that a sensor's noise at the threshold does not fire twice.
pub const REARM_FRACTION: f64 = 0.5;

/// Detector settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorConfig {
    /// Rising threshold (default [`DEFAULT_THRESHOLD`], 60 N).
    pub on: Newtons,
    /// Re-arming threshold (default [`REARM_FRACTION`] of the rising one, 30 N).
    pub off: Newtons,
    /// Shortest time between strikes (default 0.2 s, faster than any running cadence).
    pub refractory: Seconds,
    /// The loading rate of a nominal step at the crossing, in newtons per second.
    pub nominal_loading_rate: f64,
    /// Smallest intensity (default 0.1).
    pub min_intensity: f32,
    /// Largest intensity (default 2).
    pub max_intensity: f32,
}

impl Default for DetectorConfig {
    /// Thresholds as documented on the fields; the nominal loading rate is that of the
    /// gait model's nominal step (70 kg, 1.8 steps/s) read at 500 Hz.
    fn default() -> Self {
        let mut config = Self {
            on: DEFAULT_THRESHOLD,
            off: Newtons(DEFAULT_THRESHOLD.0 * REARM_FRACTION),
            refractory: Seconds(0.2),
            nominal_loading_rate: 1.0,
            min_intensity: 0.1,
            max_intensity: 2.0,
        };
        config.nominal_loading_rate = config.loading_rate_of(
            &super::gait::nominal_step(70.0, 1.8, 500.0),
            SampleRate(500),
        );
        config
    }
}

impl DetectorConfig {
    /// Sets the rising threshold to `on` and the re-arming one to [`REARM_FRACTION`] of
    /// it. The caller then sets [`nominal_loading_rate`](Self::nominal_loading_rate) for
    /// the new crossing ([`loading_rate_of`](Self::loading_rate_of)).
    pub fn set_threshold(&mut self, on: Newtons) {
        self.on = on;
        self.off = Newtons(on.0 * REARM_FRACTION);
    }

    /// The loading rate the detector measures at the `on` crossing of `step` (total force
    /// sampled at `rate`): what to use as [`nominal_loading_rate`](Self::nominal_loading_rate)
    /// for a nominal step. 1 N/s if the step never crosses.
    #[must_use]
    pub fn loading_rate_of(&self, step: &[f64], rate: SampleRate) -> f64 {
        step.windows(2)
            .find(|w| w[1] >= self.on.0 && w[0] < self.on.0)
            .map_or(1.0, |w| (w[1] - w[0]) * rate.hz())
    }
}

/// A detected heel strike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Strike {
    /// Strength relative to a nominal step.
    pub intensity: f32,
}

/// When a reading was taken, as far as the detector can know (see the module doc, *Time*).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReadingTime {
    /// The sensor's own time of the reading.
    Sensor(Seconds),
    /// When the reading reached the engine (its frame over the audio rate).
    Arrival(Seconds),
}

impl ReadingTime {
    fn seconds(self) -> f64 {
        match self {
            ReadingTime::Sensor(t) | ReadingTime::Arrival(t) => t.0,
        }
    }
}

/// The detector of one channel. Never allocates.
#[derive(Debug, Clone, PartialEq)]
pub struct StepDetector {
    on: f32,
    off: f32,
    refractory: f64,
    sensor_period: f64,
    nominal: f64,
    min_intensity: f32,
    max_intensity: f32,
    armed: bool,
    last_strike: Option<f64>,
    previous: Option<(f64, f32)>,
}

impl StepDetector {
    /// A detector for readings that come at about `sensor_rate` (the nominal period an
    /// arrival-timed stream is assumed to have).
    #[must_use]
    pub fn new(config: &DetectorConfig, sensor_rate: Hz) -> Self {
        Self {
            on: config.on.0 as f32,
            off: config.off.0.min(config.on.0) as f32,
            refractory: config.refractory.0.max(0.0),
            sensor_period: 1.0 / sensor_rate.0.max(1e-3),
            nominal: config.nominal_loading_rate.max(f64::MIN_POSITIVE),
            min_intensity: config.min_intensity,
            max_intensity: config.max_intensity.max(config.min_intensity),
            armed: true,
            last_strike: None,
            previous: None,
        }
    }

    /// A new total-force reading taken at `time`; a strike if it is one.
    pub fn update(&mut self, total: f32, time: ReadingTime) -> Option<Strike> {
        let t = time.seconds();
        if !(total.is_finite() && t.is_finite()) {
            return None;
        }
        if self.previous.is_some_and(|(t0, _)| t < t0) {
            self.reset();
        }
        let previous = self.previous.replace((t, total));
        if total < self.off {
            self.armed = true;
            return None;
        }
        if !self.armed || total < self.on {
            return None;
        }
        if let Some(last) = self.last_strike
            && t - last < self.refractory
        {
            return None;
        }
        self.armed = false;
        self.last_strike = Some(t);
        let dt = previous.map(|(t0, _)| match time {
            ReadingTime::Sensor(_) => t - t0,
            ReadingTime::Arrival(_) if t - t0 > 1.5 * self.sensor_period => t - t0,
            ReadingTime::Arrival(_) => self.sensor_period,
        });
        let intensity = match (previous, dt) {
            (Some((_, v0)), Some(dt)) if dt > 0.0 => {
                let slope = f64::from(total - v0) / dt;
                (slope / self.nominal) as f32
            }
            _ => 1.0,
        };
        Some(Strike {
            intensity: intensity.clamp(self.min_intensity, self.max_intensity),
        })
    }

    /// Forget the past (after a long silence, or a material change).
    pub fn reset(&mut self) {
        self.armed = true;
        self.last_strike = None;
        self.previous = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: f64 = 0.001;

    fn detector() -> StepDetector {
        StepDetector::new(&DetectorConfig::default(), Hz(1.0 / PERIOD))
    }

    fn sensor(t: f64) -> ReadingTime {
        ReadingTime::Sensor(Seconds(t))
    }

    #[test]
    fn one_strike_per_stance_despite_the_double_hump_and_noise() {
        let mut d = detector();
        // A stance: rise, hump, valley above `off`, hump, fall; with noise around `on`.
        let stance = [
            0.0, 20.0, 59.0, 61.0, 58.0, 62.0, 400.0, 800.0, 500.0, 700.0, 100.0, 35.0, 0.0,
        ];
        let mut strikes = Vec::new();
        for (k, f) in stance.iter().chain(stance.iter()).enumerate() {
            if let Some(s) = d.update(*f, sensor(0.1 * k as f64)) {
                strikes.push((k, s));
            }
        }
        assert_eq!(strikes.iter().map(|s| s.0).collect::<Vec<_>>(), vec![3, 16]);
    }

    #[test]
    fn the_nominal_step_has_intensity_one() {
        let config = DetectorConfig::default();
        assert!(
            config.nominal_loading_rate > 1000.0,
            "{}",
            config.nominal_loading_rate
        );
        let step = super::super::gait::nominal_step(70.0, 1.8, 500.0);
        let mut d = StepDetector::new(&config, Hz(500.0));
        let strikes: Vec<_> = step
            .iter()
            .enumerate()
            .filter_map(|(k, f)| d.update(*f as f32, sensor(k as f64 / 500.0)))
            .collect();
        assert_eq!(strikes.len(), 1);
        assert!(
            (strikes[0].intensity - 1.0).abs() < 1e-3,
            "{:?}",
            strikes[0]
        );
    }

    #[test]
    fn refractory_period_and_intensity() {
        let mut d = StepDetector::new(
            &DetectorConfig {
                nominal_loading_rate: 10_000.0,
                ..DetectorConfig::default()
            },
            Hz(100.0),
        );
        // 0 -> 100 N in 10 ms = 10 kN/s: a nominal step.
        d.update(0.0, sensor(0.0));
        let s = d.update(100.0, sensor(0.010)).unwrap();
        assert!((s.intensity - 1.0).abs() < 1e-6);
        d.update(0.0, sensor(0.020));
        assert!(
            d.update(100.0, sensor(0.030)).is_none(),
            "inside the refractory period"
        );
        d.update(0.0, sensor(0.400));
        let s = d.update(1000.0, sensor(0.410)).unwrap();
        assert_eq!(s.intensity, 2.0, "clamped");
        assert!(d.update(f32::NAN, sensor(2.0)).is_none());
        assert!(d.update(100.0, sensor(f64::NAN)).is_none());
    }

    /// The slope of a stamped stream is its own: two readings that arrive together are
    /// still their sensor period apart, and one that arrives late is no softer.
    #[test]
    fn sensor_times_make_the_intensity_independent_of_arrival() {
        let config = DetectorConfig {
            nominal_loading_rate: 10_000.0,
            ..DetectorConfig::default()
        };
        let mut stamped = StepDetector::new(&config, Hz(100.0));
        stamped.update(0.0, sensor(1.0));
        let s = stamped.update(100.0, sensor(1.01)).unwrap();
        assert!((s.intensity - 1.0).abs() < 1e-6, "{s:?}");
        // The same stream by arrival, on a grid that puts both readings in one block,
        // then one that puts them three blocks apart.
        let arrival = |t: f64| ReadingTime::Arrival(Seconds(t));
        for (t0, t1) in [(1.0, 1.0), (1.0, 1.012)] {
            let mut d = StepDetector::new(&config, Hz(100.0));
            d.update(0.0, arrival(t0));
            let s = d.update(100.0, arrival(t1)).unwrap();
            assert!((s.intensity - 1.0).abs() < 1e-6, "{t0} {t1}: {s:?}");
        }
        // A real pause in an arrival-timed stream is taken as it is.
        let mut d = StepDetector::new(&config, Hz(100.0));
        d.update(0.0, arrival(1.0));
        let s = d.update(100.0, arrival(1.04)).unwrap();
        assert!((s.intensity - 0.25).abs() < 1e-6, "{s:?}");
    }

    #[test]
    fn a_sensor_clock_that_restarts_forgets_the_past() {
        let mut d = detector();
        d.update(0.0, sensor(5.0));
        assert!(d.update(100.0, sensor(5.001)).is_some());
        d.update(0.0, sensor(5.002));
        // The clock restarts at 0: not a step back into the refractory period.
        d.update(0.0, sensor(0.0));
        assert!(d.update(100.0, sensor(0.001)).is_some());
    }
}
