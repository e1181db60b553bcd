//! Centred moving windows, from prefix sums.
//!
//! A window of `n` samples centred on `i` covers `x[i - ⌊n/2⌋ .. i - ⌊n/2⌋ + n)`: for an
//! even `n`, one sample more before `i` than after it, as numpy's
//! `convolve(x, ones(n), "same")` places it. The sums are differences of one running sum,
//! so a window costs the same whatever its length.

/// What a centred window does where it reaches past the signal's ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edges {
    /// The signal is zero beyond its ends: every window's sum is divided by its full length
    /// (numpy's `convolve(x², ones(n)/n, "same")`).
    Zeros,
    /// The window is cut at the ends and averages what it still holds.
    Clipped,
}

/// The centred moving RMS of `x` over `n` samples (at least 1).
#[must_use]
pub fn centred_rms(x: &[f64], n: usize, edges: Edges) -> Vec<f64> {
    let n = n.max(1);
    let mut prefix = Vec::with_capacity(x.len() + 1);
    prefix.push(0.0);
    let mut acc = 0.0;
    for v in x {
        acc += v * v;
        prefix.push(acc);
    }
    let before = n / 2;
    (0..x.len())
        .map(|i| {
            let lo = i.saturating_sub(before);
            let hi = (i + n - before).min(x.len());
            let length = match edges {
                Edges::Zeros => n,
                Edges::Clipped => hi - lo,
            };
            // Differences of a rounded running sum can dip just below zero.
            ((prefix[hi] - prefix[lo]).max(0.0) / length as f64).sqrt()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The window summed sample by sample, as its definition reads.
    fn naive(x: &[f64], n: usize, edges: Edges) -> Vec<f64> {
        (0..x.len() as isize)
            .map(|i| {
                let start = i - (n / 2) as isize;
                let inside: Vec<f64> = (start..start + n as isize)
                    .filter(|&j| j >= 0 && (j as usize) < x.len())
                    .map(|j| x[j as usize])
                    .collect();
                let length = match edges {
                    Edges::Zeros => n,
                    Edges::Clipped => inside.len(),
                };
                (inside.iter().map(|v| v * v).sum::<f64>() / length as f64).sqrt()
            })
            .collect()
    }

    #[test]
    fn centred_rms_is_the_window_summed_sample_by_sample() {
        let x: Vec<f64> = (0..23).map(|k| (f64::from(k) * 0.7).sin() + 0.1).collect();
        for n in [1, 2, 3, 4, 5, 8, 23, 30] {
            for edges in [Edges::Zeros, Edges::Clipped] {
                let got = centred_rms(&x, n, edges);
                for (g, w) in got.iter().zip(naive(&x, n, edges)) {
                    assert!((g - w).abs() < 1e-12, "n {n}, {edges:?}: {g} vs {w}");
                }
            }
        }
        assert!(centred_rms(&[], 4, Edges::Zeros).is_empty());
    }
}
