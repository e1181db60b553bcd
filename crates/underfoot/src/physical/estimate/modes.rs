//! Step 5 of the estimation: the candidate modes, by linear prediction ([`crate::fit::lpc`]).
//!
//! The poles come from the isolated impacts: stretches of at least `2p` samples at the
//! analysis rate (`p` the largest order) that start at an onset and end before the next
//! one. Their autocorrelations are pooled (summed, which is the autocorrelation of their
//! average power spectrum) and the Levinson-Durbin recursion gives one predictor per
//! order; its roots in the upper half-plane, inside the unit circle and in the band are
//! candidate modes (frequency and decay). With fewer than three isolated impacts (every
//! solid, and aggregates whose impacts crowd) the strike windows take their place. Rather
//! than guess the one right order, the orders 8, 12, 16, 24, 32 and 48 each contribute
//! their poles to a dictionary (a pole closer than 0.002 in the z-plane to one already in
//! it is the same mode): low orders give the broad resonances, high orders the sharp
//! ones, and the gain fit ([`super::gains`]) keeps what the spectrum needs. Decays are
//! capped at `max_decay` (0.5 s), as the IIR voice caps its modes.

use num_complex::Complex64;

use super::{EstimateConfig, EstimateError};
use crate::analysis::{AnalysisConfig, MeasuredResponse, condition};
use crate::fit::lpc::{LpcError, autocorrelation, levinson_durbin};
use crate::physical::SurfaceMode;
use crate::physical::model::GroundKind;
use crate::physical::resonator::LONGEST_DECAY;
use crate::recording::Recording;
use crate::units::{Hz, SampleRate, Seconds};

/// The stretches linear prediction runs on: the isolated impacts of an aggregate (the
/// flag is `true`) when there are at least three, else the strike windows.
pub(super) fn segments(
    recordings: &[Recording],
    kind: GroundKind,
    onsets_by_recording: &[Vec<Seconds>],
    measured: &MeasuredResponse,
    cfg: &EstimateConfig,
) -> Result<(Vec<Vec<f64>>, bool), EstimateError> {
    let a = &cfg.analysis;
    let conditioned: Vec<Vec<f64>> = recordings
        .iter()
        .map(|r| condition(r, a))
        .collect::<Result<_, _>>()?;
    let min_len = 2 * cfg.lpc_orders.iter().copied().max().unwrap_or(2);
    let mut segments = Vec::new();
    if kind == GroundKind::Aggregate {
        for (x, onsets) in conditioned.iter().zip(onsets_by_recording) {
            for (i, t) in onsets.iter().enumerate() {
                let end_t = onsets
                    .get(i + 1)
                    .map_or(t.0 + cfg.segment.0, |n| n.0.min(t.0 + cfg.segment.0));
                let (s, e) = (a.rate.samples_in(*t), a.rate.samples_in(Seconds(end_t)));
                if e > s && e - s >= min_len && e <= x.len() {
                    segments.push(x[s..e].to_vec());
                }
            }
        }
    }
    let isolated_impacts = segments.len() >= 3;
    if !isolated_impacts {
        segments.clear();
        let len = a.rate.samples_in(a.strike_length);
        for s in &measured.strikes {
            let x = &conditioned[s.recording];
            let start = a.rate.samples_in(s.onset);
            let end = (start + len).min(x.len());
            if end > start + min_len {
                segments.push(x[start..end].to_vec());
            }
        }
    }
    Ok((segments, isolated_impacts))
}

/// The candidate modes: the poles of every order in `orders`, each pole kept once
/// (poles of different orders closer than 0.002 in the z-plane are the same mode).
pub(super) fn lpc_dictionary(
    segments: &[Vec<f64>],
    rate: SampleRate,
    orders: &[usize],
    a: &AnalysisConfig,
    max_decay: Seconds,
) -> Result<Vec<SurfaceMode>, EstimateError> {
    let mut found: Vec<(Complex64, SurfaceMode)> = Vec::new();
    let mut first_error = None;
    for &order in orders {
        match pooled_lpc_modes(segments, rate, order, a, max_decay) {
            Ok(modes) => {
                for m in modes {
                    let z = pole_of(&m, rate);
                    if found.iter().all(|(q, _)| (z - q).norm() > 2e-3) {
                        found.push((z, m));
                    }
                }
            }
            Err(e) => first_error = first_error.or(Some(e)),
        }
    }
    if found.is_empty() {
        return Err(first_error.unwrap_or(EstimateError::NoModes {
            order: 0,
            lo: a.band.lo.0,
            hi: a.band.hi.0,
        }));
    }
    let mut modes: Vec<SurfaceMode> = found.into_iter().map(|(_, m)| m).collect();
    modes.sort_by(|p, q| p.frequency.0.total_cmp(&q.frequency.0));
    Ok(modes)
}

fn pole_of(m: &SurfaceMode, rate: SampleRate) -> Complex64 {
    Complex64::from_polar(
        (-1.0 / (m.decay.0 * rate.hz())).exp(),
        rate.omega(m.frequency),
    )
}

/// Modes (unit gain) from the pooled autocorrelation of `segments`.
fn pooled_lpc_modes(
    segments: &[Vec<f64>],
    rate: SampleRate,
    order: usize,
    a: &AnalysisConfig,
    max_decay: Seconds,
) -> Result<Vec<SurfaceMode>, EstimateError> {
    let mut r = vec![0.0; order + 1];
    let mut used = 0;
    for s in segments {
        let Ok(rs) = autocorrelation(s, order) else {
            continue;
        };
        // `autocorrelation` is per sample; weight each segment by its length.
        for (acc, v) in r.iter_mut().zip(&rs) {
            *acc += v * s.len() as f64;
        }
        used += 1;
    }
    if used == 0 {
        return Err(EstimateError::Lpc(LpcError::Silent));
    }
    let pred = levinson_durbin(&r, order)?;
    let roots = crate::numeric::roots(&pred.coefficients)
        .ok_or(LpcError::Numerical("predictor roots did not converge"))?;
    let fs = rate.hz();
    let mut modes: Vec<SurfaceMode> = roots
        .iter()
        .filter(|p| p.im > 0.0 && p.norm() < 1.0)
        .map(|p| SurfaceMode {
            frequency: Hz(p.arg() * fs / std::f64::consts::TAU),
            decay: Seconds((-1.0 / (fs * p.norm().ln())).min(max_decay.0.min(LONGEST_DECAY.0))),
            gain: 1.0,
        })
        .filter(|m| m.frequency.0 >= 0.5 * a.band.lo.0 && m.frequency.0 <= a.band.hi.0)
        .collect();
    modes.sort_by(|p, q| p.frequency.0.total_cmp(&q.frequency.0));
    if modes.is_empty() {
        return Err(EstimateError::NoModes {
            order,
            lo: a.band.lo.0,
            hi: a.band.hi.0,
        });
    }
    Ok(modes)
}
