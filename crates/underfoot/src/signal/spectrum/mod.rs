//! Spectra: magnitude spectra of a planned FFT, fractional-octave smoothing, and the
//! spectrogram.
//!
//! All three rest on the unnormalised DFT of a frame zero-padded to `N` samples,
//!
//! ```math
//! X_k = \sum_{n=0}^{N-1} x_n\, e^{-2\pi j k n / N}, \qquad k = 0, \dots, N/2,
//! ```
//!
//! taken with a real FFT planned once for `N` ([`SpectrumPlan`]).
//!
//! | file | what it computes |
//! |---|---|
//! | [`magnitude`] | [`SpectrumPlan`]: `\|X_k\|` of a frame, without allocating |
//! | [`smooth`] | [`fractional_octave_smooth`]: a magnitude spectrum power-averaged over `1/b`-octave bands |
//! | [`spectrogram`] | [`Spectrogram`]: levels of a Hann-windowed short-time transform on a grid of time columns and frequency rows |
//!
//! Each item is also here, at `signal::spectrum::`.

pub mod magnitude;
pub mod smooth;
pub mod spectrogram;

pub use magnitude::SpectrumPlan;
pub use smooth::fractional_octave_smooth;
pub use spectrogram::Spectrogram;
