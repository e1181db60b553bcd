//! Insole force to servo positions: the pressure points of the prosthetic-skin interface.
//!
//! Each servo presses one point of the residual limb as hard as the part of the foot it
//! stands for (heel, midfoot, toe) presses the ground. Positions are RC-servo pulse widths
//! in microseconds ([`PulseWidth`]), the unit the firmware writes to its timer, so that the
//! mapping needs no knowledge of the servo's gearing.
//!
//! # One update, in order
//!
//! [`Servo::update`] takes the force on the servo's sensors and the real time `dt` since
//! the previous update:
//!
//! 1. **Force.** `F = Σ wᵢ fᵢ` over the servo's sensors (weights from the configuration).
//!    A non-finite `F` (a NaN or infinite reading) is ignored: the previous desired
//!    position is kept and the update counted in [`ServoStats::non_finite`].
//! 2. **Desired position.** Below the force threshold `F₀` the servo rests; above it the
//!    position moves linearly from rest at `F₀` to full pressure at `F₁`, and stays there
//!    above `F₁`:
//!
//!    ```text
//!    x = clamp((F − F₀) / (F₁ − F₀), 0, 1),     desired = rest + x (full − rest)
//!    ```
//!
//!    measured from `F₀` rather than 0 so that the position does not jump at the
//!    threshold. `full < rest` reverses the direction (a servo mounted the other way
//!    round). The result is clamped to the servo's range `[min, max]`.
//! 3. **Dead band (on the target).** The target the servo moves to changes only when the
//!    desired position differs from it by at least `dead_band`, or when the desired
//!    position is rest (returning to rest is never held back: no pressure is left on the
//!    limb when the foot is lifted). Small force wobble therefore never reaches the servo
//!    and it does not hunt, while a held force is still reached exactly.
//! 4. **Rate limit.** The position moves toward the target by at most `rate × dt`, with
//!    `dt` the real elapsed time, so a late update does not make the servo jump further
//!    than it could have moved. A `dt` that is negative or not finite counts as 0 (no
//!    motion) and is counted in [`ServoStats::bad_dt`]; a huge `dt` just lets the servo
//!    reach the target.
//!
//! What this guarantees, for any sequence of inputs (see the property tests): the
//! position stays in `[min, max]`; it never moves by more than `rate × dt` in one update;
//! every change of target is at least `dead_band`, or lands on rest; and a force held
//! long enough is reached exactly.
//!
//! # Lost input
//!
//! [`ServoBank`] holds the servos of one interface and the latest insole reading. When
//! no reading has come for `insole_timeout` (a cable pulled, the firmware reset), every
//! servo's desired position becomes rest and it returns there at its rate limit: there
//! must be no pressure on the limb without a live signal. The vibration is faded out
//! separately by the engine's watchdog (`safety`).

use crate::units::{Newtons, Seconds};

/// An RC-servo pulse width in microseconds: the servo command. Typical servos take 500
/// to 2500 µs, 1500 µs being the middle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct PulseWidth(pub u16);

impl PulseWidth {
    fn us(self) -> f64 {
        f64::from(self.0)
    }
}

impl std::fmt::Display for PulseWidth {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} µs", self.0)
    }
}

/// Where the servo's travel is and what force moves it there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoCalibration {
    /// The position with no pressure on the limb.
    pub rest: PulseWidth,
    /// The position at full pressure; below `rest` for a reversed servo.
    pub full: PulseWidth,
    /// The force below which the servo rests (`F₀`, the force dead band).
    pub threshold: Newtons,
    /// The force at which it reaches `full` (`F₁`).
    pub full_force: Newtons,
}

/// One servo's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoConfig {
    /// The servo's number in the servo frame (its index in the frame's targets).
    pub id: u8,
    /// `(sensor index, weight)`: the force is `Σ weight × newtons[sensor index]`.
    pub inputs: Vec<(usize, f64)>,
    /// The lowest command ever sent.
    pub min: PulseWidth,
    /// The highest command ever sent.
    pub max: PulseWidth,
    /// Target changes smaller than this are not made (see the module doc), in µs.
    pub dead_band: f64,
    /// The fastest the command moves, in µs per second.
    pub rate: f64,
    /// Rest, full pressure and the forces between.
    pub calibration: ServoCalibration,
}

/// What is wrong with a servo's settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ServoError {
    /// A setting out of its range; `key` names it as in the configuration file.
    #[error("servo {id}: {key}: {reason}")]
    Invalid {
        /// The servo.
        id: u8,
        /// The setting.
        key: &'static str,
        /// What is wrong.
        reason: String,
    },
}

impl ServoConfig {
    /// Checks every setting; `sensors` is the number of insole sensors.
    ///
    /// # Errors
    /// [`ServoError::Invalid`] naming the first setting at fault.
    pub fn validate(&self, sensors: usize) -> Result<(), ServoError> {
        let bad = |key, reason: String| {
            Err(ServoError::Invalid {
                id: self.id,
                key,
                reason,
            })
        };
        if self.inputs.is_empty() {
            return bad("sensors", "no sensors drive this servo".into());
        }
        for &(i, w) in &self.inputs {
            if i >= sensors {
                return bad("sensors", format!("sensor {i} of {sensors}"));
            }
            if !w.is_finite() {
                return bad("weights", format!("weight {w} is not finite"));
            }
        }
        if self.min >= self.max {
            return bad(
                "range_us",
                format!("min {} is not below max {}", self.min.0, self.max.0),
            );
        }
        let c = &self.calibration;
        for (key, p) in [("rest_us", c.rest), ("full_us", c.full)] {
            if p < self.min || p > self.max {
                return bad(
                    key,
                    format!(
                        "{} is outside the range {} to {}",
                        p.0, self.min.0, self.max.0
                    ),
                );
            }
        }
        if c.rest == c.full {
            return bad(
                "full_us",
                "equal to rest_us: the servo would never move".into(),
            );
        }
        if !(c.threshold.0.is_finite() && c.threshold.0 >= 0.0) {
            return bad(
                "threshold_n",
                format!("{} N: need a finite force of 0 or more", c.threshold.0),
            );
        }
        if !(c.full_force.0.is_finite() && c.full_force.0 > c.threshold.0) {
            return bad(
                "full_force_n",
                format!(
                    "{} N: need a finite force above threshold_n ({} N)",
                    c.full_force.0, c.threshold.0
                ),
            );
        }
        if !(self.dead_band.is_finite() && self.dead_band >= 0.0) {
            return bad(
                "dead_band_us",
                format!("{}: need a finite width of 0 or more", self.dead_band),
            );
        }
        if !(self.rate.is_finite() && self.rate > 0.0) {
            return bad(
                "rate_us_per_s",
                format!("{}: need a positive finite rate", self.rate),
            );
        }
        Ok(())
    }
}

/// What a servo has met that was not ordinary input.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServoStats {
    /// Updates whose force was not finite (the previous desired position was kept).
    pub non_finite: u64,
    /// Updates whose `dt` was negative or not finite (taken as 0).
    pub bad_dt: u64,
    /// Target changes made (each at least the dead band, or to rest).
    pub target_changes: u64,
}

/// One servo's state: its settings, target and position.
#[derive(Debug, Clone, PartialEq)]
pub struct Servo {
    config: ServoConfig,
    /// The last finite desired position.
    desired: f64,
    target: f64,
    position: f64,
    stats: ServoStats,
}

impl Servo {
    /// A servo at rest.
    ///
    /// # Errors
    /// What [`ServoConfig::validate`] finds; `sensors` is the insole's sensor count.
    pub fn new(config: ServoConfig, sensors: usize) -> Result<Self, ServoError> {
        config.validate(sensors)?;
        let rest = config.calibration.rest.us();
        Ok(Self {
            config,
            desired: rest,
            target: rest,
            position: rest,
            stats: ServoStats::default(),
        })
    }

    /// The settings.
    #[must_use]
    pub fn config(&self) -> &ServoConfig {
        &self.config
    }

    /// The force on this servo's sensors; sensors missing from `newtons` count as 0 N.
    #[must_use]
    pub fn force(&self, newtons: &[f32]) -> f64 {
        self.config
            .inputs
            .iter()
            .map(|&(i, w)| w * newtons.get(i).map_or(0.0, |&f| f64::from(f)))
            .sum()
    }

    /// Where the servo would go for force `f` (step 2 of the module doc); `None` for a
    /// non-finite force.
    #[must_use]
    pub fn desired_for(&self, f: Newtons) -> Option<f64> {
        if !f.0.is_finite() {
            return None;
        }
        let c = &self.config.calibration;
        let x = ((f.0 - c.threshold.0) / (c.full_force.0 - c.threshold.0)).clamp(0.0, 1.0);
        let p = c.rest.us() + x * (c.full.us() - c.rest.us());
        Some(p.clamp(self.config.min.us(), self.config.max.us()))
    }

    /// One update: force `f` (or `None`: no live input, go to rest) after `dt` of real
    /// time. Returns the new position in µs (not rounded).
    pub fn update(&mut self, f: Option<Newtons>, dt: Seconds) -> f64 {
        let rest = self.config.calibration.rest.us();
        match f {
            None => self.desired = rest,
            Some(f) => match self.desired_for(f) {
                Some(d) => self.desired = d,
                None => self.stats.non_finite += 1,
            },
        }
        // An exact comparison: rest is an exact integer, and so is desired there.
        let to_rest = self.desired == rest;
        if self.desired != self.target
            && (to_rest || (self.desired - self.target).abs() >= self.config.dead_band)
        {
            self.target = self.desired;
            self.stats.target_changes += 1;
        }
        let dt = if dt.0.is_finite() && dt.0 >= 0.0 {
            dt.0
        } else {
            self.stats.bad_dt += 1;
            0.0
        };
        let error = self.target - self.position;
        // rate × dt may overflow to infinity for an absurd dt; min() then takes the error.
        let step = error.abs().min(self.config.rate * dt);
        if step >= error.abs() {
            // Land exactly, so a held force is reached to the bit.
            self.position = self.target;
        } else {
            self.position += step.copysign(error);
        }
        self.position
    }

    /// The current position in µs.
    #[must_use]
    pub fn position(&self) -> f64 {
        self.position
    }

    /// The current target in µs.
    #[must_use]
    pub fn target(&self) -> f64 {
        self.target
    }

    /// The command to send: the position rounded to whole microseconds, within the range.
    #[must_use]
    pub fn command(&self) -> PulseWidth {
        let p = self
            .position
            .round()
            .clamp(self.config.min.us(), self.config.max.us());
        PulseWidth(p as u16)
    }

    /// Counts so far.
    #[must_use]
    pub fn stats(&self) -> ServoStats {
        self.stats
    }
}

/// The servos of one interface, the latest insole reading and the input timeout.
#[derive(Debug, Clone)]
pub struct ServoBank {
    servos: Vec<Servo>,
    newtons: Vec<f32>,
    /// Time since the last reading; `None` before the first.
    since_reading: Option<f64>,
    timeout: Seconds,
    timeouts: u64,
    live: bool,
}

impl ServoBank {
    /// Servos at rest, waiting for a first reading of `sensors` forces. With no reading
    /// for `insole_timeout` the servos go to rest.
    ///
    /// # Errors
    /// The first servo's [`ServoError`]; a duplicate id or a bad timeout is reported as
    /// [`ServoError::Invalid`] too.
    pub fn new(
        servos: Vec<ServoConfig>,
        sensors: usize,
        insole_timeout: Seconds,
    ) -> Result<Self, ServoError> {
        let mut built: Vec<Servo> = Vec::with_capacity(servos.len());
        for config in servos {
            if built.iter().any(|s| s.config.id == config.id) {
                return Err(ServoError::Invalid {
                    id: config.id,
                    key: "id",
                    reason: "a second servo with this id".into(),
                });
            }
            built.push(Servo::new(config, sensors)?);
        }
        if !(insole_timeout.0.is_finite() && insole_timeout.0 > 0.0) {
            return Err(ServoError::Invalid {
                id: built.first().map_or(0, |s| s.config.id),
                key: "insole_timeout_s",
                reason: format!("{} s: need a positive finite time", insole_timeout.0),
            });
        }
        Ok(Self {
            servos: built,
            newtons: vec![0.0; sensors],
            since_reading: None,
            timeout: insole_timeout,
            timeouts: 0,
            live: false,
        })
    }

    /// Takes a new insole reading (newtons per sensor, in sensor order). Copies it; no
    /// allocation.
    pub fn reading(&mut self, newtons: &[f32]) {
        for (n, &v) in self.newtons.iter_mut().zip(newtons) {
            *n = v;
        }
        self.since_reading = Some(0.0);
    }

    /// Advances every servo by `dt`; returns whether the insole input is live (a reading
    /// within the timeout).
    pub fn update(&mut self, dt: Seconds) -> bool {
        let step = if dt.0.is_finite() && dt.0 > 0.0 {
            dt.0
        } else {
            0.0
        };
        let live = match &mut self.since_reading {
            Some(t) => {
                let fresh = *t <= self.timeout.0;
                *t += step;
                fresh
            }
            None => false,
        };
        if self.live && !live {
            self.timeouts += 1;
        }
        self.live = live;
        for s in &mut self.servos {
            let f = live.then(|| Newtons(s.force(&self.newtons)));
            s.update(f, dt);
        }
        live
    }

    /// The servos, in configuration order.
    #[must_use]
    pub fn servos(&self) -> &[Servo] {
        &self.servos
    }

    /// Writes each servo's command into `out[id]` (ids beyond `out` are skipped) and
    /// returns the frame length: the highest id plus one.
    pub fn commands(&self, out: &mut [u16]) -> usize {
        let mut len = 0;
        for s in &self.servos {
            let id = usize::from(s.config.id);
            if let Some(o) = out.get_mut(id) {
                *o = s.command().0;
                len = len.max(id + 1);
            }
        }
        len
    }

    /// Times the input was lost (live, then no reading within the timeout).
    #[must_use]
    pub fn timeouts(&self) -> u64 {
        self.timeouts
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn config(dead_band: f64, rate: f64, reversed: bool) -> ServoConfig {
        let (rest, full) = if reversed { (1900, 1100) } else { (1100, 1900) };
        ServoConfig {
            id: 0,
            inputs: vec![(0, 1.0), (1, 0.5)],
            min: PulseWidth(1000),
            max: PulseWidth(2000),
            dead_band,
            rate,
            calibration: ServoCalibration {
                rest: PulseWidth(rest),
                full: PulseWidth(full),
                threshold: Newtons(20.0),
                full_force: Newtons(420.0),
            },
        }
    }

    fn servo(dead_band: f64, rate: f64) -> Servo {
        Servo::new(config(dead_band, rate, false), 2).unwrap()
    }

    #[test]
    fn force_maps_linearly_from_threshold_to_full() {
        let s = servo(0.0, 1e9);
        let d = |f| s.desired_for(Newtons(f)).unwrap();
        assert_eq!(d(-50.0), 1100.0);
        assert_eq!(d(20.0), 1100.0);
        assert_eq!(d(220.0), 1500.0);
        assert_eq!(d(420.0), 1900.0);
        assert_eq!(d(1e30), 1900.0);
        assert_eq!(s.desired_for(Newtons(f64::NAN)), None);
        let r = Servo::new(config(0.0, 1e9, true), 2).unwrap();
        assert_eq!(r.desired_for(Newtons(220.0)), Some(1500.0));
        assert_eq!(r.desired_for(Newtons(420.0)), Some(1100.0));
        // The weighted sum of the servo's sensors.
        assert_eq!(s.force(&[100.0, 40.0]), 120.0);
        assert_eq!(s.force(&[100.0]), 100.0);
    }

    #[test]
    fn range_clamps_a_calibration_that_reaches_its_edge() {
        let mut c = config(0.0, 1e9, false);
        c.max = PulseWidth(1900);
        let mut s = Servo::new(c, 2).unwrap();
        assert_eq!(s.update(Some(Newtons(5000.0)), Seconds(1.0)), 1900.0);
        assert_eq!(s.command(), PulseWidth(1900));
    }

    #[test]
    fn rate_limit_uses_the_elapsed_time() {
        let mut s = servo(0.0, 1000.0);
        // 800 µs away at 1000 µs/s: 100 µs per 0.1 s, whatever the update pattern.
        assert_eq!(s.update(Some(Newtons(420.0)), Seconds(0.1)), 1200.0);
        assert_eq!(s.update(Some(Newtons(420.0)), Seconds(0.0)), 1200.0);
        assert_eq!(s.update(Some(Newtons(420.0)), Seconds(0.3)), 1500.0);
        // A late update may cover more ground, but never passes the target.
        assert_eq!(s.update(Some(Newtons(420.0)), Seconds(1e12)), 1900.0);
    }

    #[test]
    fn dead_band_holds_small_changes_but_not_rest() {
        let mut s = servo(10.0, 1e9);
        assert_eq!(s.update(Some(Newtons(220.0)), Seconds(0.01)), 1500.0);
        // 2 N is 4 µs: held back.
        assert_eq!(s.update(Some(Newtons(222.0)), Seconds(0.01)), 1500.0);
        assert_eq!(s.update(Some(Newtons(218.0)), Seconds(0.01)), 1500.0);
        // 5 N is 10 µs: made.
        assert_eq!(s.update(Some(Newtons(225.0)), Seconds(0.01)), 1510.0);
        // Lifting the foot returns to rest, even from within the dead band of rest.
        let mut s = servo(10.0, 1e9);
        s.update(Some(Newtons(21.0)), Seconds(0.01));
        assert_eq!(s.position(), 1100.0);
        s.update(Some(Newtons(24.0)), Seconds(0.01));
        assert_eq!(s.position(), 1100.0, "8 µs from rest is in the dead band");
        let mut s = servo(10.0, 1e9);
        s.update(Some(Newtons(30.0)), Seconds(0.01));
        assert_eq!(s.position(), 1120.0);
        s.update(Some(Newtons(0.0)), Seconds(0.01));
        assert_eq!(s.position(), 1100.0);
        assert_eq!(s.stats().target_changes, 2);
    }

    #[test]
    fn non_finite_force_and_bad_dt_hold_and_are_counted() {
        let mut s = servo(0.0, 1000.0);
        s.update(Some(Newtons(420.0)), Seconds(0.1));
        let target = s.target();
        for f in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            s.update(Some(Newtons(f)), Seconds(0.1));
            assert_eq!(s.target(), target);
        }
        assert_eq!(s.stats().non_finite, 3);
        assert_eq!(s.position(), 1500.0, "still moving toward the held target");
        for dt in [f64::NAN, -1.0, f64::INFINITY] {
            assert_eq!(s.update(Some(Newtons(420.0)), Seconds(dt)), 1500.0);
        }
        assert_eq!(s.stats().bad_dt, 3);
    }

    #[test]
    fn bad_settings_name_their_key() {
        let key = |c: ServoConfig| match c.validate(2) {
            Err(ServoError::Invalid { key, .. }) => key,
            Ok(()) => "ok",
        };
        let base = || config(5.0, 1000.0, false);
        assert_eq!(key(base()), "ok");
        let mut c = base();
        c.inputs = vec![(2, 1.0)];
        assert_eq!(key(c), "sensors");
        let mut c = base();
        c.inputs.clear();
        assert_eq!(key(c), "sensors");
        let mut c = base();
        c.inputs[0].1 = f64::NAN;
        assert_eq!(key(c), "weights");
        let mut c = base();
        c.min = PulseWidth(2000);
        assert_eq!(key(c), "range_us");
        let mut c = base();
        c.calibration.rest = PulseWidth(900);
        assert_eq!(key(c), "rest_us");
        let mut c = base();
        c.calibration.full = c.calibration.rest;
        assert_eq!(key(c), "full_us");
        let mut c = base();
        c.calibration.threshold = Newtons(-1.0);
        assert_eq!(key(c), "threshold_n");
        let mut c = base();
        c.calibration.full_force = Newtons(20.0);
        assert_eq!(key(c), "full_force_n");
        let mut c = base();
        c.dead_band = f64::INFINITY;
        assert_eq!(key(c), "dead_band_us");
        let mut c = base();
        c.rate = 0.0;
        assert_eq!(key(c), "rate_us_per_s");
        assert!(ServoBank::new(vec![base(), base()], 2, Seconds(0.2)).is_err());
        assert!(ServoBank::new(vec![base()], 2, Seconds(0.0)).is_err());
    }

    #[test]
    fn bank_returns_to_rest_at_the_rate_limit_when_input_stops() {
        let mut bank = ServoBank::new(vec![config(0.0, 2000.0, false)], 2, Seconds(0.2)).unwrap();
        assert!(!bank.update(Seconds(0.01)), "no reading yet");
        bank.reading(&[420.0, 0.0]);
        for _ in 0..100 {
            assert!(bank.update(Seconds(0.001)));
        }
        // 0.1 s at 2000 µs/s.
        assert!((bank.servos()[0].position() - 1300.0).abs() < 1e-9);
        // Keep the reading fresh until the servo is at full pressure.
        for _ in 0..50 {
            bank.reading(&[420.0, 0.0]);
            bank.update(Seconds(0.01));
        }
        assert_eq!(bank.servos()[0].position(), 1900.0);
        // No reading: live until the timeout, then back to rest, no faster than the rate.
        let mut t = 0.0f64;
        let mut last = 1900.0;
        while bank.update(Seconds(0.01)) {
            t += 0.01;
            last = bank.servos()[0].position();
        }
        assert!((t - 0.2).abs() < 0.011, "timed out after {t} s");
        assert_eq!(last, 1900.0);
        assert_eq!(bank.timeouts(), 1);
        // The update that found the input dead already took one step toward rest.
        assert!((bank.servos()[0].position() - 1880.0).abs() < 1e-9);
        let mut steps = 1;
        while bank.servos()[0].position() > 1100.0 {
            let before = bank.servos()[0].position();
            assert!(!bank.update(Seconds(0.01)));
            assert!(before - bank.servos()[0].position() <= 20.0 + 1e-9);
            steps += 1;
        }
        assert_eq!(steps, 40, "800 µs at 20 µs per update");
        let mut out = [0u16; 4];
        assert_eq!(bank.commands(&mut out), 1);
        assert_eq!(out[0], 1100);
    }

    /// A force as the insole might report it, bad values included.
    fn force() -> impl Strategy<Value = f64> {
        prop_oneof![
            6 => -100.0f64..1000.0,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => Just(f64::NEG_INFINITY),
            1 => any::<f64>(),
        ]
    }

    fn dt() -> impl Strategy<Value = f64> {
        prop_oneof![
            6 => 0.0f64..0.05,
            1 => Just(0.0),
            1 => Just(1e300),
            1 => Just(f64::NAN),
            1 => Just(-1.0),
            1 => 0.05f64..100.0,
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn any_input_stays_in_range_rate_limited_and_dead_banded(
            dead_band in 0.0f64..50.0,
            rate in 1.0f64..10_000.0,
            reversed in any::<bool>(),
            inputs in proptest::collection::vec((force(), dt()), 1..200),
            held in -100.0f64..1000.0,
        ) {
            let mut s = Servo::new(config(dead_band, rate, reversed), 2).unwrap();
            let rest = s.config().calibration.rest.us();
            let (lo, hi) = (s.config().min.us(), s.config().max.us());
            for (f, dt) in inputs {
                let (before, target_before) = (s.position(), s.target());
                let after = s.update(Some(Newtons(f)), Seconds(dt));
                prop_assert!((lo..=hi).contains(&after), "{after} outside the range");
                prop_assert!(s.command().us() >= lo && s.command().us() <= hi);
                let allowed = if dt.is_finite() && dt >= 0.0 { rate * dt } else { 0.0 };
                prop_assert!(
                    (after - before).abs() <= allowed * (1.0 + 1e-12) + 1e-9,
                    "moved {} with dt {dt}", after - before
                );
                let change = (s.target() - target_before).abs();
                let to_rest = s.target() == rest;
                prop_assert!(change == 0.0 || change >= dead_band || to_rest,
                    "target moved {change} < dead band {dead_band}");
            }
            // Held long enough, the force's position is reached exactly (or the target
            // already lies within the dead band of it).
            let want = s.desired_for(Newtons(held)).unwrap();
            let travel = 2.0 * (hi - lo) / rate;
            let steps = (travel / 0.01).ceil() as usize + 2;
            for _ in 0..steps {
                s.update(Some(Newtons(held)), Seconds(0.01));
            }
            prop_assert_eq!(s.position(), s.target());
            prop_assert!((s.target() - want).abs() < dead_band.max(1e-9) || s.target() == want);
        }
    }
}
