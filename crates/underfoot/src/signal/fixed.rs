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
//! ```math
//! y[n] = b_0 x[n] + b_1 x[n-1] + b_2 x[n-2] - a_1 y[n-1] - a_2 y[n-2]
//! ```
//!
//! in direct form I: the sum of five products lands in one wide accumulator and is
//! rounded once, so an intermediate overflow inside the sum does no harm as long as the
//! final value fits, and the state holds only past input and output samples of the
//! signal path.
//!
//! # Q31
//!
//! Data are Q31 (`i32`, value `v / 2^31`). The denominator of a resonant section has
//! `|a_1|` close to 2, outside `[-1, 1)`, so each section carries a *post-shift* `k` (the
//! CMSIS-DSP `postShift` convention, here per section): its coefficients are stored as
//! `round(c 2^(31-k))` (Q(k).(31-k)), the five products add up in a 64-bit accumulator
//! in Q(62-k), and the output is that accumulator shifted right by `31 - k` with
//! rounding and saturation. `k` is the smallest shift that holds the section's largest
//! coefficient, usually 1.
//!
//! ## Scaling between sections
//!
//! A resonant section has a peak gain of tens of dB, so a full-scale input would
//! overflow the data format inside the cascade. Each section therefore shifts the sum of
//! its three numerator products right by `m` bits (a gain of `2^-m`) in the
//! accumulator, before the recursive terms join it. Shifting the exact product sum costs
//! no coefficient precision, where scaling the coefficients would. The exporter picks `m`
//! per section (see `underfoot::export`); the cascade's output is then the model's
//! divided by `2^(Σm)`.
//!
//! ## Error feedback
//!
//! The rounding of `y` injects an error `e\[n\]` that the section's own poles amplify, by
//! about `1 / ((1-r) 4 sin^2 θ)` in power for a pole at radius `r` and angle `θ`: some
//! 40 dB for the 20 Hz resonances of the built-in materials at 2 kHz. Each section may
//! therefore feed its past rounding errors (the bits the shift drops, known exactly) back
//! into the accumulator with small integer weights `f_1, f_2` before rounding:
//!
//! ```math
//! v[n] = acc[n] + f_1 e[n-1] + f_2 e[n-2], \quad y[n] = \operatorname{round}(v[n]), \quad e[n] = v[n] - y[n]
//! ```
//!
//! so the error reaches the output through `(1 - f_1 z^{-1} - f_2 z^{-2}) / A(z)`
//! instead of `1 / A(z)`. With `f_1 = round(-a_1)`, `f_2 = round(-a_2)` (2 and -1 for a
//! pole near `z = 1`) the numerator nearly cancels the resonance (Higgins and Munson's
//! error-spectrum shaping). `[0, 0]` turns it off; the exporter picks, per section,
//! whichever of the two has the smaller noise gain.
//!
//! # Q15: 16-bit coefficients, 32-bit signal path
//!
//! A 16-bit direct form with 16-bit data fails the low, sharp resonances of the fitted
//! materials twice over:
//!
//! * **Data-path noise.** Rounding each section's output to 16 bits injects noise that
//!   the section's poles amplify by some 40 dB (see above) and later sections shape; the
//!   quiet band edges of a material sit close to it.
//! * **Coefficient precision near `z = 1`.** A pole pair at radius `r`, angle `θ` has
//!   `a_1 = -2 r cos θ ≈ -2`: in Q1.14 its step is `2^-14 = 6e-5`, and a 22 Hz pole at
//!   2 kHz (`θ = 0.07`) moves by a sizeable fraction of its distance to `z = 1` for one
//!   step.
//!
//! The Q15 format keeps what a 16-bit microcontroller multiplies cheaply, 16-bit
//! coefficients, and fixes both:
//!
//! * The **signal between sections and the section states are 32-bit** (Q31). The
//!   cascade's input is Q15, promoted exactly (`x 2^16`), and its **output is the last
//!   section's Q31 value**, not rounded back to 16 bits. Each product is 16 x 32 bits
//!   (two 16 x 16 multiplies on a 16-bit part), summed in a 64-bit accumulator, and each
//!   section's output is rounded to 32 bits: its rounding noise is `2^16` times smaller
//!   than with 16-bit data, far below a Q15 step even after the resonance's gain, so no
//!   error feedback is needed, and it stays so for quiet drives: the deviation of the
//!   32-bit output from the float model is the coefficients' at every level from 0 to
//!   -30 dBFS (measured on the built-ins: within 0.05 dB of the same figure at every
//!   level).
//! * **Why the output stays 32-bit.** Rounding the output to Q15 was the only part of
//!   the loop whose error grows as the drive gets quieter: an impulse at -30 dBFS
//!   peaks some 500 Q15 steps out of the (scaled) cascade, and the rounding error of its
//!   whole response, white and coherent in the decaying tail, lands on the quiet band
//!   edges of a material, far below its peak. Measured on the built-ins: 0.06-0.35 dB
//!   at 0 dBFS, 0.4-6.9 dB at -30 dBFS, where the 32-bit output stays at 0.003-0.18 dB.
//!   The same rounding of the *float* model's output costs the same (0.4-6.9 dB at
//!   -30 dBFS), so no arithmetic before it can remove it (noise shaping could only move
//!   it, and a 20-900 Hz band leaves little of 0-1000 Hz to move it to); it belongs to
//!   the output device (a 16-bit DAC
//!   quantises any filter's output alike, a 12-bit one more), which is where firmware
//!   applies it, with [`q31_to_q15`] or its own DAC width.
//! * The **denominator is split** into an integer part applied exactly and a 16-bit
//!   remainder with its own exponent: `a_i = c_i + d_i` with `c_i = round(a_i)`
//!   (`c_1 ∈ \[-2, 2\]`, `c_2 ∈ \[-1, 1\]` for a stable section) and
//!   `|d_i| <= 1/2`, stored as `round(d_i 2^{f_d})` with the largest `f_d` in
//!   `\[15, 28\]` that fits both. `c_i y` is a shift and an add of the 32-bit state; the
//!   remainder of a pole near `z = 1` is small (`a_1 = -1.98`: `d_1 = 0.02`, `f_d = 20`),
//!   so its step is `2^-20` instead of `2^-14`.
//! * The **numerator** has the same problem: the fit pairs each low resonance with
//!   zeros next to it, so `b_1 / b_0` and `b_2 / b_0` are close to -2 and 1 too. It is
//!   split the same way around `b_0` (scaling `2^-m` included): `b_0` is stored as
//!   `round(b_0 2^{f_b})` with the largest `f_b` that fits (16 bits whatever the
//!   scaling, which disappears into `f_b`), and `b_j = g_j b_0 + e_j` for `j = 1, 2`,
//!   with `g_j = round(b_j / b_0)` (clamped to `\[-2, 2\]`, 0 when `b_0 = 0`) and the
//!   remainders `e_j`, taken from the *quantised* `b_0` so that its rounding costs
//!   nothing, stored in 16 bits with their own exponent `f_e`. `g_j x` is again a shift
//!   and an add of the 32-bit state.
//!
//! Per section, with `x`, `y` Q31 and every integer part applied exactly:
//!
//! ```math
//! w = x[n] + g_1 x[n-1] + g_2 x[n-2]
//! ```
//!
//! ```math
//! acc = 2^{f_d - f_b} b_0 w + 2^{f_d - f_e} (e_1 x[n-1] + e_2 x[n-2]) - 2^{f_d} (c_1 y[n-1] + c_2 y[n-2]) - (d_1 y[n-1] + d_2 y[n-2])
//! ```
//!
//! ```math
//! y[n] = \operatorname{round}(acc\, 2^{-f_d})
//! ```
//!
//! five 16 x 32-bit multiplies (`b_0 w` is 16 x 35 bits) as in a plain direct form,
//! in that order, the numerator aligned by a left shift (saturating) or an arithmetic
//! right shift (the bits it drops lie 2^15 below the output's step), every addition
//! saturating, and the output saturated to 32 bits.
//!
//! Every addition saturates (it never wraps: a wrapped accumulator is a full-scale
//! click on skin), and every output saturates to its format.
//!
//! # Float
//!
//! The `f32` cascade is the same direct form I without any of this, summed left to
//! right in the order written above, which is what the C reference does (with
//! floating-point contraction off, as ISO C mode compiles it).

/// Rounding errors of a [`Q31Section`] are fed back with these integer weights at most.
pub const MAX_FEEDBACK: i8 = 2;

/// Fraction bits of a [`Q15Section`]'s numerator parts, at most.
pub const Q15_MAX_B_FRAC: u8 = 62;
/// Fraction bits of a [`Q15Section`]'s denominator remainders, at least: `|d| <= 1/2`
/// always fits `2^-15` steps in 16 bits.
pub const Q15_MIN_D_FRAC: u8 = 15;
/// Fraction bits of a [`Q15Section`]'s denominator remainders, at most: it keeps
/// `c y 2^d_frac` (`|c| <= 2`, `|y| < 2^31`) well inside 64 bits.
pub const Q15_MAX_D_FRAC: u8 = 28;

/// One section of the Q15 cascade: 16-bit coefficients for a 32-bit signal path (see the
/// module doc). It represents
///
/// * `b0 = b0_int 2^-b_frac`, `b_j = g_j b0 + e_int,j 2^-e_frac` (`j = 1, 2`), and
/// * `a_j = c_j + d_int,j 2^-d_frac`,
///
/// the integer parts `g`, `c` applied exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Q15Section {
    /// Numerator `b0` (scaling included), in steps of `2^-b_frac`.
    pub b0: i16,
    /// Fraction bits of `b0` (at most [`Q15_MAX_B_FRAC`]).
    pub b_frac: u8,
    /// Integer parts `g_j = round(b_j / b0)` (within ±2; 0 when `b0 = 0`).
    pub g: [i8; 2],
    /// Remainders `b_j - g_j b0`, in steps of `2^-e_frac`.
    pub e: [i16; 2],
    /// Fraction bits of `e` (at most [`Q15_MAX_B_FRAC`]).
    pub e_frac: u8,
    /// Integer parts `c_j = round(a_j)` of the denominator (`a0 = 1`, as in
    /// `y = ... - a1 y[n-1] - a2 y[n-2]`).
    pub c: [i8; 2],
    /// Remainders `a_j - c_j` (within ±1/2), in steps of `2^-d_frac`.
    pub d: [i16; 2],
    /// Fraction bits of `d` ([`Q15_MIN_D_FRAC`]..=[`Q15_MAX_D_FRAC`]).
    pub d_frac: u8,
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

/// The state of a [`Q15Section`]: its past inputs and outputs on the 32-bit path;
/// `Default` is rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Q15State {
    x: [i32; 2],
    y: [i32; 2],
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
    /// The section nearest to `b 2^-scale`, `a` (`a0 = 1`), every 16-bit part with the
    /// most fraction bits that hold it. `None` for a non-finite coefficient, a part of
    /// magnitude `2^15` or more, or `|a_j| > 2.5`.
    #[must_use]
    pub fn quantize(b: [f64; 3], a: [f64; 2], scale: u8) -> Option<Self> {
        let finest = |v: &[f64], lo: u8, hi: u8| {
            (lo..=hi)
                .rev()
                .find(|&f| v.iter().all(|&c| quantize(c, u32::from(f), 16).is_some()))
        };
        let q = |v: f64, f: u8| quantize(v, u32::from(f), 16).map(|q| q as i16);
        let b = b.map(|v| v / (1u64 << scale.min(62)) as f64);
        let b_frac = finest(&b[..1], 0, Q15_MAX_B_FRAC)?;
        let b0 = q(b[0], b_frac)?;
        let b0_value = f64::from(b0) / (1u64 << b_frac) as f64;
        // Zeros near z = 1 make b1/b0, b2/b0 close to -2 and 1, as poles do a1, a2; the
        // remainders are taken from the quantised b0, so its rounding costs nothing.
        let g = [b[1], b[2]].map(|v| {
            if b0_value == 0.0 {
                0.0
            } else {
                crate::math::round(v / b0_value).clamp(-2.0, 2.0)
            }
        });
        let e = [b[1] - g[0] * b0_value, b[2] - g[1] * b0_value];
        let e_frac = finest(&e, 0, Q15_MAX_B_FRAC)?;
        let c = a.map(crate::math::round);
        if !c.iter().all(|v| (-2.0..=2.0).contains(v)) {
            return None;
        }
        // Exact: an integer next to `a` leaves a remainder with no more bits than `a`.
        let d = [a[0] - c[0], a[1] - c[1]];
        let d_frac = finest(&d, Q15_MIN_D_FRAC, Q15_MAX_D_FRAC)?;
        Some(Self {
            b0,
            b_frac,
            g: [g[0] as i8, g[1] as i8],
            e: [q(e[0], e_frac)?, q(e[1], e_frac)?],
            e_frac,
            c: [c[0] as i8, c[1] as i8],
            d: [q(d[0], d_frac)?, q(d[1], d_frac)?],
            d_frac,
        })
    }

    /// The fraction bits as the loop uses them: `(b_frac, e_frac, d_frac)`, clamped.
    fn fracs(&self) -> (u32, u32, u32) {
        (
            u32::from(self.b_frac.min(Q15_MAX_B_FRAC)),
            u32::from(self.e_frac.min(Q15_MAX_B_FRAC)),
            u32::from(self.d_frac.clamp(Q15_MIN_D_FRAC, Q15_MAX_D_FRAC)),
        )
    }

    /// The coefficients this section represents, `(b, a)`, scaling included.
    #[must_use]
    pub fn coefficients(&self) -> ([f64; 3], [f64; 2]) {
        let (fb, fe, fd) = self.fracs();
        let b0 = f64::from(self.b0) / (1u64 << fb) as f64;
        let vb = |j: usize| f64::from(self.g[j]) * b0 + f64::from(self.e[j]) / (1u64 << fe) as f64;
        let va = |j: usize| f64::from(self.c[j]) + f64::from(self.d[j]) / (1u64 << fd) as f64;
        ([b0, vb(0), vb(1)], [va(0), va(1)])
    }

    /// One sample through the section, on the 32-bit path: `x` and the result are Q31
    /// (see [`q15_cascade`] for the 16-bit ends).
    #[inline]
    pub fn tick(&self, state: &mut Q15State, x: i32) -> i32 {
        let (fb, fe, fd) = self.fracs();
        // Aligns a sum in steps of 2^-(31+f) to the accumulator's 2^-(31+fd).
        let align = |v: i64, f: u32| {
            if fd >= f {
                shl_saturating(v, fd - f)
            } else {
                v >> (f - fd)
            }
        };
        let (x1, x2) = (i64::from(state.x[0]), i64::from(state.x[1]));
        // |w| < 2^39 and |b0 w| < 2^54 for any field values: no overflow.
        let w = i64::from(x) + i64::from(self.g[0]) * x1 + i64::from(self.g[1]) * x2;
        let mut acc = align(i64::from(self.b0) * w, fb);
        let rest = i64::from(self.e[0]) * x1 + i64::from(self.e[1]) * x2;
        acc = acc.saturating_add(align(rest, fe));
        let (y1, y2) = (i64::from(state.y[0]), i64::from(state.y[1]));
        acc = acc.saturating_sub(shl_saturating(i64::from(self.c[0]) * y1, fd));
        acc = acc.saturating_sub(shl_saturating(i64::from(self.c[1]) * y2, fd));
        acc = acc.saturating_sub(i64::from(self.d[0]) * y1);
        acc = acc.saturating_sub(i64::from(self.d[1]) * y2);
        let rounded = acc.saturating_add(1 << (fd - 1)) >> fd;
        let y = rounded.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
        state.x = [x, state.x[0]];
        state.y = [y, state.y[0]];
        y
    }
}

/// `v 2^n`, saturated to the `i64` range (`n <= 62`).
fn shl_saturating(v: i64, n: u32) -> i64 {
    if v > i64::MAX >> n {
        i64::MAX
    } else if v < i64::MIN >> n {
        i64::MIN
    } else {
        v << n
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

/// One sample through a Q15 cascade: the Q15 input is promoted to Q31 (exactly) and
/// runs through the sections on the 32-bit path; the result is the last section's Q31
/// value (see the module doc for why it is not rounded to Q15 here). Sections beyond
/// the shorter of the two slices are skipped.
#[inline]
pub fn q15_cascade(sections: &[Q15Section], states: &mut [Q15State], x: i16) -> i32 {
    sections
        .iter()
        .zip(states.iter_mut())
        .fold(i32::from(x) << 16, |v, (s, st)| s.tick(st, v))
}

/// A Q31 value truncated towards zero to Q15: for a 16-bit output device, at the very end
/// of the signal path. Truncated, not rounded: a magnitude is never rounded up, so a
/// signal clamped to a ceiling in Q31 stays within it in Q15 (as
/// [`safety::quantize`](crate::safety::quantize) does for float output).
#[must_use]
pub fn q31_to_q15(y: i32) -> i16 {
    let y = i64::from(y);
    // |y| <= 2^31, so the result is within [-32768, 32767] without a clamp.
    (if y >= 0 { y >> 16 } else { -((-y) >> 16) }) as i16
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

    /// A 20 Hz resonance at 2 kHz with zeros at DC and Nyquist: the kind of section that
    /// breaks a 16-bit direct form.
    fn low_resonance() -> ([f64; 3], [f64; 2]) {
        let (r, th) = (0.997f64, std::f64::consts::TAU * 20.0 / 2000.0);
        ([0.002, 0.0, -0.002], [-2.0 * r * th.cos(), r * r])
    }

    /// The terms of one Q15-section sample in exact integer arithmetic, each aligned to
    /// the accumulator (`2^-(31+d_frac)`): the two numerator parts, then the four
    /// recursive terms. Also the products inside the numerator parts.
    fn q15_terms(sec: &Q15Section, st: &Q15State, x: i32) -> ([i128; 6], [i128; 2]) {
        let (fb, fe, fd) = sec.fracs();
        let align = |v: i128, f: u32| {
            if fd >= f {
                v << (fd - f)
            } else {
                v.div_euclid(1 << (f - fd))
            }
        };
        let (x1, x2) = (i128::from(st.x[0]), i128::from(st.x[1]));
        let w = i128::from(x) + i128::from(sec.g[0]) * x1 + i128::from(sec.g[1]) * x2;
        let num = i128::from(sec.b0) * w;
        let rest = i128::from(sec.e[0]) * x1 + i128::from(sec.e[1]) * x2;
        let (y1, y2) = (i128::from(st.y[0]), i128::from(st.y[1]));
        (
            [
                align(num, fb),
                align(rest, fe),
                -(i128::from(sec.c[0]) * y1) << fd,
                -(i128::from(sec.c[1]) * y2) << fd,
                -i128::from(sec.d[0]) * y1,
                -i128::from(sec.d[1]) * y2,
            ],
            [num, rest],
        )
    }

    /// Round half up and clamp to Q31: what the section must output for the exact sum.
    fn q15_exact(sec: &Q15Section, terms: &[i128; 6]) -> i32 {
        let fd = sec.fracs().2;
        let v: i128 = terms.iter().sum();
        (v + (1 << (fd - 1)))
            .div_euclid(1 << fd)
            .clamp(i128::from(i32::MIN), i128::from(i32::MAX)) as i32
    }

    fn partial_sums_fit_i64(terms: &[i128]) -> bool {
        terms
            .iter()
            .scan(0i128, |acc, t| {
                *acc += t;
                Some(*acc)
            })
            .chain(terms.iter().copied())
            .all(|p| i64::try_from(p).is_ok())
    }

    #[test]
    fn q15_section_matches_the_exact_definition_on_a_resonance() {
        let (b, a) = low_resonance();
        let sec = Q15Section::quantize(b, a, 0).unwrap();
        // The remainders use the bits a Q1.14 denominator would spend on the integer part.
        assert_eq!(sec.c, [-2, 1]);
        assert!(sec.d_frac >= 19, "{sec:?}");
        let mut g = SplitMix64::new(3);
        let mut st = Q15State::default();
        for _ in 0..4000 {
            let x = (g.symmetric() * 2.0e9) as i32;
            let (terms, _) = q15_terms(&sec, &st, x);
            let exact = q15_exact(&sec, &terms);
            assert_eq!(sec.tick(&mut st, x), exact);
        }
    }

    #[test]
    fn q15_cascade_of_a_low_resonance_is_within_one_step_of_its_coefficients() {
        // The 32-bit path's rounding noise, amplified by some 40 dB by the resonance,
        // stays far below a Q15 step: the output is the exact response of the quantised
        // coefficients, rounded once.
        let (b, a) = low_resonance();
        let sec = Q15Section::quantize(b, a, 0).unwrap();
        let (qb, qa) = sec.coefficients();
        let mut st = [Q15State::default()];
        let (mut x1, mut x2, mut y1, mut y2) = (0.0f64, 0.0, 0.0, 0.0);
        let mut g = SplitMix64::new(5);
        let mut worst = 0.0f64;
        for _ in 0..20_000 {
            let x = (g.symmetric() * 16000.0) as i16;
            let xf = f64::from(x);
            let y = qb[0] * xf + qb[1] * x1 + qb[2] * x2 - qa[0] * y1 - qa[1] * y2;
            (x2, x1, y2, y1) = (x1, xf, y1, y);
            let got = q15_cascade(&[sec], &mut st, x);
            worst = worst.max((f64::from(got) / 65536.0 - y).abs());
            // Truncated for a 16-bit device: up to a step more, never away from zero.
            let truncated = f64::from(q31_to_q15(got));
            assert!((truncated - y).abs() <= 1.01, "{truncated} against {y}");
            assert!(truncated.abs() <= (f64::from(got) / 65536.0).abs());
        }
        // In Q15 steps: the 32-bit path's rounding, through some 40 dB of resonance.
        assert!(worst <= 0.01, "{worst} steps");
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

    #[test]
    fn q15_quantize_refuses_what_it_cannot_hold() {
        assert!(Q15Section::quantize([f64::NAN, 0.0, 0.0], [0.0, 0.0], 0).is_none());
        assert!(Q15Section::quantize([4e4, 0.0, 0.0], [0.0, 0.0], 0).is_none());
        assert!(Q15Section::quantize([4e4, 0.0, 0.0], [0.0, 0.0], 1).is_some());
        assert!(Q15Section::quantize([1.0, 0.0, 0.0], [-2.6, 0.0], 0).is_none());
        assert!(Q15Section::quantize([1.0, 0.0, 0.0], [0.0, f64::INFINITY], 0).is_none());
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
        fn q15_section_error_is_at_most_half_its_steps(
            b in prop::array::uniform3(-40.0f64..40.0), scale in 0u8..20,
            r in 0.0f64..0.9999, th in 0.0f64..std::f64::consts::PI,
        ) {
            let a = [-2.0 * r * th.cos(), r * r];
            let sec = Q15Section::quantize(b, a, scale).unwrap();
            let (qb, qa) = sec.coefficients();
            let step = |f: u8| 1.0 / (1u64 << f) as f64;
            let exact = b.map(|v| v / (1u64 << scale) as f64);
            let tol = |f: u8| step(f) / 2.0 * (1.0 + 1e-9) + 1e-15 * exact[0].abs();
            prop_assert!((qb[0] - exact[0]).abs() <= tol(sec.b_frac));
            for j in 1..3 {
                prop_assert!((qb[j] - exact[j]).abs() <= tol(sec.e_frac), "{sec:?}");
            }
            for (q, v) in qa.iter().zip(a) {
                prop_assert!((q - v).abs() <= step(sec.d_frac) / 2.0 * (1.0 + 1e-12));
            }
            // Never coarser than 16 bits for the denominator remainders, and b0 uses its
            // 16 bits whatever the scaling.
            prop_assert!(step(sec.d_frac) <= 1.0 / 32768.0);
            let b0 = f64::from(sec.b0.unsigned_abs());
            prop_assert!(b0 == 0.0 || b0 >= 8191.0 || sec.b_frac == Q15_MAX_B_FRAC);
        }

        #[test]
        fn q15_output_is_the_clamped_exact_value(
            seed in any::<u64>(), gain in 0.1f64..1000.0,
        ) {
            // A loud resonance driven hard. At every sample, from the section's own
            // state: whenever the exact partial sums fit the 64-bit accumulator, the
            // output is the exact rounded value clamped to the rails (a wrap would give
            // the opposite sign).
            let mut g = SplitMix64::new(seed);
            let sec =
                Q15Section::quantize([gain * 0.01, 0.0, -gain * 0.01], [-1.9, 0.95], 0).unwrap();
            let mut st = Q15State::default();
            for _ in 0..500 {
                let x = to_q31(g.symmetric());
                let (terms, num) = q15_terms(&sec, &st, x);
                let fits = partial_sums_fit_i64(&terms) && partial_sums_fit_i64(&num);
                let exact = q15_exact(&sec, &terms);
                let y = sec.tick(&mut st, x);
                if fits {
                    prop_assert_eq!(y, exact);
                }
            }
        }
    }

    #[test]
    fn a_saturated_accumulator_stays_at_the_rail() {
        // Every product at its largest, all of one sign: far past i64 once aligned; a
        // wrapping accumulator would come out with the opposite sign.
        let sec = Q15Section {
            b0: i16::MAX,
            b_frac: 0,
            g: [2, 2],
            e: [i16::MAX; 2],
            e_frac: 0,
            c: [-2, -2],
            d: [i16::MIN, i16::MIN],
            d_frac: Q15_MAX_D_FRAC,
        };
        let mut st = Q15State {
            x: [i32::MAX; 2],
            y: [i32::MAX; 2],
        };
        assert_eq!(sec.tick(&mut st, i32::MAX), i32::MAX);
        let mut st = Q15State {
            x: [i32::MIN; 2],
            y: [i32::MIN; 2],
        };
        assert_eq!(sec.tick(&mut st, i32::MIN), i32::MIN);
        let mut st = [Q15State {
            x: [i32::MAX; 2],
            y: [i32::MAX; 2],
        }];
        assert_eq!(q15_cascade(&[sec], &mut st, i16::MAX), i32::MAX);
        assert_eq!(q31_to_q15(i32::MAX), i16::MAX);
        assert_eq!(q31_to_q15(i32::MIN), i16::MIN);
        assert_eq!(q31_to_q15(-(1 << 15)), 0);
        assert_eq!(q31_to_q15(1 << 15), 0);
        assert_eq!(q31_to_q15((1 << 16) - 1), 0);
        assert_eq!(q31_to_q15(-(1 << 16) + 1), 0);
        assert_eq!(q31_to_q15(-(1 << 16)), -1);
        // A -6 dB ceiling in Q31 stays under it in Q15 (rounded, it was one code above).
        let ceiling = 0.501_187_233_627_272_3_f64;
        let c31 = (ceiling * 2_147_483_648.0).floor() as i32;
        assert!(f64::from(q31_to_q15(c31)) <= ceiling * 32768.0);
        assert!(f64::from(q31_to_q15(-c31)) >= -ceiling * 32768.0);
        // Out-of-range fields are clamped, not trusted.
        let odd = Q15Section {
            b_frac: 200,
            g: [i8::MIN, i8::MAX],
            e_frac: 255,
            c: [i8::MIN, i8::MAX],
            d_frac: 0,
            ..sec
        };
        let mut st = Q15State::default();
        let _ = odd.tick(&mut st, i32::MAX);
        let _ = odd.tick(&mut st, i32::MIN);

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
