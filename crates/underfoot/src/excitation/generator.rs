//! The excitation at an audio rate ([`Tables`]), and the [`Generator`] that plays it.

use super::{ExcitationError, ExcitationModel};
use crate::numeric::normal_quantile;
use crate::signal::noise::SplitMix64;
use crate::units::SampleRate;

/// The most bins a profile may have (1.28 s of step clock at 5 ms).
pub const MAX_BINS: usize = 256;
/// Entries of the table of time scales `s` (the top 6 bits of a draw pick one).
pub const SCALES: usize = 64;
/// Entries of the table of micro-impact magnitudes `q` (8 bits of a draw pick one).
pub const QUANTILES: usize = 256;

/// `2^32`: a threshold against which a 32-bit uniform draw is compared.
const TWO_32: f64 = 4_294_967_296.0;

/// The most draws (so the most micro-impacts) in one sample: a train denser than 16 per
/// sample is a sound no longer made of impacts, and the work per sample stays bounded.
pub const MAX_DRAWS: u32 = 16;

/// An [`ExcitationModel`] prepared for one audio rate: fixed-size tables, so that a
/// channel can take another material's without allocating.
#[derive(Debug, Clone, PartialEq)]
pub struct Tables {
    bins: usize,
    inv_bin: f64,
    heel: f32,
    threshold: [f64; MAX_BINS],
    amplitude: [f32; MAX_BINS],
    step: [f64; SCALES],
    quantiles: [f32; QUANTILES],
    /// Mean energy of one impulse (heel included) of a nominal step: what a physical
    /// model divides an impulse's energy by to strike at its mean strength.
    mean_impulse_energy: f64,
}

impl Tables {
    /// `model` at `rate`.
    ///
    /// # Errors
    /// The model is invalid ([`ExcitationModel::validate`]) or the rate zero.
    pub fn new(model: &ExcitationModel, rate: SampleRate) -> Result<Self, ExcitationError> {
        model.validate()?;
        if rate.0 == 0 {
            return Err(ExcitationError::OutOfRange {
                name: "rate",
                value: 0.0,
                expected: "a positive sample rate",
            });
        }
        let fs = rate.hz();
        let bins = model.energy.len();
        let mut threshold = [0.0; MAX_BINS];
        let mut amplitude = [0.0f32; MAX_BINS];
        for b in 0..bins {
            let (r, e) = (model.rate_hz[b], model.energy[b]);
            threshold[b] = r * TWO_32;
            if r > 0.0 {
                amplitude[b] = (e / (r * model.bin_s)).sqrt() as f32;
            }
        }
        let step = std::array::from_fn(|k| {
            let z = normal_quantile((k as f64 + 0.5) / SCALES as f64);
            1.0 / (fs * (model.duration_spread * z).exp())
        });
        let kappa = model.amplitude_shape;
        let mut quantiles: [f64; QUANTILES] = std::array::from_fn(|k| {
            (-(1.0 - (k as f64 + 0.5) / QUANTILES as f64).ln()).powf(1.0 / kappa)
        });
        let rms = (quantiles.iter().map(|q| q * q).sum::<f64>() / QUANTILES as f64).sqrt();
        for q in &mut quantiles {
            *q /= rms;
        }
        let events = model.expected_events();
        Ok(Self {
            bins,
            inv_bin: 1.0 / model.bin_s,
            heel: model.heel.sqrt() as f32,
            threshold,
            amplitude,
            step,
            quantiles: quantiles.map(|q| q as f32),
            mean_impulse_energy: 1.0
                / (events + if model.heel > 0.0 { 1.0 } else { 0.0 }).max(1e-9),
        })
    }

    /// The heel impulse alone (see [`ExcitationModel::heel_only`]) at `rate`.
    #[must_use]
    pub fn heel_only(rate: SampleRate) -> Self {
        // A valid model at a positive rate cannot fail.
        Self::new(&ExcitationModel::heel_only(), SampleRate(rate.0.max(1)))
            .unwrap_or_else(|_| unreachable!("the heel-only model is valid"))
    }

    /// Bins of the profile.
    #[must_use]
    pub fn bins(&self) -> usize {
        self.bins
    }

    /// `1 / Δ`: bins per second of step clock.
    #[must_use]
    pub fn bins_per_second(&self) -> f64 {
        self.inv_bin
    }

    /// `√h`: the heel impulse at intensity 1.
    #[must_use]
    pub fn heel(&self) -> f32 {
        self.heel
    }

    /// Per bin, `λ_b 2^{32}`: the threshold a 32-bit draw is compared with, per second of
    /// step clock.
    #[must_use]
    pub fn thresholds(&self) -> &[f64] {
        &self.threshold[..self.bins]
    }

    /// Per bin, the RMS amplitude `a_b` of a micro-impact.
    #[must_use]
    pub fn amplitudes(&self) -> &[f32] {
        &self.amplitude[..self.bins]
    }

    /// Per time scale `s_k`, `1 / (f_s s_k)`: seconds of step clock per sample at speed 1.
    #[must_use]
    pub fn steps(&self) -> &[f64; SCALES] {
        &self.step
    }

    /// The unit-RMS magnitudes `q`.
    #[must_use]
    pub fn quantiles(&self) -> &[f32; QUANTILES] {
        &self.quantiles
    }

    /// The mean energy of one impulse of a nominal step, heel included.
    #[must_use]
    pub fn mean_impulse_energy(&self) -> f64 {
        self.mean_impulse_energy
    }
}

/// One channel's excitation, playing [`Tables`]: a step's heel impulse and train. Never
/// allocates, locks or panics.
#[derive(Debug, Clone, PartialEq)]
pub struct Generator {
    rng: SplitMix64,
    active: bool,
    heel_due: bool,
    /// The train runs at speed 1 whatever the caller says (a step without force).
    free: bool,
    /// The step clock, seconds.
    pos: f64,
    /// Seconds of step clock per sample at speed 1 (this step's time scale).
    step: f64,
    gain: f32,
    events: u64,
}

impl Generator {
    /// A silent generator whose random stream is seeded by `seed`.
    #[must_use]
    pub const fn new(seed: u64) -> Self {
        Self {
            rng: SplitMix64::new(seed),
            active: false,
            heel_due: false,
            free: false,
            pos: 0.0,
            step: 0.0,
            gain: 0.0,
            events: 0,
        }
    }

    /// A heel strike of `intensity` now: the heel impulse at the next sample, then the
    /// train, on a clock the force drives. Replaces a train still running.
    pub fn strike(&mut self, tables: &Tables, intensity: f32) {
        self.start(tables, intensity, false);
    }

    /// A step announced without force: as [`strike`](Self::strike), with the clock at
    /// speed 1.
    pub fn step(&mut self, tables: &Tables, intensity: f32) {
        self.start(tables, intensity, true);
    }

    fn start(&mut self, tables: &Tables, intensity: f32, free: bool) {
        if !(intensity.is_finite() && intensity > 0.0) {
            return;
        }
        let scale = (self.rng.next_u64() >> 58) as usize;
        self.step = tables.step[scale];
        self.pos = 0.0;
        self.gain = intensity;
        self.heel_due = true;
        self.active = true;
        self.free = free;
    }

    /// Silences the generator (a train in progress ends); its random stream carries on.
    pub fn stop(&mut self) {
        self.active = false;
        self.heel_due = false;
    }

    /// Whether a step is playing.
    #[must_use]
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// Micro-impacts played so far (heels not counted).
    #[must_use]
    pub fn events(&self) -> u64 {
        self.events
    }

    /// The next sample for a clock speed `speed` (`|dF/dt| / (W ḡ)`; negative or
    /// non-finite counts as 0).
    #[inline]
    pub fn next(&mut self, tables: &Tables, speed: f32) -> f32 {
        // Most samples of a walk play no step: kept this small, the test inlines into the
        // caller's loop and an idle generator costs a load and a branch there.
        if !self.active {
            return 0.0;
        }
        self.next_active(tables, speed)
    }

    /// [`next`](Self::next) while a step is playing: out of line, so that an idle
    /// generator stays a load and a branch in the caller's loop.
    fn next_active(&mut self, tables: &Tables, speed: f32) -> f32 {
        self.advance(tables, speed)
    }

    /// One sample of a playing step.
    #[inline(always)]
    fn advance(&mut self, tables: &Tables, speed: f32) -> f32 {
        let mut y = 0.0f32;
        if self.heel_due {
            self.heel_due = false;
            y = tables.heel * self.gain;
        }
        // Through `u32`, a shorter conversion than to `usize` with the same bin: a product
        // past `u32::MAX` saturates there, past the last bin as `usize::MAX` is.
        let bin = (self.pos * tables.inv_bin) as u32 as usize;
        if bin >= tables.bins {
            self.active = false;
            return y;
        }
        let v = if self.free {
            1.0
        } else if speed > 0.0 && speed < f32::INFINITY {
            f64::from(speed)
        } else {
            0.0
        };
        let dtau = v * self.step;
        if dtau > 0.0 {
            // `λ dτ` events are due in this sample: one draw per whole event due (each a
            // certain event) and one for the fraction left, at most `MAX_DRAWS`.
            let mut due = tables.threshold[bin] * dtau;
            let mut draws = 0;
            while due > 0.0 && draws < MAX_DRAWS {
                let r = self.rng.next_u64();
                let hit = ((r >> 32) as f64) < due;
                let q = tables.quantiles[((r >> 24) & 0xFF) as usize];
                let a = tables.amplitude[bin] * q * self.gain;
                // The sign is bit 23 of the draw, put into `a`'s sign bit (all that `-a`
                // flips). The impulse is computed whether or not it is due and masked to +0
                // when it is not: in a dense train a branch on either would be mispredicted
                // at every other draw (and the compiler turns a select back into one). `y`
                // is never -0, so adding +0 leaves its bits as they are.
                let sign = ((r >> 23) as u32 & 1) << 31;
                let keep = u32::from(hit).wrapping_neg();
                y += f32::from_bits((a.to_bits() ^ sign) & keep);
                self.events += u64::from(hit);
                due -= TWO_32;
                draws += 1;
            }
            self.pos += dtau;
        }
        y
    }

    /// `out[n]` = the next sample at `speed[n]`, over the shorter of the two.
    pub fn process(&mut self, tables: &Tables, speed: &[f32], out: &mut [f32]) {
        let n = out.len().min(speed.len());
        out[..n].copy_from_slice(&speed[..n]);
        self.process_in_place(tables, &mut out[..n]);
    }

    /// As [`process`](Self::process) in place: `buf[n]` holds the clock speed on entry and
    /// the sample on return.
    pub fn process_in_place(&mut self, tables: &Tables, buf: &mut [f32]) {
        // A local copy stays in registers through the loop; `self` behind a reference is
        // loaded and stored at every sample.
        let mut g = self.clone();
        let mut played = 0;
        for x in buf.iter_mut() {
            if !g.active {
                break;
            }
            *x = g.advance(tables, *x);
            played += 1;
        }
        *self = g;
        // Only a strike starts a step again: the rest of the block is silent.
        buf[played..].fill(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn train(heel: f64, rate: f64, bins: usize, spread: f64) -> ExcitationModel {
        let share = (1.0 - heel) / bins as f64;
        ExcitationModel {
            heel,
            bin_s: 0.005,
            rate_hz: vec![rate; bins],
            energy: vec![share; bins],
            duration_spread: spread,
            amplitude_shape: 2.0,
            perturbation_db: 0.0,
        }
    }

    #[test]
    fn a_heel_only_step_is_one_impulse() {
        let t = Tables::heel_only(SampleRate(48_000));
        let mut g = Generator::new(1);
        let mut out = vec![0.0; 100];
        g.strike(&t, 0.5);
        g.process(&t, &[1.0; 100], &mut out);
        assert_eq!(out[0], 0.5);
        assert!(out[1..].iter().all(|y| *y == 0.0));
        assert!(!g.is_active());
    }

    #[test]
    fn a_train_has_its_expected_count_energy_and_length() {
        // 40 bins of 5 ms (0.2 s of clock) at 200 events/s: 40 events, half the energy.
        let model = train(0.5, 200.0, 40, 0.0);
        let fs = SampleRate(8000);
        let t = Tables::new(&model, fs).unwrap();
        let mut g = Generator::new(7);
        let (mut events, mut energy, mut samples) = (0u64, 0.0, 0usize);
        let steps = 400;
        for _ in 0..steps {
            g.strike(&t, 1.0);
            let before = g.events();
            let mut n = 0;
            while g.is_active() {
                let y = g.next(&t, 1.0);
                energy += f64::from(y).powi(2);
                n += 1;
            }
            events += g.events() - before;
            samples = samples.max(n);
        }
        let mean_events = events as f64 / f64::from(steps);
        assert!((mean_events - 40.0).abs() < 1.0, "{mean_events}");
        let mean_energy = energy / f64::from(steps);
        assert!((mean_energy - 1.0).abs() < 0.05, "{mean_energy}");
        // 0.2 s of clock at speed 1, plus the sample that finds the train over.
        assert!((1600..=1602).contains(&samples), "{samples}");
    }

    #[test]
    fn the_clock_follows_the_speed() {
        let model = train(0.0, 500.0, 20, 0.0);
        let fs = SampleRate(8000);
        let t = Tables::new(&model, fs).unwrap();
        let length = |speed: f32| {
            let mut g = Generator::new(3);
            g.strike(&t, 1.0);
            let mut n = 0;
            while g.is_active() && n < 100_000 {
                g.next(&t, speed);
                n += 1;
            }
            n
        };
        // Half the speed, twice as long; standing still, it waits.
        let (one, half) = (length(1.0), length(0.5));
        assert!((800..=802).contains(&one), "{one}");
        assert!((1600..=1602).contains(&half), "{half}");
        assert_eq!(length(0.0), 100_000);
        assert_eq!(length(f32::NAN), 100_000);
        // A free-running step ignores the speed.
        let mut g = Generator::new(3);
        g.step(&t, 1.0);
        let mut n = 0;
        while g.is_active() {
            g.next(&t, 0.0);
            n += 1;
        }
        assert_eq!(n, one);
    }

    #[test]
    fn scales_are_lognormal_quantiles_and_magnitudes_unit_rms() {
        let model = train(0.5, 100.0, 4, 0.3);
        let fs = SampleRate(1000);
        let t = Tables::new(&model, fs).unwrap();
        let logs: Vec<f64> = t.steps().iter().map(|s| -(s * 1000.0).ln()).collect();
        let mean = logs.iter().sum::<f64>() / SCALES as f64;
        let sd = (logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / SCALES as f64).sqrt();
        assert!(mean.abs() < 1e-12);
        // The midpoint quantiles of 64 bins hold a little less than the whole spread.
        assert!((sd / 0.3 - 1.0).abs() < 0.03, "{sd}");
        let ms = t
            .quantiles()
            .iter()
            .map(|q| f64::from(*q).powi(2))
            .sum::<f64>()
            / 256.0;
        assert!((ms - 1.0).abs() < 1e-6);
    }

    #[test]
    fn the_same_seed_plays_the_same_steps() {
        let model = train(0.2, 300.0, 30, 0.2);
        let t = Tables::new(&model, SampleRate(4000)).unwrap();
        let run = |seed| {
            let mut g = Generator::new(seed);
            let mut out = vec![0.0f32; 2000];
            g.strike(&t, 1.0);
            g.process(&t, &[1.0; 2000], &mut out);
            out
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }
}
