//! Safety: what stands between the synthesis and a person's skin.
//!
//! # The output stage
//!
//! Every sample that reaches a device or a file leaves the engine through one
//! [`OutputStage`](crate::engine::OutputStage) per channel, and nothing runs after it but the conversion to the
//! device's format. In order:
//!
//! 1. **Compensation** (the device equalizer and the limb filter, `--eq` and `--user`):
//!    it is part of the signal, so it runs *before* every safety stage. A compensation
//!    filter rings on after its input stops (a badly damped limb filter for hundreds of
//!    milliseconds); were the watchdog before it, that ring would outlast the input.
//! 2. **Watchdog** ([`Watchdog`]): when a channel's input stops (a cable pulled, a sender
//!    crashed), its gain fades to exactly zero: the output is silent within
//!    `timeout + fade` (100 ms by default) of the last force reading, whatever the model
//!    and the compensation, and within that of the end of a step's
//!    [`STEP_WINDOW`] for a channel fed only steps.
//! 3. **Gain and fader** ([`Fader`]): the output gain, and the start-up and shut-down ramps
//!    of the whole output, so the actuator never sees a step (a pop).
//! 4. **Non-finite guard and hard limiter** ([`Limiter`]): a NaN or an infinity becomes
//!    silence (a voice or a compensation chain that produces one has already reset itself
//!    and silenced its block; the limiter checks again whatever happened upstream), and no
//!    sample above the ceiling gets through, however loud the filter: gain reduction is
//!    instantaneous (no look-ahead, so no latency), the gain recovers smoothly, and a final
//!    clamp guards against rounding. Every such event is counted and reported.
//!
//! # Quantisation
//!
//! A device or a file in an integer format gets [`quantize`]`(x, bits)`: `x · 2^(bits-1)`
//! truncated towards zero. Truncation never increases a magnitude, so a sample at the
//! ceiling `c` becomes at most `⌊c · 2^(bits-1)⌋`: rounding to the nearest code would
//! write one code *above* the ceiling for half of all ceilings (-6 dB is 16422.9 in 16
//! bits; rounded, 16423). The price is a bias of half a step towards zero, 96 dB below
//! full scale in 16 bits.

use crate::units::{Decibels, SampleRate, Seconds};

/// `x · 2^(bits-1)` truncated towards zero, within the `bits`-bit two's complement range
/// (`bits` from 2 to 32). NaN is 0; infinities and anything beyond full scale are the
/// extreme codes. Never rounds a magnitude up, so never past a ceiling (module docs).
#[must_use]
#[inline]
pub fn quantize(x: f32, bits: u32) -> i32 {
    let bits = bits.clamp(2, 32);
    let full = f64::from(1u32 << (bits - 1));
    if x.is_nan() {
        return 0;
    }
    // `as` saturates, and the clamp keeps the code inside `bits` bits.
    crate::math::trunc(f64::from(x) * full).clamp(-full, full - 1.0) as i32
}

/// The documented window of one strike sent as an [`Event::Step`](crate::engine::Event::Step) (an OSC
/// `/underfoot/step`, a VR engine's footstep): the channel plays for this long after the
/// step, then the watchdog fades it out, so a channel fed only steps is silent within
/// `STEP_WINDOW` plus the watchdog's fade (50 ms by default) of its last step.
///
/// 0.5 s is the longest e-fold decay any voice plays
/// ([`VoiceConfig::longest_decay`](crate::synthesis::VoiceConfig::longest_decay) and the
/// physical modes' [`LONGEST_DECAY`](crate::physical::resonator::LONGEST_DECAY)): a
/// strike of a material whose modes all decay faster than that has faded by at least its
/// slowest mode's `e^{-0.5 s / τ}` when the window closes; one at the limit is cut by the
/// fade at -8.7 dB, the price of a bound on how long a lone step can leave an actuator
/// on. A later step restarts the window.
pub const STEP_WINDOW: Seconds = Seconds(0.5);

/// The limiter's ceiling unless a user sets another: 6 dB under full scale. A material's
/// playback level keeps its nominal step under it (`material::level`).
pub const DEFAULT_CEILING: Decibels = Decibels(-6.0);

/// The loudest level that still counts as silence: half a step of a 24-bit converter,
/// which the widest common output rounds to zero. Filter and limiter tails decay through
/// tiny non-zero values (-208 dBFS was seen after a step died away); they are not sound,
/// and every report (status, record, summary) shows them as silence, as an exact zero.
pub const SILENT_LEVEL: f32 = 1.0 / (1u32 << 24) as f32;

/// A level in dBFS, `None` for silence ([`SILENT_LEVEL`] or below, or not finite).
#[must_use]
pub fn level_dbfs(amplitude: f32) -> Option<f64> {
    (amplitude > SILENT_LEVEL && amplitude.is_finite())
        .then(|| 20.0 * libm::log10(f64::from(amplitude)))
}

/// `ceiling` as the `f32` amplitude a limiter holds samples to: the largest `f32` not above
/// the exact value. Rounded to the nearest `f32`, a ceiling such as -4 dB (0.630957344...)
/// becomes 0.63095737, and a sample held to it is 2.8e-7 dB over what the user set; the
/// README promises none ever is.
#[must_use]
pub fn ceiling_amplitude(ceiling: Decibels) -> f32 {
    let exact = ceiling.to_amplitude();
    let nearest = exact as f32;
    if f64::from(nearest) > exact {
        nearest.next_down()
    } else {
        nearest
    }
}

/// A peak limiter with an absolute ceiling.
///
/// The gain `g` follows `min(1, c / |x|)` down at once and recovers towards 1 with time
/// constant `release`; the output is `clamp(g x, -c, c)`. Instant attack distorts the
/// first cycle of an overload instead of letting it through: on skin, a clipped peak is
/// the lesser harm.
#[derive(Debug, Clone, PartialEq)]
pub struct Limiter {
    ceiling: f32,
    gain: f32,
    release: f32,
}

/// What a limiter did to a block.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LimiterReport {
    /// Samples whose gain was reduced.
    pub limited: u32,
    /// Non-finite samples replaced by silence.
    pub non_finite: u32,
}

impl Limiter {
    /// A limiter with `ceiling` relative to full scale (e.g. -6 dB: 0.5).
    #[must_use]
    pub fn new(ceiling: Decibels, release: Seconds, rate: SampleRate) -> Self {
        Self {
            ceiling: ceiling_amplitude(ceiling),
            gain: 1.0,
            release: (1.0 - crate::math::exp(-1.0 / (release.0.max(1e-6) * rate.hz()))) as f32,
        }
    }

    /// The ceiling as an amplitude.
    #[must_use]
    pub fn ceiling(&self) -> f32 {
        self.ceiling
    }

    /// The gain applied to the last sample (1.0: no reduction).
    #[must_use]
    pub fn gain(&self) -> f32 {
        self.gain
    }

    /// Whether [`tick`](Self::tick) would pass every sample of `x` unchanged: the gain
    /// is 1 (so it stays 1) and every sample is finite and within the ceiling. Then
    /// nothing needs doing; else tick them one by one.
    #[inline]
    #[must_use]
    pub fn passes(&self, x: &[f32]) -> bool {
        // Without a branch per sample, so that both checks stay vector loops.
        self.gain == 1.0
            && x.iter().fold(true, |ok, v| ok & v.is_finite())
            && peak_abs(x) <= self.ceiling
    }

    /// Limits one sample.
    #[inline]
    pub fn tick(&mut self, x: f32, report: &mut LimiterReport) -> f32 {
        if !x.is_finite() {
            report.non_finite += 1;
            return 0.0;
        }
        // In `f32` the recovery stalls about 7e-5 short of 1 (70 ppm at a 50 ms release),
        // where the step it adds rounds to nothing: there the release is over.
        let recovered = self.gain + (1.0 - self.gain) * self.release;
        self.gain = if recovered == self.gain {
            1.0
        } else {
            recovered
        };
        let peak = x.abs() * self.gain;
        if peak > self.ceiling {
            self.gain = self.ceiling / x.abs();
            report.limited += 1;
        }
        (x * self.gain).clamp(-self.ceiling, self.ceiling)
    }
}

/// Watchdog settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WatchdogConfig {
    /// How long without input before fading (default 50 ms: sensors report every 1-10 ms).
    pub timeout: Seconds,
    /// How long the fade to silence takes (default 50 ms, so silence within 100 ms).
    pub fade: Seconds,
    /// How long an explicit step event keeps the channel alive, for sources that send
    /// steps but no force (default [`STEP_WINDOW`],
    /// the documented window of a strike: silence within `step_hold + fade` of a step).
    pub step_hold: Seconds,
    /// How long the gain takes to come back when input resumes (default 1 ms, so a
    /// step's onset is not lost).
    pub recover: Seconds,
}

impl Default for WatchdogConfig {
    fn default() -> Self {
        Self {
            timeout: Seconds(0.05),
            fade: Seconds(0.05),
            step_hold: STEP_WINDOW,
            recover: Seconds(0.001),
        }
    }
}

/// Partial results [`peak_abs`] keeps: as many as a 256-bit vector holds.
const PEAK_LANES: usize = 8;

/// The largest `|x|` of `x`, ignoring NaN (0 for none): the same value as
/// `x.iter().fold(0.0, |m, v| m.max(v.abs()))`, as `max` does not depend on the order
/// it is taken in, but kept in eight partial maxima so that the loop is a vector loop
/// rather than one comparison waiting on the last. Real-time safe.
#[must_use]
#[inline]
pub fn peak_abs(x: &[f32]) -> f32 {
    let mut peak = [0.0f32; PEAK_LANES];
    let chunks = x.chunks_exact(PEAK_LANES);
    for (p, v) in peak.iter_mut().zip(chunks.remainder()) {
        *p = p.max(v.abs());
    }
    for chunk in chunks {
        for (p, v) in peak.iter_mut().zip(chunk) {
            *p = p.max(v.abs());
        }
    }
    peak.iter().fold(0.0, |m, p| m.max(*p))
}

/// Fades a channel out when its input stops. Per sample, never allocates.
#[derive(Debug, Clone, PartialEq)]
pub struct Watchdog {
    timeout: u64,
    step_hold: u64,
    fall: f32,
    rise: f32,
    idle: u64,
    allowed: u64,
    gain: f32,
    /// Times the watchdog has faded the channel out.
    pub trips: u64,
}

impl Watchdog {
    /// A watchdog that starts silent (no input yet).
    #[must_use]
    pub fn new(config: &WatchdogConfig, rate: SampleRate) -> Self {
        let samples = |t: Seconds| rate.samples_in(t).max(1) as u64;
        Self {
            timeout: samples(config.timeout),
            step_hold: samples(config.step_hold),
            fall: 1.0 / samples(config.fade) as f32,
            rise: 1.0 / samples(config.recover) as f32,
            idle: 1,
            allowed: 0,
            gain: 0.0,
            trips: 0,
        }
    }

    /// Input arrived (a force reading).
    pub fn feed(&mut self) {
        self.extend(self.timeout);
    }

    /// An explicit step arrived: stay alive for the step's ring.
    pub fn feed_step(&mut self) {
        self.extend(self.step_hold);
    }

    /// Keep alive for at least `hold` from now, never shortening a longer hold.
    fn extend(&mut self, hold: u64) {
        let remaining = self.allowed.saturating_sub(self.idle);
        self.allowed = remaining.max(hold);
        self.idle = 0;
    }

    /// Whether the next `n` gains are all 1 (the channel is live and stays so for `n`
    /// samples); if they are, takes those `n` ticks at once.
    #[inline]
    pub fn pass(&mut self, n: u64) -> bool {
        let live = self.gain == 1.0 && self.idle.saturating_add(n) <= self.allowed;
        if live {
            self.idle += n;
        }
        live
    }

    /// The gain for the next sample.
    #[inline]
    pub fn tick(&mut self) -> f32 {
        self.idle = self.idle.saturating_add(1);
        if self.idle > self.allowed {
            if self.gain > 0.0 {
                self.gain = (self.gain - self.fall).max(0.0);
                if self.gain == 0.0 {
                    self.trips += 1;
                }
            }
        } else {
            self.gain = (self.gain + self.rise).min(1.0);
        }
        self.gain
    }

    /// Whether the channel is silenced.
    #[must_use]
    pub fn is_silent(&self) -> bool {
        self.gain == 0.0
    }
}

/// A linear ramp between silence and full gain, for start-up and shut-down.
#[derive(Debug, Clone, PartialEq)]
pub struct Fader {
    gain: f32,
    target: f32,
    step: f32,
}

impl Fader {
    /// A fader that starts silent and ramps to full over `time`.
    #[must_use]
    pub fn fade_in(time: Seconds, rate: SampleRate) -> Self {
        Self {
            gain: 0.0,
            target: 1.0,
            step: 1.0 / rate.samples_in(time).max(1) as f32,
        }
    }

    /// Ramp to silence.
    pub fn fade_out(&mut self) {
        self.target = 0.0;
    }

    /// The gain for the next sample.
    #[inline]
    pub fn tick(&mut self) -> f32 {
        if self.gain < self.target {
            self.gain = (self.gain + self.step).min(self.target);
        } else if self.gain > self.target {
            self.gain = (self.gain - self.step).max(self.target);
        }
        self.gain
    }

    /// Whether a fade-out has finished.
    #[must_use]
    pub fn is_silent(&self) -> bool {
        self.target == 0.0 && self.gain == 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;

    proptest::proptest! {
        /// The peak in partial maxima is the plain running maximum, to the bit, NaN
        /// and infinities included, at every length.
        #[test]
        fn peak_abs_is_the_running_maximum(
            x in proptest::collection::vec(
                proptest::prop_oneof![
                    8 => -10.0f32..10.0,
                    1 => proptest::prelude::Just(f32::NAN),
                    1 => proptest::prelude::Just(f32::NEG_INFINITY),
                ],
                0..70,
            ),
        ) {
            let plain = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            proptest::prop_assert_eq!(peak_abs(&x).to_bits(), plain.to_bits());
        }
    }

    proptest::proptest! {
        /// Any ceiling, any gain, any signal: no sample above the ceiling the user set,
        /// compared in `f64` with the exact `10^(dB/20)`.
        #[test]
        fn no_sample_exceeds_a_random_ceiling(
            db in -80.0f64..=0.0,
            gain_db in -20.0f64..=60.0,
            seed in proptest::prelude::any::<u64>(),
        ) {
            let ceiling = Decibels(db);
            let exact = ceiling.to_amplitude();
            let gain = Decibels(gain_db).to_amplitude() as f32;
            let mut lim = Limiter::new(ceiling, Seconds(0.01), SampleRate(48_000));
            let mut report = LimiterReport::default();
            let mut rng = SplitMix64::new(seed);
            for n in 0..2000 {
                // Steps: a loud click every 100 samples over a quieter noise.
                let x = if n % 100 == 0 { 1.0 } else { (rng.uniform() - 0.5) as f32 };
                let y = lim.tick(x * gain, &mut report);
                proptest::prop_assert!(f64::from(y.abs()) <= exact, "{} over {}", y, exact);
            }
        }
    }

    #[test]
    fn the_ceiling_is_never_exceeded_in_exact_arithmetic() {
        // -4 dB is 0.630957344..., whose nearest f32 (0.63095737) is above it.
        let rate = SampleRate(48_000);
        let mut rounded_up = 0;
        for k in 0..=4000 {
            let db = Decibels(-40.0 + f64::from(k) * 0.01);
            let ceilings = [db, Decibels(-4.0), Decibels(-5.0), Decibels(-0.0001)];
            for ceiling in ceilings {
                let exact = ceiling.to_amplitude();
                rounded_up += usize::from(f64::from(exact as f32) > exact);
                let mut lim = Limiter::new(ceiling, Seconds(0.05), rate);
                let mut report = LimiterReport::default();
                for x in [1e3f32, -1e3, 0.99, -0.99, exact as f32, -(exact as f32)] {
                    let y = lim.tick(x, &mut report);
                    assert!(
                        f64::from(y.abs()) <= exact,
                        "{} dB: {y} over {exact}",
                        ceiling.0
                    );
                }
            }
        }
        // The test exercises the rounding it guards against.
        assert!(rounded_up > 1000, "{rounded_up}");
    }

    #[test]
    fn limiter_never_exceeds_the_ceiling_and_blocks_non_finite() {
        let rate = SampleRate(48_000);
        let mut lim = Limiter::new(Decibels(-6.0), Seconds(0.05), rate);
        let c = lim.ceiling();
        let mut rng = SplitMix64::new(9);
        let mut report = LimiterReport::default();
        for n in 0..200_000 {
            // Wild input: huge spikes, tiny values, infinities and NaN.
            let x = match n % 1000 {
                0 => f32::INFINITY,
                1 => f32::NAN,
                2 => 1e30,
                _ => (rng.normal() * 10f64.powf(rng.symmetric() * 4.0)) as f32,
            };
            let y = lim.tick(x, &mut report);
            assert!(y.is_finite() && y.abs() <= c, "{x} -> {y}");
        }
        assert_eq!(report.non_finite, 400);
        assert!(report.limited > 0);
    }

    #[test]
    fn limiter_is_transparent_below_the_ceiling() {
        let rate = SampleRate(48_000);
        let mut lim = Limiter::new(Decibels(-6.0), Seconds(0.05), rate);
        let mut report = LimiterReport::default();
        for n in 0..1000 {
            let x = 0.4 * (n as f32 * 0.05).sin();
            assert_eq!(lim.tick(x, &mut report), x);
        }
        assert_eq!(report.limited, 0);
    }

    /// After an overload the gain comes back all the way, and the limiter is
    /// transparent again, to the bit. In `f32` the recovery alone would stall about
    /// 70 ppm short of 1, where the step it adds rounds to nothing, and every later
    /// sample would come out that much quieter.
    #[test]
    fn the_limiter_releases_completely_after_an_overload() {
        let rate = SampleRate(48_000);
        let mut lim = Limiter::new(Decibels(-6.0), Seconds(0.05), rate);
        let mut report = LimiterReport::default();
        lim.tick(2.0, &mut report);
        assert_eq!(report.limited, 1);
        assert!(lim.gain() < 0.3);
        // Ten time constants bring it within 5e-5 of 1; 24 take it the rest of the way.
        for _ in 0..rate.samples_in(Seconds(1.2)) {
            lim.tick(0.0, &mut report);
        }
        assert_eq!(lim.gain(), 1.0);
        assert!(lim.passes(&[0.4, -0.3, 0.0]));
        assert_eq!(lim.tick(0.4, &mut report), 0.4);
    }

    /// What `passes` answers is what ticking would do: pass every sample unchanged.
    #[test]
    fn passes_says_when_ticking_would_change_nothing() {
        let rate = SampleRate(48_000);
        let ceiling = Decibels(-6.0).to_amplitude() as f32;
        let lim = Limiter::new(Decibels(-6.0), Seconds(0.05), rate);
        let quiet: Vec<f32> = (0..67).map(|n| 0.45 * (n as f32 * 0.3).sin()).collect();
        assert!(lim.passes(&quiet));
        for (at, bad) in [
            (0, f32::NAN),
            (66, f32::INFINITY),
            (13, 1.01 * ceiling),
            (64, -ceiling * 1.001),
        ] {
            let mut x = quiet.clone();
            x[at] = bad;
            assert!(!lim.passes(&x), "{bad} at {at}");
            let mut ticked = lim.clone();
            let mut report = LimiterReport::default();
            let changed = x
                .iter()
                .any(|v| ticked.tick(*v, &mut report).to_bits() != v.to_bits());
            assert!(changed);
        }
        let mut exact = quiet.clone();
        exact[5] = ceiling;
        assert!(lim.passes(&exact), "at the ceiling is within it");
    }

    #[test]
    fn watchdog_fades_to_silence_within_100_ms_of_the_last_input() {
        let rate = SampleRate(48_000);
        let mut wd = Watchdog::new(&WatchdogConfig::default(), rate);
        for _ in 0..480 {
            wd.feed();
            wd.tick();
        }
        assert_eq!(wd.tick(), 1.0);
        let silent_after = (0..48_000).position(|_| wd.tick() == 0.0).unwrap();
        assert!(silent_after <= 4800, "{silent_after} samples");
        assert!(silent_after >= 2400, "not before the timeout");
        assert_eq!(wd.trips, 1);
        wd.feed();
        assert!(wd.tick() > 0.0);
    }

    #[test]
    fn quantisation_never_rounds_a_magnitude_up() {
        let mut rng = SplitMix64::new(3);
        for bits in [8, 16, 24, 32] {
            let full = f64::from(1u32 << (bits - 1));
            for _ in 0..20_000 {
                let x = (rng.symmetric() * 1.2) as f32;
                let q = f64::from(quantize(x, bits));
                assert!(q.abs() <= (f64::from(x) * full).abs(), "{bits}: {x} -> {q}");
                assert!((-full..full).contains(&q), "{bits}: {x} -> {q}");
                if x.abs() < 1.0 {
                    assert!((f64::from(x) * full - q).abs() < 1.0, "{bits}: {x} -> {q}");
                }
            }
        }
        // The -6 dB ceiling: 16422.9 codes, written 16422 (rounded, it was 16423).
        let c = Decibels(-6.0).to_amplitude() as f32;
        assert_eq!(quantize(c, 16), 16_422);
        assert_eq!(quantize(-c, 16), -16_422);
        assert_eq!(quantize(1.0, 16), 32_767);
        assert_eq!(quantize(-1.0, 24), -(1 << 23));
        assert_eq!(quantize(f32::NAN, 16), 0);
        assert_eq!(quantize(f32::INFINITY, 32), i32::MAX);
        assert_eq!(quantize(f32::NEG_INFINITY, 32), i32::MIN);
    }

    #[test]
    fn fader_ramps_in_and_out() {
        let rate = SampleRate(1000);
        let mut f = Fader::fade_in(Seconds(0.01), rate);
        let up: Vec<f32> = (0..12).map(|_| f.tick()).collect();
        assert!(up.windows(2).all(|w| w[1] >= w[0]) && up[9] == 1.0);
        f.fade_out();
        let down: Vec<f32> = (0..12).map(|_| f.tick()).collect();
        assert!(down.windows(2).all(|w| w[1] <= w[0]) && f.is_silent());
    }
}
