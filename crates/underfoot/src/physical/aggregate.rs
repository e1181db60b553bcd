//! An aggregate (gravel, snow, sand) as a stream of random micro-impacts: the
//! "crumpling" model.
//!
//! # The model
//!
//! Stepping on an aggregate sets off many small collisions between its fragments. Each is
//! modelled as an [`Impact`]: a light hammer (a grain) striking, through a Hunt-Crossley
//! contact, a surface of damped modes. Three random choices make the stream:
//!
//! - **when**: the impacts form an inhomogeneous Poisson process whose rate `N(t)`
//!   (events per second) the caller gives sample by sample (for the vibrotactile tile,
//!   `N(t) = α v_F(t)`, proportional to the rate at which the foot loads the floor);
//! - **how hard**: each impact has a random kinetic energy;
//! - **which fragment**: each has a random size, which sets the pitch of its ringing.
//!
//! # When: time rescaling
//!
//! With the cumulative hazard `Λ(t) = \int_0^t N(u)\, du`, the event times `t_i` of an
//! inhomogeneous Poisson process of rate `N` are exactly those for which `Λ(t_i)` are the
//! event times of a homogeneous process of rate 1, whose gaps are independent `Exp(1)`
//! draws. So the process is run as: draw a target `E ~ Exp(1)`, accumulate the hazard
//! sample by sample,
//!
//! $$ \Lambda\[n+1\] = \Lambda\[n\] + N\[n\]\, T, \qquad T = 1/f_s , $$
//!
//! and emit an event when the hazard accrued since the last one reaches `E`, then draw
//! the next target and carry the excess over (`E - accrued` is kept as the hazard still
//! to go, and an event adds a fresh `Exp(1)` to it), so several events can fall in one
//! sample when `N T` is large. This is exact for any rate profile, up to the rate being
//! held over each sample and events being placed at the start of their sample: the count
//! over any interval is Poisson with mean `\int N dt`, counts over disjoint intervals are
//! independent, and a zero rate gives no event at all. Rates that are negative, NaN or
//! infinite are taken as zero.
//!
//! A sample holds at most as many events as there are voices (below): beyond that the
//! pool could not render them anyway. Such a sample needs `N > V f_s` (192 000 events/s
//! with four voices at 48 kHz, far beyond any aggregate); its excess hazard is dropped
//! and a fresh target drawn, which by the memorylessness of the exponential carries on
//! exactly the same process from the next sample.
//!
//! # How hard: exponential energies
//!
//! An event's strike speed is
//!
//! $$ v = v_{rms} \sqrt{X}, \qquad X \sim \operatorname{Exp}(1), $$
//!
//! so its kinetic energy `½ m v^2` is exponentially distributed with mean `½ m v_{rms}^2`
//! (hence `E[v^2] = v_{rms}^2`: `v_rms` is the RMS speed). The exponential is the
//! maximum-entropy law for a positive quantity of given mean, the Boltzmann law of a
//! granular "gas" of colliding fragments: many weak clicks and a few loud ones, with no
//! scale but the mean. It is also what an explicit [`Aggregate::strike`] scales: a
//! strength `X` gives `v = v_rms \sqrt{X}`.
//!
//! # Which fragment: log-uniform sizes
//!
//! Each event's fragment has a size `s` (relative to a typical one) drawn log-uniformly,
//!
//! $$ \ln s \sim \mathcal{U}\left(-\ln(1+\sigma),\; \ln(1+\sigma)\right), $$
//!
//! with `σ` the size spread: sizes have no preferred scale within the band, and `s` and
//! `1/s` are equally likely. The modes of a body scale inversely with its size at a given
//! material (`f ∝ c/L`), so the fragment rings at `f_k / s`. Decay times and gains are
//! kept: only the pitch carries the size, which keeps each event's loudness governed by
//! its energy alone and the model's parameters independent of one another.
//!
//! # Voices
//!
//! A pool of `V` impact voices (hammer plus surface) renders the events; their surface
//! velocities are summed. An event goes to the voice whose surface holds the least energy
//! (`Σ ½ ω_k g_k |z_k|^2`, [`ResonatorBank::energy`]) among those whose hammer is not
//! on or heading to the surface; only when every voice is mid-strike is the quietest
//! stolen (its hammer is replaced). The voice is retuned to the event's size
//! ([`Impact::retune`]) and struck. A retuned voice that was still ringing carries on at
//! the new pitch: it was the quietest, so this is the least audible choice.
//!
//! # A safeguard
//!
//! The contact's step conserves energy against a rigid surface, but its coupling to a
//! resonating one (the surface takes each sample's impulse at the sample's start) can
//! give back a little more than it took (up to ~15 % of a strike's energy in the worst
//! cases measured: a light hammer on a light mode near a quarter of the sample rate). A voice
//! restruck faster than it decays, with a hammer far heavier than its modes or an
//! extremely damped contact, could compound that into a numerical runaway. So each voice
//! keeps a budget, the kinetic energy its hammers brought (`½ m v^2` per strike), decayed
//! at the slowest mode's rate `e^{-2t/τ_{max}}`; a voice found holding more than four
//! times its budget is silenced (and any non-finite sample of that stretch zeroed). The
//! check runs every 64 samples of the aggregate's own clock, and at once on a non-finite
//! output sample. With sensible parameters it never triggers; it only keeps the output
//! finite whatever the parameters.
//!
//! # Block-size invariance
//!
//! Every sample is computed the same way wherever a block (or the stretch between two
//! events) starts or ends, and the decisions that change the arithmetic (withdrawing a
//! hammer, culling a mode, resting a voice) are taken on sample clocks (the strike's, every 16 samples;
//! the aggregate's, every 64), never at block boundaries. The output is therefore the
//! same, bit for bit, for any block size (the engine's tests check 1, 7, 64 and 512).
//!
//! # Cost
//!
//! Per sample and ringing voice whose hammer has left for good (almost all of the time:
//! a rebounding grain is out of the surface's reach within a sample or two, see
//! [`Impact`]): one complex multiply and two multiply-adds per mode, with the modes in
//! four independent partial sums. While a hammer may still touch (a fraction of a
//! millisecond per event), the contact's bookkeeping and, in contact, a second pass over
//! the modes and a scalar solve of a few iterations. Per event: the energy of every voice
//! (`V K`) and a retune (`K` complex exponentials). A voice whose hammer has left and
//! whose surface energy has fallen to `10^{-12}` (−120 dB) of the largest it held since
//! its last check is brought to rest and costs nothing until struck again; so at low
//! rates, or with short decays, the cost follows the events rather than the pool size.
//!
//! # Culling modes
//!
//! A voice's modes decay very unequally (gravel's: a median of 4 ms, the slowest 26 ms),
//! so a voice waiting for its slowest mode to fall 120 dB would spend most of its free
//! ringing on modes already far below that. At each check of the aggregate's clock, a
//! voice whose hammer has been withdrawn culls every mode whose own energy
//! `½ ω_k g_k |z_k|²` is at most `10^{-12} / K` of the voice's peak (`K` modes): the
//! mode is set to exactly zero and skipped by the free loop
//! (`ResonatorBank::cull`) until the voice is retuned or struck again, which restores
//! all its modes. A free mode only decays, so what is dropped is at most what the mode
//! held then, and all the culled modes of a voice together hold at most `10^{-12}` of its
//! peak: never more than resting the whole voice discards (each mode's amplitude at most
//! `10^{-6} / \sqrt{K}` of the peak's, below −120 dB together). The decision is taken on
//! the aggregate's clock like the rest, so the output stays the same for any block size.
//! Measured (criterion, `benches/physical.rs`, four voices at 300 events/s, 48 kHz):
//! about 22 M samples/s with 3 modes and 8 M samples/s with 16, on one core.

use super::{Impact, ImpactParams, Mode, PhysicalError, ResonatorBank, Surface};
use crate::signal::noise::SplitMix64;
use crate::units::SampleRate;

/// The largest pool [`Aggregate::new`] accepts.
pub const MAX_VOICES: usize = 64;

/// The largest size spread [`Aggregate::new`] accepts: sizes within a factor of 11 either
/// way, already past any real aggregate.
pub const MAX_SIZE_SPREAD: f64 = 10.0;

/// A voice rests once its surface energy has fallen below this fraction of its peak.
const REST_ENERGY: f64 = 1e-12;

/// A voice holding more than this many times the energy its hammers brought has run away
/// numerically (see the module doc) and is silenced.
const RUNAWAY: f64 = 4.0;

/// Samples between the rest and runaway checks of the voices.
const CHECK_EVERY: usize = 64;

/// The parameters of an aggregate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AggregateParams {
    /// The hammer of each micro-impact; `velocity` is the RMS strike speed (m/s) of an event.
    pub impact: ImpactParams,
    /// Fragment sizes are log-uniform in `[1/(1+spread), 1+spread]`; a fragment of size `s`
    /// rings at frequencies `f_k / s` (smaller grains ring higher). 0 = all alike.
    pub size_spread: f64,
    /// How many micro-impacts can ring at once (pool of impact+surface voices), `1..=64`.
    pub voices: usize,
}

impl Default for AggregateParams {
    /// A stone of a few grams on a hard surface:
    ///
    /// - mass 3 g (a gravel grain about 13 mm across);
    /// - Hertzian contact, `α = 3/2`, `k = 10^8` N/m^{3/2}: softer than stone on stone,
    ///   standing for the grains and layer between, so that at the RMS speed of 0.5 m/s
    ///   the contact lasts about 0.23 ms (`2.94 x_max / v`, see [`super::impact`]), still
    ///   10 samples at 48 kHz, and the clicks reach a few kHz;
    /// - damping `λ = 6 · 10^7` N·s/m^{5/2}: a restitution `e ≈ 1 - (2/3)(λ/k) v ≈ 0.8` at
    ///   the RMS speed;
    /// - RMS speed 0.5 m/s, four voices, size spread 0.15 (pitches within ±15 %).
    fn default() -> Self {
        Self {
            impact: ImpactParams {
                mass: 0.003,
                stiffness: 1e8,
                alpha: 1.5,
                damping: 6e7,
                velocity: 0.5,
            },
            size_spread: 0.15,
            voices: 4,
        }
    }
}

#[derive(Debug, Clone)]
struct Voice {
    impact: Impact,
    /// Whether it is ringing (or striking); a resting voice is skipped.
    active: bool,
    /// The largest surface energy seen since its last strike.
    peak: f64,
    /// The kinetic energy its hammers brought, decayed at the slowest mode's rate: an
    /// upper bound on what the surface can physically hold.
    budget: f64,
}

impl Voice {
    fn energy(&self) -> f64 {
        if self.active {
            self.impact.surface().map_or(0.0, ResonatorBank::energy)
        } else {
            0.0
        }
    }
}

/// A stochastic aggregate: Poisson micro-impacts of random energy and size on a pool of
/// resonating voices.
///
/// Prepared by [`new`](Self::new); [`process`](Self::process),
/// [`strike`](Self::strike) and [`reset`](Self::reset) never allocate or panic.
#[derive(Debug, Clone)]
pub struct Aggregate {
    rate: SampleRate,
    period: f64,
    /// The slowest energy decay over [`CHECK_EVERY`] samples, `e^{-2 T_c / τ_max}`.
    check_decay: f64,
    mass: f64,
    rms_speed: f64,
    /// `ln(1 + spread)`: the half-width of the log-size band.
    log_spread: f64,
    /// The pool; only the first `pool` voices play (the rest is room reserved by
    /// [`with_capacity`](Aggregate::with_capacity)).
    voices: Vec<Voice>,
    pool: usize,
    rng: SplitMix64,
    /// The hazard still to accrue before the next event (`E` minus what has accrued).
    to_go: f64,
    events: u64,
    /// Samples rendered: voices are checked for rest and runaway when it passes a
    /// multiple of [`CHECK_EVERY`], so the checks never depend on the block size.
    clock: u64,
    /// Voices silenced by the runaway safeguard.
    runaways: u64,
}

impl Aggregate {
    /// An aggregate whose fragments ring with `modes` (at size 1), at rest, its random
    /// stream seeded by `seed`. May allocate; validates everything.
    ///
    /// Modes that a small fragment would push past Nyquist are clamped there (see
    /// [`ResonatorBank::retune`]).
    ///
    /// # Errors
    /// A zero rate; modes [`ResonatorBank::new`] rejects,; hammer
    /// parameters [`Impact::new`] rejects; an RMS speed that is negative or not finite; a
    /// size spread outside `[0, 10]`; a pool outside `1..=64`.
    pub fn new(
        modes: &[Mode],
        params: &AggregateParams,
        rate: SampleRate,
        seed: u64,
    ) -> Result<Self, PhysicalError> {
        let mut aggregate = Self::build(modes, params, rate, seed)?;
        aggregate.reserve(0, 0);
        Ok(aggregate)
    }

    /// As [`new`](Self::new), with room for up to `max_modes` modes and `max_voices`
    /// voices, so that [`assign_from`](Self::assign_from) another aggregate of at most that
    /// size (at the same rate) never allocates: how a material is changed on the audio
    /// thread.
    ///
    /// # Errors
    /// As [`new`](Self::new).
    pub fn with_capacity(
        modes: &[Mode],
        params: &AggregateParams,
        rate: SampleRate,
        seed: u64,
        max_modes: usize,
        max_voices: usize,
    ) -> Result<Self, PhysicalError> {
        let mut aggregate = Self::build(modes, params, rate, seed)?;
        aggregate.reserve(max_modes, max_voices);
        Ok(aggregate)
    }

    /// Makes room for `max_modes` modes and `max_voices` voices (see
    /// [`with_capacity`](Self::with_capacity)); a clone does not keep the room, so a clone
    /// that is to be assigned into calls this again. May allocate.
    pub fn reserve(&mut self, max_modes: usize, max_voices: usize) {
        let want = max_voices.min(MAX_VOICES).max(self.voices.len());
        while self.voices.len() < want {
            let spare = self.voices[0].clone();
            self.voices.push(spare);
        }
        for v in &mut self.voices {
            v.impact.reserve(max_modes);
        }
    }

    fn build(
        modes: &[Mode],
        params: &AggregateParams,
        rate: SampleRate,
        seed: u64,
    ) -> Result<Self, PhysicalError> {
        let invalid = |name, value, expected| PhysicalError::InvalidParameter {
            name,
            value,
            expected,
        };
        if rate.0 == 0 {
            return Err(PhysicalError::ZeroRate);
        }
        let rms = params.impact.velocity;
        if !(rms.is_finite() && rms >= 0.0) {
            return Err(invalid(
                "velocity",
                rms,
                "non-negative and finite (RMS m/s of a micro-impact)",
            ));
        }
        let spread = params.size_spread;
        if !(spread.is_finite() && (0.0..=MAX_SIZE_SPREAD).contains(&spread)) {
            return Err(invalid("size_spread", spread, "in [0, 10]"));
        }
        if !(1..=MAX_VOICES).contains(&params.voices) {
            return Err(invalid("voices", params.voices as f64, "in 1..=64"));
        }
        let bank = ResonatorBank::new(modes, rate)?;
        // Each strike is thrown explicitly: no voice starts with one armed.
        let hammer = ImpactParams {
            velocity: 0.0,
            ..params.impact
        };
        let voice = Voice {
            impact: Impact::new(hammer, Surface::Resonant(bank), rate)?,
            active: false,
            peak: 0.0,
            budget: 0.0,
        };
        let slowest = modes
            .iter()
            .fold(0.0f64, |m, mode| m.max(mode.played_decay().0));
        let mut rng = SplitMix64::new(seed);
        let to_go = exponential(&mut rng);
        Ok(Self {
            rate,
            period: 1.0 / rate.hz(),
            check_decay: (-2.0 * CHECK_EVERY as f64 / (slowest * rate.hz())).exp(),
            mass: params.impact.mass,
            rms_speed: rms,
            log_spread: spread.ln_1p(),
            voices: vec![voice; params.voices],
            pool: params.voices,
            rng,
            to_go,
            events: 0,
            clock: 0,
            runaways: 0,
        })
    }

    /// Takes on `other`'s material (modes, hammer, spread, pool) and silences every
    /// voice; keeps this aggregate's random stream. Allocates nothing when `other` fits in
    /// the room [`with_capacity`](Self::with_capacity) reserved; a pool larger than that
    /// room is cut to it.
    pub fn assign_from(&mut self, other: &Aggregate) {
        self.rate = other.rate;
        self.period = other.period;
        self.check_decay = other.check_decay;
        self.mass = other.mass;
        self.rms_speed = other.rms_speed;
        self.log_spread = other.log_spread;
        self.pool = other.pool.min(self.voices.len());
        for (mine, theirs) in self.voices.iter_mut().zip(&other.voices[..other.pool]) {
            mine.impact.assign_from(&theirs.impact);
        }
        self.reset();
    }

    /// The rate it runs at.
    #[must_use]
    pub fn rate(&self) -> SampleRate {
        self.rate
    }

    /// Events the Poisson process has generated since construction or the last
    /// [`reset`](Self::reset) (explicit [`strike`](Self::strike)s are not counted).
    #[must_use]
    pub fn events(&self) -> u64 {
        self.events
    }

    /// Silences every voice and zeroes the event count; the random stream carries on
    /// (so a reset does not replay the same events).
    pub fn reset(&mut self) {
        for v in &mut self.voices[..self.pool] {
            v.impact.reset();
            v.active = false;
            v.peak = 0.0;
            v.budget = 0.0;
        }
        self.events = 0;
    }

    /// A single strike now, of energy `strength` times the mean (1: the RMS speed), by a
    /// fragment of size 1, into the quietest voice. Ignored unless `strength` is positive
    /// and finite.
    pub fn strike(&mut self, strength: f64) {
        if strength.is_finite() && strength > 0.0 {
            self.strike_voice(strength, 1.0);
        }
    }

    /// Runs one block: `events_per_second[n]` is the rate `N` at sample `n`, and `out[n]`
    /// receives the summed surface velocity of all voices (m/s with gains in m/(N·s)).
    /// Runs over the shorter of the two; the rest of `out` is left alone.
    pub fn process(&mut self, events_per_second: &[f32], out: &mut [f32]) {
        let n = events_per_second.len().min(out.len());
        let out = &mut out[..n];
        out.fill(0.0);
        let mut start = 0;
        for (i, &rate) in events_per_second[..n].iter().enumerate() {
            let rate = if rate.is_finite() && rate > 0.0 {
                f64::from(rate)
            } else {
                0.0
            };
            self.to_go -= rate * self.period;
            if self.to_go <= 0.0 {
                // The voices catch up to this sample, whose start the events share.
                self.render(&mut out[start..i]);
                start = i;
                let mut emitted = 0;
                while self.to_go <= 0.0 && emitted < self.pool {
                    self.event();
                    self.to_go += exponential(&mut self.rng);
                    emitted += 1;
                }
                if self.to_go <= 0.0 {
                    self.to_go = exponential(&mut self.rng);
                }
            }
        }
        self.render(&mut out[start..]);
    }

    fn event(&mut self) {
        self.events += 1;
        let energy = exponential(&mut self.rng);
        let size = (self.log_spread * self.rng.symmetric()).exp();
        self.strike_voice(energy, size);
    }

    fn strike_voice(&mut self, energy: f64, size: f64) {
        let quietest = |free_only: bool| {
            self.voices[..self.pool]
                .iter()
                .enumerate()
                .filter(|(_, v)| !(free_only && v.impact.is_striking()))
                .map(|(i, v)| (i, v.energy()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(i, _)| i)
        };
        let Some(index) = quietest(true).or_else(|| quietest(false)) else {
            return;
        };
        let speed = self.rms_speed * energy.sqrt();
        let voice = &mut self.voices[index];
        // Both succeed for a size in [1/11, 11] and a finite speed; a failure would leave
        // the voice as it was, which is the harmless outcome.
        if voice.impact.retune(1.0 / size).is_ok() && voice.impact.strike(speed).is_ok() {
            voice.active = true;
            voice.peak = voice.energy();
            voice.budget += 0.5 * self.mass * speed * speed;
        }
    }

    /// Adds the active voices over `out`, then rests those that have died away.
    fn render(&mut self, out: &mut [f32]) {
        let mut rest = out;
        while !rest.is_empty() {
            let due = CHECK_EVERY - (self.clock % CHECK_EVERY as u64) as usize;
            let (head, tail) = rest.split_at_mut(rest.len().min(due));
            for v in self.voices[..self.pool].iter_mut().filter(|v| v.active) {
                v.impact.process_add(head);
            }
            self.clock += head.len() as u64;
            let on_clock = self.clock % CHECK_EVERY as u64 == 0;
            // A blown-up voice is caught at once rather than at the next check.
            if on_clock || head.iter().any(|o| !o.is_finite()) {
                self.check(head, on_clock);
            }
            rest = tail;
        }
    }

    /// Rests the voices that have faded (on the clock only) and silences runaways (see the
    /// module documentation); `last` is the stretch just rendered.
    fn check(&mut self, last: &mut [f32], on_clock: bool) {
        let mut runaway = false;
        for v in self.voices[..self.pool].iter_mut().filter(|v| v.active) {
            let energy = v.energy();
            if on_clock {
                v.peak = v.peak.max(energy);
                v.budget *= self.check_decay;
            }
            let resting = on_clock && !v.impact.is_striking() && energy <= REST_ENERGY * v.peak;
            // Written so that a NaN energy counts as a runaway.
            let bounded = energy <= RUNAWAY * v.budget;
            runaway |= !bounded;
            self.runaways += u64::from(!bounded);
            if resting || !bounded {
                v.impact.reset();
                v.active = false;
                v.peak = 0.0;
                v.budget = 0.0;
            } else if on_clock {
                // Each mode may take its share of what resting the voice would drop.
                let modes = v.impact.surface().map_or(1, |b| b.modes().len());
                v.impact
                    .cull_quiet_modes(REST_ENERGY * v.peak / modes as f64);
            }
        }
        if runaway {
            for o in last.iter_mut().filter(|o| !o.is_finite()) {
                *o = 0.0;
            }
        }
    }
}

/// An `Exp(1)` draw: `-ln(1 - U)` with `1 - U` in `(0, 1]`, so always finite.
fn exponential(rng: &mut SplitMix64) -> f64 {
    -(1.0 - rng.uniform()).ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{Hz, Seconds};
    use proptest::prelude::*;

    const RATE: SampleRate = SampleRate(8_000);

    fn modes() -> [Mode; 3] {
        [
            Mode {
                frequency: Hz(300.0),
                decay: Seconds(0.03),
                gain: 2e-3,
            },
            Mode {
                frequency: Hz(900.0),
                decay: Seconds(0.02),
                gain: 1e-3,
            },
            Mode {
                frequency: Hz(1700.0),
                decay: Seconds(0.01),
                gain: 5e-4,
            },
        ]
    }

    fn aggregate(params: &AggregateParams, seed: u64) -> Aggregate {
        Aggregate::new(&modes(), params, RATE, seed).unwrap()
    }

    /// Events in each one-second window of a run at `rate(t)` events/s.
    fn counts(agg: &mut Aggregate, seconds: usize, rate: impl Fn(f64) -> f32) -> Vec<u64> {
        let fs = RATE.0 as usize;
        let mut rates = vec![0.0f32; fs];
        let mut out = vec![0.0f32; fs];
        let mut counts = Vec::with_capacity(seconds);
        for s in 0..seconds {
            for (n, r) in rates.iter_mut().enumerate() {
                *r = rate(s as f64 + n as f64 / fs as f64);
            }
            let before = agg.events();
            // Odd blocks, so events fall across block edges.
            for (r, o) in rates.chunks(333).zip(out.chunks_mut(333)) {
                agg.process(r, o);
            }
            counts.push(agg.events() - before);
        }
        counts
    }

    fn within_4_sigma(count: u64, mean: f64) -> bool {
        (count as f64 - mean).abs() < 4.0 * mean.sqrt()
    }

    #[test]
    fn a_constant_rate_gives_poisson_counts() {
        let mut agg = aggregate(&AggregateParams::default(), 1);
        let c = counts(&mut agg, 200, |_| 50.0);
        let total: u64 = c.iter().sum();
        let mean = total as f64 / c.len() as f64;
        let var = c.iter().map(|&k| (k as f64 - mean).powi(2)).sum::<f64>() / (c.len() - 1) as f64;
        eprintln!(
            "200 s at 50/s: {total} events (expected 10000 ± 100), dispersion {:.3}",
            var / mean
        );
        assert!(within_4_sigma(total, 10_000.0), "{total}");
        assert!(
            (0.7..1.3).contains(&(var / mean)),
            "dispersion {}",
            var / mean
        );
    }

    #[test]
    fn a_ramp_gives_its_integral() {
        // N(t) = 2 t over 100 s: 2500 events in the first half, 7500 in the second.
        let mut agg = aggregate(&AggregateParams::default(), 2);
        let c = counts(&mut agg, 100, |t| (2.0 * t) as f32);
        let first: u64 = c[..50].iter().sum();
        let second: u64 = c[50..].iter().sum();
        eprintln!("ramp: {first} (2500) then {second} (7500)");
        assert!(within_4_sigma(first, 2500.0), "{first}");
        assert!(within_4_sigma(second, 7500.0), "{second}");
        // Window by window, too: a 1 s window at N = 2t holds 2t + 1 events on average.
        let worst = c
            .iter()
            .enumerate()
            .map(|(s, &k)| (k as f64 - (2.0 * s as f64 + 1.0)) / (2.0 * s as f64 + 1.0).sqrt())
            .fold(0.0f64, |m, z| m.max(z.abs()));
        assert!(worst < 4.5, "worst window {worst} sigma");
    }

    #[test]
    fn silence_without_events_and_sound_only_after_them() {
        let mut agg = aggregate(&AggregateParams::default(), 3);
        let fs = RATE.0 as usize;
        let mut out = vec![1.0f32; 2 * fs];
        agg.process(&vec![0.0; 2 * fs], &mut out);
        assert!(out.iter().all(|&v| v == 0.0));
        assert_eq!(agg.events(), 0);

        // Half a second of events, then none for three.
        let mut rates = vec![0.0f32; 4 * fs];
        rates[fs..fs + fs / 2].fill(100.0);
        let mut out = vec![0.0f32; 4 * fs];
        let mut after = 0;
        for (r, o) in rates.chunks(128).zip(out.chunks_mut(128)) {
            agg.process(r, o);
            if r[0] > 0.0 {
                after = agg.events();
            }
        }
        assert!(after > 20, "{after}");
        assert_eq!(agg.events(), after, "events without a rate");
        assert!(out[..fs].iter().all(|&v| v == 0.0), "sound before events");
        assert!(out[fs..fs + fs / 2].iter().any(|&v| v != 0.0));
        // The ringing dies away and every voice comes to rest: exactly silent.
        assert!(out[3 * fs..].iter().all(|&v| v == 0.0), "no rest");
        assert!(agg.voices.iter().all(|v| !v.active));
    }

    #[test]
    fn no_spread_rings_at_the_given_frequencies() {
        let params = AggregateParams {
            size_spread: 0.0,
            ..AggregateParams::default()
        };
        let reference = ResonatorBank::new(&modes(), RATE).unwrap();
        let mut agg = aggregate(&params, 4);
        let mut out = vec![0.0f32; RATE.0 as usize];
        agg.process(&vec![200.0; out.len()], &mut out);
        assert!(agg.events() > 100);
        for v in &agg.voices {
            let bank = v.impact.surface().unwrap();
            assert_eq!(bank.frequency_scale(), 1.0);
            assert_eq!(bank.poles(), reference.poles());
        }
        // And the sound's spectrum peaks at the single mode's frequency.
        let one = [Mode {
            frequency: Hz(440.0),
            decay: Seconds(0.05),
            gain: 1e-3,
        }];
        let mut agg = Aggregate::new(&one, &params, RATE, 5).unwrap();
        agg.process(&vec![100.0; out.len()], &mut out);
        let peak = (100..=2000)
            .step_by(5)
            .map(|f| (f, goertzel(&out, f64::from(f) / RATE.hz())))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap()
            .0;
        assert_eq!(peak, 440);
    }

    /// Power of `x` at `f` cycles per sample.
    fn goertzel(x: &[f32], f: f64) -> f64 {
        let c = 2.0 * (std::f64::consts::TAU * f).cos();
        let (mut s1, mut s2) = (0.0, 0.0);
        for &v in x {
            let s = f64::from(v) + c * s1 - s2;
            s2 = s1;
            s1 = s;
        }
        s1 * s1 + s2 * s2 - c * s1 * s2
    }

    #[test]
    fn sizes_scale_the_frequencies_within_the_spread() {
        let spread = 0.3;
        let params = AggregateParams {
            size_spread: spread,
            ..AggregateParams::default()
        };
        let reference = ResonatorBank::new(&modes(), RATE).unwrap();
        let mut agg = aggregate(&params, 6);
        let mut scales = Vec::new();
        let (mut one, mut out) = ([300.0f32], [0.0f32]);
        while scales.len() < 2000 {
            let before = agg.events();
            agg.process(&one, &mut out);
            if agg.events() == before + 1 {
                // The voice just struck is the one whose hammer is out.
                let v = agg.voices.iter().find(|v| v.impact.is_striking()).unwrap();
                let bank = v.impact.surface().unwrap();
                let scale = bank.frequency_scale();
                for (p, q) in bank.poles().iter().zip(reference.poles()) {
                    // Observed: the pole angle is 2π f / f_s.
                    let observed = p.arg() / q.arg();
                    assert!((observed / scale - 1.0).abs() < 1e-12);
                }
                scales.push(scale);
            }
            one[0] = 300.0;
        }
        let (lo, hi) = scales
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(l, h), &s| (l.min(s), h.max(s)));
        let mean_log = scales.iter().map(|s| s.ln()).sum::<f64>() / scales.len() as f64;
        eprintln!("scales in [{lo:.4}, {hi:.4}], mean log {mean_log:.4}");
        let bound = 1.0 + spread;
        assert!(lo >= 1.0 / bound && hi <= bound);
        // Log-uniform: the extremes are reached and the logs centre on zero.
        assert!(lo < 1.0 / bound * 1.01 && hi > bound / 1.01);
        let sd = bound.ln() / 3f64.sqrt() / (scales.len() as f64).sqrt();
        assert!(mean_log.abs() < 4.0 * sd, "{mean_log}");
    }

    #[test]
    fn a_seed_fixes_the_stream_and_bad_rates_are_zero() {
        let params = AggregateParams::default();
        let rates: Vec<f32> = (0..16_000)
            .map(|n| 80.0 + 60.0 * ((n / 900) % 3) as f32)
            .collect();
        let run = |seed, rates: &[f32]| {
            let mut agg = aggregate(&params, seed);
            let mut out = vec![0.0f32; rates.len()];
            for (r, o) in rates.chunks(100).zip(out.chunks_mut(100)) {
                agg.process(r, o);
            }
            (out, agg.events())
        };
        let a = run(7, &rates);
        assert!(a.1 > 0);
        assert_eq!(a, run(7, &rates));
        assert_ne!(a.0, run(8, &rates).0);
        // Non-finite and negative rates are zero, and break nothing.
        let mut bad = rates.clone();
        let mut zeroed = rates.clone();
        for (n, (b, z)) in bad.iter_mut().zip(&mut zeroed).enumerate() {
            if n % 7 == 0 {
                *b = [f32::NAN, -5.0, f32::INFINITY, f32::NEG_INFINITY][n / 7 % 4];
                *z = 0.0;
            }
        }
        let b = run(7, &bad);
        assert!(b.0.iter().all(|v| v.is_finite()));
        assert_eq!(b, run(7, &zeroed));
        // Only the shorter of the two slices is run.
        let mut agg = aggregate(&params, 7);
        let mut out = [9.0f32; 10];
        agg.process(&[1e6; 4], &mut out);
        assert_eq!(out[4..], [9.0; 6]);
    }

    #[test]
    fn reset_silences_and_the_stream_goes_on() {
        let mut agg = aggregate(&AggregateParams::default(), 9);
        let rates = vec![400.0f32; 4000];
        let mut first = vec![0.0f32; 4000];
        agg.process(&rates, &mut first);
        assert!(agg.events() > 0);
        agg.reset();
        assert_eq!(agg.events(), 0);
        let mut silent = vec![1.0f32; 100];
        agg.process(&[0.0; 100], &mut silent);
        assert!(silent.iter().all(|&v| v == 0.0));
        let mut second = vec![0.0f32; 4000];
        agg.process(&rates, &mut second);
        assert_ne!(first, second, "a reset must not replay the stream");
    }

    #[test]
    fn a_strike_rings_without_counting_as_an_event() {
        let mut agg = aggregate(&AggregateParams::default(), 10);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            agg.strike(bad);
        }
        let mut out = vec![0.0f32; 800];
        agg.process(&[0.0; 800], &mut out);
        assert!(out.iter().all(|&v| v == 0.0));
        agg.strike(1.0);
        agg.process(&[0.0; 800], &mut out);
        assert!(out.iter().any(|&v| v != 0.0));
        assert_eq!(agg.events(), 0);
        // A stronger strike is louder: the contact is nonlinear, but monotone.
        let peak = |s: &[f32]| s.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let mut loud = vec![0.0f32; 800];
        let mut agg = aggregate(&AggregateParams::default(), 10);
        agg.strike(4.0);
        agg.process(&[0.0; 800], &mut loud);
        assert!(peak(&loud) > 1.5 * peak(&out));
    }

    #[test]
    fn a_flood_of_events_is_capped_per_sample() {
        let params = AggregateParams::default();
        let mut agg = aggregate(&params, 11);
        let mut out = vec![0.0f32; 1000];
        agg.process(&vec![f32::MAX; 1000], &mut out);
        assert_eq!(agg.events(), 1000 * params.voices as u64);
        assert!(out.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn sensible_parameters_never_trip_the_safeguard() {
        for (rate, spread) in [(RATE, 0.15), (SampleRate(48_000), 0.5)] {
            let params = AggregateParams {
                size_spread: spread,
                ..AggregateParams::default()
            };
            let mut agg = Aggregate::new(&modes(), &params, rate, 12).unwrap();
            let n = rate.0 as usize;
            let mut out = vec![0.0f32; n];
            // Dense bursts (every voice restruck while ringing), then a sparse stream.
            for burst in [3000.0, 20_000.0, 50.0] {
                agg.process(&vec![burst; n], &mut out);
            }
            assert!(agg.events() > 20_000);
            assert_eq!(agg.runaways, 0, "at {rate}, spread {spread}");
        }
    }

    #[test]
    fn default_micro_impacts_are_short_and_lossy() {
        let p = AggregateParams::default().impact;
        let mut impact = Impact::new(p, Surface::Rigid, SampleRate(48_000)).unwrap();
        let mut out = vec![0.0f32; 480];
        impact.process(&mut out);
        let t = impact.contact_time().unwrap().0;
        let e = -impact.hammer_velocity() / p.velocity;
        eprintln!(
            "default grain: contact {:.3} ms, restitution {e:.3}",
            t * 1e3
        );
        assert!(t > 0.1e-3 && t < 0.5e-3, "{t}");
        assert!(e > 0.6 && e < 0.9, "{e}");
    }

    #[test]
    fn bad_parameters_are_errors() {
        let good = AggregateParams::default();
        let bad = [
            AggregateParams { voices: 0, ..good },
            AggregateParams {
                voices: MAX_VOICES + 1,
                ..good
            },
            AggregateParams {
                size_spread: -0.1,
                ..good
            },
            AggregateParams {
                size_spread: f64::NAN,
                ..good
            },
            AggregateParams {
                impact: ImpactParams {
                    velocity: f64::NAN,
                    ..good.impact
                },
                ..good
            },
            AggregateParams {
                impact: ImpactParams {
                    mass: 0.0,
                    ..good.impact
                },
                ..good
            },
        ];
        for p in bad {
            assert!(
                matches!(
                    Aggregate::new(&modes(), &p, RATE, 0),
                    Err(PhysicalError::InvalidParameter { .. })
                ),
                "{p:?}"
            );
        }
        assert_eq!(
            Aggregate::new(&[], &good, RATE, 0).err(),
            Some(PhysicalError::NoModes)
        );
        assert_eq!(
            Aggregate::new(&modes(), &good, SampleRate(0), 0).err(),
            Some(PhysicalError::ZeroRate)
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        /// Any valid parameters and any rates, finite or not: finite output.
        #[test]
        fn output_stays_finite(
            seed in any::<u64>(),
            mass in 1e-5f64..10.0,
            log_k in 2.0f64..12.0,
            alpha in 1.0f64..3.0,
            log_damping in -3.0f64..10.0,
            velocity in 0.0f64..20.0,
            spread in 0.0f64..=MAX_SIZE_SPREAD,
            voices in 1usize..=8,
            freqs in prop::collection::vec((0.001f64..0.4999, 1e-4f64..2.0, 0.0f64..1.0), 1..6),
            rates in prop::collection::vec(
                prop_oneof![
                    4 => 0.0f32..5000.0,
                    1 => Just(f32::NAN),
                    1 => Just(-1.0f32),
                    1 => Just(f32::INFINITY),
                    1 => 1e5f32..1e30,
                ],
                1..64,
            ),
        ) {
            let modes: Vec<Mode> = freqs
                .iter()
                .map(|&(f, tau, g)| Mode {
                    frequency: Hz(f * RATE.hz()),
                    decay: Seconds(tau),
                    gain: g,
                })
                .collect();
            let params = AggregateParams {
                impact: ImpactParams {
                    mass,
                    stiffness: 10f64.powf(log_k),
                    alpha,
                    damping: 10f64.powf(log_damping),
                    velocity,
                },
                size_spread: spread,
                voices,
            };
            let mut agg = Aggregate::new(&modes, &params, RATE, seed).unwrap();
            let mut out = vec![0.0f32; 200];
            for k in 0..20 {
                let block: Vec<f32> = (0..200).map(|n| rates[(n + k * 200) / 50 % rates.len()]).collect();
                agg.process(&block, &mut out);
                prop_assert!(out.iter().all(|v| v.is_finite()), "block {k}: {out:?}");
                if k == 10 {
                    agg.strike(3.0);
                }
            }
        }
    }
}
