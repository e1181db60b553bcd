//! The spectrogram: levels of a short-time Fourier transform on a grid of time columns
//! and frequency rows, bounded in size whatever the signal's length.
//!
//! Frames of `N` samples ([`Spectrogram::window_len`]: bins of 4 to 6 Hz) are weighted
//! by the Hann window and transformed:
//!
//! ```math
//! w_n = \tfrac12 - \tfrac12 \cos\frac{2\pi n}{N}, \qquad
//!   X^{(m)}_k = \sum_{n=0}^{N-1} w_n\, x_{m - N/2 + n}\, e^{-2\pi j k n / N},
//! ```
//!
//! the frame centred on sample `m`, with `x` zero outside the signal. Column `c` spans
//! the samples `c h ..= (c + 1) h` for a hop `h` that gives at most the number of columns
//! asked for (and at least `N / 8`: frames overlapping by more than 7/8 of a Hann window
//! are nearly alike). A column wider than half a window gets `F = ⌈h / (N/2)⌉` frames,
//! centred at `m = c h + (2i + 1) h / (2F)`, `i = 0..F`, and their power is summed, so
//! that no stretch of the signal (no footstep) goes unseen:
//!
//! ```math
//! P_c(k) = \sum_{i=0}^{F-1} \left| X^{(m_i)}_k \right|^2 .
//! ```
//!
//! The bins `0..B` up to the top frequency are grouped into at most the number of rows
//! asked for, row `r` holding bins `⌊r B / R⌋ .. ⌊(r + 1) B / R⌋`, and a row takes the
//! loudest of its bins (averaged, a tone narrower than the row would fade by the number of
//! bins it shares the row with). A cell's level is in dB re the loudest cell, floored at
//! `-range`:
//!
//! ```math
//! L_{c,r} = \max\!\left(10 \log_{10} \frac{\max_{k \in r} P_c(k)}{\max_{c', r'} P_{c'}(r')},
//!   \ -\text{range}\right),
//! ```
//!
//! and an all-zero signal is at the floor everywhere.

use std::f64::consts::TAU;

use super::SpectrumPlan;
use crate::signal::SignalError;
use crate::units::{Decibels, Hz, SampleRate};

/// Levels of a short-time Fourier transform on a grid of time columns and frequency rows;
/// see the [module docs](self).
#[derive(Debug, Clone, PartialEq)]
pub struct Spectrogram {
    /// The FFT (and Hann window) length, in samples.
    pub window: usize,
    /// The spacing of the FFT's bins, in Hz.
    pub bin_hz: f64,
    /// Column `c` spans `c * col_s ..= (c + 1) * col_s` seconds; its frames are centred in
    /// between.
    pub col_s: f64,
    /// Row `r` spans `edges_hz[r] ..= edges_hz[r + 1]`, from 0 Hz to the top frequency.
    pub edges_hz: Vec<f64>,
    /// dB re the loudest cell, in `[-range, 0]`, column after column.
    pub db: Vec<f64>,
}

impl Spectrogram {
    /// The STFT length at `rate`: bins of 4 to 6 Hz, fine enough to part the resonances
    /// of a material below 1 kHz, while a frame (~0.17 s at 48 kHz) stays about one
    /// footstep long.
    #[must_use]
    pub fn window_len(rate: SampleRate) -> usize {
        (rate.0 as usize / 6).next_power_of_two().max(16)
    }

    /// The spectrogram of `samples` at `rate` from 0 Hz to `top` (lowered to the Nyquist
    /// frequency if above it), with at most `max_cells` = (columns, rows) cells, levels
    /// floored at `range` below the loudest cell.
    ///
    /// # Errors
    /// [`SignalError::TooShort`] for no samples; [`SignalError::InvalidParameter`] for a
    /// zero rate, a `top` that is not positive, a `range` that is not, no cells, or a
    /// sample that is not finite.
    pub fn new(
        samples: &[f32],
        rate: SampleRate,
        top: Hz,
        max_cells: (usize, usize),
        range: Decibels,
    ) -> Result<Self, SignalError> {
        let invalid = |what: String| Err(SignalError::InvalidParameter(what));
        if samples.is_empty() {
            return Err(SignalError::TooShort {
                len: 0,
                needed: 1,
                what: "a spectrogram",
            });
        }
        if rate.0 == 0 {
            return invalid("a spectrogram at 0 Hz".into());
        }
        if !(top.0.is_finite() && top.0 > 0.0) {
            return invalid(format!("a spectrogram's top frequency of {top}"));
        }
        if !(range.0.is_finite() && range.0 > 0.0) {
            return invalid(format!("a spectrogram's range of {range}"));
        }
        if max_cells.0 == 0 || max_cells.1 == 0 {
            return invalid(format!("a spectrogram of {max_cells:?} cells"));
        }
        if let Some(i) = samples.iter().position(|x| !x.is_finite()) {
            return invalid(format!("sample {i} of a spectrogram is {}", samples[i]));
        }
        let top_hz = top.0.min(rate.nyquist().0);
        stft(samples, rate, top_hz, max_cells, range.0)
    }

    /// The number of frequency rows.
    #[must_use]
    pub fn rows(&self) -> usize {
        self.edges_hz.len() - 1
    }

    /// The number of time columns.
    #[must_use]
    pub fn cols(&self) -> usize {
        self.db.len() / self.rows()
    }

    /// The levels of column `c`, from the lowest row up.
    ///
    /// # Panics
    /// If `c` is not below [`cols`](Self::cols).
    #[must_use]
    pub fn column(&self, c: usize) -> &[f64] {
        let rows = self.rows();
        &self.db[c * rows..(c + 1) * rows]
    }
}

/// [`Spectrogram::new`] of checked arguments.
fn stft(
    samples: &[f32],
    rate: SampleRate,
    top_hz: f64,
    (max_cols, max_rows): (usize, usize),
    range_db: f64,
) -> Result<Spectrogram, SignalError> {
    let n = Spectrogram::window_len(rate);
    let len = samples.len();
    // Frames overlapping by more than 7/8 of a Hann window are nearly alike: a shorter hop
    // would add columns but no detail.
    let hop = len.div_ceil(max_cols).max(n / 8);
    let cols = len.div_ceil(hop);
    let bin_hz = rate.hz() / n as f64;
    let bins = ((top_hz / bin_hz).round() as usize).min(n / 2) + 1;
    let rows = bins.min(max_rows);
    let first_bin = |r: usize| r * bins / rows;
    let edges_hz = (0..=rows)
        .map(|r| ((first_bin(r) as f64 - 0.5) * bin_hz).clamp(0.0, top_hz))
        .collect();

    let window: Vec<f64> = (0..n)
        .map(|i| 0.5 - 0.5 * (TAU * i as f64 / n as f64).cos())
        .collect();
    let mut plan = SpectrumPlan::new(n);
    let mut frame = vec![0.0; n];
    let mut magnitude = vec![0.0; plan.bins()];
    let mut power = vec![0.0; bins];
    let mut cells = Vec::with_capacity(cols * rows);
    let pad = n / 2;
    let frames = hop.div_ceil(n / 2);
    for c in 0..cols {
        power.fill(0.0);
        for k in 0..frames {
            // The frame spans `centre - pad .. centre - pad + n` in the signal, zero
            // where that reaches past either end.
            let centre = c * hop + (2 * k + 1) * hop / (2 * frames);
            let (skip, from) = match centre.checked_sub(pad) {
                Some(from) => (0, from.min(len)),
                None => (pad - centre, 0),
            };
            let to = (centre + (n - pad)).clamp(from, len);
            frame.fill(0.0);
            for ((f, w), x) in frame[skip..]
                .iter_mut()
                .zip(&window[skip..])
                .zip(&samples[from..to])
            {
                *f = f64::from(*x) * w;
            }
            plan.magnitude(&frame, &mut magnitude)?;
            for (p, m) in power.iter_mut().zip(&magnitude) {
                *p += m * m;
            }
        }
        cells.extend((0..rows).map(|r| {
            power[first_bin(r)..first_bin(r + 1)]
                .iter()
                .fold(0.0, |a: f64, &b| a.max(b))
        }));
    }
    let loudest = cells.iter().fold(0.0, |a: f64, &b| a.max(b));
    for p in &mut cells {
        // All-zero input has no loudest cell: everything is at the floor.
        *p = if *p > 0.0 {
            (10.0 * (*p / loudest).log10()).max(-range_db)
        } else {
            -range_db
        };
    }
    Ok(Spectrogram {
        window: n,
        bin_hz,
        col_s: hop as f64 / rate.hz(),
        edges_hz,
        db: cells,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::signal::noise::SplitMix64;

    const RANGE: Decibels = Decibels(60.0);
    const PNG_CELLS: (usize, usize) = (1200, 300);

    fn tone(rate_hz: u32, seconds: f64, hz: f64) -> Vec<f32> {
        let n = (f64::from(rate_hz) * seconds) as usize;
        (0..n)
            .map(|i| (TAU * hz * i as f64 / f64::from(rate_hz)).sin() as f32)
            .collect()
    }

    fn stft(x: &[f32], rate_hz: u32, top_hz: f64, cells: (usize, usize)) -> Spectrogram {
        Spectrogram::new(x, SampleRate(rate_hz), Hz(top_hz), cells, RANGE).expect("stft")
    }

    /// `|X_k|²` of `frame` by the definition, `k = 0..=N/2`.
    fn naive_power(frame: &[f64]) -> Vec<f64> {
        let n = frame.len();
        (0..=n / 2)
            .map(|k| {
                let (mut re, mut im) = (0.0, 0.0);
                for (i, v) in frame.iter().enumerate() {
                    // Reduce k i mod N first so the angle stays small and exact.
                    let ang = -TAU * ((k * i) % n) as f64 / n as f64;
                    re += v * ang.cos();
                    im += v * ang.sin();
                }
                re * re + im * im
            })
            .collect()
    }

    /// The module docs' definition, term by term: one Hann frame per column (columns no
    /// wider than half a window), every bin its own row.
    #[test]
    fn matches_the_definition_with_a_naive_dft() {
        let mut noise = SplitMix64::new(3);
        let x: Vec<f32> = (0..1000).map(|_| noise.symmetric() as f32).collect();
        let rate = SampleRate(600);
        let n = Spectrogram::window_len(rate);
        assert_eq!(n, 128);
        let got = Spectrogram::new(&x, rate, Hz(300.0), (16, 1000), RANGE).unwrap();
        let hop = 1000usize.div_ceil(16);
        assert!(hop <= n / 2);
        assert_eq!((got.window, got.cols(), got.rows()), (n, 16, n / 2 + 1));
        assert!((got.col_s - hop as f64 / 600.0).abs() < 1e-15);

        let mut want = Vec::new();
        for c in 0..16 {
            let centre = c * hop + hop / 2;
            let frame: Vec<f64> = (0..n)
                .map(|i| {
                    let w = 0.5 - 0.5 * (TAU * i as f64 / n as f64).cos();
                    let at = (centre + i).checked_sub(n / 2);
                    at.and_then(|j| x.get(j)).map_or(0.0, |v| w * f64::from(*v))
                })
                .collect();
            want.extend(naive_power(&frame));
        }
        let loudest = want.iter().fold(0.0f64, |a, &b| a.max(b));
        for (i, (g, p)) in got.db.iter().zip(&want).enumerate() {
            let w = (10.0 * (p / loudest).log10()).max(-RANGE.0);
            assert!(
                (g - w).abs() < 1e-9,
                "cell {i}: {g} dB, by definition {w} dB"
            );
        }
        assert!(got.db.contains(&0.0));
    }

    #[test]
    fn bad_arguments_are_errors() {
        let one = [0.0f32];
        let r = SampleRate(48_000);
        assert!(Spectrogram::new(&[], r, Hz(1000.0), PNG_CELLS, RANGE).is_err());
        assert!(Spectrogram::new(&one, SampleRate(0), Hz(1000.0), PNG_CELLS, RANGE).is_err());
        assert!(Spectrogram::new(&one, r, Hz(0.0), PNG_CELLS, RANGE).is_err());
        assert!(Spectrogram::new(&one, r, Hz(f64::NAN), PNG_CELLS, RANGE).is_err());
        assert!(Spectrogram::new(&one, r, Hz(1000.0), (0, 300), RANGE).is_err());
        assert!(Spectrogram::new(&one, r, Hz(1000.0), PNG_CELLS, Decibels(0.0)).is_err());
        let e = Spectrogram::new(&[0.0, f32::NAN], r, Hz(1000.0), PNG_CELLS, RANGE);
        assert!(e.unwrap_err().to_string().contains("sample 1"));
        // A top above the Nyquist frequency is lowered to it.
        let s = Spectrogram::new(&one, SampleRate(600), Hz(1e6), PNG_CELLS, RANGE).unwrap();
        assert_eq!(s.edges_hz[s.rows()], 300.0);
    }

    #[test]
    fn zero_input_is_at_the_floor() {
        let x = vec![0.0; 20_000];
        let spec = stft(&x, 48_000, 1000.0, PNG_CELLS);
        assert!(spec.db.iter().all(|&v| v == -RANGE.0));
    }

    #[test]
    fn a_sine_peaks_in_its_row() {
        let x = tone(48_000, 2.0, 200.0);
        for max_rows in [300, 40] {
            let spec = stft(&x, 48_000, 1000.0, (1200, max_rows));
            assert_eq!(spec.window, 8192);
            assert!(spec.rows() <= max_rows && spec.cols() <= 1200);
            assert_eq!(spec.edges_hz[0], 0.0);
            assert_eq!(spec.edges_hz[spec.rows()], 1000.0);
            // A column in the middle, where the frame lies wholly inside the signal.
            let column = spec.column(spec.cols() / 2);
            let peak = (0..spec.rows())
                .max_by(|&a, &b| column[a].total_cmp(&column[b]))
                .expect("rows");
            let (lo, hi) = (spec.edges_hz[peak], spec.edges_hz[peak + 1]);
            assert!(
                lo - spec.bin_hz <= 200.0 && 200.0 <= hi + spec.bin_hz,
                "rows of at most {max_rows}: peak in {lo}..{hi} Hz"
            );
            if max_rows == 300 {
                let centre = (lo + hi) / 2.0;
                assert!((centre - 200.0).abs() <= spec.bin_hz, "peak at {centre} Hz");
            }
            // Columns differ only in the tone's phase against the window.
            assert!(column[peak] > -0.1, "{} dB", column[peak]);
            // Far from the tone, the Hann window's side lobes are far below the floor.
            assert_eq!(column[spec.rows() - 1], -RANGE.0);
        }
    }

    #[test]
    fn wide_columns_miss_nothing() {
        // 600 Hz: a 128-sample window. Four columns of 1000 samples each, and a burst
        // at 150 Hz in the first 100 samples only, far from the first column's centre.
        let mut x = vec![0.0f32; 4000];
        for (i, v) in x[..100].iter_mut().enumerate() {
            *v = (TAU * 150.0 * i as f64 / 600.0).sin() as f32;
        }
        let spec = stft(&x, 600, 300.0, (4, 300));
        assert_eq!((spec.window, spec.cols()), (128, 4));
        let column = spec.column(0);
        let peak = (0..spec.rows())
            .max_by(|&a, &b| column[a].total_cmp(&column[b]))
            .expect("rows");
        let centre = (spec.edges_hz[peak] + spec.edges_hz[peak + 1]) / 2.0;
        assert!((centre - 150.0).abs() <= spec.bin_hz, "peak at {centre} Hz");
        assert_eq!(column[peak], 0.0);
        assert!(spec.column(3).iter().all(|&v| v == -RANGE.0));
    }
}
