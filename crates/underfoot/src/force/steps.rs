//! Heel-strike detection: a Schmitt trigger on the total force.
//!
//! A strike is the total force rising through `on`; the detector re-arms only when the
//! force has fallen below `off < on` (the foot has left the ground), and ignores strikes
//! closer than `refractory` to the previous one. The gap between the thresholds keeps
//! sensor noise and the double hump of a stance from counting as new steps.
//!
//! Each strike has an *intensity*: the loading rate at the crossing (the slope between the
//! two readings around it) over a nominal loading rate, clamped to
//! `[min_intensity, max_intensity]`. A foot that comes down hard excites the ground more;
//! the clamp keeps one glitchy reading from making a step ten times louder.

use crate::units::{Newtons, SampleRate, Seconds};

/// Detector settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorConfig {
    /// Rising threshold (default 60 N: well above a force-sensing resistor's ±10 N).
    pub on: Newtons,
    /// Re-arming threshold (default 30 N).
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
            on: Newtons(60.0),
            off: Newtons(30.0),
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

/// The detector of one channel. Never allocates.
#[derive(Debug, Clone, PartialEq)]
pub struct StepDetector {
    on: f32,
    off: f32,
    refractory: u64,
    rate: f64,
    nominal: f64,
    min_intensity: f32,
    max_intensity: f32,
    armed: bool,
    last_strike: Option<u64>,
    previous: Option<(u64, f32)>,
}

impl StepDetector {
    /// A detector for readings timed in frames of `rate`.
    #[must_use]
    pub fn new(config: &DetectorConfig, rate: SampleRate) -> Self {
        Self {
            on: config.on.0 as f32,
            off: config.off.0.min(config.on.0) as f32,
            refractory: rate.samples_in(config.refractory) as u64,
            rate: rate.hz(),
            nominal: config.nominal_loading_rate.max(f64::MIN_POSITIVE),
            min_intensity: config.min_intensity,
            max_intensity: config.max_intensity.max(config.min_intensity),
            armed: true,
            last_strike: None,
            previous: None,
        }
    }

    /// A new total-force reading at engine frame `frame`; a strike if it is one.
    pub fn update(&mut self, total: f32, frame: u64) -> Option<Strike> {
        if !total.is_finite() {
            return None;
        }
        let previous = self.previous.replace((frame, total));
        if total < self.off {
            self.armed = true;
            return None;
        }
        if !self.armed || total < self.on {
            return None;
        }
        if let Some(last) = self.last_strike
            && frame.saturating_sub(last) < self.refractory
        {
            return None;
        }
        self.armed = false;
        self.last_strike = Some(frame);
        let intensity = match previous {
            Some((f0, v0)) if frame > f0 => {
                let slope = f64::from(total - v0) * self.rate / (frame - f0) as f64;
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

    fn detector() -> StepDetector {
        StepDetector::new(&DetectorConfig::default(), SampleRate(1000))
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
            if let Some(s) = d.update(*f, 100 * k as u64) {
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
        let mut d = StepDetector::new(&config, SampleRate(500));
        let strikes: Vec<_> = step
            .iter()
            .enumerate()
            .filter_map(|(k, f)| d.update(*f as f32, k as u64))
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
            SampleRate(1000),
        );
        // 0 -> 100 N in 10 ms = 10 kN/s: a nominal step.
        d.update(0.0, 0);
        let s = d.update(100.0, 10).unwrap();
        assert!((s.intensity - 1.0).abs() < 1e-6);
        d.update(0.0, 20);
        assert!(
            d.update(100.0, 30).is_none(),
            "inside the refractory period"
        );
        d.update(0.0, 400);
        let s = d.update(1000.0, 410).unwrap();
        assert_eq!(s.intensity, 2.0, "clamped");
        assert!(d.update(f32::NAN, 2000).is_none());
    }
}
