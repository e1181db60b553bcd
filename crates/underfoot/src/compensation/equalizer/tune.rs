//! Tuning by successive sweeps: each pass measures through the current weights and the
//! next corrects them (equations (4)-(5), [`SpectralWeights::update`]).
//!
//! The equalizer is tuned through the realisation it will run with ([`equalize`]), so
//! each pass measures, and the next corrects, that realisation's own errors.
//!
//! # Passes that never make it worse
//!
//! On an uneven device a full step (`μ = 1`) can overshoot: a realisation that cannot
//! follow the weights (too short a filter at the band's low edge), or measurement noise
//! on a deep notch, makes the next measurement worse than the last, and each further
//! pass builds on the error. So a pass whose RMS deviation is above the best measured so
//! far is not kept: the next candidate starts again from the best weights and their
//! measurement, with the step halved (`PassReport::kept`, `PassReport::step`). The
//! weights returned are always the best measured ([`Equalization::best`]).
//!
//! # Where the bounds bind
//!
//! The weights stay within `+max_boost` / `-max_cut` of their mean. Where the best pass
//! still measures the device below (above) its mean at a bin held at the boost (cut)
//! bound, the bound has stopped the correction: [`Equalization::capped`] lists those
//! frequency ranges with the most still missing, and [`Equalization::cap_residual`] the
//! RMS deviation those frequencies alone leave (over every measured frequency, so that it
//! compares with the pass's own figure).
//!
//! # A filter long enough for the weights
//!
//! A minimum-phase FIR of `L` taps follows the weights' log-magnitude only to a
//! resolution of about `fs / L`: 2048 taps at 48 kHz smooth over 23 Hz, which is half an
//! octave at a 40 Hz band edge, and steep weights there are not realised, so passes
//! diverge. [`auto_taps`] starts from the band's lowest frequency (`L >= fs / f_lo`, at
//! least 2048) and then, pass by pass, sizes it from the weights themselves: while the
//! designed filter misses the weights by more than [`MAX_REALISATION_ERROR`] (RMS over
//! the band's bins), `L` doubles, up to [`MAX_AUTO_TAPS`]. (Longer is not better for its
//! own sake: on the mild simulated tile 8192 taps leave 0.09 dB after three passes where
//! 2048 leave 0.05, the longer response reaching further into the sweep's window.) The filter has no bulk delay whatever its length; its group delay
//! at the band's low edge is what the length costs ([`EqualizerFilter::group_delay`]).

use super::filter::{EqualizerFilter, Realisation};
use super::weights::{EqualizerConfig, SpectralWeights, centred_db, deviation};
use crate::compensation::CompensationError;
use crate::compensation::sweep::{Device, FrequencyResponse, Sweep, interpolate_log, measure};
use crate::units::{Decibels, Hz, SampleRate};

/// The most a low-delay filter sized by [`auto_taps`] may miss the weights by (RMS over
/// the band's bins) before it is lengthened.
pub const MAX_REALISATION_ERROR: Decibels = Decibels(0.1);
/// The longest low-delay filter [`auto_taps`] and [`equalize`] choose.
pub const MAX_AUTO_TAPS: usize = 32_768;

/// The low-delay filter length to start from for a band starting at `config.band.lo` at
/// `rate`: the power of two at least `fs / f_lo` (one period of the lowest frequency),
/// from 2048 to [`MAX_AUTO_TAPS`] (2048 for the default 40 Hz edge at 48 kHz, 8192 for a
/// 10 Hz one). [`equalize`] lengthens it when the weights need it.
#[must_use]
pub fn auto_taps(config: &EqualizerConfig, rate: SampleRate) -> usize {
    let want = (rate.hz() / config.band.lo.0.max(1.0)).ceil() as usize;
    want.next_power_of_two().clamp(2048, MAX_AUTO_TAPS)
}

/// A range of frequencies where a bound stopped the correction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capped {
    /// The lowest bin held at the bound.
    pub lo: Hz,
    /// The highest.
    pub hi: Hz,
    /// The boost bound (`true`) or the cut bound.
    pub boost: bool,
    /// The most the best pass still measured the device off its mean there.
    pub short: Decibels,
}

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
    /// Whether this pass measured the best deviation so far (its weights are the ones the
    /// next pass corrects); `false`: worse than the best before, so the next pass starts
    /// again from the best weights with the step halved.
    pub kept: bool,
    /// The relaxation `μ` of the update made after this pass (the last pass makes none).
    pub step: f64,
    /// The low-delay filter's length in this pass (`None` for the bank).
    pub taps: Option<usize>,
}

/// The result of [`equalize`].
#[derive(Debug, Clone)]
pub struct Equalization {
    /// The weights of the best pass measured.
    pub weights: SpectralWeights,
    /// How they were realised in that pass (a low-delay filter at the length it had).
    pub realisation: Realisation,
    /// Every pass, in order.
    pub passes: Vec<PassReport>,
    /// The pass whose weights these are (1-based): the lowest RMS deviation measured.
    pub best: usize,
    /// Where the boost or cut bound stopped the correction in the best pass.
    pub capped: Vec<Capped>,
    /// The RMS deviation the capped frequencies alone leave in the best pass.
    pub cap_residual: Decibels,
}

/// Tunes an equalizer on `device` by `passes` sweeps: each measures through the current
/// weights (realised as `realisation`) and, except the last, updates them by equations
/// (4)-(5), from the best pass so far (see the [module documentation](self)). The weights
/// returned are those of the best pass measured, as measured. A low-delay realisation is
/// lengthened (doubling, up to [`MAX_AUTO_TAPS`]) while it misses the weights by more than
/// [`MAX_REALISATION_ERROR`] when `grow` is set (`calibrate equalize --taps auto`); pass
/// [`auto_taps`] as its length to size it from the band too.
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
    grow: bool,
) -> Result<Equalization, CompensationError> {
    if passes == 0 {
        return Err(CompensationError::InvalidParameter {
            name: "passes",
            value: 0.0,
            expected: "at least 1",
        });
    }
    let mut weights = SpectralWeights::flat(config, sweep.config().rate)?;
    let mut realisation = realisation;
    let mut filter = EqualizerFilter::new(&weights, realisation)?;
    let mut reports: Vec<PassReport> = Vec::with_capacity(passes);
    // The best pass: its number, weights, realisation and measurement.
    let mut best: Option<(usize, SpectralWeights, Realisation, FrequencyResponse)> = None;
    let mut step = config.step;
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
        let kept = best
            .as_ref()
            .is_none_or(|(b, ..)| rms.0 <= reports[*b - 1].deviation.0);
        if kept {
            best = Some((pass, weights.clone(), realisation, response.clone()));
        } else {
            step *= 0.5;
        }
        reports.push(PassReport {
            pass,
            deviation: rms,
            peak,
            response,
            kept,
            step: if pass < passes { step } else { 0.0 },
            taps: match realisation {
                Realisation::LowDelay { taps } => Some(taps),
                Realisation::Bank => None,
            },
        });
        if pass < passes {
            let (_, from, _, measured) = best.as_ref().expect("the first pass is kept");
            weights = from.clone();
            weights.config.step = step;
            weights.update(measured)?;
            weights.config.step = config.step;
            filter = EqualizerFilter::new(&weights, realisation)?;
            while grow
                && let Realisation::LowDelay { taps } = realisation
                && taps < MAX_AUTO_TAPS
                && filter
                    .realisation_error(&weights)
                    .is_some_and(|e| e > MAX_REALISATION_ERROR.0)
            {
                realisation = Realisation::LowDelay { taps: taps * 2 };
                filter = EqualizerFilter::new(&weights, realisation)?;
            }
        }
    }
    let (best, weights, realisation, measured) = best.expect("at least one pass");
    let (capped, cap_residual) = capped(&weights, &measured)?;
    Ok(Equalization {
        weights,
        realisation,
        passes: reports,
        best,
        capped,
        cap_residual,
    })
}

/// The ranges where `weights` sit at a bound while `measured` (through them) is still off
/// its mean the same way, and the RMS deviation those measured frequencies leave.
fn capped(
    weights: &SpectralWeights,
    measured: &FrequencyResponse,
) -> Result<(Vec<Capped>, Decibels), CompensationError> {
    /// Below this the bound is not what stops the correction.
    const SHORT: f64 = 0.25;
    let (freqs, centred) = centred_db(measured)?;
    let (boost, cut) = (weights.config.max_boost.0, weights.config.max_cut.0);
    let band = weights.config.band;
    let mut ranges: Vec<Capped> = Vec::new();
    let mut open = false;
    for k in weights.corrected() {
        let f = weights.bin_frequency(k);
        let g = weights.gains_db[k];
        let off = interpolate_log(&freqs, &centred, f);
        let at = if f.0 < band.lo.0 || f.0 > band.hi.0 {
            None
        } else if g >= boost - 1e-6 && off < -SHORT {
            Some(true)
        } else if g <= -cut + 1e-6 && off > SHORT {
            Some(false)
        } else {
            None
        };
        match (at, ranges.last_mut()) {
            (Some(b), Some(last)) if open && last.boost == b => {
                last.hi = f;
                last.short = Decibels(last.short.0.max(off.abs()));
            }
            (Some(b), _) => ranges.push(Capped {
                lo: f,
                hi: f,
                boost: b,
                short: Decibels(off.abs()),
            }),
            (None, _) => {}
        }
        open = at.is_some();
    }
    // A measured frequency belongs to a range if it lies within half a bin of it.
    let half = weights.rate.hz() / weights.config.bins as f64 / 2.0;
    let inside = |f: f64| {
        ranges
            .iter()
            .any(|r| f >= r.lo.0 - half && f <= r.hi.0 + half)
    };
    let sum: f64 = freqs
        .iter()
        .zip(&centred)
        .filter(|(f, _)| inside(**f))
        .map(|(_, a)| a * a)
        .sum();
    let residual = (sum / freqs.len().max(1) as f64).sqrt();
    Ok((ranges, Decibels(residual)))
}

/// The deviation from flat (RMS, peak) of a measured response over its frequencies.
///
/// # Errors
/// As [`SpectralWeights::update`].
pub fn flatness(measured: &FrequencyResponse) -> Result<(Decibels, Decibels), CompensationError> {
    Ok(deviation(&centred_db(measured)?.1))
}
