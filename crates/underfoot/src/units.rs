//! Physical units as types, so that a bare `f64` is never misread.
//!
//! A sample rate is not a frequency, a frequency is not an angular frequency, and a
//! magnitude is not a level in decibels. Each gets a newtype; conversions are explicit.

use core::fmt;
use serde::{Deserialize, Serialize};

/// Samples per second of a discrete-time signal.
///
/// Kept as an integer because rates are exact in files and devices, and because the
/// polyphase resampler needs the exact ratio between two rates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct SampleRate(pub u32);

impl SampleRate {
    /// The rate in hertz, as a float for arithmetic.
    #[must_use]
    pub fn hz(self) -> f64 {
        f64::from(self.0)
    }

    /// The Nyquist frequency, half the rate.
    #[must_use]
    pub fn nyquist(self) -> Hz {
        Hz(self.hz() / 2.0)
    }

    /// The duration of `n` samples.
    #[must_use]
    pub fn duration_of(self, n: usize) -> Seconds {
        Seconds(n as f64 / self.hz())
    }

    /// The number of whole samples in `t` (rounded to nearest), saturating: a negative or
    /// NaN duration gives 0 and one too long for `usize` gives `usize::MAX`.
    ///
    /// Saturation keeps the conversion from wrapping, but a saturated count is still no
    /// size to allocate: where `t` comes from outside, use [`SampleRate::checked_samples_in`].
    #[must_use]
    pub fn samples_in(self, t: Seconds) -> usize {
        let n = crate::math::round(t.0 * self.hz());
        if n >= 0.0 {
            // `as` saturates at usize::MAX (and a NaN fails the test above).
            n as usize
        } else {
            0
        }
    }

    /// The number of whole samples in `t`, if `t` is finite, not negative and at most
    /// `max` samples long; `None` otherwise. For durations that size a buffer.
    #[must_use]
    pub fn checked_samples_in(self, t: Seconds, max: usize) -> Option<usize> {
        if !(t.0.is_finite() && t.0 >= 0.0) {
            return None;
        }
        let n = crate::math::round(t.0 * self.hz());
        (n <= max as f64).then_some(n as usize)
    }

    /// Normalised angular frequency `omega = 2 pi f / fs` in radians per sample.
    #[must_use]
    pub fn omega(self, f: Hz) -> f64 {
        2.0 * core::f64::consts::PI * f.0 / self.hz()
    }
}

impl fmt::Display for SampleRate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} Hz", self.0)
    }
}

/// A frequency in hertz (cycles per second).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Hz(pub f64);

impl fmt::Display for Hz {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} Hz", self.0)
    }
}

/// A duration in seconds.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Seconds(pub f64);

impl fmt::Display for Seconds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} s", self.0)
    }
}

/// A level or level difference in decibels (20 log10 of an amplitude ratio).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Decibels(pub f64);

impl Decibels {
    /// The level of an amplitude ratio.
    #[must_use]
    pub fn from_amplitude(ratio: f64) -> Self {
        Self(20.0 * crate::math::log10(ratio))
    }

    /// The amplitude ratio of this level.
    #[must_use]
    pub fn to_amplitude(self) -> f64 {
        crate::math::powf(10.0, self.0 / 20.0)
    }
}

impl fmt::Display for Decibels {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} dB", self.0)
    }
}

/// A force in newtons (a vertical ground-reaction force, or one sensor's share of it).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Newtons(pub f64);

impl Newtons {
    /// Standard gravity, for body weight from mass.
    pub const STANDARD_GRAVITY: f64 = 9.806_65;

    /// The weight of a mass of `kg` kilograms at standard gravity.
    #[must_use]
    pub fn weight_of(kg: f64) -> Self {
        Self(kg * Self::STANDARD_GRAVITY)
    }
}

impl fmt::Display for Newtons {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} N", self.0)
    }
}

/// A frequency band `[lo, hi]` in hertz.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "[f64; 2]", from = "[f64; 2]")]
pub struct Band {
    /// Lower edge.
    pub lo: Hz,
    /// Upper edge.
    pub hi: Hz,
}

impl Band {
    /// The lowest lower edge a band may have: 0.1 Hz. Below it a log-frequency grid spans
    /// so many decades that a fit's least-squares matrices lose every digit (a band from
    /// 1e-200 Hz filled them with non-finite values).
    pub const MIN_EDGE: f64 = 0.1;

    /// The highest upper edge a band may be given as text: 100 kHz, above every rate the
    /// pipeline analyses at.
    pub const MAX_EDGE: f64 = 100_000.0;

    /// A band from its edges in hertz. Validity is checked by [`Band::fits`].
    #[must_use]
    pub const fn new(lo: f64, hi: f64) -> Self {
        Self {
            lo: Hz(lo),
            hi: Hz(hi),
        }
    }

    /// Whether the band is non-empty, from at least [`Band::MIN_EDGE`] and below the
    /// Nyquist frequency of `rate`.
    #[must_use]
    pub fn fits(self, rate: SampleRate) -> bool {
        self.lo.0.is_finite()
            && self.hi.0.is_finite()
            && self.lo.0 >= Self::MIN_EDGE
            && self.hi.0 > self.lo.0
            && self.hi.0 < rate.nyquist().0
    }

    /// `n` frequencies spaced evenly on a log axis from `lo` to `hi`, both included.
    #[cfg(feature = "std")]
    #[must_use]
    pub fn log_grid(self, n: usize) -> Vec<Hz> {
        match n {
            0 => Vec::new(),
            1 => vec![Hz((self.lo.0 * self.hi.0).sqrt())],
            _ => {
                let (l, h) = (self.lo.0.ln(), self.hi.0.ln());
                (0..n)
                    .map(|i| Hz((l + (h - l) * i as f64 / (n - 1) as f64).exp()))
                    .collect()
            }
        }
    }
}

impl From<Band> for [f64; 2] {
    fn from(b: Band) -> Self {
        [b.lo.0, b.hi.0]
    }
}

impl From<[f64; 2]> for Band {
    fn from([lo, hi]: [f64; 2]) -> Self {
        Band::new(lo, hi)
    }
}

impl fmt::Display for Band {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}-{} Hz",
            Significant(self.lo.0),
            Significant(self.hi.0)
        )
    }
}

/// A number to 12 significant digits, then as short as it reads back: a derived edge
/// such as `0.2 * 1.5` prints `0.3`, not `0.30000000000000004`, and a typed one as typed.
struct Significant(f64);

impl fmt::Display for Significant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        #[cfg(feature = "std")]
        let rounded: f64 = format!("{:.11e}", self.0).parse().unwrap_or(self.0);
        // Without an allocator (firmware), as it is.
        #[cfg(not(feature = "std"))]
        let rounded = self.0;
        write!(f, "{rounded}")
    }
}

/// A band `LO:HI` in Hz (`LO,HI` is accepted too): finite, with
/// [`Band::MIN_EDGE`] <= LO < HI <= [`Band::MAX_EDGE`]. Whether it fits below a rate's
/// Nyquist frequency is for the caller, who knows the rate ([`Band::fits`]).
#[cfg(feature = "std")]
impl core::str::FromStr for Band {
    type Err = BandError;

    fn from_str(s: &str) -> Result<Self, BandError> {
        let syntax = || BandError::Syntax { input: clipped(s) };
        let (lo, hi) = s
            .split_once(':')
            .or_else(|| s.split_once(','))
            .ok_or_else(syntax)?;
        let lo: f64 = lo.trim().parse().map_err(|_| syntax())?;
        let hi: f64 = hi.trim().parse().map_err(|_| syntax())?;
        let edges = (Self::MIN_EDGE..=Self::MAX_EDGE).contains(&lo)
            && (Self::MIN_EDGE..=Self::MAX_EDGE).contains(&hi);
        if !(edges && lo < hi) {
            return Err(BandError::Range { input: clipped(s) });
        }
        Ok(Self::new(lo, hi))
    }
}

/// A band given as text that was refused.
#[cfg(feature = "std")]
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum BandError {
    /// Not two numbers separated by `:` or `,`.
    #[error("band {input:?}: {}", self.reason())]
    Syntax {
        /// The text (its first 200 bytes, then `…`).
        input: String,
    },
    /// Edges out of order or outside [`Band::MIN_EDGE`]..=[`Band::MAX_EDGE`].
    #[error("band {input:?}: {}", self.reason())]
    Range {
        /// The text (its first 200 bytes, then `…`).
        input: String,
    },
}

#[cfg(feature = "std")]
impl BandError {
    /// The text refused.
    #[must_use]
    pub fn input(&self) -> &str {
        match self {
            Self::Syntax { input } | Self::Range { input } => input,
        }
    }

    /// What is wrong with it, and what is expected.
    #[must_use]
    pub fn reason(&self) -> String {
        match self {
            Self::Syntax { .. } => "expected LO:HI in Hz, e.g. 20:900".to_owned(),
            Self::Range { .. } => format!(
                "need {} <= LO < HI <= {} Hz",
                Band::MIN_EDGE,
                Band::MAX_EDGE
            ),
        }
    }
}

/// `s`, cut after 200 bytes (at a character boundary) and marked `…`: an error names
/// its input, but a fuzzer's megabyte of junk need not be echoed whole.
#[cfg(feature = "std")]
pub(crate) fn clipped(s: &str) -> String {
    let mut input = s.to_owned();
    if input.len() > 200 {
        let mut cut = 200;
        while !input.is_char_boundary(cut) {
            cut -= 1;
        }
        input.truncate(cut);
        input.push('…');
    }
    input
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(feature = "std")]
    #[test]
    fn a_band_prints_its_edges_without_float_noise() {
        assert_eq!(Band::new(0.1, 0.2 * 1.5).to_string(), "0.1-0.3 Hz");
        assert_eq!(Band::new(20.0, 900.0).to_string(), "20-900 Hz");
        assert_eq!(
            Band::new(12.345_678, 1e-5).to_string(),
            "12.345678-0.00001 Hz"
        );
    }

    #[test]
    fn log_grid_spans_band_evenly_in_log() {
        let g = Band::new(20.0, 900.0).log_grid(96);
        assert_eq!(g.len(), 96);
        assert!((g[0].0 - 20.0).abs() < 1e-9 && (g[95].0 - 900.0).abs() < 1e-9);
        let r0 = g[1].0 / g[0].0;
        assert!(g.windows(2).all(|w| (w[1].0 / w[0].0 - r0).abs() < 1e-9));
    }

    #[test]
    fn band_fits_rate() {
        assert!(Band::new(20.0, 900.0).fits(SampleRate(2000)));
        assert!(!Band::new(20.0, 1000.0).fits(SampleRate(2000)));
        assert!(!Band::new(900.0, 20.0).fits(SampleRate(2000)));
        assert!(!Band::new(0.0, 20.0).fits(SampleRate(2000)));
        assert!(!Band::new(1e-200, 900.0).fits(SampleRate(2000)));
        assert!(Band::new(0.1, 900.0).fits(SampleRate(2000)));
    }

    #[cfg(feature = "std")]
    #[test]
    fn bands_parse_from_text_within_the_edges() {
        assert_eq!("20:900".parse::<Band>(), Ok(Band::new(20.0, 900.0)));
        assert_eq!(" 40 , 1024 ".parse::<Band>(), Ok(Band::new(40.0, 1024.0)));
        assert_eq!(
            "20-900".parse::<Band>().unwrap_err().to_string(),
            "band \"20-900\": expected LO:HI in Hz, e.g. 20:900"
        );
        assert_eq!(
            "900:20".parse::<Band>().unwrap_err().to_string(),
            "band \"900:20\": need 0.1 <= LO < HI <= 100000 Hz"
        );
        for bad in ["0.05:900", "20:100001", "20:inf", "NaN:900", "20", ":900"] {
            assert!(bad.parse::<Band>().is_err(), "{bad}");
        }
        let long = format!("20:{}", "9".repeat(1000));
        let e = long.parse::<Band>().unwrap_err();
        assert!(e.input().len() < 210 && e.input().ends_with('…'), "{e}");
    }

    #[test]
    fn sample_counts_saturate_or_fail_instead_of_overflowing() {
        let r = SampleRate(48_000);
        assert_eq!(r.samples_in(Seconds(1.0)), 48_000);
        assert_eq!(r.samples_in(Seconds(-1.0)), 0);
        assert_eq!(r.samples_in(Seconds(f64::NAN)), 0);
        assert_eq!(r.samples_in(Seconds(1e300)), usize::MAX);
        assert_eq!(r.samples_in(Seconds(f64::INFINITY)), usize::MAX);
        assert_eq!(r.checked_samples_in(Seconds(1.0), 48_000), Some(48_000));
        assert_eq!(r.checked_samples_in(Seconds(1.0), 47_999), None);
        for t in [1e300, f64::INFINITY, f64::NAN, -1.0, 1.7e9] {
            assert_eq!(r.checked_samples_in(Seconds(t), 1 << 30), None, "{t}");
        }
    }

    #[test]
    fn decibels_round_trip() {
        assert!((Decibels::from_amplitude(10.0).0 - 20.0).abs() < 1e-12);
        assert!((Decibels(-6.0).to_amplitude() - 0.501_187).abs() < 1e-6);
    }
}
