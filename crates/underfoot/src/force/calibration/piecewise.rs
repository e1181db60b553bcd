//! The piecewise model's fit: group means in reading order made increasing by
//! pool-adjacent-violators (isotonic regression), the end segments extended to the
//! extreme readings (see the parent module, *The piecewise alternative*).

use super::MAX_KNOTS;
use super::fit::min_max;

/// Group means in reading order, made increasing by pool-adjacent-violators.
pub(super) fn fit_piecewise(raw: &[f64], load: &[f64]) -> Vec<[f64; 2]> {
    let mut idx: Vec<usize> = (0..raw.len()).collect();
    idx.sort_by(|&i, &j| raw[i].total_cmp(&raw[j]).then(load[i].total_cmp(&load[j])));
    let n = idx.len();
    let groups = ((2.0 * (n as f64).sqrt()).round() as usize).clamp(2, MAX_KNOTS.min(n / 3).max(2));
    // (sum of readings, sum of loads, count) per block.
    let mut blocks: Vec<(f64, f64, f64)> = Vec::with_capacity(groups);
    let mut start = 0;
    for g in 0..groups {
        let end = (g + 1) * n / groups;
        if end <= start {
            continue;
        }
        let (mut sr, mut sl) = (0.0, 0.0);
        for &k in &idx[start..end] {
            sr += raw[k];
            sl += load[k];
        }
        let c = (end - start) as f64;
        // Equal readings in neighbouring groups would give two knots at one reading.
        match blocks.last_mut() {
            Some(last) if last.0 / last.2 >= sr / c => {
                last.0 += sr;
                last.1 += sl;
                last.2 += c;
            }
            _ => blocks.push((sr, sl, c)),
        }
        start = end;
    }
    let mut pooled: Vec<(f64, f64, f64)> = Vec::with_capacity(blocks.len());
    for b in blocks {
        pooled.push(b);
        while pooled.len() >= 2 {
            let (p, q) = (pooled[pooled.len() - 2], pooled[pooled.len() - 1]);
            if p.1 / p.2 >= q.1 / q.2 {
                pooled.pop();
                let last = pooled.len() - 1;
                pooled[last] = (p.0 + q.0, p.1 + q.1, p.2 + q.2);
            } else {
                break;
            }
        }
    }
    let mut knots: Vec<[f64; 2]> = pooled.iter().map(|b| [b.0 / b.2, b.1 / b.2]).collect();
    // Group means sit inside the data, half a group from either end; stopping the curve
    // there would clamp the extremes (the rest reading and the heaviest load) to a
    // group's average. Extend the end segments' slopes to the extreme readings instead,
    // never below the lightest load.
    let (r_lo, r_hi) = min_max(raw);
    let (l_lo, _) = min_max(load);
    if let [first, second, ..] = knots[..]
        && r_lo < first[0]
    {
        let slope = (second[1] - first[1]) / (second[0] - first[0]);
        knots.insert(
            0,
            [
                r_lo,
                (first[1] - slope * (first[0] - r_lo)).max(l_lo.min(first[1])),
            ],
        );
    }
    if let [.., before, last] = knots[..]
        && r_hi > last[0]
    {
        let slope = (last[1] - before[1]) / (last[0] - before[0]);
        knots.push([r_hi, last[1] + slope * (r_hi - last[0])]);
    }
    // Clamping at the lightest load can tie the first two knots' forces; keep the knot
    // sequence strictly increasing in reading and non-decreasing in force.
    knots
}
