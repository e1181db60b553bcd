//! Tuning by successive sweeps: each pass measures through the current weights and the
//! next corrects them (equations (4)-(5), [`SpectralWeights::update`]).
//!
//! The equalizer is tuned through the realisation it will run with ([`equalize`]), so
//! each pass measures, and the next corrects, that realisation's own errors.

use super::filter::{EqualizerFilter, Realisation};
use super::weights::{EqualizerConfig, SpectralWeights, centred_db, deviation};
use crate::compensation::CompensationError;
use crate::compensation::sweep::{Device, FrequencyResponse, Sweep, measure};
use crate::units::Decibels;

/// A device heard through an equalizer: the excitation is filtered first, and the
/// filter's bulk delay is removed from the recording so the sweep's window stays put.
pub struct Equalized<'a, D: Device + ?Sized> {
    /// The equalizer.
    pub filter: &'a mut EqualizerFilter,
    /// The device behind it.
    pub device: &'a mut D,
}

impl<D: Device + ?Sized> Device for Equalized<'_, D> {
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        let delay = self.filter.latency();
        self.filter.reset();
        let input: Vec<f32> = excitation
            .iter()
            .map(|&v| v as f32)
            .chain(std::iter::repeat_n(0.0, delay))
            .collect();
        let mut filtered = vec![0.0f32; input.len()];
        self.filter.process(&input, &mut filtered);
        let drive: Vec<f64> = filtered[delay..].iter().map(|&v| f64::from(v)).collect();
        self.device.play(&drive)
    }
}

/// One sweep of the iterative equalization.
#[derive(Debug, Clone, PartialEq)]
pub struct PassReport {
    /// 1 for the first sweep (through flat weights).
    pub pass: usize,
    /// RMS deviation from flat over the band (the compensation paper's figure).
    pub deviation: Decibels,
    /// Largest deviation from flat at any measured frequency.
    pub peak: Decibels,
    /// The response measured in this pass.
    pub response: FrequencyResponse,
}

/// The result of [`equalize`].
#[derive(Debug, Clone)]
pub struct Equalization {
    /// The weights in force during the last pass.
    pub weights: SpectralWeights,
    /// How they were realised.
    pub realisation: Realisation,
    /// Every pass, in order.
    pub passes: Vec<PassReport>,
}

/// Tunes an equalizer on `device` by `passes` sweeps: each measures through the current
/// weights (realised as `realisation`) and, except the last, updates them by equations
/// (4)-(5). The weights returned are those the last pass measured, so the last report is
/// what the user will get.
///
/// # Errors
/// A bad configuration or sweep; a device returning too little or non-finite data;
/// [`CompensationError::InvalidParameter`] for `passes == 0`.
pub fn equalize<D: Device + ?Sized>(
    device: &mut D,
    sweep: &Sweep,
    config: EqualizerConfig,
    realisation: Realisation,
    passes: usize,
) -> Result<Equalization, CompensationError> {
    if passes == 0 {
        return Err(CompensationError::InvalidParameter {
            name: "passes",
            value: 0.0,
            expected: "at least 1",
        });
    }
    let mut weights = SpectralWeights::flat(config, sweep.config().rate)?;
    let mut filter = EqualizerFilter::new(&weights, realisation)?;
    let mut reports = Vec::with_capacity(passes);
    for pass in 1..=passes {
        let response = measure(
            &mut Equalized {
                filter: &mut filter,
                device,
            },
            sweep,
        )?;
        let (_, centred) = centred_db(&response)?;
        let (rms, peak) = deviation(&centred);
        reports.push(PassReport {
            pass,
            deviation: rms,
            peak,
            response: response.clone(),
        });
        if pass < passes {
            weights.update(&response)?;
            filter = EqualizerFilter::new(&weights, realisation)?;
        }
    }
    Ok(Equalization {
        weights,
        realisation,
        passes: reports,
    })
}

/// The deviation from flat (RMS, peak) of a measured response over its frequencies.
///
/// # Errors
/// As [`SpectralWeights::update`].
pub fn flatness(measured: &FrequencyResponse) -> Result<(Decibels, Decibels), CompensationError> {
    Ok(deviation(&centred_db(measured)?.1))
}
