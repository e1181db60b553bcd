//! Order statistics.
//!
//! The median of an even count is the mean of the two middle values; the percentile is
//! the nearest rank, `$x_{(\mathrm{round}(p (n-1)))}$` of the sorted values, so it is
//! always one of them. Both sort with [`f64::total_cmp`], so a NaN sorts to an end
//! instead of breaking the sort.

/// The median of `x`, sorting it in place; 0 for an empty slice.
#[must_use]
pub fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    x.sort_by(f64::total_cmp);
    let m = x.len() / 2;
    if x.len().is_multiple_of(2) {
        0.5 * (x[m - 1] + x[m])
    } else {
        x[m]
    }
}

/// The `p`-th percentile (nearest rank, `p` in 0..=1, clamped; a non-finite `p` is 0)
/// of `v`; `None` for an empty `v`.
#[must_use]
pub fn percentile(v: &[f64], p: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut sorted = v.to_vec();
    sorted.sort_by(f64::total_cmp);
    let p = if p.is_finite() {
        p.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let rank = (p * (sorted.len() - 1) as f64).round() as usize;
    Some(sorted[rank.min(sorted.len() - 1)])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&mut []), 0.0);
    }

    #[test]
    fn percentile_is_a_nearest_rank() {
        let v = [5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(percentile(&v, 0.0), Some(1.0));
        assert_eq!(percentile(&v, 0.5), Some(3.0));
        assert_eq!(percentile(&v, 0.74), Some(4.0));
        assert_eq!(percentile(&v, 1.0), Some(5.0));
        assert_eq!(percentile(&v, 7.0), Some(5.0));
        assert_eq!(percentile(&v, f64::NAN), Some(1.0));
        assert_eq!(percentile(&[], 0.5), None);
    }
}
