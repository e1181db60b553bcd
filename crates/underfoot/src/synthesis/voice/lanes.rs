//! Several voices at once, one per SIMD lane: what the engine runs its channels with.
//!
//! A lone [`Voice`] is bound by the latency of its recurrences, not by arithmetic: each
//! sample's modes must wait for the previous sample's, and the post filter's sections
//! for each other, so most of a vector unit sits idle. Channels are independent, so
//! [`VoiceLanes`] runs up to [`LANE_WIDTH`] voices side by side, voice `c` in lane `c`
//! of every vector: the same recurrences, but each instruction now advances eight
//! channels.
//!
//! # Same output as a lone voice, to the bit
//!
//! Each lane performs exactly the operations [`Voice::process`] performs, in the same
//! order and in `f32`, so a voice gives the same samples whichever way it is run (the
//! engine plays a channel's fading voice alone and its current voice in a lane, and a
//! voice changes between the two when its material changes):
//!
//! - the modes are summed into four partial sums, mode `k` into sum `k mod 4`, and the
//!   four added pairwise, as the lone voice's four-wide groups do;
//! - lanes with fewer modes or post sections than the widest run the others with zero
//!   coefficients and identity sections, which leave every finite value unchanged;
//! - a lane whose output goes non-finite resets its own state only, and counts one;
//! - each voice flushes its tiny states on its own sample clock, so a run of lanes is
//!   cut where any of them is due.
//!
//! A test plays every built-in material both ways at random block sizes and compares
//! every sample.
//!
//! # Vector width
//!
//! Eight `f32` lanes fill a 256-bit register. The loops are written over fixed-size
//! arrays, which the compiler vectorises for the baseline instruction set (two 128-bit
//! halves on x86-64); where the processor has AVX (checked once, at construction) the
//! same code is compiled a second time with AVX enabled and that copy runs. Rust never
//! fuses a multiply and an add, so both copies round identically.

use super::play::{FLUSH, FLUSH_EVERY};
use super::{LANES, MAX_MODES, MAX_POST_SECTIONS, Section, Voice};

/// How many voices run together.
pub const LANE_WIDTH: usize = 8;

/// Samples per inner run: the engine's sub-block, and at most one flush period.
const RUN: usize = FLUSH_EVERY;

type V = [f32; LANE_WIDTH];
const ZERO: V = [0.0; LANE_WIDTH];

/// One voice's part in a [`VoiceLanes::process`] call: the voice, its input and where its
/// output goes (the same length for every lane of a call).
#[derive(Debug)]
pub struct Lane<'a> {
    /// The voice; its state is carried on as if it had run alone.
    pub voice: &'a mut Voice,
    /// Its drive.
    pub input: &'a [f32],
    /// Its output, overwritten.
    pub output: &'a mut [f32],
}

/// Runs up to [`LANE_WIDTH`] voices together. Holds the voices' coefficients and state
/// in lane order while they run, and the inputs and outputs of a run transposed; made
/// once, off the audio thread (about 8 KB), then never allocates.
#[derive(Debug, Clone)]
pub struct VoiceLanes {
    pole_re: [V; MAX_MODES],
    pole_im: [V; MAX_MODES],
    res_re: [V; MAX_MODES],
    res_im: [V; MAX_MODES],
    state_re: [V; MAX_MODES],
    state_im: [V; MAX_MODES],
    direct: V,
    gain: V,
    b: [[V; 3]; MAX_POST_SECTIONS],
    a: [[V; 2]; MAX_POST_SECTIONS],
    s: [[V; 2]; MAX_POST_SECTIONS],
    x: [V; RUN],
    y: [V; RUN],
    /// Whose coefficients each lane holds ([`Voice::generation`]; 0: none).
    generation: [u64; LANE_WIDTH],
    avx: bool,
}

impl Default for VoiceLanes {
    fn default() -> Self {
        Self::new()
    }
}

impl VoiceLanes {
    /// Lanes for any voices, with the widest vectors the processor has.
    #[must_use]
    pub fn new() -> Self {
        Self {
            pole_re: [ZERO; MAX_MODES],
            pole_im: [ZERO; MAX_MODES],
            res_re: [ZERO; MAX_MODES],
            res_im: [ZERO; MAX_MODES],
            state_re: [ZERO; MAX_MODES],
            state_im: [ZERO; MAX_MODES],
            direct: ZERO,
            gain: ZERO,
            // Every lane holds no voice: zero modes, identity sections.
            b: [[[1.0; LANE_WIDTH], ZERO, ZERO]; MAX_POST_SECTIONS],
            a: [[ZERO; 2]; MAX_POST_SECTIONS],
            s: [[ZERO; 2]; MAX_POST_SECTIONS],
            x: [ZERO; RUN],
            y: [ZERO; RUN],
            generation: [0; LANE_WIDTH],
            avx: has_avx(),
        }
    }

    /// The same, on the baseline instruction set whatever the processor has: for the
    /// tests that compare the two.
    #[must_use]
    pub fn baseline() -> Self {
        Self {
            avx: false,
            ..Self::new()
        }
    }

    /// Runs each present lane's voice over its input into its output, as
    /// [`Voice::process`] would, and returns the non-finite samples met (each reset its
    /// voice and was written as zero). Lanes must share one length; a lane whose input
    /// or output is shorter than the first lane's is left out. Never allocates, locks or
    /// panics.
    pub fn process(&mut self, lanes: &mut [Option<Lane<'_>>; LANE_WIDTH]) -> u32 {
        let Some(n) = lanes.iter().flatten().map(|l| l.input.len()).next() else {
            return 0;
        };
        for lane in lanes.iter_mut() {
            if lane
                .as_ref()
                .is_some_and(|l| l.input.len() < n || l.output.len() < n)
            {
                *lane = None;
            }
        }
        // A voice on its own runs alone: the same bits, without seven idle lanes.
        if lanes.iter().flatten().count() == 1
            && let Some(l) = lanes.iter_mut().flatten().next()
        {
            return l.voice.process(&l.input[..n], &mut l.output[..n]);
        }
        let (groups, sections) = self.gather(lanes);
        let mut resets = [0u32; LANE_WIDTH];
        let mut start = 0;
        while start < n {
            // Up to the first flush any voice is due, so each flushes on its own clock.
            let len = lanes
                .iter()
                .flatten()
                .map(|l| FLUSH_EVERY - (l.voice.clock % FLUSH_EVERY as u64) as usize)
                .fold(n - start, usize::min);
            for (c, lane) in lanes.iter().enumerate() {
                match lane {
                    Some(l) => {
                        for (x, v) in self.x[..len].iter_mut().zip(&l.input[start..start + len]) {
                            x[c] = *v;
                        }
                    }
                    None => self.x[..len].iter_mut().for_each(|x| x[c] = 0.0),
                }
            }
            self.dispatch(groups, sections, len, &mut resets);
            for (c, lane) in lanes.iter_mut().enumerate() {
                if let Some(l) = lane {
                    for (out, y) in l.output[start..start + len].iter_mut().zip(&self.y) {
                        *out = y[c];
                    }
                    l.voice.clock += len as u64;
                    if l.voice.clock.is_multiple_of(FLUSH_EVERY as u64) {
                        self.flush_lane(c, l.voice.lanes);
                    }
                }
            }
            start += len;
        }
        self.scatter(lanes, sections);
        resets.iter().sum()
    }

    /// Copies the voices into lane order: the coefficients of a lane whose voice changed
    /// since the last call (absent lanes get zeros and identity sections), the state
    /// of all. Returns the groups of four modes and the post sections the widest voice
    /// runs, as [`Voice::process`] counts them.
    fn gather(&mut self, lanes: &[Option<Lane<'_>>; LANE_WIDTH]) -> (usize, usize) {
        let groups = lanes
            .iter()
            .flatten()
            .map(|l| l.voice.lanes / LANES)
            .max()
            .unwrap_or(0)
            .min(MAX_MODES / LANES);
        let sections = lanes
            .iter()
            .flatten()
            .map(|l| section_run(l.voice.section_count))
            .max()
            .unwrap_or(0);
        for (c, lane) in lanes.iter().enumerate() {
            let v = lane.as_ref().map(|l| &*l.voice);
            if v.map_or(0, |v| v.generation) != self.generation[c] {
                self.copy_coefficients(c, v);
            }
            // A voice's modes past its own count run as zeros, whatever its arrays hold.
            let own = v.map_or(0, |v| v.lanes).min(MAX_MODES);
            for k in 0..groups * LANES {
                let (re, im) = match v {
                    Some(v) if k < own => (v.state_re[k], v.state_im[k]),
                    _ => (0.0, 0.0),
                };
                self.state_re[k][c] = re;
                self.state_im[k][c] = im;
            }
            for i in 0..sections {
                let [s0, s1] = v.map_or([0.0; 2], |v| v.sections[i].s);
                self.s[i][0][c] = s0;
                self.s[i][1][c] = s1;
            }
        }
        (groups, sections)
    }

    /// Lane `c`'s coefficients from `voice` (zeros and identity sections for none),
    /// all of them, so that the lane is right whatever the other lanes' widths.
    fn copy_coefficients(&mut self, c: usize, voice: Option<&Voice>) {
        let own = voice.map_or(0, |v| v.lanes).min(MAX_MODES);
        for k in 0..MAX_MODES {
            let (pr, pi, rr, ri) = match voice {
                Some(v) if k < own => (v.pole_re[k], v.pole_im[k], v.res_re[k], v.res_im[k]),
                _ => (0.0, 0.0, 0.0, 0.0),
            };
            self.pole_re[k][c] = pr;
            self.pole_im[k][c] = pi;
            self.res_re[k][c] = rr;
            self.res_im[k][c] = ri;
        }
        self.direct[c] = voice.map_or(0.0, |v| v.direct);
        self.gain[c] = voice.map_or(0.0, |v| v.gain);
        for i in 0..MAX_POST_SECTIONS {
            let sec = voice.map_or(Section::IDENTITY, |v| v.sections[i]);
            for (t, f) in self.b[i].iter_mut().zip(sec.b) {
                t[c] = f;
            }
            for (t, f) in self.a[i].iter_mut().zip(sec.a) {
                t[c] = f;
            }
        }
        self.generation[c] = voice.map_or(0, |v| v.generation);
    }

    /// Copies the state back into the voices.
    fn scatter(&self, lanes: &mut [Option<Lane<'_>>; LANE_WIDTH], sections: usize) {
        for (c, lane) in lanes.iter_mut().enumerate() {
            let Some(l) = lane else { continue };
            let v = &mut *l.voice;
            let modes = v.lanes.min(MAX_MODES);
            for k in 0..modes {
                v.state_re[k] = self.state_re[k][c];
                v.state_im[k] = self.state_im[k][c];
            }
            for i in 0..sections {
                v.sections[i].s = [self.s[i][0][c], self.s[i][1][c]];
            }
        }
    }

    /// [`Voice`]'s flush, on lane `c`'s first `modes` modes and all its sections.
    fn flush_lane(&mut self, c: usize, modes: usize) {
        for k in 0..modes.min(MAX_MODES) {
            if self.state_re[k][c].abs() < FLUSH && self.state_im[k][c].abs() < FLUSH {
                self.state_re[k][c] = 0.0;
                self.state_im[k][c] = 0.0;
            }
        }
        for s in &mut self.s {
            for v in s {
                if v[c].abs() < FLUSH {
                    v[c] = 0.0;
                }
            }
        }
    }

    fn dispatch(
        &mut self,
        groups: usize,
        sections: usize,
        len: usize,
        resets: &mut [u32; LANE_WIDTH],
    ) {
        // One monomorphised loop per group and section count, as in `Voice::process`.
        macro_rules! sections {
            ($g:literal) => {
                match sections {
                    0 => self.run_best::<$g, 0>(len, resets),
                    1 => self.run_best::<$g, 1>(len, resets),
                    2 => self.run_best::<$g, 2>(len, resets),
                    3 => self.run_best::<$g, 3>(len, resets),
                    4 => self.run_best::<$g, 4>(len, resets),
                    _ => self.run_best::<$g, MAX_POST_SECTIONS>(len, resets),
                }
            };
        }
        match groups {
            0 => sections!(0),
            1 => sections!(1),
            2 => sections!(2),
            3 => sections!(3),
            4 => sections!(4),
            5 => sections!(5),
            6 => sections!(6),
            7 => sections!(7),
            _ => sections!(8),
        }
    }

    fn run_best<const G: usize, const S: usize>(
        &mut self,
        len: usize,
        resets: &mut [u32; LANE_WIDTH],
    ) {
        #[cfg(target_arch = "x86_64")]
        if self.avx {
            // SAFETY: `avx` is set only where the processor reported AVX at construction.
            unsafe { self.run_avx::<G, S>(len, resets) };
            return;
        }
        self.run::<G, S>(len, resets);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    fn run_avx<const G: usize, const S: usize>(
        &mut self,
        len: usize,
        resets: &mut [u32; LANE_WIDTH],
    ) {
        self.run::<G, S>(len, resets);
    }

    /// The loop of [`Voice::process`], each operation on all lanes.
    #[inline(always)]
    fn run<const G: usize, const S: usize>(&mut self, len: usize, resets: &mut [u32; LANE_WIDTH]) {
        let modes = G * LANES;
        let (pr, pi) = (&self.pole_re[..modes], &self.pole_im[..modes]);
        let (rr, ri) = (&self.res_re[..modes], &self.res_im[..modes]);
        let (sr, si) = (&mut self.state_re[..modes], &mut self.state_im[..modes]);
        let (b, a) = (&self.b[..S], &self.a[..S]);
        let s = &mut self.s[..S];
        let (gain, direct) = (self.gain, self.direct);
        for (xin, yout) in self.x[..len].iter().zip(&mut self.y[..len]) {
            let x = mul(*xin, gain);
            let mut acc = [ZERO; LANES];
            for k in 0..modes {
                let nr = add(sub(mul(pr[k], sr[k]), mul(pi[k], si[k])), mul(rr[k], x));
                let ni = add(add(mul(pr[k], si[k]), mul(pi[k], sr[k])), mul(ri[k], x));
                sr[k] = nr;
                si[k] = ni;
                acc[k % LANES] = add(acc[k % LANES], nr);
            }
            let mut v = add(
                mul(direct, x),
                add(add(acc[0], acc[1]), add(acc[2], acc[3])),
            );
            for ((bi, ai), si) in b.iter().zip(a).zip(s.iter_mut()) {
                let y = add(mul(bi[0], v), si[0]);
                si[0] = add(sub(mul(bi[1], v), mul(ai[0], y)), si[1]);
                si[1] = sub(mul(bi[2], v), mul(ai[1], y));
                v = y;
            }
            if !all_finite(&v) {
                for c in 0..LANE_WIDTH {
                    if v[c].is_finite() {
                        continue;
                    }
                    for k in 0..modes {
                        sr[k][c] = 0.0;
                        si[k][c] = 0.0;
                    }
                    for [s0, s1] in s.iter_mut() {
                        s0[c] = 0.0;
                        s1[c] = 0.0;
                    }
                    resets[c] += 1;
                    v[c] = 0.0;
                }
            }
            *yout = v;
        }
    }
}

#[inline(always)]
fn add(a: V, b: V) -> V {
    std::array::from_fn(|c| a[c] + b[c])
}

#[inline(always)]
fn sub(a: V, b: V) -> V {
    std::array::from_fn(|c| a[c] - b[c])
}

/// Without a branch per lane, so that it stays a vector comparison.
#[inline(always)]
fn all_finite(v: &V) -> bool {
    v.iter().fold(true, |ok, x| ok & x.is_finite())
}

#[inline(always)]
fn mul(a: V, b: V) -> V {
    std::array::from_fn(|c| a[c] * b[c])
}

/// The post sections [`Voice::process`] runs for `count`: up to four as they are, more
/// as all eight (the spare ones pass their input through).
fn section_run(count: usize) -> usize {
    if count <= 4 { count } else { MAX_POST_SECTIONS }
}

fn has_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
