//! A streaming FIR filter, and the minimum-phase design that turns spectral weights into
//! one: the low-delay realisation of the equalizer.
//!
//! # Why minimum phase
//!
//! The uniform filter bank ([`FilterBank`](super::filterbank::FilterBank)) applies its
//! sub-band gains with a delay of `N - 1` samples, and the resolution the device's
//! resonances need (bins of about 10 Hz, `N = 4096` at 48 kHz) makes that 85 ms: far
//! above the one or two milliseconds between a heel strike and the vibration that users
//! expect. The low-delay filter-bank equalizer (Löllmann & Vary, the compensation paper's reference
//! \[2\]) keeps the bank's weights but applies them with a time-domain filter. Of all
//! causal filters with a given magnitude response, the minimum-phase one concentrates its
//! energy earliest: it has no bulk delay, only the group delay the resonances it corrects
//! need. So the weights are realised as a minimum-phase FIR.
//!
//! # The design (homomorphic, via the real cepstrum)
//!
//! With `|W[k]|` the magnitude on the `M/2 + 1` bins of an `M`-point DFT:
//!
//! 1. the real cepstrum `c[n] = IDFT(ln |W[k]|)`, real and even;
//! 2. folding onto positive quefrency, `ĉ[0] = c[0]`, `ĉ[n] = 2c[n]` for `0 < n < M/2`,
//!    `ĉ[M/2] = c[M/2]`, zero after: the cepstrum of the minimum-phase filter with the
//!    same magnitude (its log-spectrum is analytic outside the unit circle);
//! 3. `H[k] = exp(DFT(ĉ)[k])` and `h = IDFT(H)`;
//! 4. `h` is kept for `L` taps, with a half-Hann fade over its last quarter so that the
//!    truncation does not ripple the response.
//!
//! The cepstrum is time-aliased by the `M`-point DFT, which is negligible when `M` is
//! several times the filter's decay; the designer uses `M ≥ 8L`. Truncation smooths the
//! response on a scale of `fs / L` (11.7 Hz for 4096 taps at 48 kHz); the iterative
//! equalizer measures through the realised filter, so what truncation misses at the
//! first pass, the next pass corrects.
//!
//! # Real time
//!
//! [`Fir::process`] and [`Fir::set_taps`] never allocate, lock or panic, nor does
//! [`MinPhaseDesigner::design`], whose FFT plans and buffers are made up front: a new
//! set of weights can be designed and swapped in on the audio thread. A tap change is
//! cross-faded over [`Fir::FADE`] samples (both filters run meanwhile), so it cannot
//! click. The history is stored twice over so that every output is one contiguous dot
//! product, which the compiler vectorises.

use std::f64::consts::PI;
use std::fmt;
use std::sync::Arc;

use num_complex::Complex;
use underfoot_fft::{ComplexToReal, RealFftPlanner, RealToComplex};

use super::CompensationError;

/// Samples per partition of the tail, and length of the directly computed head.
const PART: usize = 128;

/// One impulse response, in the two forms the filter runs: the head time-reversed for
/// the direct dot product, the tail as partition spectra.
#[derive(Clone)]
struct Response {
    head: Vec<f32>,
    /// `parts` spectra of `PART + 1` bins: partition `p` holds taps
    /// `PART + p·PART .. PART + (p+1)·PART`, zero-padded to `2·PART`.
    tail: Vec<Complex<f32>>,
    /// The tail's output for the current partition, computed at its start.
    tail_out: Vec<f32>,
}

/// A streaming FIR filter in `f32`, without latency, with cross-faded coefficient
/// changes.
///
/// # How
///
/// Direct convolution costs `L` multiply-adds per sample (2048 at 48 kHz is 2% of a core
/// per channel). A uniformly partitioned FFT convolution is ten times cheaper but delays
/// its output by a partition. Both are combined (a non-uniform partitioned convolution):
/// the first `P = 128` taps are a direct dot product, so the output has no delay; taps
/// `P..L` are partitions of `P`, convolved by overlap-save with `2P`-point FFTs and a
/// frequency-domain delay line of past input spectra. The tail of output sample `n` needs
/// inputs up to `n - P` only, so it is computed when the previous partition of input
/// completes, in time.
///
/// The work happens per sample and at fixed partition boundaries of the sample count, so
/// the output does not depend on how the caller cuts its blocks.
pub struct Fir {
    len: usize,
    /// The response playing, and the one faded in.
    responses: [Response; 2],
    current: usize,
    /// The last `PART` inputs twice over, for the head's contiguous dot product.
    history: Vec<f32>,
    pos: usize,
    /// The tail's state: the last `2·PART` inputs, the delay line of their spectra.
    parts: usize,
    forward: Arc<dyn RealToComplex<f32>>,
    inverse: Arc<dyn ComplexToReal<f32>>,
    window: Vec<f32>,
    spectra: Vec<Complex<f32>>,
    newest: usize,
    fill: usize,
    time: Vec<f32>,
    acc: Vec<Complex<f32>>,
    scratch_forward: Vec<Complex<f32>>,
    scratch_inverse: Vec<Complex<f32>>,
    /// A change waiting for the next partition boundary to start fading.
    pending: bool,
    /// Samples into the current fade, or `None`.
    fade: Option<usize>,
    non_finite: u64,
}

impl fmt::Debug for Fir {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Fir")
            .field("taps", &self.len)
            .field("fading", &(self.pending || self.fade.is_some()))
            .field("non_finite", &self.non_finite)
            .finish_non_exhaustive()
    }
}

impl Fir {
    /// Length of the cross-fade of a tap change, in samples (10 ms at 48 kHz).
    pub const FADE: usize = 480;

    /// A filter with impulse response `taps`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] when `taps` is empty or holds a non-finite
    /// value.
    pub fn new(taps: &[f64]) -> Result<Self, CompensationError> {
        check_taps(taps)?;
        let len = taps.len();
        let parts = len.saturating_sub(PART).div_ceil(PART);
        let mut planner = RealFftPlanner::<f32>::new();
        let forward = planner.plan_fft_forward(2 * PART);
        let inverse = planner.plan_fft_inverse(2 * PART);
        let bins = PART + 1;
        let blank = Response {
            head: vec![0.0; PART],
            tail: vec![Complex::new(0.0, 0.0); parts * bins],
            tail_out: vec![0.0; PART],
        };
        let mut fir = Self {
            len,
            responses: [blank.clone(), blank],
            current: 0,
            history: vec![0.0; 2 * PART],
            pos: 0,
            parts,
            window: vec![0.0; 2 * PART],
            spectra: vec![Complex::new(0.0, 0.0); parts * bins],
            newest: 0,
            fill: 0,
            time: forward.make_input_vec(),
            acc: forward.make_output_vec(),
            scratch_forward: forward.make_scratch_vec(),
            scratch_inverse: inverse.make_scratch_vec(),
            forward,
            inverse,
            pending: false,
            fade: None,
            non_finite: 0,
        };
        fir.load(0, taps.iter().copied());
        fir.load(1, taps.iter().copied());
        Ok(fir)
    }

    /// Number of taps.
    #[must_use]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the filter has no taps (never: [`Fir::new`] refuses that).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Writes `taps` into response `which`: the head reversed, the tail's partition
    /// spectra. No allocation.
    fn load(&mut self, which: usize, taps: impl IntoIterator<Item = f64>) {
        let bins = PART + 1;
        let r = &mut self.responses[which];
        r.head.fill(0.0);
        self.time.fill(0.0);
        let mut part = 0;
        let mut in_part = 0;
        let mut flush = |time: &mut Vec<f32>, part: usize, r: &mut Response| {
            if part < self.parts {
                let out = &mut r.tail[part * bins..(part + 1) * bins];
                if self
                    .forward
                    .process_with_scratch(time, out, &mut self.scratch_forward)
                    .is_err()
                {
                    out.fill(Complex::new(0.0, 0.0));
                }
            }
            time.fill(0.0);
        };
        for (i, t) in taps.into_iter().take(self.len).enumerate() {
            let t = t as f32;
            if i < PART {
                r.head[PART - 1 - i] = t;
            } else {
                let j = i - PART;
                (part, in_part) = (j / PART, j % PART);
                self.time[in_part] = t;
                if in_part == PART - 1 {
                    flush(&mut self.time, part, r);
                }
            }
        }
        if self.len > PART && in_part != PART - 1 {
            flush(&mut self.time, part, r);
        }
        // Later partitions of a shorter `taps` stay as they were: clear them.
        let used = self.len.saturating_sub(PART).div_ceil(PART);
        r.tail[used.min(self.parts) * bins..].fill(Complex::new(0.0, 0.0));
    }

    /// The current impulse response (the one being faded in, during a fade).
    #[must_use]
    pub fn taps(&self) -> Vec<f32> {
        let which = if self.pending || self.fade.is_some() {
            1 - self.current
        } else {
            self.current
        };
        let r = &self.responses[which];
        let mut out: Vec<f32> = r.head.iter().rev().copied().collect();
        let mut planner = RealFftPlanner::<f32>::new();
        let inverse = planner.plan_fft_inverse(2 * PART);
        let bins = PART + 1;
        for p in 0..self.parts {
            let mut spectrum = r.tail[p * bins..(p + 1) * bins].to_vec();
            let mut time = vec![0.0; 2 * PART];
            if inverse.process(&mut spectrum, &mut time).is_ok() {
                out.extend(time[..PART].iter().map(|v| v / (2 * PART) as f32));
            }
        }
        out.truncate(self.len);
        out
    }

    /// Starts a change to `taps`: it is cross-faded over [`Fir::FADE`] samples from the
    /// next partition boundary (within 128 samples). Taps beyond the filter's length are
    /// ignored and missing ones are zero; a non-finite tap makes the call a no-op (returns
    /// `false`). A change requested during a fade completes the fade at once first.
    /// Real-time safe: no allocation, about `L / 128` FFTs of 256 points.
    pub fn set_taps(&mut self, taps: impl IntoIterator<Item = f64> + Clone) -> bool {
        if taps.clone().into_iter().any(|t| !t.is_finite()) {
            return false;
        }
        if self.fade.take().is_some() {
            self.current = 1 - self.current;
        }
        let next = 1 - self.current;
        self.load(next, taps);
        self.pending = true;
        true
    }

    /// How many non-finite input samples were replaced by 0.
    #[must_use]
    pub fn non_finite_inputs(&self) -> u64 {
        self.non_finite
    }

    /// Forgets the signal; a change in progress completes at once.
    pub fn reset(&mut self) {
        self.history.fill(0.0);
        self.pos = 0;
        self.window.fill(0.0);
        self.spectra.fill(Complex::new(0.0, 0.0));
        self.newest = 0;
        self.fill = 0;
        if self.fade.take().is_some() || std::mem::take(&mut self.pending) {
            self.current = 1 - self.current;
        }
        for r in &mut self.responses {
            r.tail_out.fill(0.0);
        }
    }

    /// Filters `input` into `output`, over the shorter of the two. Streaming, so the
    /// result does not depend on the block size. Never allocates, locks or panics.
    pub fn process(&mut self, input: &[f32], output: &mut [f32]) {
        for (&x, y) in input.iter().zip(output.iter_mut()) {
            let x = if x.is_finite() {
                x
            } else {
                self.non_finite += 1;
                0.0
            };
            self.history[self.pos] = x;
            self.history[self.pos + PART] = x;
            let recent = &self.history[self.pos + 1..=self.pos + PART];
            let here = self.fill;
            let play = |r: &Response| dot(&r.head, recent) + r.tail_out[here];
            let current = play(&self.responses[self.current]);
            *y = match self.fade {
                None => current,
                Some(n) => {
                    let t = (n + 1) as f32 / Self::FADE as f32;
                    let faded = play(&self.responses[1 - self.current]);
                    if n + 1 >= Self::FADE {
                        self.current = 1 - self.current;
                        self.fade = None;
                    } else {
                        self.fade = Some(n + 1);
                    }
                    current + t * (faded - current)
                }
            };
            self.pos = if self.pos + 1 == PART {
                0
            } else {
                self.pos + 1
            };
            self.window[PART + self.fill] = x;
            self.fill += 1;
            if self.fill == PART {
                self.partition_done();
            }
        }
    }

    /// A partition of input is complete: its spectrum enters the delay line, and the
    /// tail's output for the next partition is computed (for both responses while they
    /// fade).
    fn partition_done(&mut self) {
        self.fill = 0;
        if std::mem::take(&mut self.pending) {
            self.fade = Some(0);
        }
        if self.parts > 0 {
            let bins = PART + 1;
            self.newest = (self.newest + 1) % self.parts;
            self.time.copy_from_slice(&self.window);
            let slot = &mut self.spectra[self.newest * bins..(self.newest + 1) * bins];
            if self
                .forward
                .process_with_scratch(&mut self.time, slot, &mut self.scratch_forward)
                .is_err()
            {
                slot.fill(Complex::new(0.0, 0.0));
            }
            let fading = self.fade.is_some();
            for which in [self.current, 1 - self.current] {
                if which != self.current && !fading {
                    continue;
                }
                self.acc.fill(Complex::new(0.0, 0.0));
                for p in 0..self.parts {
                    let age = (self.newest + self.parts - p) % self.parts;
                    let x = &self.spectra[age * bins..(age + 1) * bins];
                    let h = &self.responses[which].tail[p * bins..(p + 1) * bins];
                    for ((a, &xv), &hv) in self.acc.iter_mut().zip(x).zip(h) {
                        *a += xv * hv;
                    }
                }
                self.acc[0].im = 0.0;
                self.acc[PART].im = 0.0;
                let out = &mut self.responses[which].tail_out;
                if self
                    .inverse
                    .process_with_scratch(&mut self.acc, &mut self.time, &mut self.scratch_inverse)
                    .is_err()
                {
                    out.fill(0.0);
                } else {
                    // Overlap-save: the second half is the linear convolution.
                    let scale = 1.0 / (2 * PART) as f32;
                    for (o, &t) in out.iter_mut().zip(&self.time[PART..]) {
                        *o = t * scale;
                    }
                }
            }
        } else {
            for r in &mut self.responses {
                r.tail_out.fill(0.0);
            }
        }
        self.window.copy_within(PART.., 0);
    }
}

/// A dot product with eight partial sums, which the compiler turns into vector code.
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut sum: f32 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    for v in acc {
        sum += v;
    }
    sum
}

fn check_taps(taps: &[f64]) -> Result<(), CompensationError> {
    if taps.is_empty() {
        return Err(CompensationError::InvalidParameter {
            name: "taps",
            value: 0.0,
            expected: "at least one tap",
        });
    }
    if let Some(&bad) = taps.iter().find(|t| !t.is_finite()) {
        return Err(CompensationError::InvalidParameter {
            name: "taps",
            value: bad,
            expected: "finite coefficients",
        });
    }
    Ok(())
}

/// Designs minimum-phase FIR filters of a fixed length from magnitude responses; see the
/// [module documentation](self).
pub struct MinPhaseDesigner {
    taps: usize,
    /// The design DFT size `M`.
    size: usize,
    forward: Arc<dyn RealToComplex<f64>>,
    inverse: Arc<dyn ComplexToReal<f64>>,
    real: Vec<f64>,
    spectrum: Vec<Complex<f64>>,
    scratch_forward: Vec<Complex<f64>>,
    scratch_inverse: Vec<Complex<f64>>,
    fade: Vec<f64>,
}

impl fmt::Debug for MinPhaseDesigner {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("MinPhaseDesigner")
            .field("taps", &self.taps)
            .field("size", &self.size)
            .finish_non_exhaustive()
    }
}

impl MinPhaseDesigner {
    /// A designer of `taps`-long filters, whose DFT has at least `min_size` points (the
    /// resolution of the magnitudes it will be given) and at least `8 · taps`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] when `taps` is 0 or above 2^20.
    pub fn new(taps: usize, min_size: usize) -> Result<Self, CompensationError> {
        if taps == 0 || taps > 1 << 20 {
            return Err(CompensationError::InvalidParameter {
                name: "taps",
                value: taps as f64,
                expected: "1 to 2^20",
            });
        }
        let size = (8 * taps).max(min_size).max(16).next_power_of_two();
        let mut planner = RealFftPlanner::<f64>::new();
        let forward = planner.plan_fft_forward(size);
        let inverse = planner.plan_fft_inverse(size);
        let quarter = (taps / 4).max(1);
        // Half-Hann from 1 down to (almost) 0 over the last quarter of the taps.
        let fade = (0..taps)
            .map(|i| {
                let from_end = taps - i;
                if from_end > quarter {
                    1.0
                } else {
                    let x = from_end as f64 / (quarter + 1) as f64;
                    (0.5 * PI * x).sin().powi(2)
                }
            })
            .collect();
        Ok(Self {
            taps,
            size,
            real: forward.make_input_vec(),
            spectrum: forward.make_output_vec(),
            scratch_forward: forward.make_scratch_vec(),
            scratch_inverse: inverse.make_scratch_vec(),
            forward,
            inverse,
            fade,
        })
    }

    /// The design DFT size `M`.
    #[must_use]
    pub fn size(&self) -> usize {
        self.size
    }

    /// The filter length.
    #[must_use]
    pub fn taps(&self) -> usize {
        self.taps
    }

    /// Designs the minimum-phase filter whose magnitude at normalised frequency
    /// `ν ∈ [0, 1/2]` (cycles per sample) is `10^(gain_db(ν)/20)`, into `out` (its first
    /// `taps` values; the rest is zeroed). Gains are floored at -200 dB. Never allocates;
    /// returns `false` (and leaves `out` alone) if the design is not finite.
    pub fn design(&mut self, mut gain_db: impl FnMut(f64) -> f64, out: &mut [f64]) -> bool {
        let m = self.size;
        let bins = m / 2 + 1;
        // 1. ln|W| on the bins, as a real spectrum.
        for (k, s) in self.spectrum.iter_mut().enumerate().take(bins) {
            let db = gain_db(k as f64 / m as f64).max(-200.0);
            *s = Complex::new(db * (std::f64::consts::LN_10 / 20.0), 0.0);
        }
        if self
            .inverse
            .process_with_scratch(
                &mut self.spectrum,
                &mut self.real,
                &mut self.scratch_inverse,
            )
            .is_err()
        {
            return false;
        }
        // 2. Fold onto positive quefrency (the 1/M of the inverse DFT included).
        let scale = 1.0 / m as f64;
        for (n, c) in self.real.iter_mut().enumerate() {
            *c *= scale
                * match n {
                    0 => 1.0,
                    n if n < m / 2 => 2.0,
                    n if n == m / 2 => 1.0,
                    _ => 0.0,
                };
        }
        // 3. exp of its spectrum, and back.
        if self
            .forward
            .process_with_scratch(
                &mut self.real,
                &mut self.spectrum,
                &mut self.scratch_forward,
            )
            .is_err()
        {
            return false;
        }
        for s in &mut self.spectrum {
            *s = s.exp();
        }
        self.spectrum[0].im = 0.0;
        self.spectrum[bins - 1].im = 0.0;
        if self
            .inverse
            .process_with_scratch(
                &mut self.spectrum,
                &mut self.real,
                &mut self.scratch_inverse,
            )
            .is_err()
        {
            return false;
        }
        // 4. Truncate with the fade.
        if self.real[..self.taps].iter().any(|v| !v.is_finite()) {
            return false;
        }
        for (o, (&h, &w)) in out.iter_mut().zip(self.real.iter().zip(&self.fade)) {
            *o = h * scale * w;
        }
        let used = self.taps.min(out.len());
        out[used..].fill(0.0);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64;

    fn response(taps: &[f64], nu: f64) -> Complex64 {
        taps.iter()
            .enumerate()
            .map(|(n, &h)| h * Complex64::from_polar(1.0, -2.0 * PI * nu * n as f64))
            .sum()
    }

    #[test]
    fn minimum_phase_design_follows_the_magnitude() {
        // A smooth bump: +6 dB around 0.05 cycles/sample, 0 dB elsewhere.
        let target = |nu: f64| 6.0 * (-((nu - 0.05) / 0.01).powi(2)).exp();
        let mut d = MinPhaseDesigner::new(512, 0).unwrap();
        let mut taps = vec![0.0; 512];
        assert!(d.design(target, &mut taps));
        for i in 1..50 {
            let nu = i as f64 * 0.005;
            let got = 20.0 * response(&taps, nu).norm().log10();
            assert!(
                (got - target(nu)).abs() < 0.05,
                "{nu}: {got} vs {}",
                target(nu)
            );
        }
        // Minimum phase: the energy comes first. Half of it within the first 2% of taps.
        let total: f64 = taps.iter().map(|t| t * t).sum();
        let early: f64 = taps[..10].iter().map(|t| t * t).sum();
        assert!(early > 0.5 * total, "{early} of {total}");
    }

    #[test]
    fn a_flat_magnitude_is_an_impulse() {
        let mut d = MinPhaseDesigner::new(64, 0).unwrap();
        let mut taps = vec![0.0; 64];
        assert!(d.design(|_| 0.0, &mut taps));
        assert!((taps[0] - 1.0).abs() < 1e-12);
        assert!(taps[1..].iter().all(|t| t.abs() < 1e-12));
    }

    fn convolve(taps: &[f64], input: &[f32]) -> Vec<f32> {
        (0..input.len())
            .map(|n| {
                (0..taps.len().min(n + 1))
                    .map(|j| taps[j] * f64::from(input[n - j]))
                    .sum::<f64>() as f32
            })
            .collect()
    }

    fn signal(len: usize) -> Vec<f32> {
        (0..len)
            .map(|i| ((i * 13 % 17) as f32 - 8.0) / 8.0)
            .collect()
    }

    #[test]
    fn fir_matches_direct_convolution_for_any_block_size() {
        // Head only, head and one partial partition, several partitions.
        for len in [37, 128, 129, 300, 1000] {
            let taps: Vec<f64> = (0..len)
                .map(|i| ((i * 7 % 11) as f64 - 5.0) / 10.0 * (-(i as f64) / 400.0).exp())
                .collect();
            let input = signal(2500);
            let direct = convolve(&taps, &input);
            let mut reference: Option<Vec<f32>> = None;
            for block in [1, 7, 64, 512] {
                let mut fir = Fir::new(&taps).unwrap();
                let mut out = vec![0.0f32; input.len()];
                for (x, y) in input.chunks(block).zip(out.chunks_mut(block)) {
                    fir.process(x, y);
                }
                for (n, (a, b)) in out.iter().zip(&direct).enumerate() {
                    assert!(
                        (a - b).abs() < 1e-4,
                        "len {len} block {block} n {n}: {a} vs {b}"
                    );
                }
                match &reference {
                    None => reference = Some(out),
                    Some(r) => assert_eq!(r, &out, "len {len}: block {block} differs"),
                }
            }
            let back = Fir::new(&taps).unwrap().taps();
            assert_eq!(back.len(), len);
            for (a, b) in back.iter().zip(&taps) {
                assert!((f64::from(*a) - b).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn tap_changes_cross_fade() {
        let mut fir = Fir::new(&[1.0]).unwrap();
        assert!(fir.set_taps([0.0]));
        let input = vec![1.0f32; PART + Fir::FADE + 10];
        let mut out = vec![0.0f32; input.len()];
        fir.process(&input, &mut out);
        // Unchanged up to the partition boundary, then falls smoothly from 1 to 0 over
        // the fade, then stays at 0.
        assert!(out[..PART].iter().all(|&v| v == 1.0));
        assert!(out.windows(2).all(|w| w[1] <= w[0]));
        assert!((out[PART + Fir::FADE / 2] - 0.5).abs() < 0.01);
        assert!(out[PART + Fir::FADE..].iter().all(|&v| v == 0.0));
        assert!(!fir.set_taps([f64::NAN]));
    }

    #[test]
    fn a_long_filter_changes_to_the_new_response() {
        let old: Vec<f64> = (0..600).map(|i| (-(i as f64) / 50.0).exp()).collect();
        let new: Vec<f64> = (0..600).map(|i| if i == 3 { 0.5 } else { 0.0 }).collect();
        let input = signal(4000);
        let mut fir = Fir::new(&old).unwrap();
        let mut out = vec![0.0f32; input.len()];
        fir.process(&input[..1000], &mut out[..1000]);
        assert!(fir.set_taps(new.iter().copied()));
        fir.process(&input[1000..], &mut out[1000..]);
        // Long after the fade, the output is the new filter's (it has the whole history).
        let expected = convolve(&new, &input);
        for n in 2500..4000 {
            assert!(
                (out[n] - expected[n]).abs() < 1e-4,
                "{n}: {} vs {}",
                out[n],
                expected[n]
            );
        }
    }

    #[test]
    fn non_finite_input_is_zeroed_and_counted() {
        let mut fir = Fir::new(&[0.5, 0.5]).unwrap();
        let mut out = [0.0f32; 3];
        fir.process(&[f32::NAN, 1.0, f32::INFINITY], &mut out);
        assert_eq!(out, [0.0, 0.5, 0.5]);
        assert_eq!(fir.non_finite_inputs(), 2);
        assert!(Fir::new(&[]).is_err());
        assert!(Fir::new(&[f64::NAN]).is_err());
    }
}
