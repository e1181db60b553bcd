//! The loops an impact runs the bank with: free ringing, summed in vector lanes, and
//! the contact's impulse added after the free step.

use num_complex::Complex64;

use super::ResonatorBank;

/// Modes summed side by side in the free loop.
const LANES: usize = 4;

/// The most live modes the free loop copies to arrays on the stack to run them as vectors.
const SOA_MODES: usize = 64;

impl ResonatorBank {
    /// Advances one sample with no impulse and returns the velocity before the step and
    /// the displacement after it: [`velocity`](Self::velocity), `tick(0.0)` and
    /// [`displacement`](Self::displacement) in one pass over the modes.
    /// [`add_delayed_impulse`](Self::add_delayed_impulse) then adds the step's impulse.
    pub(crate) fn advance_free(&mut self) -> (f64, f64) {
        let (mut velocity, mut displacement) = (0.0, 0.0);
        for (((z, p), g), gs) in self.state[..self.live]
            .iter_mut()
            .zip(&self.pole)
            .zip(&self.gain)
            .zip(&self.gain_slope)
        {
            velocity += gs.re * z.im + gs.im * z.re;
            *z *= p;
            displacement += g * z.im;
        }
        (velocity, displacement)
    }

    /// Rings freely over `out`, adding the velocity of each sample to it (as
    /// [`velocity`](Self::velocity) then `tick(0.0)`, sample by sample).
    pub(crate) fn add_free_velocity(&mut self, out: &mut [f32]) {
        let live = self.live;
        if live > SOA_MODES {
            self.add_free_velocity_aos(out);
            return;
        }
        // The live modes go into separate arrays of real and imaginary parts (a struct of
        // arrays, on the stack), padded with silent modes to a whole number of lanes, so
        // that the compiler can run the lanes of the sample loop as vector operations.
        // The arithmetic of each mode is that of the complex loop.
        let padded = live.div_ceil(LANES) * LANES;
        let mut zr = [0.0; SOA_MODES];
        let mut zi = [0.0; SOA_MODES];
        let mut pr = [0.0; SOA_MODES];
        let mut pi = [0.0; SOA_MODES];
        let mut sr = [0.0; SOA_MODES];
        let mut si = [0.0; SOA_MODES];
        for k in 0..live {
            zr[k] = self.state[k].re;
            zi[k] = self.state[k].im;
            pr[k] = self.pole[k].re;
            pi[k] = self.pole[k].im;
            sr[k] = self.gain_slope[k].re;
            si[k] = self.gain_slope[k].im;
        }
        let (zr, zi) = (&mut zr[..padded], &mut zi[..padded]);
        let (pr, pi, sr, si) = (&pr[..padded], &pi[..padded], &sr[..padded], &si[..padded]);
        for o in out.iter_mut() {
            let mut lanes = [0.0; LANES];
            for ((((zr, zi), pr), pi), (sr, si)) in zr
                .chunks_exact_mut(LANES)
                .zip(zi.chunks_exact_mut(LANES))
                .zip(pr.chunks_exact(LANES))
                .zip(pi.chunks_exact(LANES))
                .zip(sr.chunks_exact(LANES).zip(si.chunks_exact(LANES)))
            {
                for l in 0..LANES {
                    lanes[l] += sr[l] * zi[l] + si[l] * zr[l];
                    let re = zr[l] * pr[l] - zi[l] * pi[l];
                    zi[l] = zr[l] * pi[l] + zi[l] * pr[l];
                    zr[l] = re;
                }
            }
            *o += ((lanes[0] + lanes[1]) + (lanes[2] + lanes[3])) as f32;
        }
        for (k, z) in self.state[..live].iter_mut().enumerate() {
            *z = Complex64::new(zr[k], zi[k]);
        }
    }

    /// [`add_free_velocity`](Self::add_free_velocity) for banks of more than
    /// [`SOA_MODES`] live modes, on the complex arrays in place.
    fn add_free_velocity_aos(&mut self, out: &mut [f32]) {
        // Modes go four at a time into separate partial sums, so that a sample's sum is
        // not one long chain of additions. Every sample is computed the same way wherever
        // a block starts or ends, which keeps the engine's output independent of its
        // block size, bit for bit.
        let live = self.live;
        let split = live / LANES * LANES;
        let (state, state_tail) = self.state[..live].split_at_mut(split);
        let (pole, pole_tail) = self.pole.split_at(split);
        let (slope, slope_tail) = self.gain_slope.split_at(split);
        for o in out.iter_mut() {
            let mut lanes = [0.0; LANES];
            for ((z, p), gs) in state
                .chunks_exact_mut(LANES)
                .zip(pole.chunks_exact(LANES))
                .zip(slope.chunks_exact(LANES))
            {
                for l in 0..LANES {
                    lanes[l] += gs[l].re * z[l].im + gs[l].im * z[l].re;
                    z[l] *= p[l];
                }
            }
            let mut velocity = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
            for ((z, p), gs) in state_tail
                .iter_mut()
                .zip(&pole_tail[..live - split])
                .zip(slope_tail)
            {
                velocity += gs.re * z.im + gs.im * z.re;
                *z *= p;
            }
            *o += velocity as f32;
        }
    }

    /// `Σ |g_k| |z_k|`: no displacement, now or later without input, exceeds it in size
    /// (each `|z_k|` only decays).
    pub(crate) fn amplitude_bound(&self) -> f64 {
        self.state[..self.live]
            .iter()
            .zip(&self.gain)
            .map(|(z, g)| g.abs() * z.norm())
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
        for (z, p) in self.state[..self.live].iter_mut().zip(&self.pole) {
            *z += p * impulse;
        }
    }

    /// `h[1]`: how much the next displacement moves per unit impulse now.
    pub(crate) fn first_sample_gain(&self) -> f64 {
        self.first_sample
    }
}
