//! # underfoot
//!
//! Learn how a ground material vibrates from recordings of footsteps, and play that
//! vibration back step by step.
//!
//! The crate is laid out as the pipeline it implements; dependencies point one way:
//!
//! | stage | module | what it does |
//! |---|---|---|
//! | recordings | [`recording`] | decode WAV/FLAC/Ogg/CSV, find each heel strike's onset |
//! | signal conditioning | [`signal`] | resample, Savitzky-Golay, Butterworth SOS, zero-phase filtering, spectra |
//! | analysis | [`analysis`] | the measured response of a material: RMS-averaged, 1/6-octave smoothed strike spectra |
//! | fitting | [`fit`] | IIR fits to a measured response: Levi, vector fitting, damped Gauss-Newton, order search |
//! | material models | [`material`] | the material model, the versioned library file, the built-in presets |
//!
//! Units are types ([`units`]): a [`SampleRate`](units::SampleRate) is not a
//! [`Hz`](units::Hz), and neither is a bare `f64`.
//!
//! Every stage reports bad input through its own error enum; nothing panics on a bad file.
pub mod analysis;
pub mod fit;
pub mod material;
pub mod recording;
pub mod signal;
pub mod units;
