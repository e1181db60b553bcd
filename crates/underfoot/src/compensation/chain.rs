//! The compensation the engine applies to each output channel, before its limiter: the
//! device equalizer, then the limb compensation `Z_c` (the cascade of the compensation paper's
//! Fig. 3).
//!
//! [`Compensation`] is the description (built off the audio thread, from files);
//! [`CompensationChain`] is one channel's running instance. Its
//! [`process`](CompensationChain::process) never allocates, locks or panics, and if
//! anything non-finite ever came out of it, the block is silenced, the filters are reset
//! and the event counted, so the device never sees it.

use super::CompensationError;
use super::equalizer::{EqualizerFilter, Realisation, SpectralWeights};
use crate::signal::Sos;
use crate::units::SampleRate;

/// What the engine applies to every channel before its limiter.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Compensation {
    /// The device's equalizer and how to realise it.
    pub equalizer: Option<(SpectralWeights, Realisation)>,
    /// The limb compensation `Z_c`, as sections at the engine's rate.
    pub limb: Option<Sos>,
}

impl Compensation {
    /// Whether it does nothing.
    #[must_use]
    pub fn is_identity(&self) -> bool {
        self.equalizer.is_none() && self.limb.is_none()
    }
}

/// One channel's compensation, running.
#[derive(Debug)]
pub struct CompensationChain {
    equalizer: Option<EqualizerFilter>,
    limb: Option<(Sos, Vec<[f64; 2]>)>,
    scratch: Vec<f32>,
    wide: Vec<f64>,
    resets: u64,
}

impl CompensationChain {
    /// Prepares `compensation` at `rate` for blocks of up to `max_block` samples (longer
    /// ones are processed in pieces). Allocates.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] when the equalizer was made for another
    /// rate or the limb filter is unstable; the equalizer's own errors.
    pub fn new(
        compensation: &Compensation,
        rate: SampleRate,
        max_block: usize,
    ) -> Result<Self, CompensationError> {
        let equalizer = match &compensation.equalizer {
            Some((weights, realisation)) => {
                if weights.rate != rate {
                    return Err(CompensationError::InvalidParameter {
                        name: "equalizer rate",
                        value: f64::from(weights.rate.0),
                        expected: "the engine's sample rate (measure the device at the rate it plays)",
                    });
                }
                Some(EqualizerFilter::new(weights, *realisation)?)
            }
            None => None,
        };
        let limb = match &compensation.limb {
            Some(sos) => {
                if !sos.is_stable() {
                    return Err(CompensationError::InvalidParameter {
                        name: "limb filter",
                        value: f64::NAN,
                        expected: "stable sections",
                    });
                }
                Some((sos.clone(), vec![[0.0; 2]; sos.sections.len()]))
            }
            None => None,
        };
        let block = max_block.max(1);
        Ok(Self {
            equalizer,
            limb,
            scratch: vec![0.0; block],
            wide: vec![0.0; block],
            resets: 0,
        })
    }

    /// The bulk delay it adds, in samples.
    #[must_use]
    pub fn latency(&self) -> usize {
        self.equalizer.as_ref().map_or(0, EqualizerFilter::latency)
    }

    /// The equalizer, to retune it (e.g. by online adaptation).
    pub fn equalizer_mut(&mut self) -> Option<&mut EqualizerFilter> {
        self.equalizer.as_mut()
    }

    /// How many times a non-finite output silenced a block and reset the filters.
    #[must_use]
    pub fn resets(&self) -> u64 {
        self.resets
    }

    /// Forgets the signal.
    pub fn reset(&mut self) {
        if let Some(eq) = &mut self.equalizer {
            eq.reset();
        }
        if let Some((_, state)) = &mut self.limb {
            state.fill([0.0; 2]);
        }
    }

    /// Compensates `buf` in place. Streaming: the result does not depend on the block
    /// size. Returns how many blocks were silenced for a non-finite value (0 or more).
    /// Never allocates, locks or panics.
    pub fn process(&mut self, buf: &mut [f32]) -> u32 {
        let mut silenced = 0;
        let step = self.scratch.len();
        for chunk in buf.chunks_mut(step) {
            let n = chunk.len();
            if let Some(eq) = &mut self.equalizer {
                let tmp = &mut self.scratch[..n];
                eq.process(chunk, tmp);
                chunk.copy_from_slice(tmp);
            }
            if let Some((sos, state)) = &mut self.limb {
                let wide = &mut self.wide[..n];
                for (w, &x) in wide.iter_mut().zip(chunk.iter()) {
                    *w = f64::from(x);
                }
                sos.filter_with_state(wide, state);
                for (x, &w) in chunk.iter_mut().zip(wide.iter()) {
                    *x = w as f32;
                }
            }
            if chunk.iter().any(|v| !v.is_finite()) {
                chunk.fill(0.0);
                self.reset();
                self.resets += 1;
                silenced += 1;
            }
        }
        silenced
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensation::equalizer::EqualizerConfig;
    use crate::signal::Biquad;

    const RATE: SampleRate = SampleRate(48_000);

    fn weights() -> SpectralWeights {
        let mut w = SpectralWeights::flat(EqualizerConfig::default(), RATE).unwrap();
        w.add_in_band(|f| 6.0 * (-((f.0 - 300.0) / 80.0).powi(2)).exp());
        w
    }

    #[test]
    fn block_size_does_not_matter() {
        let limb = Sos::new(vec![Biquad {
            b: [0.2, 0.1, 0.0],
            a: [1.0, -0.5, 0.0],
        }]);
        let input: Vec<f32> = (0..3000)
            .map(|i| ((i * 7919 % 257) as f32 - 128.0) / 128.0)
            .collect();
        for realisation in [Realisation::LowDelay { taps: 256 }, Realisation::Bank] {
            let comp = Compensation {
                equalizer: Some((weights(), realisation)),
                limb: Some(limb.clone()),
            };
            let mut reference = None;
            for block in [1, 7, 64, 512] {
                let mut chain = CompensationChain::new(&comp, RATE, 64).unwrap();
                let mut out = input.clone();
                for c in out.chunks_mut(block) {
                    chain.process(c);
                }
                match &reference {
                    None => reference = Some(out),
                    Some(r) => assert_eq!(r, &out, "{realisation:?} block {block}"),
                }
            }
        }
    }

    #[test]
    fn wrong_rate_and_unstable_limb_are_refused() {
        let comp = Compensation {
            equalizer: Some((weights(), Realisation::Bank)),
            limb: None,
        };
        assert!(CompensationChain::new(&comp, SampleRate(44_100), 64).is_err());
        let comp = Compensation {
            equalizer: None,
            limb: Some(Sos::new(vec![Biquad {
                b: [1.0, 0.0, 0.0],
                a: [1.0, -2.5, 1.2],
            }])),
        };
        assert!(CompensationChain::new(&comp, RATE, 64).is_err());
        assert!(Compensation::default().is_identity());
    }
}
