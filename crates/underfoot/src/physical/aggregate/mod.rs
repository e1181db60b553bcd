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
//! ```math
//! \Lambda[n+1] = \Lambda[n] + N[n]\, T, \qquad T = 1/f_s ,
//! ```
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
//! A sample holds at most as many events as there are slots (below): beyond that the
//! pool could not render them anyway. Such a sample needs `N > V f_s` (192 000 events/s
//! with four impacts in flight at 48 kHz, far beyond any aggregate); its excess hazard is dropped
//! and a fresh target drawn, which by the memorylessness of the exponential carries on
//! exactly the same process from the next sample.
//!
//! # How hard: exponential energies
//!
//! An event's strike speed is
//!
//! ```math
//! v = v_{rms} \sqrt{X}, \qquad X \sim \operatorname{Exp}(1),
//! ```
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
//! ```math
//! \ln s \sim \mathcal{U}\left(-\ln(1+\sigma),\; \ln(1+\sigma)\right),
//! ```
//!
//! with `σ` the size spread: sizes have no preferred scale within the band, and `s` and
//! `1/s` are equally likely. The modes of a body scale inversely with its size at a given
//! material (`f ∝ c/L`), so the fragment rings at `f_k / s`. Decay times and gains are
//! kept: only the pitch carries the size, which keeps each event's loudness governed by
//! its energy alone and the model's parameters independent of one another.
//!
//! # The pool
//!
//! A pool of `V` slots, each an impact (hammer plus surface), renders the events; their surface
//! velocities are summed. An event goes to the slot whose surface holds the least energy
//! (`Σ ½ ω_k g_k |z_k|^2`, [`ResonatorBank::energy`]) among those whose hammer is not
//! on or heading to the surface; only when every slot is mid-strike is the quietest
//! stolen (its hammer is replaced). The slot is retuned to the event's size
//! ([`Impact::retune`]) and struck. A retuned slot that was still ringing carries on at
//! the new pitch: it was the quietest, so this is the least audible choice.
//!
//! # A safeguard
//!
//! The contact's step conserves energy against a rigid surface, but its coupling to a
//! resonating one (the surface takes each sample's impulse at the sample's start) can
//! give back a little more than it took (up to ~15 % of a strike's energy in the worst
//! cases measured: a light hammer on a light mode near a quarter of the sample rate). A slot
//! restruck faster than it decays, with a hammer far heavier than its modes or an
//! extremely damped contact, could compound that into a numerical runaway. So each slot
//! keeps a budget, the kinetic energy its hammers brought (`½ m v^2` per strike), decayed
//! at the slowest mode's rate `e^{-2t/τ_{max}}`; a slot found holding more than four
//! times its budget is silenced (and any non-finite sample of that stretch zeroed). The
//! check runs every 64 samples of the aggregate's own clock, and at once on a non-finite
//! output sample. With sensible parameters it never triggers; it only keeps the output
//! finite whatever the parameters.
//!
//! # Block-size invariance
//!
//! Every sample is computed the same way wherever a block (or the stretch between two
//! events) starts or ends, and the decisions that change the arithmetic (withdrawing a
//! hammer, culling a mode, resting a slot) are taken on sample clocks (the strike's, every 16 samples;
//! the aggregate's, every 64), never at block boundaries. The output is therefore the
//! same, bit for bit, for any block size (the engine's tests check 1, 7, 64 and 512).
//!
//! # Cost
//!
//! Per sample and ringing slot whose hammer has left for good (almost all of the time:
//! a rebounding grain is out of the surface's reach within a sample or two, see
//! [`Impact`]): one complex multiply and two multiply-adds per mode, with the modes in
//! four independent partial sums. While a hammer may still touch (a fraction of a
//! millisecond per event), the contact's bookkeeping and, in contact, a second pass over
//! the modes and a scalar solve of a few iterations. Per event: the energy of every slot
//! (`V K`) and a retune (`K` complex exponentials). A slot whose hammer has left and
//! whose surface energy has fallen to `10^{-12}` (−120 dB) of the largest it held since
//! its last check is brought to rest and costs nothing until struck again; so at low
//! rates, or with short decays, the cost follows the events rather than the pool size.
//!
//! # Culling modes
//!
//! A slot's modes decay very unequally (gravel's: a median of 4 ms, the slowest 26 ms),
//! so a slot waiting for its slowest mode to fall 120 dB would spend most of its free
//! ringing on modes already far below that. At each check of the aggregate's clock, a
//! slot whose hammer has been withdrawn culls every mode whose own energy
//! `½ ω_k g_k |z_k|²` is at most `10^{-12} / K` of the slot's peak (`K` modes): the
//! mode is set to exactly zero and skipped by the free loop
//! (`ResonatorBank::cull`) until the slot is retuned or struck again, which restores
//! all its modes. A free mode only decays, so what is dropped is at most what the mode
//! held then, and all the culled modes of a slot together hold at most `10^{-12}` of its
//! peak: never more than resting the whole slot discards (each mode's amplitude at most
//! `10^{-6} / \sqrt{K}` of the peak's, below −120 dB together). The decision is taken on
//! the aggregate's clock like the rest, so the output stays the same for any block size.
//! Its cost against a plain C crumpling loop of the same work is measured by
//! `underfoot-bench`'s `benches/anchors.rs` (in the README's performance table).

use super::{Impact, ImpactParams, PhysicalError, ResonatorBank, Surface, SurfaceMode};
use crate::signal::noise::SplitMix64;
use crate::units::SampleRate;

/// The largest pool [`Aggregate::new`] accepts.
pub const MAX_IMPACT_POOL: usize = 64;

/// The largest size spread [`Aggregate::new`] accepts: sizes within a factor of 11 either
/// way, already past any real aggregate.
pub const MAX_SIZE_SPREAD: f64 = 10.0;

/// A slot rests once its surface energy has fallen below this fraction of its peak.
const REST_ENERGY: f64 = 1e-12;

/// A slot holding more than this many times the energy its hammers brought has run away
/// numerically (see the module doc) and is silenced.
const RUNAWAY: f64 = 4.0;

/// Samples between the rest and runaway checks of the slots.
const CHECK_EVERY: usize = 64;

/// Impulses of an excitation closer than this (seconds) to the previous strike merge into
/// the next ([`Aggregate::process_impulses`]): at most 500 strikes a second.
pub const MERGE_WITHIN: f64 = 0.002;

/// The parameters of an aggregate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AggregateParams {
    /// The hammer of each micro-impact; `velocity` is the RMS strike speed (m/s) of an event.
    pub impact: ImpactParams,
    /// Fragment sizes are log-uniform in `[1/(1+spread), 1+spread]`; a fragment of size `s`
    /// rings at frequencies `f_k / s` (smaller grains ring higher). 0 = all alike.
    pub size_spread: f64,
    /// How many micro-impacts can ring at once (the pool of slots, each a hammer and a surface), `1..=64`.
    pub impacts_in_flight: usize,
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
    /// - RMS speed 0.5 m/s, four impacts in flight, size spread 0.15 (pitches within ±15 %).
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
            impacts_in_flight: 4,
        }
    }
}

#[derive(Debug, Clone)]
struct Slot {
    impact: Impact,
    /// Whether it is ringing (or striking); a resting slot is skipped.
    active: bool,
    /// The largest surface energy seen since its last strike.
    peak: f64,
    /// The kinetic energy its hammers brought, decayed at the slowest mode's rate: an
    /// upper bound on what the surface can physically hold.
    budget: f64,
}

impl Slot {
    fn energy(&self) -> f64 {
        if self.active {
            self.impact.surface().map_or(0.0, ResonatorBank::energy)
        } else {
            0.0
        }
    }
}

/// A stochastic aggregate: Poisson micro-impacts of random energy and size on a pool of
/// resonating slots.
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
    /// The pool; only the first `pool` slots play (the rest is room reserved by
    /// [`with_capacity`](Aggregate::with_capacity)).
    slots: Vec<Slot>,
    pool: usize,
    rng: SplitMix64,
    /// The hazard still to accrue before the next event (`E` minus what has accrued).
    to_go: f64,
    events: u64,
    /// Samples rendered: slots are checked for rest and runaway when it passes a
    /// multiple of [`CHECK_EVERY`], so the checks never depend on the block size.
    clock: u64,
    /// Slots silenced by the runaway safeguard.
    runaways: u64,
    /// Energy of impulses waiting to strike ([`process_impulses`](Self::process_impulses)).
    pending: f64,
    /// Samples since the last strike of [`process_impulses`](Self::process_impulses).
    since_strike: u64,
    /// [`MERGE_WITHIN`] in samples.
    merge_within: u64,
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
        modes: &[SurfaceMode],
        params: &AggregateParams,
        rate: SampleRate,
        seed: u64,
    ) -> Result<Self, PhysicalError> {
        let mut aggregate = Self::build(modes, params, rate, seed)?;
        aggregate.reserve(0, 0);
        Ok(aggregate)
    }

    /// As [`new`](Self::new), with room for up to `max_modes` modes and `max_impacts`
    /// impacts in flight, so that [`assign_from`](Self::assign_from) another aggregate of at most that
    /// size (at the same rate) never allocates: how a material is changed on the audio
    /// thread.
    ///
    /// # Errors
    /// As [`new`](Self::new).
    pub fn with_capacity(
        modes: &[SurfaceMode],
        params: &AggregateParams,
        rate: SampleRate,
        seed: u64,
        max_modes: usize,
        max_impacts: usize,
    ) -> Result<Self, PhysicalError> {
        let mut aggregate = Self::build(modes, params, rate, seed)?;
        aggregate.reserve(max_modes, max_impacts);
        Ok(aggregate)
    }

    /// Makes room for `max_modes` modes and `max_impacts` impacts in flight (see
    /// [`with_capacity`](Self::with_capacity)); a clone does not keep the room, so a clone
    /// that is to be assigned into calls this again. May allocate.
    pub fn reserve(&mut self, max_modes: usize, max_impacts: usize) {
        let want = max_impacts.min(MAX_IMPACT_POOL).max(self.slots.len());
        while self.slots.len() < want {
            let spare = self.slots[0].clone();
            self.slots.push(spare);
        }
        for v in &mut self.slots {
            v.impact.reserve(max_modes);
        }
    }

    fn build(
        modes: &[SurfaceMode],
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
        if !(1..=MAX_IMPACT_POOL).contains(&params.impacts_in_flight) {
            return Err(invalid(
                "impacts_in_flight",
                params.impacts_in_flight as f64,
                "in 1..=64",
            ));
        }
        let bank = ResonatorBank::new(modes, rate)?;
        // Each strike is thrown explicitly: no slot starts with one armed.
        let hammer = ImpactParams {
            velocity: 0.0,
            ..params.impact
        };
        let slot = Slot {
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
            slots: vec![slot; params.impacts_in_flight],
            pool: params.impacts_in_flight,
            rng,
            to_go,
            events: 0,
            clock: 0,
            runaways: 0,
            pending: 0.0,
            since_strike: u64::MAX,
            merge_within: (MERGE_WITHIN * rate.hz()).round() as u64,
        })
    }

    /// Takes on `other`'s material (modes, hammer, spread, pool) and silences every
    /// slot; keeps this aggregate's random stream. Allocates nothing when `other` fits in
    /// the room [`with_capacity`](Self::with_capacity) reserved; a pool larger than that
    /// room is cut to it.
    pub fn assign_from(&mut self, other: &Aggregate) {
        self.rate = other.rate;
        self.period = other.period;
        self.check_decay = other.check_decay;
        self.mass = other.mass;
        self.rms_speed = other.rms_speed;
        self.log_spread = other.log_spread;
        self.pool = other.pool.min(self.slots.len());
        self.merge_within = other.merge_within;
        for (mine, theirs) in self.slots.iter_mut().zip(&other.slots[..other.pool]) {
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

    /// Silences every slot and zeroes the event count; the random stream carries on
    /// (so a reset does not replay the same events).
    pub fn reset(&mut self) {
        for v in &mut self.slots[..self.pool] {
            v.impact.reset();
            v.active = false;
            v.peak = 0.0;
            v.budget = 0.0;
        }
        self.events = 0;
        self.pending = 0.0;
        self.since_strike = u64::MAX;
    }

    /// A single strike now, of energy `strength` times the mean (1: the RMS speed), by a
    /// fragment of size 1, into the quietest slot. Ignored unless `strength` is positive
    /// and finite.
    pub fn strike(&mut self, strength: f64) {
        if strength.is_finite() && strength > 0.0 {
            self.strike_slot(strength, 1.0);
        }
    }

    /// Runs one block: `events_per_second[n]` is the rate `N` at sample `n`, and `out[n]`
    /// receives the summed surface velocity of all slots (m/s with gains in m/(N·s)).
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
                // The slots catch up to this sample, whose start the events share.
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

    /// Runs one block struck by `impulses`: each non-zero sample `x` brings energy
    /// `x² / mean_energy` times the mean (so an impulse of mean energy strikes at the RMS
    /// speed). Impulses closer than [`MERGE_WITHIN`] to the last strike wait and merge
    /// into the next one, which strikes with their summed energy: a few impacts in flight
    /// cannot ring under a train of thousands a second, each taking the quietest slot and
    /// cutting its ringing short (a sand step's low modes never rang, 4 dB off its
    /// spectrum), and the surface takes the same energy either way. Each strike is by a
    /// fragment of random size. `out[n]` receives the summed surface velocity, as
    /// [`process`](Self::process) does; the Poisson process is not run. Runs over the
    /// shorter of the two.
    pub fn process_impulses(&mut self, impulses: &[f32], mean_energy: f64, out: &mut [f32]) {
        let n = impulses.len().min(out.len());
        let out = &mut out[..n];
        out.fill(0.0);
        let mut start = 0;
        for (i, &x) in impulses[..n].iter().enumerate() {
            let strength = f64::from(x) * f64::from(x) / mean_energy;
            if strength > 0.0 && strength.is_finite() {
                self.pending += strength;
            }
            if self.pending > 0.0 && self.since_strike >= self.merge_within {
                self.render(&mut out[start..i]);
                start = i;
                self.events += 1;
                let size = (self.log_spread * self.rng.symmetric()).exp();
                self.strike_slot(self.pending, size);
                self.pending = 0.0;
                self.since_strike = 0;
            }
            self.since_strike = self.since_strike.saturating_add(1);
        }
        self.render(&mut out[start..]);
    }

    fn event(&mut self) {
        self.events += 1;
        let energy = exponential(&mut self.rng);
        let size = (self.log_spread * self.rng.symmetric()).exp();
        self.strike_slot(energy, size);
    }

    fn strike_slot(&mut self, energy: f64, size: f64) {
        let quietest = |free_only: bool| {
            self.slots[..self.pool]
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
        let slot = &mut self.slots[index];
        // Both succeed for a size in [1/11, 11] and a finite speed; a failure would leave
        // the slot as it was, which is the harmless outcome.
        if slot.impact.retune(1.0 / size).is_ok() && slot.impact.strike(speed).is_ok() {
            slot.active = true;
            slot.peak = slot.energy();
            slot.budget += 0.5 * self.mass * speed * speed;
        }
    }

    /// Adds the active slots over `out`, then rests those that have died away.
    fn render(&mut self, out: &mut [f32]) {
        let mut rest = out;
        while !rest.is_empty() {
            let due = CHECK_EVERY - (self.clock % CHECK_EVERY as u64) as usize;
            let (head, tail) = rest.split_at_mut(rest.len().min(due));
            for v in self.slots[..self.pool].iter_mut().filter(|v| v.active) {
                v.impact.process_add(head);
            }
            self.clock += head.len() as u64;
            let on_clock = self.clock.is_multiple_of(CHECK_EVERY as u64);
            // A blown-up slot is caught at once rather than at the next check.
            if on_clock || head.iter().any(|o| !o.is_finite()) {
                self.check(head, on_clock);
            }
            rest = tail;
        }
    }

    /// Rests the slots that have faded (on the clock only) and silences runaways (see the
    /// module documentation); `last` is the stretch just rendered.
    fn check(&mut self, last: &mut [f32], on_clock: bool) {
        let mut runaway = false;
        for v in self.slots[..self.pool].iter_mut().filter(|v| v.active) {
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
                // Each mode may take its share of what resting the slot would drop.
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
mod tests;
