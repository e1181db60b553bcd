//! Culling the modes that have died away.
//!
//! Without input each mode only decays (`|p_k| < 1`), so once a mode's share of the
//! energy, `½ ω_k |g_k| |z_k|²`, is negligible it stays negligible: a caller that knows
//! the scale of what matters (an [`Aggregate`](crate::physical::Aggregate) slot, from its peak
//! energy) may cull it (`ResonatorBank::cull`): its state is set to exactly zero and
//! every loop skips it. The live modes are kept at the front of the per-mode arrays (a
//! culled one is swapped with the last live one), so the loops run over one contiguous
//! prefix with the arithmetic of each live mode unchanged. Any impulse, retune or reset
//! restores all the modes (at rest, as they were culled) and the modes' order. Culling
//! is a decision, so it must be taken on a sample clock of the caller's, never at a block
//! boundary, to keep the output independent of the block size.

use super::ResonatorBank;

impl ResonatorBank {
    /// Culls every live mode whose energy `½ ω_k |g_k| |z_k|²` (its share of
    /// [`energy`](Self::energy)) is at most `floor`: its state is set to exactly zero and
    /// the free loops skip it until [`restore`](Self::restore) (which a retune, a reset or
    /// an impulse bring). Each mode only decays without input, so a culled mode would
    /// have stayed at most that small. The live modes are swapped to the front of the
    /// per-mode arrays; their own arithmetic is unchanged.
    ///
    /// Real time: no allocation, one pass over the live modes.
    pub(crate) fn cull(&mut self, floor: f64) {
        let mut k = 0;
        while k < self.live {
            let energy = self.lanes.mode_energy(k);
            if energy <= floor {
                self.lanes.zr[k] = 0.0;
                self.lanes.zi[k] = 0.0;
                self.live -= 1;
                self.swap(k, self.live);
            } else {
                k += 1;
            }
        }
    }

    /// Brings every culled mode back into the loops (at rest, as it was culled) and the
    /// per-mode arrays back to the modes' order. Real time: at most one swap per mode.
    pub(crate) fn restore(&mut self) {
        self.live = self.modes.len();
        for k in 0..self.order.len() {
            while self.order[k] != k {
                let j = self.order[k];
                self.swap(k, j);
            }
        }
    }

    /// The number of modes computed (not culled).
    #[must_use]
    #[cfg(test)]
    pub(crate) fn live_modes(&self) -> usize {
        self.live
    }

    fn swap(&mut self, a: usize, b: usize) {
        self.pole.swap(a, b);
        self.gain.swap(a, b);
        self.gain_slope.swap(a, b);
        self.lanes.swap(a, b);
        self.order.swap(a, b);
    }
}
