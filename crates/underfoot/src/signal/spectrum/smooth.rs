//! Fractional-octave smoothing of a magnitude spectrum.
//!
//! [`fractional_octave_smooth`] replaces each bin `k ≥ 1` (centre `f = k Δf`) by the RMS of
//! the magnitude over the band `[f / r, f r]`, `r = 2^{1/(2b)}` for a `1/b` octave. The
//! spectrum is treated as piecewise constant in power, bin `j` owning the interval
//! `[j - ½, j + ½]` (bin 0 only `[0, ½]`, the DC half), so that
//!
//! ```math
//! S_k = \sqrt{\frac{1}{f_2 - f_1}\int_{f_1}^{f_2} |X(\nu)|^2\, d\nu}, \qquad
//!   [f_1, f_2] = [k/r,\ k r] \cap [0, N_b - ½]
//! ```
//!
//! in units of bins (the smoothing is scale-free, so `Δf` cancels). Partly covered bins
//! count in proportion to their overlap: a band narrower than a bin, as at low
//! frequencies, averages over that one bin alone and returns it unchanged. At the top, a
//! band reaching past the last bin averages over the part that exists.
//!
//! Whole bins are summed from prefix sums, `O(1)` per output bin. The prefix sums are kept
//! in double-double precision (a compensated sum): a measured spectrum can span 120 dB or
//! more, and a plain prefix difference would cancel the quiet bands into the rounding
//! noise of the loud ones. The relative error of a band is then about
//! `10⁻³² × (total power / band power)`, negligible below ~250 dB of power range.

/// `mag` smoothed over bands `1/fraction` of an octave wide, power-averaged (see the module
/// docs). Bin 0 is returned unchanged. `bin_hz` is the bin spacing; because the bands are
/// proportional to frequency the result does not depend on it, but it must be positive.
///
/// A `fraction` or `bin_hz` that is not positive (or NaN) smooths nothing: `mag` is
/// returned as it is. An infinite `fraction` (zero-width bands) also returns `mag`.
#[must_use]
pub fn fractional_octave_smooth(mag: &[f64], bin_hz: f64, fraction: f64) -> Vec<f64> {
    let n = mag.len();
    if n == 0 || fraction.is_nan() || fraction <= 0.0 || !bin_hz.is_finite() || bin_hz <= 0.0 {
        return mag.to_vec();
    }
    let r = 2f64.powf(1.0 / (2.0 * fraction));
    let power: Vec<f64> = mag.iter().map(|m| m * m).collect();
    let prefix = PrefixSum::new(&power);
    let top = n as f64 - 0.5;
    let bin_of = |x: f64| ((x + 0.5).floor() as usize).min(n - 1);

    let mut out = Vec::with_capacity(n);
    out.push(mag[0]);
    for k in 1..n {
        let lo = (k as f64 / r).max(0.0);
        let hi = (k as f64 * r).min(top);
        let (jl, jh) = (bin_of(lo), bin_of(hi));
        if jl == jh || hi <= lo {
            // The whole band lies in one bin: its average is that bin.
            out.push(mag[jl].abs());
            continue;
        }
        let first = power[jl] * (jl as f64 + 0.5 - lo);
        let last = power[jh] * (hi - (jh as f64 - 0.5));
        let whole = prefix.between(jl + 1, jh);
        out.push(((first + whole + last) / (hi - lo)).sqrt());
    }
    out
}

/// Prefix sums in double-double: `sum[j] ≈ hi[j] + lo[j] = Σ_{i<j} p_i`.
struct PrefixSum {
    hi: Vec<f64>,
    lo: Vec<f64>,
}

impl PrefixSum {
    fn new(p: &[f64]) -> Self {
        let mut hi = Vec::with_capacity(p.len() + 1);
        let mut lo = Vec::with_capacity(p.len() + 1);
        let (mut h, mut l) = (0.0, 0.0);
        hi.push(h);
        lo.push(l);
        for &v in p {
            let (s, e) = two_sum(h, v);
            (h, l) = fast_two_sum(s, l + e);
            hi.push(h);
            lo.push(l);
        }
        Self { hi, lo }
    }

    /// `Σ_{a <= i < b} p_i`.
    fn between(&self, a: usize, b: usize) -> f64 {
        if b <= a {
            return 0.0;
        }
        (self.hi[b] - self.hi[a]) + (self.lo[b] - self.lo[a])
    }
}

/// `s + e = a + b` exactly, `s = fl(a + b)` (Knuth).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// `s + e = a + b` exactly, for `|a| >= |b|` (Dekker).
fn fast_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::signal::noise::SplitMix64;

    /// Direct integration of the piecewise-constant power over each band, bin by bin.
    fn naive_smooth(mag: &[f64], fraction: f64) -> Vec<f64> {
        let n = mag.len();
        let r = 2f64.powf(1.0 / (2.0 * fraction));
        let mut out = vec![mag[0]];
        for k in 1..n {
            let lo = k as f64 / r;
            let hi = (k as f64 * r).min(n as f64 - 0.5);
            let mut acc = 0.0;
            for (j, m) in mag.iter().enumerate() {
                let (a, b) = (if j == 0 { 0.0 } else { j as f64 - 0.5 }, j as f64 + 0.5);
                let overlap = (b.min(hi) - a.max(lo)).max(0.0);
                acc += m * m * overlap;
            }
            out.push((acc / (hi - lo)).sqrt());
        }
        out
    }

    #[test]
    fn smoothing_matches_direct_integration() {
        let mut rng = SplitMix64::new(5);
        // Levels spread over 170 dB, loud at the bottom: plain prefix sums of power would
        // cancel the quiet top into rounding noise (relative error ~ 1e-16 * 1e17).
        let mag: Vec<f64> = (0..3000)
            .map(|k| 10f64.powf(4.0 - 8.0 * (k as f64 / 3000.0) + 0.5 * rng.symmetric()))
            .collect();
        for fraction in [1.0, 3.0, 6.0, 24.0, 0.3] {
            let got = fractional_octave_smooth(&mag, 0.5, fraction);
            let want = naive_smooth(&mag, fraction);
            assert_eq!(got.len(), mag.len());
            for (k, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!((g - w).abs() <= 1e-9 * w, "1/{fraction} k={k}: {g} vs {w}");
            }
        }
    }

    #[test]
    fn flat_stays_flat_and_low_bins_are_kept() {
        let flat = vec![0.25; 2049];
        for fraction in [1.0, 6.0, 48.0] {
            for v in fractional_octave_smooth(&flat, 0.5, fraction) {
                assert!((v - 0.25).abs() < 1e-14);
            }
        }
        // At 1/6 octave the bands of bins 1..=8 are narrower than a bin: kept as they are.
        let mut rng = SplitMix64::new(1);
        let mag: Vec<f64> = (0..100).map(|_| rng.symmetric().abs()).collect();
        let s = fractional_octave_smooth(&mag, 2.0, 6.0);
        for k in 0..=8 {
            assert_eq!(s[k], mag[k], "bin {k}");
        }
        assert_ne!(s[20], mag[20]);
    }

    #[test]
    fn single_bin_spreads_over_a_sixth_octave() {
        let (n, k0, m) = (4097, 1000usize, 3.0);
        let mut mag = vec![0.0; n];
        mag[k0] = m;
        let s = fractional_octave_smooth(&mag, 0.5, 6.0);
        let r = 2f64.powf(1.0 / 12.0);
        for (k, v) in s.iter().enumerate() {
            // Bin k's band [k/r, k r] overlaps [k0 - 1/2, k0 + 1/2] exactly for these k.
            let touches = (k as f64) * r > k0 as f64 - 0.5 && (k as f64) / r < k0 as f64 + 0.5;
            assert_eq!(*v > 0.0, touches, "k={k}");
        }
        let spread = s.iter().filter(|v| **v > 0.0).count() as f64;
        let width = (k0 as f64) * (r - 1.0 / r);
        assert!((spread - width).abs() <= 2.0, "{spread} bins vs {width}");
        // Power is conserved up to the proportional-band factor 2 ln r / (r - 1/r).
        let total: f64 = s.iter().map(|v| v * v).sum();
        let factor = 2.0 * r.ln() / (r - 1.0 / r);
        assert!(
            (total / (m * m) - factor).abs() < 2e-3,
            "{total} vs {}",
            m * m * factor
        );
        assert!((factor - 1.0).abs() < 1e-3);
    }

    #[test]
    fn degenerate_smoothing_arguments() {
        let mag = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(fractional_octave_smooth(&mag, 1.0, 0.0), mag.to_vec());
        assert_eq!(fractional_octave_smooth(&mag, 1.0, f64::NAN), mag.to_vec());
        assert_eq!(fractional_octave_smooth(&mag, 0.0, 6.0), mag.to_vec());
        assert_eq!(
            fractional_octave_smooth(&mag, 1.0, f64::INFINITY),
            mag.to_vec()
        );
        assert!(fractional_octave_smooth(&[], 1.0, 6.0).is_empty());
        assert_eq!(fractional_octave_smooth(&[7.0], 1.0, 6.0), vec![7.0]);
    }
}
