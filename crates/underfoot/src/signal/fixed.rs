//! Second-order-section cascades in `f32`, Q15 and Q31, for firmware: the per-sample
//! arithmetic of the C reference that `underfoot::export` writes, bit for bit.
//!
//! Everything here works without `std` and never allocates: sections and states are
//! slices the caller owns (static arrays on a microcontroller).
//!
//! # Structure: direct form I
//!
//! Each section computes
//!
//! $$ y\[n\] = b_0 x\[n\] + b_1 x\[n-1\] + b_2 x\[n-2\] - a_1 y\[n-1\] - a_2 y\[n-2\] $$
//!
//! in direct form I: the sum of five products lands in one wide accumulator and is
//! rounded once, so an intermediate overflow inside the sum does no harm as long as the
//! final value fits, and the state holds only input and output samples (data-format
//! values, nothing wider).
//!
//! # Fixed-point formats
//!
//! Data are Q15 (`i16`, value `v / 2^15`) or Q31 (`i32`, `v / 2^31`). The denominator
//! of a resonant section has `|a_1|` close to 2, outside Q15's `[-1, 1)`, so each
//! section carries a *post-shift* `k` (the CMSIS-DSP `postShift` convention, here per
//! section): its coefficients are stored as `round(c 2^(15-k))` (Q(k).(15-k)), the five
//! products add up in a 32-bit accumulator in Q(30-k), and the output is that
//! accumulator shifted right by `15 - k` with rounding and saturation. `k` is the
//! smallest shift that holds the section's largest coefficient, usually 1 (Q1.14): one
//! bit of coefficient precision is the whole price. Q31 is the same with 32-bit
//! coefficients, a 64-bit accumulator and a shift of `31 - k`.
//!
//! # Scaling between sections
//!
//! A resonant section has a peak gain of tens of dB, so a full-scale input would
//! overflow the data format inside the cascade. Each section therefore shifts the sum of
//! its three numerator products right by `m` bits (a gain of `2^-m`) in the
//! accumulator, before the recursive terms join it. Shifting the exact 32-bit (64-bit)
//! product sum costs no coefficient precision, where scaling the coefficients would: a
//! numerator scaled by 1/300 keeps only 7 of its 15 bits in Q15, and the zeros the fit
//! placed next to its poles move. The exporter picks `m` per section (see
//! `underfoot::export`); the cascade's output is then the model's divided by `2^(Σm)`.
//!
//! Every addition saturates (it never wraps: a wrapped accumulator is a full-scale
//! click on skin), and the output saturates to the data format.
//!
//! # Error feedback
//!
//! The rounding of `y` injects an error `e\[n\]` that the section's own poles amplify, by
//! about `1 / ((1-r) 4 sin^2 θ)` in power for a pole at radius `r` and angle `θ`: some
//! 40 dB for the 20 Hz resonances of the built-in materials at 2 kHz, which would bury
//! their quiet band edges in Q15 noise. Each section may therefore feed its past
//! rounding errors (the bits the shift drops, known exactly) back into the accumulator
//! with small integer weights `f_1, f_2` before rounding:
//!
//! $$ v\[n\] = acc\[n\] + f_1 e\[n-1\] + f_2 e\[n-2\], \quad y\[n\] = \operatorname{round}(v\[n\]), \quad e\[n\] = v\[n\] - y\[n\] $$
//!
//! so the error reaches the output through `(1 - f_1 z^{-1} - f_2 z^{-2}) / A(z)`
//! instead of `1 / A(z)`. With `f_1 = round(-a_1)`, `f_2 = round(-a_2)` (2 and -1 for a
//! pole near `z = 1`) the numerator nearly cancels the resonance (Higgins and Munson's
//! error-spectrum shaping). The weights are integers, so the feedback costs two small
//! multiplies and no precision; `[0, 0]` turns it off. The exporter picks, per section,
//! whichever of the two has the smaller noise gain. (Feedback can also sustain a small
//! zero-input limit cycle; the exporter's impulse-response check sees it.)
//!
//! # Float
//!
//! The `f32` cascade is the same direct form I without any of this, summed left to
//! right in the order written above, which is what the C reference does (with
//! floating-point contraction off, as ISO C mode compiles it).

/// Rounding errors are fed back with these integer weights at most.
pub const MAX_FEEDBACK: i8 = 2;

/// One section in Q15: coefficients in Q(k).(15-k) for the post-shift `k`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Q15Section {
    /// Numerator `b0, b1, b2`.
    pub b: [i16; 3],
    /// Denominator `a1, a2` (`a0 = 1`), as in `y = ... - a1 y[n-1] - a2 y[n-2]`.
    pub a: [i16; 2],
    /// Post-shift `k`: integer bits of the coefficients (at most 14).
    pub shift: u8,
    /// Error-feedback weights `f1, f2` (see the module doc); `[0, 0]` for none.
    pub feedback: [i8; 2],
    /// Scaling: the numerator's sum is shifted right by this many bits (at most 30).
    pub scale: u8,
}

/// One section in Q31: coefficients in Q(k).(31-k) for the post-shift `k`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Q31Section {
    /// Numerator `b0, b1, b2`.
    pub b: [i32; 3],
    /// Denominator `a1, a2` (`a0 = 1`).
    pub a: [i32; 2],
    /// Post-shift `k` (at most 30).
    pub shift: u8,
    /// Error-feedback weights `f1, f2`; `[0, 0]` for none.
    pub feedback: [i8; 2],
    /// Scaling: the numerator's sum is shifted right by this many bits (at most 62).
    pub scale: u8,
}

/// One section in `f32`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct F32Section {
    /// Numerator `b0, b1, b2`.
    pub b: [f32; 3],
    /// Denominator `a1, a2` (`a0 = 1`).
    pub a: [f32; 2],
}

/// The state of a [`Q15Section`]; `Default` is rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Q15State {
    x: [i16; 2],
    y: [i16; 2],
    e: [i32; 2],
}

/// The state of a [`Q31Section`]; `Default` is rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Q31State {
    x: [i32; 2],
    y: [i32; 2],
    e: [i64; 2],
}

/// The state of an [`F32Section`]; `Default` is rest.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct F32State {
    x: [f32; 2],
    y: [f32; 2],
}

/// `round(c 2^frac)` as an integer of `bits` bits, or `None` when it does not fit or
/// `c` is not finite.
#[must_use]
pub fn quantize(c: f64, frac: u32, bits: u32) -> Option<i64> {
    if !c.is_finite() || frac > 62 || !(2..=63).contains(&bits) {
        return None;
    }
    let q = crate::math::round(c * (1u64 << frac) as f64);
    let max = ((1i64 << (bits - 1)) - 1) as f64;
    let min = -((1i64 << (bits - 1)) as f64);
    (q >= min && q <= max).then_some(q as i64)
}

/// The smallest post-shift whose Q(k).(bits-1-k) holds every coefficient, up to
/// `bits - 2`; `None` when none does (or a coefficient is not finite).
#[must_use]
pub fn post_shift(coefficients: &[f64], bits: u32) -> Option<u8> {
    (0..bits.saturating_sub(1)).find_map(|k| {
        coefficients
            .iter()
            .all(|&c| quantize(c, bits - 1 - k, bits).is_some())
            .then_some(k as u8)
    })
}

impl Q15Section {
    /// The section nearest to `b 2^-scale`, `a` (`a0 = 1`), with the smallest post-shift
    /// that holds `b` and `a`; `None` for a non-finite coefficient or one of magnitude `2^14` or
    /// more.
    #[must_use]
    pub fn quantize(b: [f64; 3], a: [f64; 2], feedback: [i8; 2], scale: u8) -> Option<Self> {
        let all = [b[0], b[1], b[2], a[0], a[1]];
        let shift = post_shift(&all, 16)?;
        let frac = 15 - u32::from(shift);
        let q = |c: f64| quantize(c, frac, 16).map(|v| v as i16);
        Some(Self {
            b: [q(b[0])?, q(b[1])?, q(b[2])?],
            a: [q(a[0])?, q(a[1])?],
            shift,
            feedback: clamp_feedback(feedback),
            scale,
        })
    }

    /// The coefficients this section represents, `(b, a)`, scaling included.
    #[must_use]
    pub fn coefficients(&self) -> ([f64; 3], [f64; 2]) {
        let scale = 1.0 / (1u64 << (15 - u32::from(self.shift.min(14)))) as f64;
        let v = |c: i16| f64::from(c) * scale;
        let g = 1.0 / (1u64 << self.scale.min(30)) as f64;
        (
            [v(self.b[0]) * g, v(self.b[1]) * g, v(self.b[2]) * g],
            [v(self.a[0]), v(self.a[1])],
        )
    }

    /// One sample through the section.
    #[inline]
    pub fn tick(&self, state: &mut Q15State, x: i16) -> i16 {
        let s = 15 - u32::from(self.shift.min(14));
        let mut acc = i32::from(self.b[0]) * i32::from(x);
        acc = acc.saturating_add(i32::from(self.b[1]) * i32::from(state.x[0]));
        acc = acc.saturating_add(i32::from(self.b[2]) * i32::from(state.x[1]));
        acc >>= self.scale.min(30);
        acc = acc.saturating_sub(i32::from(self.a[0]) * i32::from(state.y[0]));
        acc = acc.saturating_sub(i32::from(self.a[1]) * i32::from(state.y[1]));
        acc = acc.saturating_add(i32::from(self.feedback[0]) * state.e[0]);
        acc = acc.saturating_add(i32::from(self.feedback[1]) * state.e[1]);
        let rounded = acc.saturating_add(1 << (s - 1)) >> s;
        let y = rounded.clamp(i32::from(i16::MIN), i32::from(i16::MAX));
        // A saturated output's "error" is the overload itself: feeding it back would
        // keep the section pinned, so it is dropped.
        let e = if y == rounded { acc - (y << s) } else { 0 };
        state.x = [x, state.x[0]];
        state.y = [y as i16, state.y[0]];
        state.e = [e, state.e[0]];
        y as i16
    }
}

impl Q31Section {
    /// The section nearest to `b 2^-scale`, `a` (`a0 = 1`), with the smallest post-shift
    /// that holds `b` and `a`; `None` for a non-finite coefficient or one of magnitude `2^30` or
    /// more.
    #[must_use]
    pub fn quantize(b: [f64; 3], a: [f64; 2], feedback: [i8; 2], scale: u8) -> Option<Self> {
        let all = [b[0], b[1], b[2], a[0], a[1]];
        let shift = post_shift(&all, 32)?;
        let frac = 31 - u32::from(shift);
        let q = |c: f64| quantize(c, frac, 32).map(|v| v as i32);
        Some(Self {
            b: [q(b[0])?, q(b[1])?, q(b[2])?],
            a: [q(a[0])?, q(a[1])?],
            shift,
            feedback: clamp_feedback(feedback),
            scale,
        })
    }

    /// The coefficients this section represents, `(b, a)`, scaling included.
    #[must_use]
    pub fn coefficients(&self) -> ([f64; 3], [f64; 2]) {
        let scale = 1.0 / (1u64 << (31 - u32::from(self.shift.min(30)))) as f64;
        let v = |c: i32| f64::from(c) * scale;
        let g = 1.0 / (1u64 << self.scale.min(62)) as f64;
        (
            [v(self.b[0]) * g, v(self.b[1]) * g, v(self.b[2]) * g],
            [v(self.a[0]), v(self.a[1])],
        )
    }

    /// One sample through the section.
    #[inline]
    pub fn tick(&self, state: &mut Q31State, x: i32) -> i32 {
        let s = 31 - u32::from(self.shift.min(30));
        let mut acc = i64::from(self.b[0]) * i64::from(x);
        acc = acc.saturating_add(i64::from(self.b[1]) * i64::from(state.x[0]));
        acc = acc.saturating_add(i64::from(self.b[2]) * i64::from(state.x[1]));
        acc >>= self.scale.min(62);
        acc = acc.saturating_sub(i64::from(self.a[0]) * i64::from(state.y[0]));
        acc = acc.saturating_sub(i64::from(self.a[1]) * i64::from(state.y[1]));
        acc = acc.saturating_add(i64::from(self.feedback[0]) * state.e[0]);
        acc = acc.saturating_add(i64::from(self.feedback[1]) * state.e[1]);
        let rounded = acc.saturating_add(1 << (s - 1)) >> s;
        let y = rounded.clamp(i64::from(i32::MIN), i64::from(i32::MAX));
        let e = if y == rounded { acc - (y << s) } else { 0 };
        state.x = [x, state.x[0]];
        state.y = [y as i32, state.y[0]];
        state.e = [e, state.e[0]];
        y as i32
    }
}

impl F32Section {
    /// The section nearest to `b`, `a` (`a0 = 1`) in `f32`.
    #[must_use]
    pub fn new(b: [f64; 3], a: [f64; 2]) -> Self {
        Self {
            b: [b[0] as f32, b[1] as f32, b[2] as f32],
            a: [a[0] as f32, a[1] as f32],
        }
    }

    /// One sample through the section.
    #[inline]
    pub fn tick(&self, state: &mut F32State, x: f32) -> f32 {
        let y = self.b[0] * x + self.b[1] * state.x[0] + self.b[2] * state.x[1]
            - self.a[0] * state.y[0]
            - self.a[1] * state.y[1];
        state.x = [x, state.x[0]];
        state.y = [y, state.y[0]];
        y
    }
}

fn clamp_feedback(f: [i8; 2]) -> [i8; 2] {
    f.map(|w| w.clamp(-MAX_FEEDBACK, MAX_FEEDBACK))
}

/// One sample through a Q15 cascade; sections beyond the shorter of the two slices are
/// skipped.
#[inline]
pub fn q15_cascade(sections: &[Q15Section], states: &mut [Q15State], x: i16) -> i16 {
    sections
        .iter()
        .zip(states.iter_mut())
        .fold(x, |v, (s, st)| s.tick(st, v))
}

/// One sample through a Q31 cascade; sections beyond the shorter of the two slices are
/// skipped.
#[inline]
pub fn q31_cascade(sections: &[Q31Section], states: &mut [Q31State], x: i32) -> i32 {
    sections
        .iter()
        .zip(states.iter_mut())
        .fold(x, |v, (s, st)| s.tick(st, v))
}

/// One sample through an `f32` cascade; sections beyond the shorter of the two slices
/// are skipped.
#[inline]
pub fn f32_cascade(sections: &[F32Section], states: &mut [F32State], x: f32) -> f32 {
    sections
        .iter()
        .zip(states.iter_mut())
        .fold(x, |v, (s, st)| s.tick(st, v))
}

/// A Q15 value from a float in `[-1, 1)`, rounded and saturated.
#[must_use]
pub fn to_q15(x: f32) -> i16 {
    let v = crate::math::round(f64::from(x) * 32768.0);
    if v.is_nan() {
        0
    } else {
        v.clamp(-32768.0, 32767.0) as i16
    }
}

/// A Q31 value from a float in `[-1, 1)`, rounded and saturated.
#[must_use]
pub fn to_q31(x: f64) -> i32 {
    let v = crate::math::round(x * 2_147_483_648.0);
    if v.is_nan() {
        0
    } else {
        v.clamp(-2_147_483_648.0, 2_147_483_647.0) as i32
    }
}

/// Saturates a Q15 sample to `±ceiling`: the fixed-point path's hard limit (the float
/// path has [`crate::safety::Limiter`]).
#[must_use]
pub fn clamp_q15(x: i16, ceiling: i16) -> i16 {
    let c = ceiling.max(0);
    x.clamp(-c, c)
}

/// Saturates a Q31 sample to `±ceiling`.
#[must_use]
pub fn clamp_q31(x: i32, ceiling: i32) -> i32 {
    let c = ceiling.max(0);
    x.clamp(-c, c)
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::signal::noise::SplitMix64;
    use proptest::prelude::*;

    /// The definition, in exact integer arithmetic (i128, no saturation inside the sum):
    /// what the Q15 section must compute whenever nothing saturates.
    fn naive_q15(sec: &Q15Section, x: &[i16]) -> Vec<i16> {
        let s = 15 - u32::from(sec.shift);
        let (mut x1, mut x2, mut y1, mut y2, mut e1, mut e2) = (0i128, 0i128, 0i128, 0, 0, 0);
        let c = |v: i16| i128::from(v);
        let mut out = Vec::new();
        for &xn in x {
            let num = c(sec.b[0]) * i128::from(xn) + c(sec.b[1]) * x1 + c(sec.b[2]) * x2;
            let v = num.div_euclid(1 << sec.scale) - c(sec.a[0]) * y1 - c(sec.a[1]) * y2
                + i128::from(sec.feedback[0]) * e1
                + i128::from(sec.feedback[1]) * e2;
            // Round half up: floor((v + 2^(s-1)) / 2^s).
            let y = (v + (1 << (s - 1))).div_euclid(1 << s);
            let y = y.clamp(-32768, 32767);
            let e = v - (y << s);
            (x2, x1, y2, y1, e2, e1) = (x1, i128::from(xn), y1, y, e1, e);
            out.push(y as i16);
        }
        out
    }

    #[test]
    fn q15_matches_the_exact_definition_on_a_resonance() {
        // A 20 Hz resonance at 2 kHz with zeros at DC and Nyquist, scaled so that a
        // half-scale input stays well inside the range: nothing saturates.
        let (r, th) = (0.997f64, std::f64::consts::TAU * 20.0 / 2000.0);
        let a = [-2.0 * r * th.cos(), r * r];
        let b = [0.002, 0.0, -0.002];
        for feedback in [[0, 0], [2, -1]] {
            let sec = Q15Section::quantize(b, a, feedback, 0).unwrap();
            assert_eq!(sec.shift, 1);
            let sec = Q15Section {
                b: sec.b.map(|v| v * 8),
                scale: 3,
                ..sec
            };
            let mut g = SplitMix64::new(3);
            let x: Vec<i16> = (0..4000)
                .map(|_| (g.symmetric() * 16000.0) as i16)
                .collect();
            let mut st = Q15State::default();
            let got: Vec<i16> = x.iter().map(|&v| sec.tick(&mut st, v)).collect();
            assert_eq!(got, naive_q15(&sec, &x), "feedback {feedback:?}");
        }
    }

    #[test]
    fn error_feedback_lowers_the_noise_of_a_low_resonance() {
        let (r, th) = (0.997f64, std::f64::consts::TAU * 20.0 / 2000.0);
        let a = [-2.0 * r * th.cos(), r * r];
        let b = [0.002, 0.0, -0.002];
        let noise = |feedback| {
            let q = Q15Section::quantize(b, a, feedback, 0).unwrap();
            let (qb, qa) = q.coefficients();
            let f = F32Section::new(qb, qa);
            let (mut sq, mut sf) = (Q15State::default(), F32State::default());
            let mut g = SplitMix64::new(5);
            (0..20_000)
                .map(|_| {
                    let x = (g.symmetric() * 8000.0) as i16;
                    let yq = f64::from(q.tick(&mut sq, x));
                    let yf = f64::from(f.tick(&mut sf, f32::from(x)));
                    (yq - yf).powi(2)
                })
                .sum::<f64>()
        };
        let (plain, shaped) = (noise([0, 0]), noise([2, -1]));
        assert!(shaped * 10.0 < plain, "{shaped} vs {plain}");
    }

    #[test]
    fn post_shift_is_the_smallest_that_fits() {
        assert_eq!(post_shift(&[0.5, -0.99], 16), Some(0));
        assert_eq!(post_shift(&[-1.98, 0.99], 16), Some(1));
        assert_eq!(post_shift(&[3.5], 16), Some(2));
        assert_eq!(post_shift(&[f64::NAN], 16), None);
        assert_eq!(post_shift(&[1e9], 16), None);
        // Exactly 1.0 does not fit Q0.15 (its largest value is 1 - 2^-15).
        assert_eq!(post_shift(&[1.0], 16), Some(1));
    }

    proptest! {
        #[test]
        fn quantisation_error_is_at_most_half_a_step(
            c in -1.9f64..1.9, k in 1u32..4,
        ) {
            for (bits, frac) in [(16u32, 15 - k), (32, 31 - k)] {
                let q = quantize(c, frac, bits).unwrap();
                let step = 1.0 / (1u64 << frac) as f64;
                prop_assert!((q as f64 * step - c).abs() <= step / 2.0 + 1e-18);
            }
        }

        #[test]
        fn q15_output_is_the_clamped_exact_value(
            seed in any::<u64>(), gain in 0.1f64..100.0, fb in 0usize..2,
        ) {
            // A loud resonance driven hard. At every sample, from the section's own
            // state: whenever the exact partial sums fit the 32-bit accumulator, the
            // output is the exact rounded value clamped to the rails (a wrap would give
            // the opposite sign).
            let mut g = SplitMix64::new(seed);
            let feedback = [[0, 0], [2, -1]][fb];
            let Some(sec) =
                Q15Section::quantize([gain * 0.01, 0.0, -gain * 0.01], [-1.9, 0.95], feedback, 0)
            else {
                return Ok(());
            };
            let s = 15 - u32::from(sec.shift);
            let mut st = Q15State::default();
            for _ in 0..500 {
                let x = to_q15(g.symmetric() as f32);
                let terms = [
                    i128::from(sec.b[0]) * i128::from(x),
                    i128::from(sec.b[1]) * i128::from(st.x[0]),
                    i128::from(sec.b[2]) * i128::from(st.x[1]),
                    -i128::from(sec.a[0]) * i128::from(st.y[0]),
                    -i128::from(sec.a[1]) * i128::from(st.y[1]),
                    i128::from(sec.feedback[0]) * i128::from(st.e[0]),
                    i128::from(sec.feedback[1]) * i128::from(st.e[1]),
                ];
                let fits = terms
                    .iter()
                    .scan(0i128, |acc, t| { *acc += t; Some(*acc) })
                    .all(|p| i32::try_from(p).is_ok());
                let v: i128 = terms.iter().sum();
                let exact = (v + (1 << (s - 1))).div_euclid(1 << s);
                let y = sec.tick(&mut st, x);
                if fits {
                    prop_assert_eq!(i128::from(y), exact.clamp(-32768, 32767));
                }
            }
        }
    }

    #[test]
    fn a_saturated_accumulator_stays_at_the_rail() {
        // Every product at its largest: the exact sum is 5 * 2^30, far past i32; a
        // wrapping accumulator would come out negative.
        let sec = Q15Section {
            b: [i16::MAX; 3],
            a: [i16::MIN, i16::MIN],
            shift: 0,
            feedback: [0, 0],
            scale: 0,
        };
        let mut st = Q15State {
            x: [i16::MAX; 2],
            y: [i16::MAX; 2],
            e: [0; 2],
        };
        assert_eq!(sec.tick(&mut st, i16::MAX), i16::MAX);
        let sec31 = Q31Section {
            b: [i32::MAX; 3],
            a: [i32::MIN, i32::MIN],
            shift: 0,
            feedback: [0, 0],
            scale: 0,
        };
        let mut st = Q31State {
            x: [i32::MAX; 2],
            y: [i32::MAX; 2],
            e: [0; 2],
        };
        assert_eq!(sec31.tick(&mut st, i32::MAX), i32::MAX);
        let neg = Q31Section {
            b: [i32::MIN; 3],
            ..sec31
        };
        let mut st = Q31State {
            x: [i32::MAX; 2],
            y: [i32::MIN; 2],
            e: [0; 2],
        };
        assert_eq!(neg.tick(&mut st, i32::MAX), i32::MIN);
    }
}
