//! The weights as a running filter: the filter bank, or its low-delay minimum-phase form.
//!
//! - [`Realisation::Bank`]: the compensation paper's uniform FFT analysis-synthesis filter bank (WOLA,
//!   [`FilterBank`] with `N` bands, hop `N/4`), gains = weights. Its latency is `N - 1`
//!   samples (85.3 ms for `N = 4096` at 48 kHz).
//! - [`Realisation::LowDelay`]: the same weights as a minimum-phase FIR
//!   ([`MinPhaseDesigner`], the low-delay filter-bank equalizer of the compensation paper's reference
//!   \[2\]): no bulk delay, for the milliseconds between heel strike and vibration.

use serde::{Deserialize, Serialize};

use super::weights::SpectralWeights;
use crate::compensation::CompensationError;
use crate::compensation::filterbank::{FilterBank, FilterBankConfig, Window};
use crate::compensation::fir::{Fir, MinPhaseDesigner};
use crate::units::{Decibels, SampleRate};

/// How the weights are turned into a filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "kind")]
pub enum Realisation {
    /// The uniform WOLA filter bank with `N` bands, hop `N/4`: latency `N - 1`.
    Bank,
    /// A minimum-phase FIR with this many taps: no bulk delay.
    LowDelay {
        /// Filter length.
        taps: usize,
    },
}

impl Default for Realisation {
    /// A 2048-tap minimum-phase FIR (42.7 ms of impulse response at 48 kHz, no delay).
    fn default() -> Self {
        Self::LowDelay { taps: 2048 }
    }
}

/// The equalizer, ready to run: either realisation behind one real-time interface.
#[derive(Debug)]
pub struct EqualizerFilter {
    inner: Inner,
    rate: SampleRate,
}

#[derive(Debug)]
enum Inner {
    Bank(Box<FilterBank>),
    LowDelay {
        fir: Box<Fir>,
        designer: Box<MinPhaseDesigner>,
        taps: Vec<f64>,
        /// The weights being realised, copied so `set_weights` never allocates.
        weights: Vec<f64>,
    },
}

impl EqualizerFilter {
    /// Prepares `weights` as `realisation`. Allocates.
    ///
    /// # Errors
    /// From the weights' [`SpectralWeights::validate`], the bank, or the designer.
    pub fn new(
        weights: &SpectralWeights,
        realisation: Realisation,
    ) -> Result<Self, CompensationError> {
        weights.validate()?;
        let inner = match realisation {
            Realisation::Bank => {
                let n = weights.config.bins;
                let cfg = FilterBankConfig {
                    bands: n,
                    hop: n / 4,
                    window: Window::SqrtHann,
                };
                let mut bank = FilterBank::new(cfg, weights.rate)?;
                bank.set_gains(&weights.linear());
                Inner::Bank(Box::new(bank))
            }
            Realisation::LowDelay { taps } => {
                let mut designer = Box::new(MinPhaseDesigner::new(taps, weights.config.bins)?);
                let mut coefficients = vec![0.0; taps];
                let w = weights.gains_db.clone();
                if !designer.design(|nu| lookup(&w, nu), &mut coefficients) {
                    return Err(CompensationError::NonFinite {
                        what: "minimum-phase design",
                        index: 0,
                    });
                }
                Inner::LowDelay {
                    fir: Box::new(Fir::new(&coefficients)?),
                    designer,
                    taps: coefficients,
                    weights: w,
                }
            }
        };
        Ok(Self {
            inner,
            rate: weights.rate,
        })
    }

    /// The bulk delay in samples: `N - 1` for the bank, 0 for the low-delay filter.
    #[must_use]
    pub fn latency(&self) -> usize {
        match &self.inner {
            Inner::Bank(bank) => bank.latency(),
            Inner::LowDelay { .. } => 0,
        }
    }

    /// The rate it runs at.
    #[must_use]
    pub fn rate(&self) -> SampleRate {
        self.rate
    }

    /// How far the low-delay filter's magnitude misses `weights`: the RMS, over the
    /// band's bins, of its response in dB minus the weight; `None` for the bank (which
    /// applies the weights exactly at its bins). Allocates nothing; costs a DFT of the
    /// taps per bin: for reports and for sizing, not the audio thread.
    #[must_use]
    pub fn realisation_error(&self, weights: &SpectralWeights) -> Option<f64> {
        let Inner::LowDelay { taps, .. } = &self.inner else {
            return None;
        };
        let band = weights.config.band;
        let (mut sum, mut n) = (0.0, 0usize);
        for k in weights.corrected() {
            let f = weights.bin_frequency(k);
            if f.0 < band.lo.0 || f.0 > band.hi.0 {
                continue;
            }
            let h = crate::numeric::dtft(taps, self.rate.omega(f)).norm();
            let e = 20.0 * h.max(1e-12).log10() - weights.gains_db[k];
            sum += e * e;
            n += 1;
        }
        (n > 0).then(|| (sum / n as f64).sqrt())
    }

    /// The low-delay filter's group delay at `f`: `Re(Σ n h[n] e^{-jωn} / Σ h[n]
    /// e^{-jωn})` samples, as time. What a longer filter costs: it has no bulk delay, but
    /// low frequencies come out this much later. `None` for the bank (its delay is
    /// [`latency`](Self::latency)) or where the response vanishes.
    #[must_use]
    pub fn group_delay(&self, f: crate::units::Hz) -> Option<crate::units::Seconds> {
        let Inner::LowDelay { taps, .. } = &self.inner else {
            return None;
        };
        let w = self.rate.omega(f);
        let step = num_complex::Complex64::from_polar(1.0, -w);
        let mut phasor = num_complex::Complex64::new(1.0, 0.0);
        let (mut h, mut nh) = (
            num_complex::Complex64::default(),
            num_complex::Complex64::default(),
        );
        for (n, &v) in taps.iter().enumerate() {
            h += phasor * v;
            nh += phasor * (v * n as f64);
            phasor *= step;
        }
        (h.norm() > 1e-12).then(|| crate::units::Seconds((nh / h).re / self.rate.hz()))
    }

    /// The low-delay filter's length, or `None` for the bank.
    #[must_use]
    pub fn taps(&self) -> Option<usize> {
        match &self.inner {
            Inner::LowDelay { taps, .. } => Some(taps.len()),
            Inner::Bank(_) => None,
        }
    }

    /// Realises new weights of the same shape (same `bins`), smoothly: the bank changes
    /// gains from its next frame, the FIR cross-fades. Returns `false` (and keeps the old
    /// weights) for weights of another shape or non-finite ones. Never allocates; the
    /// low-delay redesign costs three FFTs of the design size.
    pub fn set_weights(&mut self, gains_db: &[f64]) -> bool {
        if gains_db.iter().any(|g| !g.is_finite()) {
            return false;
        }
        match &mut self.inner {
            Inner::Bank(bank) => {
                if gains_db.len() != bank.bins() {
                    return false;
                }
                bank.set_gains_with(|f| {
                    let k = (f.0 * bank_bins_per_hz(gains_db.len(), self.rate)).round() as usize;
                    Decibels(gains_db[k.min(gains_db.len() - 1)]).to_amplitude() as f32
                });
                true
            }
            Inner::LowDelay {
                fir,
                designer,
                taps,
                weights,
            } => {
                if gains_db.len() != weights.len() {
                    return false;
                }
                weights.copy_from_slice(gains_db);
                let w = &*weights;
                if !designer.design(|nu| lookup(w, nu), taps) {
                    return false;
                }
                fir.set_taps(taps.iter().copied())
            }
        }
    }

    /// Forgets the signal.
    pub fn reset(&mut self) {
        match &mut self.inner {
            Inner::Bank(bank) => bank.reset(),
            Inner::LowDelay { fir, .. } => fir.reset(),
        }
    }

    /// Filters `input` into `output` (the shorter of the two). Never allocates, locks or
    /// panics; non-finite input is treated as silence.
    pub fn process(&mut self, input: &[f32], output: &mut [f32]) {
        match &mut self.inner {
            Inner::Bank(bank) => bank.process(input, output),
            Inner::LowDelay { fir, .. } => fir.process(input, output),
        }
    }
}

/// Bins per hertz of a bank whose weights have `len = N/2 + 1` entries.
fn bank_bins_per_hz(len: usize, rate: SampleRate) -> f64 {
    (2 * (len - 1)) as f64 / rate.hz()
}

/// The weight (dB) at normalised frequency `nu` (cycles per sample), linear between bins.
fn lookup(gains_db: &[f64], nu: f64) -> f64 {
    let x = nu * (2 * (gains_db.len() - 1)) as f64;
    let k = (x.floor().max(0.0) as usize).min(gains_db.len() - 1);
    match gains_db.get(k + 1) {
        Some(&b) => gains_db[k] + (x - k as f64) * (b - gains_db[k]),
        None => gains_db[k],
    }
}
