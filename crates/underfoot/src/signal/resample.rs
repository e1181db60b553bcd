//! Band-limited rational resampling with a polyphase Kaiser-windowed sinc filter.
//!
//! # Rational ratio
//!
//! Going from `from` to `to` samples per second is upsampling by `L` and downsampling by
//! `M`, `L/M = to/from` reduced by their greatest common divisor. Conceptually the input
//! is zero-stuffed to the rate `F = L·from`, low-pass filtered there, and every `M`-th
//! sample kept. Input sample `n` sits at index `nL` of the fine grid and output sample `m`
//! at index `mM`, so with a zero-phase (centred, symmetric) prototype `h`
//!
//! ```math
//! y_m = \sum_n x_n\, h(mM - nL).
//! ```
//!
//! Writing `mM = n_0 L + φ` (`0 ≤ φ < L`) and `n = n_0 - j`, the taps used are
//! `h(φ + jL)`: only `L` different sub-filters exist, one per phase `φ`. That is the
//! polyphase table; no zero is ever multiplied. Because `h` is centred, output sample `m`
//! is the signal at time `m / to`: the group delay is compensated, and samples outside
//! the input count as zero.
//!
//! # Prototype
//!
//! With `f_n = min(from, to)/2` the lower Nyquist frequency, the passband is
//! `[0, 0.9 f_n]` and the stopband `[1.1 f_n, F/2]`: whatever aliases or images folds
//! back above `0.9 f_n`, out of the bands analysed. The prototype is a windowed ideal
//! low-pass with cutoff `f_c = f_n` (mid-transition),
//!
//! ```math
//! h(k) = \frac{2 f_c}{F}\,\mathrm{sinc}\!\left(\frac{2 f_c k}{F}\right)
//!   \frac{I_0\!\left(\beta\sqrt{1 - (k/K)^2}\right)}{I_0(\beta)},\qquad |k| \le K,
//! ```
//!
//! with `I_0` the modified Bessel function of the first kind. Kaiser's formulas for a
//! stopband attenuation `A` dB and transition width `Δω = 2π (0.2 f_n)/F` rad/sample:
//!
//! * `β = 0.1102 (A - 8.7)` (for `A > 50`);
//! * length `2K + 1` with `2K ≥ (A - 7.95) / (2.285 Δω)`.
//!
//! A Kaiser design has (nearly) equal ripple `δ = 10^(-A/20)` in both bands. We design
//! for `A = 90` dB, which leaves margin over the required 80 dB stopband (Kaiser's length
//! estimate is approximate) and gives passband ripple `20 log10(1 + δ) ≈ 3·10⁻⁴` dB, far
//! inside the 0.01 dB asked for.
//!
//! Each phase's taps are scaled to sum to exactly 1. In exact arithmetic they sum to
//! `1 ± δ`; normalising makes the DC gain exactly one at every output sample, so a
//! constant does not pick up a pattern of period `L` from the slightly uneven phases.
//!
//! # Table or direct evaluation
//!
//! The table holds `2K + L` taps, which for ratios of coprime rates (large `L`) can run
//! to millions. Above [`TABLE_LIMIT`] taps the kernel is evaluated directly for each
//! output sample instead: slower (a sine and a Bessel series per tap), the same result.

use super::SignalError;
use crate::units::SampleRate;
use std::sync::{Arc, Mutex, PoisonError};

/// The largest polyphase table (in taps) built; larger designs evaluate the kernel directly.
pub const TABLE_LIMIT: usize = 1 << 20;

/// Stopband attenuation designed for, in dB.
const ATTENUATION_DB: f64 = 90.0;

/// A band-limited resampler from one fixed rate to another.
#[derive(Debug, Clone)]
pub struct Resampler {
    from: SampleRate,
    to: SampleRate,
    up: u64,
    down: u64,
    kernel: Kernel,
}

#[derive(Debug, Clone)]
enum Kernel {
    Identity,
    Table { taps: Vec<f64>, phases: Vec<Phase> },
    Direct(Prototype),
}

/// The sub-filter of one phase: `taps[offset..offset + len]` multiply the inputs
/// `n0 - j_hi ..= n0 - j_hi + len - 1`, in increasing time.
#[derive(Debug, Clone, Copy)]
struct Phase {
    offset: usize,
    len: usize,
    j_hi: i64,
}

#[derive(Debug, Clone, Copy)]
struct Prototype {
    /// `2 f_c / F`, cycles per fine-grid sample times two.
    cutoff: f64,
    /// Half-length `K` in fine-grid samples.
    half: i64,
    beta: f64,
    i0_beta: f64,
    up: i64,
}

impl Prototype {
    fn design(from: SampleRate, to: SampleRate, up: u64) -> Self {
        let fine = up as f64 * from.hz();
        let nyquist = from.hz().min(to.hz()) / 2.0;
        let transition = 2.0 * std::f64::consts::PI * 0.2 * nyquist / fine;
        let span = (ATTENUATION_DB - 7.95) / (2.285 * transition);
        let beta = 0.1102 * (ATTENUATION_DB - 8.7);
        Self {
            cutoff: 2.0 * nyquist / fine,
            half: (span / 2.0).ceil() as i64,
            beta,
            i0_beta: bessel_i0(beta),
            up: up as i64,
        }
    }

    /// `h(k)`, unnormalised.
    fn tap(&self, k: i64) -> f64 {
        if k.abs() > self.half {
            return 0.0;
        }
        let r = k as f64 / self.half as f64;
        let arg = std::f64::consts::PI * self.cutoff * k as f64;
        let sinc = if k == 0 { 1.0 } else { arg.sin() / arg };
        self.cutoff * sinc * bessel_i0(self.beta * (1.0 - r * r).sqrt()) / self.i0_beta
    }

    /// The range `j_lo..=j_hi` with `|φ + jL| <= K`.
    fn j_range(&self, phase: i64) -> (i64, i64) {
        let lo = (-self.half - phase).div_euclid(self.up)
            + i64::from((-self.half - phase).rem_euclid(self.up) != 0);
        let hi = (self.half - phase).div_euclid(self.up);
        (lo, hi)
    }

    /// The taps of one phase in increasing input time, normalised to sum to one.
    fn phase_taps(&self, phase: i64) -> (i64, Vec<f64>) {
        let (lo, hi) = self.j_range(phase);
        let mut taps: Vec<f64> = (lo..=hi)
            .rev()
            .map(|j| self.tap(phase + j * self.up))
            .collect();
        let sum: f64 = taps.iter().sum();
        if sum != 0.0 {
            taps.iter_mut().for_each(|t| *t /= sum);
        }
        (hi, taps)
    }

    fn table_size(&self) -> u64 {
        2 * self.half as u64 + self.up as u64
    }
}

/// The designs [`Resampler::shared`] keeps, by `(from, to)` rate.
type Designs = Vec<((u32, u32), Arc<Resampler>)>;

/// How many resampler designs [`Resampler::shared`] keeps.
pub const SHARED_DESIGNS: usize = 8;

impl Resampler {
    /// A resampler from `from` to `to`.
    ///
    /// # Errors
    /// [`SignalError::InvalidParameter`] if either rate is zero.
    pub fn new(from: SampleRate, to: SampleRate) -> Result<Self, SignalError> {
        Self::build(from, to, false)
    }

    /// The same resampler as [`new`](Self::new), designed once per pair of rates in this
    /// process and shared.
    ///
    /// A design at an awkward ratio (44.1 kHz to 2 kHz: 441 phases of a windowed sinc)
    /// costs more than resampling a footstep, and one `fit` conditions each recording
    /// several times (the quality gate, the measurement, the physical estimation and its
    /// rendered steps). The cache holds the few ratios a process meets, at most
    /// [`SHARED_DESIGNS`]; past that the oldest is dropped.
    ///
    /// # Errors
    /// As [`new`](Self::new).
    pub fn shared(from: SampleRate, to: SampleRate) -> Result<Arc<Self>, SignalError> {
        static DESIGNS: Mutex<Designs> = Mutex::new(Vec::new());
        let key = (from.0, to.0);
        // A poisoned lock only means another thread panicked mid-lookup; the list itself
        // is always whole, so it is used as it is.
        let lookup = |designs: &Designs| {
            designs
                .iter()
                .find(|(k, _)| *k == key)
                .map(|(_, r)| Arc::clone(r))
        };
        if let Some(r) = lookup(&DESIGNS.lock().unwrap_or_else(PoisonError::into_inner)) {
            return Ok(r);
        }
        // Designed outside the lock: two threads may both design it; one copy is kept.
        let design = Arc::new(Self::new(from, to)?);
        let mut designs = DESIGNS.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(r) = lookup(&designs) {
            return Ok(r);
        }
        if designs.len() >= SHARED_DESIGNS {
            designs.remove(0);
        }
        designs.push((key, Arc::clone(&design)));
        Ok(design)
    }

    fn build(from: SampleRate, to: SampleRate, force_direct: bool) -> Result<Self, SignalError> {
        if from.0 == 0 || to.0 == 0 {
            return Err(SignalError::InvalidParameter(format!(
                "cannot resample from {from} to {to}: rates must be positive"
            )));
        }
        let g = gcd(u64::from(from.0), u64::from(to.0));
        let (up, down) = (u64::from(to.0) / g, u64::from(from.0) / g);
        let kernel = if up == down {
            Kernel::Identity
        } else {
            let proto = Prototype::design(from, to, up);
            if force_direct || proto.table_size() > TABLE_LIMIT as u64 {
                Kernel::Direct(proto)
            } else {
                let mut taps = Vec::with_capacity(proto.table_size() as usize);
                let phases = (0..up as i64)
                    .map(|phase| {
                        let (j_hi, t) = proto.phase_taps(phase);
                        let p = Phase {
                            offset: taps.len(),
                            len: t.len(),
                            j_hi,
                        };
                        taps.extend(t);
                        p
                    })
                    .collect();
                Kernel::Table { taps, phases }
            }
        };
        Ok(Self {
            from,
            to,
            up,
            down,
            kernel,
        })
    }

    /// The input rate.
    #[must_use]
    pub fn input_rate(&self) -> SampleRate {
        self.from
    }

    /// The output rate.
    #[must_use]
    pub fn output_rate(&self) -> SampleRate {
        self.to
    }

    /// `(L, M)`: the output rate is `L/M` times the input rate, in lowest terms.
    #[must_use]
    pub fn ratio(&self) -> (u64, u64) {
        (self.up, self.down)
    }

    /// How far, in input samples, the kernel reaches either side of an output sample's time:
    /// output sample `m` depends only on inputs within `reach` samples of time `m / to`.
    ///
    /// A signal resampled with this many zeros (or more) added at each end therefore holds
    /// the whole of its band-limited version, pre- and post-ringing included, rather than
    /// the part of it that falls inside the original span. Zero for equal rates.
    #[must_use]
    pub fn reach(&self) -> usize {
        match &self.kernel {
            Kernel::Identity => 0,
            Kernel::Table { .. } | Kernel::Direct(_) => {
                let proto = Prototype::design(self.from, self.to, self.up);
                (proto.half as u64).div_ceil(self.up) as usize + 1
            }
        }
    }

    /// The number of output samples for `len` input samples: `ceil(len · L / M)`.
    #[must_use]
    pub fn output_len(&self, len: usize) -> usize {
        let (l, m) = (u128::from(self.up), u128::from(self.down));
        ((len as u128 * l).div_ceil(m)) as usize
    }

    /// `x` resampled: output sample `m` is the band-limited signal at time `m / to`,
    /// treating the signal as zero outside `x`.
    #[must_use]
    pub fn process(&self, x: &[f64]) -> Vec<f64> {
        let out_len = self.output_len(x.len());
        let (l, m) = (self.up as i64, self.down as i64);
        let len = x.len() as i64;
        match &self.kernel {
            Kernel::Identity => x.to_vec(),
            Kernel::Table { taps, phases } => (0..out_len as i64)
                .map(|i| table_sample(taps, phases, (l, m), x, i))
                .collect(),
            Kernel::Direct(proto) => (0..out_len as i64)
                .map(|i| {
                    let fine = i * m;
                    let (n0, phase) = (fine.div_euclid(l), fine.rem_euclid(l));
                    let (j_lo, j_hi) = proto.j_range(phase);
                    let (mut acc, mut sum) = (0.0, 0.0);
                    for j in j_lo..=j_hi {
                        let t = proto.tap(phase + j * l);
                        sum += t;
                        let n = n0 - j;
                        if (0..len).contains(&n) {
                            acc += t * x[n as usize];
                        }
                    }
                    if sum == 0.0 { acc } else { acc / sum }
                })
                .collect(),
        }
    }

    /// The largest `|y_m|` of `y =` [`process`](Self::process)`(x)`, the same value to the
    /// bit, computing only the output samples that can hold it.
    ///
    /// With a table, `|y_m| ≤ Σ_j |h_φ[j]| · max |x|` over the inputs output `m` reads:
    /// the outputs are visited after those around the largest input, and one whose bound
    /// (with a margin far above rounding) is under the peak found so far is skipped. An
    /// eightfold true-peak upsampling of a step computes a few hundred of its tens of
    /// thousands of outputs. A direct kernel computes them all.
    #[must_use]
    pub fn peak(&self, x: &[f64]) -> f64 {
        let (l, m) = (self.up as i64, self.down as i64);
        let Kernel::Table { taps, phases } = &self.kernel else {
            return self.process(x).iter().fold(0.0, |p, v| p.max(v.abs()));
        };
        let out_len = self.output_len(x.len()) as i64;
        if out_len == 0 {
            return 0.0;
        }
        // The largest |x| over blocks of `BLOCK` inputs, and each phase's sum of |taps|.
        const BLOCK: usize = 16;
        let block_max: Vec<f64> = x
            .chunks(BLOCK)
            .map(|c| c.iter().fold(0.0f64, |p, v| p.max(v.abs())))
            .collect();
        let gain: Vec<f64> = phases
            .iter()
            .map(|p| {
                taps[p.offset..p.offset + p.len]
                    .iter()
                    .map(|t| t.abs())
                    .sum()
            })
            .collect();
        let len = x.len() as i64;
        let bound = |i: i64| -> f64 {
            let fine = i * m;
            let (n0, phase) = (fine.div_euclid(l), fine.rem_euclid(l) as usize);
            let p = phases[phase];
            let start = (n0 - p.j_hi).max(0);
            let stop = (n0 - p.j_hi + p.len as i64).min(len);
            if stop <= start {
                return 0.0;
            }
            let (b0, b1) = (start as usize / BLOCK, (stop as usize - 1) / BLOCK);
            gain[phase] * block_max[b0..=b1].iter().fold(0.0f64, |a, &v| a.max(v))
        };
        // First the outputs around the largest input: a peak near the final one early,
        // so that the bound skips nearly everything else.
        let loudest = x
            .iter()
            .enumerate()
            .fold(
                (0, 0.0f64),
                |(k, a), (n, v)| if v.abs() > a { (n, v.abs()) } else { (k, a) },
            )
            .0 as i64;
        let centre = loudest * l / m;
        let near = (centre - 2 * l).max(0)..(centre + 2 * l + 1).min(out_len);
        let mut peak = near
            .clone()
            .map(|i| table_sample(taps, phases, (l, m), x, i).abs())
            .fold(0.0f64, f64::max);
        for i in (0..out_len).filter(|i| !near.contains(i)) {
            if bound(i) * (1.0 + 1e-9) > peak {
                peak = peak.max(table_sample(taps, phases, (l, m), x, i).abs());
            }
        }
        peak
    }
}

/// `x` resampled from `from` to `to` (see [`Resampler::process`]).
///
/// # Errors
/// [`SignalError::InvalidParameter`] if either rate is zero.
pub fn resample(x: &[f64], from: SampleRate, to: SampleRate) -> Result<Vec<f64>, SignalError> {
    Ok(Resampler::shared(from, to)?.process(x))
}

fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// `I_0(x) = Σ_k ((x/2)^k / k!)²`; all terms are positive, so the series is summed until a
/// term no longer changes the total, or for at most 1000 terms (a NaN argument never
/// satisfies the test; any finite `x` of a Kaiser window converges in well under 100).
fn bessel_i0(x: f64) -> f64 {
    let q = x * x / 4.0;
    let (mut sum, mut term) = (1.0, 1.0);
    for k in 1..=1000u32 {
        let k = f64::from(k);
        term *= q / (k * k);
        if term <= sum * 1e-17 {
            break;
        }
        sum += term;
    }
    sum
}

/// A dot product with four accumulators, so the compiler can keep several lanes busy.
/// Output sample `i` of a polyphase table (up `L`, down `M`): [`Resampler::process`]'s
/// sum, one sample of it.
fn table_sample(taps: &[f64], phases: &[Phase], (l, m): (i64, i64), x: &[f64], i: i64) -> f64 {
    let len = x.len() as i64;
    let fine = i * m;
    let (n0, phase) = (fine.div_euclid(l), fine.rem_euclid(l) as usize);
    let p = phases[phase];
    let start = n0 - p.j_hi;
    let skip = (-start).max(0);
    let stop = (start + p.len as i64).min(len);
    if stop <= start + skip {
        return 0.0;
    }
    let h = &taps[p.offset + skip as usize..p.offset + (stop - start) as usize];
    dot(h, &x[(start + skip) as usize..stop as usize])
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(p, q)| p * q)
        .sum();
    for (p, q) in ca.zip(cb) {
        for k in 0..4 {
            acc[k] += p[k] * q[k];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn sine(rate: SampleRate, f: f64, phase: f64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| (2.0 * PI * f * i as f64 / rate.hz() + phase).sin())
            .collect()
    }

    /// Output samples far enough from both ends that the kernel sees only real input.
    fn interior(
        from: SampleRate,
        to: SampleRate,
        in_len: usize,
        out_len: usize,
    ) -> std::ops::Range<usize> {
        let guard = (0.1 * to.hz()) as usize; // 100 ms: longer than any half-kernel here.
        let last = (((in_len as f64) / from.hz()) * to.hz()) as usize;
        guard..last.min(out_len).saturating_sub(guard)
    }

    /// Largest deviation of the resampled sine from the ideal one sampled at the new rate.
    fn sine_error(rs: &Resampler, f: f64, seconds: f64) -> f64 {
        let (from, to) = (rs.input_rate(), rs.output_rate());
        let n = (seconds * from.hz()) as usize;
        let y = rs.process(&sine(from, f, 0.7, n));
        assert_eq!(y.len(), rs.output_len(n));
        let want = sine(to, f, 0.7, y.len());
        let range = interior(from, to, n, y.len());
        assert!(range.len() > 10);
        range.map(|m| (y[m] - want[m]).abs()).fold(0.0, f64::max)
    }

    #[test]
    fn sines_keep_amplitude_frequency_and_phase() {
        let cases: [(u32, u32, &[f64]); 5] = [
            (44_100, 2000, &[3.0, 123.4, 500.0, 850.0, 899.0]),
            (48_000, 2000, &[3.0, 123.4, 500.0, 850.0, 899.0]),
            (22_050, 2000, &[35.0, 700.0, 899.0]),
            (2000, 48_000, &[35.0, 440.0, 899.0]),
            (44_100, 48_000, &[100.0, 5000.0, 19_000.0]),
        ];
        for (from, to, freqs) in cases {
            let rs = Resampler::new(SampleRate(from), SampleRate(to)).unwrap();
            for &f in freqs {
                let err = sine_error(&rs, f, 0.5);
                assert!(err < 1e-3, "{from}->{to} f={f}: error {err}");
            }
        }
    }

    #[test]
    fn out_of_band_is_attenuated() {
        for (from, f) in [
            (48_000, 1100.0),
            (48_000, 1500.0),
            (44_100, 1150.0),
            (44_100, 7000.0),
            (22_050, 10_000.0),
        ] {
            let (from, to) = (SampleRate(from), SampleRate(2000));
            let rs = Resampler::new(from, to).unwrap();
            let n = (0.5 * from.hz()) as usize;
            let y = rs.process(&sine(from, f, 0.3, n));
            let peak = interior(from, to, n, y.len())
                .map(|m| y[m].abs())
                .fold(0.0, f64::max);
            let db = 20.0 * peak.log10();
            assert!(db < -80.0, "{from} -> {to}, {f} Hz: {db} dB");
        }
        // Upsampling: the images of an in-band tone are removed, so what comes out is
        // the tone alone (checked against the ideal sine above); a tone just above the
        // input's own band cannot occur, so check the images directly instead.
        let rs = Resampler::new(SampleRate(2000), SampleRate(48_000)).unwrap();
        let err = sine_error(&rs, 899.0, 0.5);
        assert!(err < 1e-4, "images left: {err}");
    }

    #[test]
    fn dc_gain_is_one_everywhere() {
        for (from, to) in [
            (44_100, 2000),
            (48_000, 2000),
            (2000, 48_000),
            (44_100, 48_000),
            (300, 700),
        ] {
            let (from, to) = (SampleRate(from), SampleRate(to));
            let rs = Resampler::new(from, to).unwrap();
            let n = from.0 as usize;
            let y = rs.process(&vec![2.5; n]);
            for m in interior(from, to, n, y.len()) {
                assert!((y[m] - 2.5).abs() < 1e-12, "{from}->{to} m={m}: {}", y[m]);
            }
        }
    }

    #[test]
    fn lengths_and_identity() {
        let rs = Resampler::new(SampleRate(44_100), SampleRate(2000)).unwrap();
        assert_eq!(rs.ratio(), (20, 441));
        assert_eq!(rs.output_len(44_100), 2000);
        assert_eq!(rs.output_len(44_101), 2001);
        assert_eq!(rs.output_len(1), 1);
        assert!(rs.process(&[]).is_empty());
        assert_eq!(rs.process(&[1.0]).len(), 1);
        let x = [1.0, -2.0, 3.5];
        assert_eq!(
            resample(&x, SampleRate(8000), SampleRate(8000)).unwrap(),
            x.to_vec()
        );
        assert_eq!(
            resample(&x, SampleRate(2000), SampleRate(48_000))
                .unwrap()
                .len(),
            72
        );
        assert!(Resampler::new(SampleRate(0), SampleRate(2000)).is_err());
        assert!(resample(&x, SampleRate(2000), SampleRate(0)).is_err());
    }

    #[test]
    fn output_sits_at_m_over_to() {
        // A band-limited pulse centred on an input sample whose time is also an output
        // sample's time must peak exactly there, symmetrically.
        let (from, to) = (SampleRate(44_100), SampleRate(2000));
        let rs = Resampler::new(from, to).unwrap();
        let centre = 441 * 20; // 0.2 s: output sample 400.
        let x: Vec<f64> = (0..44_100)
            .map(|n| {
                let t = (n as f64 - centre as f64) / from.hz();
                (-(t * 300.0).powi(2)).exp()
            })
            .collect();
        let y = rs.process(&x);
        for k in 1..20 {
            assert!((y[400 - k] - y[400 + k]).abs() < 1e-6, "asymmetric at {k}");
            assert!(y[400] > y[400 + k]);
        }
    }

    #[test]
    fn direct_evaluation_equals_table() {
        for (from, to) in [(44_100, 2000), (2000, 48_000), (44_100, 48_000)] {
            let (from, to) = (SampleRate(from), SampleRate(to));
            let table = Resampler::build(from, to, false).unwrap();
            assert!(matches!(table.kernel, Kernel::Table { .. }));
            let direct = Resampler::build(from, to, true).unwrap();
            let x = sine(from, 321.0, 0.1, from.0 as usize / 20);
            for (a, b) in table.process(&x).iter().zip(direct.process(&x)) {
                assert!((a - b).abs() < 1e-12);
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]

        /// `peak` skips outputs by a bound; whatever it skips, it returns the largest
        /// output of `process` to the bit: decaying noise bursts (a step's shape), at the
        /// ratios of the level's upsampling and of the analysis.
        #[test]
        fn peak_is_the_largest_output(seed in proptest::prelude::any::<u64>(),
                                      len in 1usize..3000, decay in 1.0f64..2000.0,
                                      ratio in 0usize..3) {
            let (from, to) = [(2000, 16_000), (48_000, 2000), (44_100, 48_000)][ratio];
            let rs = Resampler::shared(SampleRate(from), SampleRate(to)).unwrap();
            let mut rng = crate::signal::noise::SplitMix64::new(seed);
            let x: Vec<f64> = (0..len)
                .map(|n| rng.symmetric() * (-(n as f64) / decay).exp())
                .collect();
            let all = rs.process(&x).iter().fold(0.0f64, |m, v| m.max(v.abs()));
            proptest::prop_assert_eq!(rs.peak(&x).to_bits(), all.to_bits());
        }
    }

    #[test]
    fn peak_of_nothing_and_of_silence_is_zero() {
        let rs = Resampler::new(SampleRate(2000), SampleRate(16_000)).unwrap();
        assert_eq!(rs.peak(&[]), 0.0);
        assert_eq!(rs.peak(&[0.0; 100]), 0.0);
    }

    #[test]
    fn coprime_rates_use_direct_evaluation() {
        let rs = Resampler::new(SampleRate(47_999), SampleRate(2000)).unwrap();
        assert_eq!(rs.ratio(), (2000, 47_999));
        assert!(matches!(rs.kernel, Kernel::Direct(_)));
        for f in [123.0, 850.0] {
            let err = sine_error(&rs, f, 0.3);
            assert!(err < 1e-3, "f={f}: {err}");
        }
    }

    #[test]
    fn bessel_i0_matches_known_values() {
        // Abramowitz & Stegun, table 9.8.
        for (x, want) in [
            (0.0, 1.0),
            (1.0, 1.266_065_877_752_008),
            (5.0, 27.239_871_823_604_44),
        ] {
            let got = bessel_i0(x);
            assert!((got - want).abs() < 1e-12 * want, "I0({x}) = {got}");
        }
    }

    #[test]
    fn bessel_i0_of_nan_ends() {
        assert!(bessel_i0(f64::NAN).is_nan());
        assert!(bessel_i0(1e300).is_infinite());
    }

    /// A shared design is the same design, made once.
    #[test]
    fn shared_designs_are_made_once_and_match_new() {
        let (from, to) = (SampleRate(44_100), SampleRate(2000));
        let a = Resampler::shared(from, to).unwrap();
        let b = Resampler::shared(from, to).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        let x: Vec<f64> = (0..5000).map(|n| (n as f64 * 0.01).sin()).collect();
        assert_eq!(a.process(&x), Resampler::new(from, to).unwrap().process(&x));
        assert!(Resampler::shared(SampleRate(0), to).is_err());
    }
}
