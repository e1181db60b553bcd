//! The spectral weights and their update by successive sweeps.
//!
//! # The weight update (equations (4)-(5) of the compensation paper)
//!
//! A sweep through the equalized device gives the accelerometer magnitude `A` on a log
//! grid of the band. The compensation paper writes
//!
//! ```math
//! a = A - \bar A, \qquad w_k = w_{k-1} \, \frac{\bar a}{a},
//! ```
//!
//! which read literally in linear units divides by a quantity that is zero on average.
//! It is physically right in decibels, where it says "cut each frequency by as much as it
//! stands above the mean":
//!
//! ```math
//! a_{dB}(f) = A_{dB}(f) - \overline{A_{dB}}, \qquad
//!   w_k(f) = w_{k-1}(f) \cdot 10^{-\mu\, a_{dB}(f) / 20},
//! ```
//!
//! with a relaxation `μ` ([`EqualizerConfig::step`], 1 by default: the compensation paper's update).
//! If the realised filter applied `w` exactly and the device were linear and noiseless,
//! one update would flatten the response; a second pass corrects what the first
//! realisation and the measurement noise missed, which is what the compensation paper's 15.3, 0.90,
//! 0.28 dB sequence shows.
//!
//! The weights live on the `N/2 + 1` bins of the equalizer's uniform bank (`fs/N` apart,
//! 11.7 Hz for the default `N = 4096` at 48 kHz). `a_dB` is interpolated onto the bins
//! inside the band, linearly in dB against log-frequency. Three choices keep them safe on
//! skin and meaningful:
//!
//! - **Level.** After each update the weights are shifted so that their mean in dB over
//!   the band is 0 dB: the equalizer reshapes, it does not make the device louder.
//! - **Bounds.** No bin is boosted above [`EqualizerConfig::max_boost`] or cut below
//!   `-max_cut`: a deep notch of the device (the suspension, an actuator's edge) is not
//!   chased with a boost that would overdrive it.
//! - **Outside the band** the device is not measured, so it is not corrected, and not
//!   boosted: past the bin beyond each edge, a cut at the edge is held for a third of an
//!   octave and then returns to 0 dB along a raised cosine in log-frequency over
//!   [`EqualizerConfig::taper`] octaves; a boost at the edge eases off to 0 dB over the
//!   next six bins (70 Hz at the defaults), the filter's resolution, and is 0 dB beyond
//!   (it was held like a cut: +12 dB a third of an octave past a 1024 Hz edge).
//!   Raising what the sweep never measured could drive an actuator's unmeasured
//!   resonance into the skin; a cut held past the edge only lowers it.

use serde::{Deserialize, Serialize};

use crate::compensation::CompensationError;
use crate::compensation::sweep::{FrequencyResponse, interpolate_log};
use crate::units::{Band, Decibels, Hz, SampleRate};

/// The bins beyond the corrected ones over which a boost at the band's edge eases off to
/// 0 dB (70 Hz at the default 4096 bins at 48 kHz): the realised filter's resolution, so
/// that it is right up to the edge. On the simulated tile (three passes, RMS dB from
/// flat): 1 bin leaves 2.83, 0.17, 0.13; 2 bins 0.13, 0.08; 4 bins 0.13, 0.06; 6 or more
/// 0.13, 0.05, as a boost held a third of an octave past the edge did.
const BOOST_GUARD_BINS: f64 = 6.0;

/// How the equalizer's weights are updated and bounded.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EqualizerConfig {
    /// The band that is measured and flattened.
    pub band: Band,
    /// The size `N` of the uniform bank whose `N/2 + 1` bins carry the weights.
    pub bins: usize,
    /// The relaxation `μ` of the update, in (0, 1].
    pub step: f64,
    /// The largest boost of any bin relative to the band's mean.
    pub max_boost: Decibels,
    /// The deepest cut of any bin relative to the band's mean (a positive number).
    pub max_cut: Decibels,
    /// Octaves over which the weights return to 0 dB outside the band.
    pub taper: f64,
}

impl Default for EqualizerConfig {
    /// 40-1024 Hz, `N = 4096`, `μ = 1`, +12 dB / -30 dB, a one-octave taper.
    fn default() -> Self {
        Self {
            band: Band::new(40.0, 1024.0),
            bins: 4096,
            step: 1.0,
            max_boost: Decibels(12.0),
            max_cut: Decibels(30.0),
            taper: 1.0,
        }
    }
}

impl EqualizerConfig {
    /// Checks every field against `rate`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] naming the first bad field.
    pub fn validate(&self, rate: SampleRate) -> Result<(), CompensationError> {
        let bad = |name, value, expected| {
            Err(CompensationError::InvalidParameter {
                name,
                value,
                expected,
            })
        };
        if !self.band.fits(rate) {
            return bad("band.hi", self.band.hi.0, "0 < lo < hi < Nyquist");
        }
        if !bins_are_valid(self.bins) {
            return bad("bins", self.bins as f64, "a power of two from 16 to 2^20");
        }
        if !(self.step > 0.0 && self.step <= 1.0) {
            return bad("step", self.step, "0 < step <= 1");
        }
        if !(self.max_boost.0.is_finite() && self.max_boost.0 >= 0.0) {
            return bad("max_boost", self.max_boost.0, "finite, >= 0 dB");
        }
        if !(self.max_cut.0.is_finite() && self.max_cut.0 >= 0.0) {
            return bad("max_cut", self.max_cut.0, "finite, >= 0 dB");
        }
        if !(self.taper.is_finite() && self.taper > 0.0) {
            return bad("taper", self.taper, "finite, > 0 octaves");
        }
        Ok(())
    }
}

/// The equalizer's spectral weights: a gain in dB on each bin of a uniform bank.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpectralWeights {
    /// The rate of the signal they apply to.
    pub rate: SampleRate,
    /// How they were made, and the band they flatten.
    pub config: EqualizerConfig,
    /// Gain of bin `k` (at `k · rate / bins`), `k = 0..=bins/2`, in dB.
    pub gains_db: Vec<f64>,
}

impl SpectralWeights {
    /// Flat weights (all 0 dB).
    ///
    /// # Errors
    /// As [`EqualizerConfig::validate`].
    pub fn flat(config: EqualizerConfig, rate: SampleRate) -> Result<Self, CompensationError> {
        config.validate(rate)?;
        Ok(Self {
            rate,
            config,
            gains_db: vec![0.0; config.bins / 2 + 1],
        })
    }

    /// Checks the configuration, the number of weights and that each is finite: what a
    /// loaded file must pass.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] or [`CompensationError::NonFinite`].
    pub fn validate(&self) -> Result<(), CompensationError> {
        self.config.validate(self.rate)?;
        if self.gains_db.len() != self.config.bins / 2 + 1 {
            return Err(CompensationError::InvalidParameter {
                name: "gains_db",
                value: self.gains_db.len() as f64,
                expected: "bins / 2 + 1 weights",
            });
        }
        if let Some(index) = self.gains_db.iter().position(|g| !g.is_finite()) {
            return Err(CompensationError::NonFinite {
                what: "equalizer weights",
                index,
            });
        }
        Ok(())
    }

    /// The centre frequency of bin `k`.
    #[must_use]
    pub fn bin_frequency(&self, k: usize) -> Hz {
        Hz(k as f64 * self.rate.hz() / self.config.bins as f64)
    }

    /// The centre frequencies of all bins.
    #[must_use]
    pub fn frequencies(&self) -> Vec<Hz> {
        (0..self.gains_db.len())
            .map(|k| self.bin_frequency(k))
            .collect()
    }

    /// The gain at `f` in dB, linear between bins (0 dB past Nyquist).
    #[must_use]
    pub fn gain_db_at(&self, f: Hz) -> f64 {
        let x = f.0 * self.config.bins as f64 / self.rate.hz();
        if !x.is_finite() || x < 0.0 {
            return self.gains_db[0];
        }
        let k = x.floor() as usize;
        match (self.gains_db.get(k), self.gains_db.get(k + 1)) {
            (Some(&a), Some(&b)) => a + (x - k as f64) * (b - a),
            (Some(&a), None) => a,
            _ => 0.0,
        }
    }

    /// The weights as linear gains, one per bin.
    #[must_use]
    pub fn linear(&self) -> Vec<f32> {
        self.gains_db
            .iter()
            .map(|&g| Decibels(g).to_amplitude() as f32)
            .collect()
    }

    /// One step of equations (4)-(5) from a response measured through the current
    /// weights; returns `(rms, peak)` deviation of that response from flat.
    ///
    /// # Errors
    /// [`CompensationError::TooShort`] for a response with fewer than two frequencies,
    /// [`CompensationError::NonFinite`] for a non-finite one.
    pub fn update(
        &mut self,
        measured: &FrequencyResponse,
    ) -> Result<(Decibels, Decibels), CompensationError> {
        let (freqs, a) = centred_db(measured)?;
        let deviation = deviation(&a);
        let mu = self.config.step;
        for k in self.corrected() {
            self.gains_db[k] -= mu * interpolate_log(&freqs, &a, self.bin_frequency(k));
        }
        self.finish();
        Ok(deviation)
    }

    /// Adds `extra(f)` dB to every bin inside the band (e.g. a limb compensation's
    /// response), then re-levels, bounds and tapers as after an update.
    pub fn add_in_band(&mut self, mut extra: impl FnMut(Hz) -> f64) {
        for k in self.corrected() {
            self.gains_db[k] += extra(self.bin_frequency(k));
        }
        self.finish();
    }

    /// The bins that are corrected: those in the band and the one beyond each edge, so
    /// that the interpolation between bins is right up to the edges.
    #[must_use]
    pub fn corrected(&self) -> std::ops::RangeInclusive<usize> {
        let per_hz = self.config.bins as f64 / self.rate.hz();
        let first = (self.config.band.lo.0 * per_hz).floor() as usize;
        let last = ((self.config.band.hi.0 * per_hz).ceil() as usize).min(self.gains_db.len() - 1);
        first..=last
    }

    /// Re-levels to a 0 dB mean over the band, bounds, and rebuilds the out-of-band taper.
    /// Never allocates: the online adapter calls it on the audio thread.
    pub(crate) fn finish(&mut self) {
        let cfg = self.config;
        let corrected = self.corrected();
        let (first, last) = (*corrected.start(), *corrected.end());
        let (lo, hi) = (self.bin_frequency(first).0, self.bin_frequency(last).0);
        let inside = &self.gains_db[corrected];
        let mean = inside.iter().sum::<f64>() / inside.len().max(1) as f64;
        for g in &mut self.gains_db[first..=last] {
            *g = (*g - mean).clamp(-cfg.max_cut.0, cfg.max_boost.0);
        }
        // A cut is held past the edge and tapered; a boost only eases off over the
        // filter's resolution, so that the realised filter is right up to the edge.
        let (edge_lo, edge_hi) = (self.gains_db[first], self.gains_db[last]);
        const HOLD: f64 = 1.0 / 3.0;
        for k in (0..first).chain(last + 1..self.gains_db.len()) {
            let f = self.bin_frequency(k).0;
            let (edge, octaves) = if k < first {
                (
                    edge_lo,
                    if f > 0.0 {
                        (lo / f).log2()
                    } else {
                        f64::INFINITY
                    },
                )
            } else {
                (edge_hi, (f / hi).log2())
            };
            let t = if edge > 0.0 {
                let bins = if k < first { first - k } else { k - last } as f64;
                (bins / BOOST_GUARD_BINS).clamp(0.0, 1.0)
            } else {
                ((octaves - HOLD) / cfg.taper).clamp(0.0, 1.0)
            };
            self.gains_db[k] = edge * 0.5 * (1.0 + (std::f64::consts::PI * t).cos());
        }
    }
}

/// The measured magnitude in dB minus its mean (equation (4)), with its frequencies.
pub(super) fn centred_db(
    measured: &FrequencyResponse,
) -> Result<(Vec<f64>, Vec<f64>), CompensationError> {
    measured.check()?;
    let db: Vec<f64> = measured.magnitude_db().iter().map(|d| d.0).collect();
    let mean = db.iter().sum::<f64>() / db.len() as f64;
    Ok((
        measured.freqs.iter().map(|f| f.0).collect(),
        db.iter().map(|d| d - mean).collect(),
    ))
}

/// RMS and peak of a centred curve.
pub(super) fn deviation(centred: &[f64]) -> (Decibels, Decibels) {
    let n = centred.len().max(1) as f64;
    let rms = (centred.iter().map(|a| a * a).sum::<f64>() / n).sqrt();
    let peak = centred.iter().fold(0.0f64, |m, a| m.max(a.abs()));
    (Decibels(rms), Decibels(peak))
}

/// The fewest bins of the uniform bank ([`EqualizerConfig::bins`]).
pub const MIN_BINS: usize = 16;

/// The most bins of the uniform bank: 2^20, 22 s of a 48 kHz frame.
pub const MAX_BINS: usize = 1 << 20;

/// Whether `bins` is a bank size the equalizer takes: a power of two from [`MIN_BINS`]
/// to [`MAX_BINS`] (the FFT of the bank is radix-2).
#[must_use]
pub fn bins_are_valid(bins: usize) -> bool {
    (MIN_BINS..=MAX_BINS).contains(&bins) && bins.is_power_of_two()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outside_the_band_a_cut_is_held_and_a_boost_is_not() {
        let rate = SampleRate(48_000);
        let mut w = SpectralWeights::flat(EqualizerConfig::default(), rate).unwrap();
        // A tilt: cut at the low edge, boosted at the high one (a limb's inverse).
        w.add_in_band(|f| 20.0 * (f.0 / 200.0).log10());
        let corrected = w.corrected();
        let (first, last) = (*corrected.start(), *corrected.end());
        assert!(
            w.gains_db[first] < -6.0 && w.gains_db[last] > 6.0,
            "{:?}",
            &w.gains_db[first..=last]
        );
        // Below: the cut held a third of an octave, then eased to 0 dB.
        let lo = w.bin_frequency(first).0;
        for k in 1..first {
            let f = w.bin_frequency(k).0;
            let g = w.gains_db[k];
            assert!(g <= 0.0 && g >= w.gains_db[first] - 1e-9, "{f} Hz: {g}");
            if f >= lo * 2f64.powf(-1.0 / 3.0) {
                assert!((g - w.gains_db[first]).abs() < 1e-9, "held at {f} Hz: {g}");
            }
        }
        // Above: the boost eases off over the guard, and nothing is raised beyond it.
        let guard = last + BOOST_GUARD_BINS as usize;
        let easing = &w.gains_db[last + 1..=guard];
        assert!(easing.windows(2).all(|p| p[1] <= p[0]), "{easing:?}");
        assert!(easing[0] < w.gains_db[last] && easing.iter().all(|&g| g >= 0.0));
        assert!(w.gains_db[guard..].iter().all(|&g| g == 0.0));
    }
}
