//! The loops an impact runs the bank with: free ringing, summed in vector lanes, and
//! the contact's impulse added after the free step.
//!
//! The bank keeps its state and coefficients as a struct of arrays (`Lanes`), padded
//! with silent modes to a whole number of [`LANES`], so that the loops below run
//! [`LANES`] modes side by side as vector operations, each lane keeping its own partial
//! sums, which are added in one fixed order, `(l0 + l1) + (l2 + l3)`. The arithmetic of
//! each mode is that of the complex loop ([`tick`](ResonatorBank::tick)); only the order
//! of the sums over modes differs (by rounding). Every sample is computed the same way
//! wherever a block starts or ends, which keeps the engine's output independent of its
//! block size, bit for bit.
//!
//! On x86-64 the loops are compiled twice, for the baseline (SSE2: two lanes a vector
//! operation) and for AVX (all four), and the AVX build is chosen at run time when the
//! processor has it. Both builds do the same operations in the same order (no fused
//! multiply-add, which Rust never forms on its own), so they give the same output bit for
//! bit; the tests run whichever the machine picks and compare it with the baseline.

use super::ResonatorBank;

/// Modes computed side by side.
pub(super) const LANES: usize = 4;

/// `modes` rounded up to a whole number of lanes.
pub(super) fn padded(modes: usize) -> usize {
    modes.div_ceil(LANES) * LANES
}

/// Samples whose lane sums [`free_velocity_kernel`] keeps at once.
const BLOCK: usize = 64;

/// Chunks of [`LANES`] modes that one pass of [`free_velocity_kernel`] runs together.
const GROUP: usize = 4;

/// The free ringing over `out`, adding each sample's velocity (before the step) to it.
///
/// Up to [`GROUP`] chunks of modes run together through a stretch of samples with their
/// state in registers: the recursion of each mode is then a chain of a multiply and an
/// add per sample, and the chunks' chains overlap, where a loop over the modes inside a
/// loop over the samples would store and reload every state each sample. The lane sums
/// of each sample are kept in a buffer between groups, added in the chunks' order, so
/// the sums are those of the plain loop (`lanes[l] += ...` chunk after chunk, then
/// `(l0 + l1) + (l2 + l3)`), bit for bit.
#[inline(always)]
fn free_velocity_kernel(
    zr: &mut [f64],
    zi: &mut [f64],
    pr: &[f64],
    pi: &[f64],
    sr: &[f64],
    si: &[f64],
    out: &mut [f32],
) {
    let chunks = zr.len() / LANES;
    for block in out.chunks_mut(BLOCK) {
        let mut acc = [[0.0; LANES]; BLOCK];
        let acc = &mut acc[..block.len()];
        let mut start = 0;
        while start < chunks {
            let range = start * LANES..chunks.min(start + GROUP) * LANES;
            let (zr, zi) = (&mut zr[range.clone()], &mut zi[range.clone()]);
            let (pr, pi, sr, si) = (
                &pr[range.clone()],
                &pi[range.clone()],
                &sr[range.clone()],
                &si[range],
            );
            match chunks - start {
                1 => ring::<1>(zr, zi, pr, pi, sr, si, acc),
                2 => ring::<2>(zr, zi, pr, pi, sr, si, acc),
                3 => ring::<3>(zr, zi, pr, pi, sr, si, acc),
                _ => ring::<GROUP>(zr, zi, pr, pi, sr, si, acc),
            }
            start += GROUP;
        }
        for (o, a) in block.iter_mut().zip(acc.iter()) {
            *o += ((a[0] + a[1]) + (a[2] + a[3])) as f32;
        }
    }
}

/// `C` chunks of modes (`C × LANES` entries of each array) ringing over `acc.len()`
/// samples, each sample's velocity added to its lane sums.
#[inline(always)]
fn ring<const C: usize>(
    zr: &mut [f64],
    zi: &mut [f64],
    pr: &[f64],
    pi: &[f64],
    sr: &[f64],
    si: &[f64],
    acc: &mut [[f64; LANES]],
) {
    let load = |x: &[f64]| -> [[f64; LANES]; C] {
        std::array::from_fn(|c| std::array::from_fn(|l| x[c * LANES + l]))
    };
    let (mut r, mut i) = (load(zr), load(zi));
    let (p_r, p_i, s_r, s_i) = (load(pr), load(pi), load(sr), load(si));
    for a in acc.iter_mut() {
        for c in 0..C {
            for l in 0..LANES {
                a[l] += s_r[c][l] * i[c][l] + s_i[c][l] * r[c][l];
                let re = r[c][l] * p_r[c][l] - i[c][l] * p_i[c][l];
                i[c][l] = r[c][l] * p_i[c][l] + i[c][l] * p_r[c][l];
                r[c][l] = re;
            }
        }
    }
    for c in 0..C {
        for l in 0..LANES {
            zr[c * LANES + l] = r[c][l];
            zi[c * LANES + l] = i[c][l];
        }
    }
}

/// One free step: the velocity before it and the displacement after it.
#[inline(always)]
fn advance_kernel(
    zr: &mut [f64],
    zi: &mut [f64],
    pr: &[f64],
    pi: &[f64],
    g: &[f64],
    sr: &[f64],
    si: &[f64],
) -> (f64, f64) {
    let mut velocity = [0.0; LANES];
    let mut displacement = [0.0; LANES];
    for (((((zr, zi), pr), pi), g), (sr, si)) in zr
        .chunks_exact_mut(LANES)
        .zip(zi.chunks_exact_mut(LANES))
        .zip(pr.chunks_exact(LANES))
        .zip(pi.chunks_exact(LANES))
        .zip(g.chunks_exact(LANES))
        .zip(sr.chunks_exact(LANES).zip(si.chunks_exact(LANES)))
    {
        for l in 0..LANES {
            velocity[l] += sr[l] * zi[l] + si[l] * zr[l];
            let re = zr[l] * pr[l] - zi[l] * pi[l];
            zi[l] = zr[l] * pi[l] + zi[l] * pr[l];
            zr[l] = re;
            displacement[l] += g[l] * zi[l];
        }
    }
    (
        (velocity[0] + velocity[1]) + (velocity[2] + velocity[3]),
        (displacement[0] + displacement[1]) + (displacement[2] + displacement[3]),
    )
}

#[cfg(target_arch = "x86_64")]
mod avx {
    /// [`super::free_velocity_kernel`] built for AVX.
    #[target_feature(enable = "avx")]
    pub(super) fn free_velocity(
        zr: &mut [f64],
        zi: &mut [f64],
        pr: &[f64],
        pi: &[f64],
        sr: &[f64],
        si: &[f64],
        out: &mut [f32],
    ) {
        super::free_velocity_kernel(zr, zi, pr, pi, sr, si, out);
    }

    /// [`super::advance_kernel`] built for AVX.
    #[target_feature(enable = "avx")]
    pub(super) fn advance(
        zr: &mut [f64],
        zi: &mut [f64],
        pr: &[f64],
        pi: &[f64],
        g: &[f64],
        sr: &[f64],
        si: &[f64],
    ) -> (f64, f64) {
        super::advance_kernel(zr, zi, pr, pi, g, sr, si)
    }
}

/// Whether the AVX build of the loops runs (x86-64 with AVX, unless a test asked for
/// the baseline).
#[inline]
fn use_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        #[cfg(test)]
        if super::tests::BASELINE_ONLY.with(std::cell::Cell::get) {
            return false;
        }
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

impl ResonatorBank {
    /// Advances one sample with no impulse and returns the velocity before the step and
    /// the displacement after it: [`velocity`](Self::velocity), `tick(0.0)` and
    /// [`displacement`](Self::displacement) in one pass over the modes (in lanes: equal
    /// to them up to the order of the sums).
    /// [`add_delayed_impulse`](Self::add_delayed_impulse) then adds the step's impulse.
    pub(crate) fn advance_free(&mut self) -> (f64, f64) {
        let n = padded(self.live);
        let l = &mut self.lanes;
        let (zr, zi) = (&mut l.zr[..n], &mut l.zi[..n]);
        let (pr, pi, g, sr, si) = (&l.pr[..n], &l.pi[..n], &l.g[..n], &l.sr[..n], &l.si[..n]);
        // Called once a sample: for one chunk of modes the inlined baseline beats a call.
        #[cfg(target_arch = "x86_64")]
        if n > LANES && use_avx() {
            // SAFETY: the processor has AVX (checked just above).
            return unsafe { avx::advance(zr, zi, pr, pi, g, sr, si) };
        }
        advance_kernel(zr, zi, pr, pi, g, sr, si)
    }

    /// Rings freely over `out`, adding the velocity of each sample to it (as
    /// [`velocity`](Self::velocity) then `tick(0.0)`, sample by sample, up to the order of
    /// the sums over modes).
    pub(crate) fn add_free_velocity(&mut self, out: &mut [f32]) {
        let n = padded(self.live);
        let l = &mut self.lanes;
        let (zr, zi) = (&mut l.zr[..n], &mut l.zi[..n]);
        let (pr, pi, sr, si) = (&l.pr[..n], &l.pi[..n], &l.sr[..n], &l.si[..n]);
        #[cfg(target_arch = "x86_64")]
        if use_avx() {
            // SAFETY: the processor has AVX (checked just above).
            unsafe { avx::free_velocity(zr, zi, pr, pi, sr, si, out) };
            return;
        }
        free_velocity_kernel(zr, zi, pr, pi, sr, si, out);
    }

    /// `Σ |g_k| |z_k|`: no displacement, now or later without input, exceeds it in size
    /// (each `|z_k|` only decays).
    pub(crate) fn amplitude_bound(&self) -> f64 {
        let l = &self.lanes;
        (0..self.live)
            // The state is far from overflow: no need for hypot's care (or cost).
            .map(|k| l.g[k].abs() * (l.zr[k] * l.zr[k] + l.zi[k] * l.zi[k]).sqrt())
            .sum()
    }

    /// Adds the impulse `J` (N·s) of the sample just advanced by
    /// [`advance_free`](Self::advance_free): `z_k += p_k J`, so that together they are
    /// `z_k ← p_k (z_k + J)` as in [`tick`](Self::tick), and the displacement grows by
    /// `h[1] J`.
    pub(crate) fn add_delayed_impulse(&mut self, impulse: f64) {
        if impulse != 0.0 && self.live < self.modes.len() {
            self.restore();
        }
        let n = padded(self.live);
        let l = &mut self.lanes;
        for ((zr, zi), (pr, pi)) in l.zr[..n]
            .iter_mut()
            .zip(&mut l.zi[..n])
            .zip(l.pr[..n].iter().zip(&l.pi[..n]))
        {
            *zr += pr * impulse;
            *zi += pi * impulse;
        }
    }

    /// `h[1]`: how much the next displacement moves per unit impulse now.
    pub(crate) fn first_sample_gain(&self) -> f64 {
        self.first_sample
    }
}
