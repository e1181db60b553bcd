//! Heel-strike onset detection.
//!
//! A recording may hold one footstep or a walk of many; either way each heel strike is an
//! abrupt burst of vibration standing well above a noise floor. [`find_onsets`] finds the
//! sample where each burst begins, in four steps (`fs` the rate, `x` the signal):
//!
//! 1. **Envelope.** The centred moving RMS over `W = envelope_window * fs` samples,
//!    `e[n] = sqrt( (1/|S_n|) sum_{m in S_n} x[m]^2 )`, `S_n = [n - W/2, n + W - W/2) ∩ [0, N)`,
//!    computed from a prefix sum of `x^2`. Centred so that the envelope is not delayed.
//! 2. **Noise floor.** `sigma` = the `noise_percentile`-th percentile (nearest rank) of the
//!    envelope: a low percentile rather than the median because in a walk most of the time
//!    may be strikes and their tails. For white noise it reads low (the 10th percentile of
//!    a 10-sample RMS is about 0.7 of the true RMS), which the margins below absorb.
//! 3. **Detection.** The threshold is
//!    `T = max(P * 10^(-threshold_below_peak/20), sigma * 10^(noise_margin/20))`,
//!    `P = max e`: relative to the loudest strike, so one gain setting fits any file, and
//!    clearly above the noise, so that a file of noise alone gives no onsets at all rather
//!    than its loudest noise spikes. The default `noise_margin` of 12 dB is a compromise
//!    measured, not derived: in a minute of white noise at 2 kHz `P` stands about 9 dB
//!    above the floor (2 dB at 44.1 kHz, where the window holds more samples), while the
//!    shortest real single-step clips, which are all strike and fade-out with no quiet
//!    before the step, reach only 14 to 16 dB.
//!    A detector is armed at the start; when armed and `e[n] >= T` it fires and disarms; it
//!    re-arms once `e[n] < T * 10^(-hysteresis/20)`. A firing less than `min_interval`
//!    after the last accepted one is the same strike (a double hit, heel then sole) and is
//!    dropped.
//! 4. **Refinement.** The threshold crossing is late: it is where the strike is already
//!    loud. From the end of the crossing's envelope window, the search goes back to the
//!    latest sample with `|x| > L` (the strike), then back through the strike to the latest
//!    run of `quiet_run` consecutive samples with `|x| <= L`, the noise before it; the
//!    onset is the first sample after that run. The rise level is
//!    `L = max(sigma * 10^(rise_margin/20), max|x| * 10^(-rise_floor_below_peak/20))`:
//!    a few times the noise (with the floor reading low, a 14 dB margin puts it 3.5 to 5
//!    noise standard deviations up, which a Gaussian noise sample exceeds with probability
//!    below 5e-4, so a stray noise peak rarely drags the onset early), but never far below
//!    the peak, so that a noiseless signal's filter pre-ringing does not count as the strike.
//!    The default floor of 50 dB below the peak is measured: the analysis's zero-phase trend
//!    filter rings ahead of a strike down to about -60 dB over tens of milliseconds, and
//!    with a 60 dB floor a little noise (1e-4) in that ringing moved the onsets of the shared
//!    `ice` clips by 14-28 ms and their measured response by 0.6 dB at 20 Hz; at 50 dB the
//!    onsets no longer depend on whether the quiet before a strike is noise or silence.
//!    Single samples with a run length, rather than another envelope, keep the onset sharp
//!    (no window smearing) while zero crossings inside the strike, being shorter than the
//!    run, do not stop the search. The search goes back at most `max_rise` and never past
//!    the previous strike's crossing; at the start of the file the time before the first
//!    sample counts as quiet. If no quiet run is found within those bounds (a strike rising
//!    out of the tail of the last one), the onset is the latest minimum of the envelope
//!    there, the valley between the two.
//!
//! Everything is expressed in seconds and decibels, so the detector behaves the same at
//! any rate (it is meant for the conditioned signal at the 2 kHz analysis rate, but raw
//! 44.1 kHz audio works too). Non-finite input, an empty signal or a 0 Hz rate give no onsets.

use crate::numeric::window::{Edges, centred_rms};
use crate::units::{Decibels, SampleRate, Seconds};

/// Parameters of heel-strike detection; see the [module docs](self) for how each is used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnsetConfig {
    /// Length of the RMS envelope window.
    pub envelope_window: Seconds,
    /// Two strikes closer than this are one strike.
    pub min_interval: Seconds,
    /// An onset is where the envelope rises to within this many dB of the recording's peak.
    pub threshold_below_peak: Decibels,
    /// The envelope must fall this many dB below the threshold before another onset can fire.
    pub hysteresis: Decibels,
    /// Which percentile (0 to 1) of the envelope is the noise floor.
    pub noise_percentile: f64,
    /// The detection threshold is at least this far above the noise floor.
    pub noise_margin: Decibels,
    /// A sample is part of a strike when it is this far above the noise floor.
    pub rise_margin: Decibels,
    /// ... and never counted as noise when within this many dB of the peak sample.
    pub rise_floor_below_peak: Decibels,
    /// How long the signal must stay at noise level to count as the quiet before a strike.
    pub quiet_run: Seconds,
    /// How far before its detection a strike's onset may be.
    pub max_rise: Seconds,
}

impl Default for OnsetConfig {
    fn default() -> Self {
        Self {
            envelope_window: Seconds(0.005),
            min_interval: Seconds(0.3),
            threshold_below_peak: Decibels(20.0),
            hysteresis: Decibels(6.0),
            noise_percentile: 0.1,
            noise_margin: Decibels(12.0),
            rise_margin: Decibels(14.0),
            rise_floor_below_peak: Decibels(50.0),
            quiet_run: Seconds(0.002),
            max_rise: Seconds(0.1),
        }
    }
}

/// Sample indices of the heel-strike onsets in `x`, in increasing order.
///
/// Returns no onsets when nothing stands clearly above the noise, and for empty or
/// non-finite input or a 0 Hz rate.
#[must_use]
pub fn find_onsets(x: &[f64], rate: SampleRate, cfg: &OnsetConfig) -> Vec<usize> {
    if x.is_empty() || rate.0 == 0 || x.iter().any(|v| !v.is_finite()) {
        return Vec::new();
    }
    let samples = |t: Seconds| rate.samples_in(t);
    let w = samples(cfg.envelope_window).max(1);
    let env = centred_rms(x, w, Edges::Clipped);
    let min_gap = samples(cfg.min_interval);
    let Some((kept, sigma)) = crossings(&env, cfg, min_gap) else {
        return Vec::new();
    };
    let peak_abs = x.iter().fold(0.0, |m: f64, v| m.max(v.abs()));
    let rise = (sigma * up(cfg.rise_margin)).max(peak_abs * down(cfg.rise_floor_below_peak));
    let refine = Refine {
        x,
        env: &env,
        rise,
        quiet_run: samples(cfg.quiet_run).max(1),
        max_back: samples(cfg.max_rise),
    };
    kept.iter()
        .enumerate()
        .map(|(i, &n)| {
            let window_end = (n + w - w / 2).min(x.len()) - 1;
            // Never past the strike before's crossing.
            let lo = i.checked_sub(1).map_or(0, |p| kept[p] + 1);
            refine.onset(window_end, lo)
        })
        .collect()
}

/// Steps 2 and 3 of the module docs on an envelope `env`: where each strike's envelope
/// crosses the threshold (a crossing within `min_gap` of the last one kept is the same
/// strike), with the noise floor `sigma`. `None` when nothing stands clearly above the
/// noise.
///
/// [`find_onsets`] runs it on the moving RMS; a long recording's first pass
/// ([`super::excerpts`]) on the RMS of 5 ms blocks, with `min_gap` in blocks.
pub(crate) fn crossings(
    env: &[f64],
    cfg: &OnsetConfig,
    min_gap: usize,
) -> Option<(Vec<usize>, f64)> {
    let peak_env = env.iter().copied().fold(0.0, f64::max);
    if peak_env <= 0.0 {
        return None;
    }
    let sigma = crate::numeric::percentile(env, cfg.noise_percentile).unwrap_or(0.0);
    let threshold = (peak_env * down(cfg.threshold_below_peak)).max(sigma * up(cfg.noise_margin));
    if threshold > peak_env {
        return None;
    }
    let rearm = threshold * down(cfg.hysteresis);
    let mut kept: Vec<usize> = Vec::new();
    let mut armed = true;
    for (n, &e) in env.iter().enumerate() {
        if armed {
            if e >= threshold {
                armed = false;
                if kept.last().is_none_or(|&c| n - c >= min_gap) {
                    kept.push(n);
                }
            }
        } else if e < rearm {
            armed = true;
        }
    }
    Some((kept, sigma))
}

fn up(db: Decibels) -> f64 {
    db.to_amplitude()
}

fn down(db: Decibels) -> f64 {
    Decibels(-db.0).to_amplitude()
}

/// Step 4 of the module docs: from a detection back to where the strike rises out of
/// the noise.
struct Refine<'a> {
    x: &'a [f64],
    env: &'a [f64],
    rise: f64,
    quiet_run: usize,
    max_back: usize,
}

impl Refine<'_> {
    /// The onset of the strike detected with its envelope window ending at `end`,
    /// searching no earlier than `lo`.
    fn onset(&self, end: usize, lo: usize) -> usize {
        let lo = lo.max(end.saturating_sub(self.max_back));
        let loud = |i: usize| self.x[i].abs() > self.rise;
        let Some(top) = (lo..=end).rev().find(|&i| loud(i)) else {
            return end;
        };
        let mut run = 0;
        for i in (lo..=top).rev() {
            if loud(i) {
                run = 0;
            } else {
                run += 1;
                if run == self.quiet_run {
                    return i + run;
                }
            }
        }
        if lo == 0 {
            // Before the file is quiet: the strike starts after the partial quiet run.
            return run;
        }
        let mut valley = top;
        for i in (lo..=top).rev() {
            if self.env[i] < self.env[valley] {
                valley = i;
            }
        }
        valley
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    use crate::signal::noise::SplitMix64;

    /// One heel strike: two decaying resonances (a ground mode and a higher one) that start
    /// at rest, optionally after a linear attack.
    #[derive(Debug, Clone, Copy)]
    struct Burst {
        at: f64,
        amp: f64,
        freq: f64,
        attack: f64,
    }

    /// Seeded white noise of standard deviation `noise` plus the bursts, `len` seconds at `fs`.
    fn synth(fs: u32, len: f64, noise: f64, seed: u64, bursts: &[Burst]) -> Vec<f64> {
        let fs = f64::from(fs);
        let mut rng = SplitMix64::new(seed);
        let n = (len * fs) as usize;
        let mut x: Vec<f64> = (0..n).map(|_| noise * rng.normal()).collect();
        for b in bursts {
            let start = (b.at * fs).round() as usize;
            for (i, v) in x.iter_mut().enumerate().skip(start) {
                let t = (i - start) as f64 / fs;
                if t > 0.4 {
                    break;
                }
                let ramp = if b.attack > 0.0 {
                    (t / b.attack).min(1.0)
                } else {
                    1.0
                };
                let w = 2.0 * std::f64::consts::PI * b.freq * t;
                *v += b.amp
                    * ramp
                    * ((-t / 0.03).exp() * w.sin() + 0.5 * (-t / 0.012).exp() * (2.7 * w).sin());
            }
        }
        x
    }

    fn burst(at: f64, amp: f64) -> Burst {
        Burst {
            at,
            amp,
            freq: 120.0,
            attack: 0.0,
        }
    }

    /// Asserts one onset within 2 ms of each burst start, and no others.
    fn assert_onsets_match(x: &[f64], fs: u32, bursts: &[Burst], cfg: &OnsetConfig) {
        let got = find_onsets(x, SampleRate(fs), cfg);
        let want: Vec<f64> = bursts
            .iter()
            .map(|b| (b.at * f64::from(fs)).round())
            .collect();
        assert_eq!(
            got.len(),
            want.len(),
            "at {fs} Hz: got {got:?}, want {want:?}"
        );
        let tol = 0.002 * f64::from(fs);
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (*g as f64 - w).abs() <= tol,
                "at {fs} Hz: onset {g}, truth {w}, tol {tol}"
            );
        }
    }

    #[test]
    fn burst_trains_are_found_within_2ms_at_several_rates() {
        let bursts = [
            Burst {
                at: 0.5,
                amp: 0.8,
                freq: 90.0,
                attack: 0.0,
            },
            Burst {
                at: 1.3,
                amp: 0.3,
                freq: 150.0,
                attack: 0.002,
            },
            Burst {
                at: 2.05,
                amp: 1.0,
                freq: 60.0,
                attack: 0.0,
            },
            Burst {
                at: 2.9,
                amp: 0.5,
                freq: 300.0,
                attack: 0.004,
            },
        ];
        for (seed, fs) in [2000u32, 4000, 8000, 22_050, 44_100]
            .into_iter()
            .enumerate()
        {
            for noise in [1e-4, 3e-3] {
                let x = synth(fs, 3.5, noise, seed as u64, &bursts);
                assert_onsets_match(&x, fs, &bursts, &OnsetConfig::default());
            }
        }
    }

    #[test]
    fn no_onsets_in_noise_alone() {
        for (seed, fs) in [(1, 2000u32), (2, 2000), (3, 8000), (4, 44_100)] {
            let x = synth(fs, 10.0, 0.05, seed, &[]);
            assert_eq!(
                find_onsets(&x, SampleRate(fs), &OnsetConfig::default()),
                Vec::<usize>::new()
            );
        }
    }

    #[test]
    fn double_hit_100ms_apart_is_one_strike() {
        let fs = 2000;
        let x = synth(fs, 2.0, 1e-3, 7, &[burst(0.6, 0.7), burst(0.7, 0.7)]);
        assert_onsets_match(&x, fs, &[burst(0.6, 0.7)], &OnsetConfig::default());
        // The same pair with the merge window shortened below 100 ms is two strikes.
        let cfg = OnsetConfig {
            min_interval: Seconds(0.05),
            ..OnsetConfig::default()
        };
        assert_onsets_match(&x, fs, &[burst(0.6, 0.7), burst(0.7, 0.7)], &cfg);
    }

    #[test]
    fn threshold_is_relative_to_the_loudest_strike() {
        let fs = 2000;
        // 30 dB below the loudest: under the 20 dB threshold; 10 dB below: over it.
        let loud = burst(0.5, 1.0);
        let faint = burst(1.2, 10f64.powf(-30.0 / 20.0));
        let softer = burst(1.9, 10f64.powf(-10.0 / 20.0));
        let x = synth(fs, 2.5, 1e-5, 8, &[loud, faint, softer]);
        assert_onsets_match(&x, fs, &[loud, softer], &OnsetConfig::default());
        // Lowering the threshold to 40 dB below the peak lets the faint one in.
        let cfg = OnsetConfig {
            threshold_below_peak: Decibels(40.0),
            ..OnsetConfig::default()
        };
        assert_onsets_match(&x, fs, &[loud, faint, softer], &cfg);
    }

    #[test]
    fn hysteresis_decides_whether_a_dip_rearms() {
        // A steady tone whose amplitude dips to `dip` (relative to the threshold) between
        // two plateaus; merging by interval is disabled so only hysteresis decides.
        let fs = 2000u32;
        let cfg = OnsetConfig {
            min_interval: Seconds(0.0),
            ..OnsetConfig::default()
        };
        let threshold = 10f64.powf(-20.0 / 20.0); // peak RMS 1, 20 dB below
        let signal = |dip: f64| -> Vec<f64> {
            let a = std::f64::consts::SQRT_2; // RMS 1
            (0..(2 * fs) as usize)
                .map(|i| {
                    let t = f64::from(i as u32) / f64::from(fs);
                    let env = if !(0.2..1.8).contains(&t) {
                        0.0
                    } else if (0.9..1.1).contains(&t) {
                        dip * threshold
                    } else {
                        1.0
                    };
                    a * env * (2.0 * std::f64::consts::PI * 100.0 * t).sin()
                })
                .collect()
        };
        // 0.7 of the threshold is only 3 dB down: no re-arm with 6 dB hysteresis.
        assert_eq!(find_onsets(&signal(0.7), SampleRate(fs), &cfg).len(), 1);
        // 0.3 is 10 dB down: re-armed, and the second plateau is a second onset.
        let two = find_onsets(&signal(0.3), SampleRate(fs), &cfg);
        assert_eq!(two.len(), 2, "{two:?}");
        assert!(
            (two[1] as f64 - 1.1 * f64::from(fs)).abs() <= 0.002 * f64::from(fs),
            "{two:?}"
        );
    }

    #[test]
    fn a_strike_at_the_first_sample_is_found_there() {
        let fs = 2000;
        // Starting at rest, the burst's first non-zero sample is sample 1.
        let x = synth(fs, 1.0, 0.0, 9, &[burst(0.0, 1.0)]);
        assert_eq!(
            find_onsets(&x, SampleRate(fs), &OnsetConfig::default()),
            vec![1]
        );
        let x = synth(fs, 1.0, 1e-3, 9, &[burst(0.0, 1.0)]);
        assert_onsets_match(&x, fs, &[burst(0.0, 1.0)], &OnsetConfig::default());
    }

    #[test]
    fn noiseless_strike_is_found_to_the_sample() {
        // Digital silence before the strike: the noise floor is 0 and the onset exact.
        let fs = 8000;
        let x = synth(fs, 1.0, 0.0, 10, &[burst(0.25, 0.5)]);
        // The burst starts at rest (sin 0 = 0), so its first non-zero sample is one later.
        assert_eq!(
            find_onsets(&x, SampleRate(fs), &OnsetConfig::default()),
            vec![2001]
        );
    }

    #[test]
    fn degenerate_input_gives_no_onsets() {
        let cfg = OnsetConfig::default();
        assert!(find_onsets(&[], SampleRate(2000), &cfg).is_empty());
        assert!(find_onsets(&[0.0; 1000], SampleRate(2000), &cfg).is_empty());
        let mut x = synth(2000, 1.0, 1e-3, 11, &[burst(0.3, 1.0)]);
        assert!(find_onsets(&x, SampleRate(0), &cfg).is_empty());
        x[100] = f64::NAN;
        assert!(find_onsets(&x, SampleRate(2000), &cfg).is_empty());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn random_strike_trains_are_found_within_2ms(
            fs in prop::sample::select(vec![2000u32, 3000, 8000, 16_000, 48_000]),
            seed in any::<u64>(),
            gaps in prop::collection::vec(0.45f64..1.2, 1..6),
            amps in prop::collection::vec(0.2f64..1.0, 6),
            freqs in prop::collection::vec(40.0f64..350.0, 6),
            attacks in prop::collection::vec(0.0f64..0.003, 6),
            noise_db in -70.0f64..-40.0,
        ) {
            let mut at = 0.2;
            let bursts: Vec<Burst> = gaps
                .iter()
                .enumerate()
                .map(|(k, g)| {
                    let b = Burst { at, amp: amps[k], freq: freqs[k], attack: attacks[k] };
                    at += g;
                    b
                })
                .collect();
            let x = synth(fs, at + 0.3, 10f64.powf(noise_db / 20.0), seed, &bursts);
            assert_onsets_match(&x, fs, &bursts, &OnsetConfig::default());
        }
    }
}
