//! A floor tile on its suspension, with an actuator and an accelerometer: the device the
//! compensation measures, where no hardware is at hand.
//!
//! The tile is a cascade of second-order sections: a peaking section per plate mode
//! ([`TileResonance`]), the notch of the elastomer suspension, and the actuator's
//! second-order Butterworth high-pass and low-pass; then an overall gain and, optionally,
//! Gaussian sensor noise at a level relative to the output's RMS. Its noiseless response
//! ([`SimulatedTile::true_response`]) is the oracle the sweep measurements are checked
//! against.

use num_complex::Complex64;

use crate::compensation::CompensationError;
use crate::compensation::sweep::Device;
use crate::signal::noise::SplitMix64;
use crate::signal::{Biquad, Sos, butterworth};
use crate::units::{Decibels, Hz, SampleRate};

/// A resonance of the tile: a peaking section.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileResonance {
    /// Centre frequency.
    pub freq: Hz,
    /// Quality factor.
    pub q: f64,
    /// Gain at the centre relative to off-resonance.
    pub gain: Decibels,
}

/// Settings of a [`SimulatedTile`].
#[derive(Debug, Clone, PartialEq)]
pub struct TileConfig {
    /// The tile's plate modes.
    pub modes: Vec<TileResonance>,
    /// Frequency of the notch the elastomer suspension makes.
    pub suspension: Hz,
    /// Quality factor of that notch.
    pub suspension_q: f64,
    /// Corner of the actuator's second-order Butterworth high-pass.
    pub highpass: Hz,
    /// Corner of the actuator's second-order Butterworth low-pass.
    pub lowpass: Hz,
    /// Overall gain, accelerometer units per unit of drive.
    pub gain: f64,
    /// Sensor noise relative to the RMS of the noiseless output of each call, or none.
    pub noise: Option<Decibels>,
    /// Seed of the sensor noise.
    pub seed: u64,
}

impl Default for TileConfig {
    /// Three plate modes (180 Hz Q 5 +9 dB, 420 Hz Q 6 +6 dB, 760 Hz Q 8 +7 dB), a 20 Hz
    /// Q 2 suspension notch, a 50-900 Hz actuator, gain 0.5, no noise.
    fn default() -> Self {
        Self {
            modes: vec![
                TileResonance {
                    freq: Hz(180.0),
                    q: 5.0,
                    gain: Decibels(9.0),
                },
                TileResonance {
                    freq: Hz(420.0),
                    q: 6.0,
                    gain: Decibels(6.0),
                },
                TileResonance {
                    freq: Hz(760.0),
                    q: 8.0,
                    gain: Decibels(7.0),
                },
            ],
            suspension: Hz(20.0),
            suspension_q: 2.0,
            highpass: Hz(50.0),
            lowpass: Hz(900.0),
            gain: 0.5,
            noise: None,
            seed: 0x5EED,
        }
    }
}

/// A floor tile on its suspension, driven by an actuator and read by an accelerometer:
/// a cascade of second-order sections plus Gaussian sensor noise.
#[derive(Debug, Clone)]
pub struct SimulatedTile {
    rate: SampleRate,
    sos: Sos,
    gain: f64,
    noise: Option<Decibels>,
    rng: SplitMix64,
    state: Vec<[f64; 2]>,
}

/// The bilinear transform of `(b2 s^2 + b1 s + b0) / (a2 s^2 + a1 s + a0)`, `s` normalised
/// to `f0`, prewarped so `f0` lands exactly: [`crate::numeric::bilinear`] with
/// `c = 1 / tan(π f0 / fs)` ([`warped`](crate::numeric::bilinear::warped)), the
/// prewarping constant of `s / (2π f0)`.
fn bilinear(
    b: [f64; 3],
    a: [f64; 3],
    f0: f64,
    rate: SampleRate,
) -> Result<Biquad, CompensationError> {
    let c = 1.0 / crate::numeric::bilinear::warped(Hz(f0), rate);
    Biquad::from_row(crate::numeric::bilinear(b, a, c))
        .ok_or_else(|| CompensationError::invalid("frequency", f0, "0 < f < Nyquist"))
}

impl SimulatedTile {
    /// A tile at `rate`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] for a frequency not strictly between 0 and
    /// Nyquist, a non-positive or non-finite Q or gain, or a non-finite noise level.
    pub fn new(cfg: &TileConfig, rate: SampleRate) -> Result<Self, CompensationError> {
        let nyq = rate.nyquist().0;
        let freq_ok = |f: Hz| f.0.is_finite() && f.0 > 0.0 && f.0 < nyq;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let mut sections = Vec::with_capacity(cfg.modes.len() + 3);
        for m in &cfg.modes {
            if !freq_ok(m.freq) {
                return Err(CompensationError::invalid(
                    "mode.freq",
                    m.freq.0,
                    "0 < f < Nyquist",
                ));
            }
            if !pos(m.q) {
                return Err(CompensationError::invalid("mode.q", m.q, "finite, > 0"));
            }
            if !m.gain.0.is_finite() {
                return Err(CompensationError::invalid(
                    "mode.gain",
                    m.gain.0,
                    "finite dB",
                ));
            }
            // Peak gain A^2 at the centre: the zeros' damping is A^2 times the poles'.
            let a = 10f64.powf(m.gain.0 / 40.0);
            sections.push(bilinear(
                [1.0, a / m.q, 1.0],
                [1.0, 1.0 / (a * m.q), 1.0],
                m.freq.0,
                rate,
            )?);
        }
        if !freq_ok(cfg.suspension) {
            return Err(CompensationError::invalid(
                "suspension",
                cfg.suspension.0,
                "0 < f < Nyquist",
            ));
        }
        if !pos(cfg.suspension_q) {
            return Err(CompensationError::invalid(
                "suspension_q",
                cfg.suspension_q,
                "finite, > 0",
            ));
        }
        sections.push(bilinear(
            [1.0, 0.0, 1.0],
            [1.0, 1.0 / cfg.suspension_q, 1.0],
            cfg.suspension.0,
            rate,
        )?);
        if !freq_ok(cfg.highpass) {
            return Err(CompensationError::invalid(
                "highpass",
                cfg.highpass.0,
                "0 < f < Nyquist",
            ));
        }
        // The actuator's roll-offs are the crate's own Butterworth designs.
        let highpass = butterworth::highpass(2, cfg.highpass, rate).map_err(|_| {
            CompensationError::invalid("highpass", cfg.highpass.0, "0 < f < Nyquist")
        })?;
        sections.extend(highpass.sections);
        if !freq_ok(cfg.lowpass) {
            return Err(CompensationError::invalid(
                "lowpass",
                cfg.lowpass.0,
                "0 < f < Nyquist",
            ));
        }
        let lowpass = butterworth::lowpass(2, cfg.lowpass, rate)
            .map_err(|_| CompensationError::invalid("lowpass", cfg.lowpass.0, "0 < f < Nyquist"))?;
        sections.extend(lowpass.sections);
        if !pos(cfg.gain) {
            return Err(CompensationError::invalid("gain", cfg.gain, "finite, > 0"));
        }
        if let Some(n) = cfg.noise
            && !n.0.is_finite()
        {
            return Err(CompensationError::invalid("noise", n.0, "finite dB"));
        }
        let sos = Sos::new(sections);
        let state = vec![[0.0; 2]; sos.sections.len()];
        Ok(Self {
            rate,
            sos,
            gain: cfg.gain,
            noise: cfg.noise,
            rng: SplitMix64::new(cfg.seed),
            state,
        })
    }

    /// The sections of the noiseless device, gain excluded.
    #[must_use]
    pub fn sos(&self) -> &Sos {
        &self.sos
    }

    /// The noiseless response at `f`, as the oracle for measurements.
    #[must_use]
    pub fn true_response(&self, f: Hz) -> Complex64 {
        self.sos.response(self.rate.omega(f)) * self.gain
    }

    /// Returns the filters to rest; the noise stream runs on.
    pub fn reset(&mut self) {
        self.state.fill([0.0; 2]);
    }

    /// Runs `input` through the tile, continuing from the previous call's state, and adds
    /// the sensor noise.
    pub fn process(&mut self, input: &[f64]) -> Vec<f64> {
        let mut out: Vec<f64> = input.iter().map(|v| v * self.gain).collect();
        self.sos.filter_with_state(&mut out, &mut self.state);
        if let Some(level) = self.noise
            && !out.is_empty()
        {
            let rms = (out.iter().map(|v| v * v).sum::<f64>() / out.len() as f64).sqrt();
            let sigma = rms * level.to_amplitude();
            for v in &mut out {
                *v += sigma * self.rng.normal();
            }
        }
        out
    }
}

impl Device for SimulatedTile {
    /// Plays from rest.
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        self.reset();
        Ok(self.process(excitation))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RATE: SampleRate = SampleRate(48_000);

    #[test]
    fn bad_tile_configs_are_errors() {
        let tc = TileConfig::default();
        for t in [
            TileConfig {
                highpass: Hz(0.0),
                ..tc.clone()
            },
            TileConfig {
                lowpass: Hz(30_000.0),
                ..tc.clone()
            },
            TileConfig {
                gain: f64::NAN,
                ..tc.clone()
            },
            TileConfig {
                suspension_q: 0.0,
                ..tc.clone()
            },
            TileConfig {
                noise: Some(Decibels(f64::NAN)),
                ..tc.clone()
            },
        ] {
            assert!(SimulatedTile::new(&t, RATE).is_err());
        }
    }
}
