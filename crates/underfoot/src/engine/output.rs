//! The engine's output stage: the one place where a channel's synthesis becomes what a
//! device or a file receives. It composes the configured compensation with the safety
//! stages of [`crate::safety`] (whose module docs give the order and why): compensation,
//! watchdog, gain and fade, non-finite guard and limiter. Nothing runs after it but the
//! conversion to the device's format ([`crate::safety::quantize`]).
//!
//! It lives here, not in `safety`, because the compensation chain needs the standard
//! library while the safety stages are part of the `no_std` firmware core.

use crate::compensation::chain::CompensationChain;
use crate::safety::{Limiter, LimiterReport, Watchdog, WatchdogConfig};
use crate::units::{Decibels, SampleRate, Seconds};

/// The last stages before a device or a file for one channel: compensation, watchdog,
/// gain and fade, non-finite guard and limiter, in that order ([`crate::safety`] module docs). Never
/// allocates after construction.
#[derive(Debug)]
pub struct OutputStage {
    compensation: Option<CompensationChain>,
    watchdog: Watchdog,
    limiter: Limiter,
    /// The trim below the configured gain (an amplitude, 0 to 1), where it is heading,
    /// and the per-sample step of the one-pole smoothing that takes it there (a trim
    /// that jumped would click on the skin).
    trim: f32,
    trim_target: f32,
    trim_step: f32,
    /// The limiter's smallest gain since [`take_min_gain`](Self::take_min_gain).
    min_gain: f32,
}

/// Samples a steady stretch of [`OutputStage::process`] takes at a time (a stack buffer).
const STEADY_CHUNK: usize = 64;

/// Time constant of the trim's smoothing.
const TRIM_SMOOTHING: Seconds = Seconds(0.01);

impl OutputStage {
    /// A stage with `compensation` (or none), a watchdog that starts silent (no input
    /// yet), and a limiter at `ceiling`.
    #[must_use]
    pub fn new(
        compensation: Option<CompensationChain>,
        watchdog: &WatchdogConfig,
        ceiling: Decibels,
        release: Seconds,
        rate: SampleRate,
    ) -> Self {
        Self {
            compensation,
            watchdog: Watchdog::new(watchdog, rate),
            limiter: Limiter::new(ceiling, release, rate),
            trim: 1.0,
            trim_target: 1.0,
            trim_step: (1.0 - (-1.0 / (TRIM_SMOOTHING.0 * rate.hz())).exp()) as f32,
            min_gain: 1.0,
        }
    }

    /// Sets the trim, an amplitude below the configured gain: clamped to 0 to 1 (so
    /// it can only lower the output; the limiter's ceiling stays where it was set), a
    /// non-finite value refused (`false`). Reached smoothly over about 10 ms.
    pub fn set_trim(&mut self, amplitude: f32) -> bool {
        if !amplitude.is_finite() {
            return false;
        }
        self.trim_target = amplitude.clamp(0.0, 1.0);
        true
    }

    /// The trim last set, as an amplitude: where the smoothing is heading.
    #[must_use]
    pub fn trim_target(&self) -> f32 {
        self.trim_target
    }

    /// The limiter's smallest gain since the previous call (1.0: no reduction), and
    /// resets it.
    pub fn take_min_gain(&mut self) -> f32 {
        std::mem::replace(&mut self.min_gain, 1.0)
    }

    /// Whether the watchdog lets the channel play.
    #[must_use]
    pub fn is_live(&self) -> bool {
        !self.watchdog.is_silent()
    }

    /// Retunes the equalizer ([`EqualizerFilter::set_weights`]); `false` (nothing changed)
    /// without one, or for weights it refuses. Never allocates.
    ///
    /// [`EqualizerFilter::set_weights`]: crate::compensation::equalizer::EqualizerFilter::set_weights
    pub fn set_equalizer_weights(&mut self, gains_db: &[f64]) -> bool {
        self.compensation
            .as_mut()
            .and_then(CompensationChain::equalizer_mut)
            .is_some_and(|eq| eq.set_weights(gains_db))
    }

    /// Input arrived (a force reading).
    pub fn feed(&mut self) {
        self.watchdog.feed();
    }

    /// An explicit step arrived: stay alive for its window.
    pub fn feed_step(&mut self) {
        self.watchdog.feed_step();
    }

    /// Times the watchdog has faded the channel out.
    #[must_use]
    pub fn watchdog_trips(&self) -> u64 {
        self.watchdog.trips
    }

    /// The limiter's ceiling as an amplitude.
    #[must_use]
    pub fn ceiling(&self) -> f32 {
        self.limiter.ceiling()
    }

    /// Takes `buf` (the synthesis) to what the device may play, in place: every sample
    /// is finite and within the ceiling, and zero once the watchdog has faded out. `gain`
    /// holds the output gain times the fader for each sample (at least `buf.len()`).
    /// Returns how many blocks the compensation silenced for a non-finite value.
    #[inline]
    pub fn process(&mut self, buf: &mut [f32], gain: &[f32], report: &mut LimiterReport) -> u32 {
        let resets = match &mut self.compensation {
            Some(chain) => chain.process(buf),
            None => 0,
        };
        for (chunk, gain) in buf.chunks_mut(STEADY_CHUNK).zip(gain.chunks(STEADY_CHUNK)) {
            if !self.process_steady(chunk, gain, report) {
                self.process_each(chunk, gain, report);
            }
        }
        resets
    }

    /// The usual stretch: the channel live throughout, the trim settled. Then the
    /// watchdog's gain is exactly 1 and the trim constant, so each sample is the
    /// product [`process_each`](Self::process_each) would form, taken as one vector loop;
    /// and when none of them is near the ceiling (the limiter's gain is 1 and stays so)
    /// they are the output. Returns `false`, having done nothing, when the stretch is
    /// not steady.
    #[inline]
    fn process_steady(
        &mut self,
        buf: &mut [f32],
        gain: &[f32],
        report: &mut LimiterReport,
    ) -> bool {
        let n = buf.len().min(gain.len());
        if n > STEADY_CHUNK || self.trim != self.trim_target || !self.watchdog.pass(n as u64) {
            return false;
        }
        let trim = self.trim;
        let mut scaled = [0.0f32; STEADY_CHUNK];
        let scaled = &mut scaled[..n];
        for ((s, y), g) in scaled.iter_mut().zip(buf.iter()).zip(gain) {
            *s = *y * g * trim;
        }
        if self.limiter.passes(scaled) {
            buf[..n].copy_from_slice(scaled);
            self.min_gain = self.min_gain.min(1.0);
        } else {
            for (y, s) in buf.iter_mut().zip(scaled.iter()) {
                *y = self.limiter.tick(*s, report);
                self.min_gain = self.min_gain.min(self.limiter.gain());
            }
        }
        true
    }

    /// Sample by sample: the watchdog, the trim's smoothing and the limiter.
    fn process_each(&mut self, buf: &mut [f32], gain: &[f32], report: &mut LimiterReport) {
        for (y, g) in buf.iter_mut().zip(gain) {
            let w = self.watchdog.tick();
            self.trim += (self.trim_target - self.trim) * self.trim_step;
            // A silenced channel is exactly zero, whatever the compensation still holds
            // (even a non-finite value: there is nothing to count, nothing is played).
            let limited = self.limiter.tick(
                if w == 0.0 {
                    0.0
                } else {
                    *y * w * g * self.trim
                },
                report,
            );
            self.min_gain = self.min_gain.min(self.limiter.gain());
            *y = limited;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The steady path changes nothing: a stage run by `process` gives the same bits,
    /// limiter counts and smallest gains as one run sample by sample, through a walk
    /// with overloads (and the limiter's release after them), a trim moved mid-way, a
    /// non-finite sample, and the sensor going quiet (the watchdog's fade) and coming
    /// back, in blocks of every length.
    #[test]
    fn the_steady_path_is_the_sample_by_sample_path() {
        use crate::signal::noise::SplitMix64;
        let rate = SampleRate(48_000);
        let new = || {
            OutputStage::new(
                None,
                &WatchdogConfig::default(),
                Decibels(-6.0),
                Seconds(0.05),
                rate,
            )
        };
        let (mut fast, mut slow) = (new(), new());
        let (mut fast_report, mut slow_report) =
            (LimiterReport::default(), LimiterReport::default());
        let mut rng = SplitMix64::new(3);
        let mut steady = 0;
        let mut sample = 0usize;
        for block in 0..3000 {
            let n = 1 + (rng.uniform() * 150.0) as usize;
            let gain: Vec<f32> = (0..n)
                .map(|i| 0.9 + 0.1 * ((sample + i) as f32 * 1e-4).sin())
                .collect();
            let mut x: Vec<f32> = (0..n)
                .map(|_| {
                    let loud = if rng.uniform() < 0.002 { 3.0 } else { 0.3 };
                    (loud * (rng.uniform() - 0.5)) as f32
                })
                .collect();
            if block == 1700 {
                x[n / 2] = f32::NAN;
            }
            // Fed for a while, quiet long enough to fade out, then fed again.
            if !(800..1200).contains(&block) {
                fast.feed();
                slow.feed();
            }
            if block == 2000 {
                assert!(fast.set_trim(0.5) && slow.set_trim(0.5));
            }
            let mut y_fast = x.clone();
            fast.process(&mut y_fast, &gain, &mut fast_report);
            let mut y_slow = x.clone();
            slow.process_each(&mut y_slow, &gain, &mut slow_report);
            for (i, (a, b)) in y_fast.iter().zip(&y_slow).enumerate() {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "block {block}, sample {i}: {a} vs {b}"
                );
            }
            assert_eq!(fast.take_min_gain(), slow.take_min_gain(), "block {block}");
            steady += usize::from(fast.trim == fast.trim_target && fast.is_live());
            sample += n;
        }
        assert_eq!(fast_report, slow_report);
        assert!(fast_report.limited > 10 && fast_report.non_finite == 1);
        assert_eq!(fast.watchdog_trips(), 1);
        assert!(steady > 1000, "the steady path ran ({steady} blocks)");
    }

    /// Whatever the compensation still rings with, a channel whose watchdog has faded
    /// out is exactly zero; the ceiling holds on what does come out.
    #[test]
    fn the_output_stage_silences_after_the_compensation() {
        use crate::compensation::chain::Compensation;
        use crate::signal::{Biquad, Sos};
        let rate = SampleRate(48_000);
        // A limb filter that rings for seconds.
        let r = 0.99999;
        let w: f64 = 0.02;
        let limb = Sos::new(vec![Biquad {
            b: [1.0, 0.0, 0.0],
            a: [1.0, -2.0 * r * w.cos(), r * r],
        }]);
        let chain = CompensationChain::new(
            &Compensation {
                equalizer: None,
                limb: Some(limb),
            },
            rate,
            64,
        )
        .unwrap();
        let mut stage = OutputStage::new(
            Some(chain),
            &WatchdogConfig::default(),
            Decibels(-6.0),
            Seconds(0.05),
            rate,
        );
        let gain = [1.0f32; 64];
        let mut report = LimiterReport::default();
        let mut out = Vec::new();
        for block in 0..200 {
            if block < 10 {
                stage.feed();
            }
            let mut buf = [0.0f32; 64];
            if block == 0 {
                buf[0] = 1.0;
            }
            stage.process(&mut buf, &gain, &mut report);
            out.extend_from_slice(&buf);
        }
        let c = stage.ceiling();
        assert!(out.iter().all(|v| v.is_finite() && v.abs() <= c));
        assert!(report.limited > 0, "the ring is loud enough to limit");
        // The last feed was at sample 576: silent 100 ms (4800 samples) after it.
        assert!(out[576 + 4800..].iter().all(|v| *v == 0.0));
        assert!(out[..576].iter().any(|v| *v != 0.0));
        assert_eq!(stage.watchdog_trips(), 1);
    }
}
