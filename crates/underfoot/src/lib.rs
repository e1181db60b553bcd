//! # underfoot
//!
//! Learn how a ground material vibrates from recordings of footsteps, and play that
//! vibration back step by step.
//!
//! The crate is laid out as the pipeline it implements. Dependencies point one way: a
//! module uses only modules on its own row's left or on rows above it (a test in
//! `tests/` checks every `use crate::` edge against this table).
//!
//! | layer | module | what it does | from |
//! |---|---|---|---|
//! | 0 | [`math`], [`units`] | `libm` or std math for the `no_std` core; typed units | |
//! | 1 | [`numeric`] | bounded least squares, SVD least squares, polynomial roots, bilinear transform, DTFT, median, percentile | |
//! | 2 | [`signal`], [`safety`] | resample, Savitzky-Golay, Butterworth SOS, zero-phase filtering, spectra, wavelets, fixed point; the hard limiter, watchdog, fades | [iir], [tile] |
//! | 3 | [`limits`], [`atomic_file`], [`document`] | bounds on inputs; the output policy and atomic writes; the one versioned-document layer | |
//! | 4 | [`recording`], [`force`] | decode WAV/FLAC/Ogg/CSV and find each heel strike; sensor readings, their calibration, force tracks, the gait, steps and the drive | [iir], [tile] |
//! | 5 | [`fit`], [`compensation`], [`interface`] | IIR fits to a measured response (Levi, vector fitting, damped Gauss-Newton, order search), linear prediction; a device's response, the equalizer, the limb model, the table of users, online adaptation; the prosthetic-skin interface: insole force to servo positions | [iir], [tile], [limb] |
//! | 6 | [`analysis`], [`excitation`] | a material's measured response: conditioning, strikes, the RMS strike spectrum; a step measured in time; what drives a step, the heel impact and its train of micro-impacts, fitted from recordings and played on a clock the foot drives | [iir], [tile] |
//! | 7 | [`physical`] | a hammer striking a surface of damped modes (Hunt-Crossley contact); aggregates as Poisson micro-impacts; parameters estimated from recordings | [iir], [tile] |
//! | 8 | [`material`] | the material model, the versioned library file, the built-in presets, fit quality, the evaluation of renders | [iir] |
//! | 9 | [`synthesis`] | a material's modes at the audio rate; the voice with its per-step perturbation | [iir] |
//! | 10 | [`engine`] | N channels in real time: lock-free events, no allocation in the callback; offline renders | |
//! | 11 | [`io`] | inputs (CSV replay, serial, OSC, gait) and outputs (WAV, audio devices), each device behind a feature | |
//! | 12 | [`sim`] | simulators, not production paths: a tile, a user's leg, a sensor board, the prosthetic interface's board, for tests, examples, `--device-under-test simulated` and a simulated interface link | |
//! | 13 | [`live`] | a live session: an input polled into the engine, an output playing it (a sound card, or paced like one into a WAV file or nowhere), its summary; its record (force, strikes, changes, markers, output) in one folder, and Lab Streaming Layer streams (`lsl` feature) | |
//! | 14 | [`export`], [`fuzzing`] | a library as a C99 header for firmware; the fuzz targets (hidden) | |
//!
//! Units are types ([`units`]): a [`SampleRate`](units::SampleRate) is not a
//! [`Hz`](units::Hz), and neither is a bare `f64`.
//!
//! Every stage reports bad input through its own error enum; nothing panics on a bad file.
//! Every file the project writes is a [`document`] (one header, one version scheme) or a
//! recording, saved through [`atomic_file`], so a failed save leaves the old file as it
//! was.
//!
//! # References
//!
//! Three papers are behind the science; the docs name them by these short names.
//!
//! - **\[iir\] the IIR paper**: P. Fortin, M. J.-D. Otis, V. Duchaine, *Event-based haptic
//!   vibration synthesis using a recursive filter for lower limb prosthetics*. Strike
//!   conditioning ([`signal::savgol`], [`signal::butterworth`], [`recording`]), the
//!   measured response ([`analysis`]), the IIR fit with its order chosen by NRMSE
//!   ([`fit`]), force-driven playback with numerator noise at every step
//!   ([`synthesis::voice`]), and the physical impact model it compares with
//!   ([`physical`]).
//! - **\[tile\] the tile paper**: Y. Visell et al., *A Vibrotactile Device for Display of
//!   Virtual Ground Materials in Walking*. The drive from the falling rate of force
//!   ([`force`]), the stochastic model of aggregates ([`physical`]), and its parameters
//!   estimated by linear prediction and wavelet analysis
//!   ([`physical::estimate`](mod@physical::estimate), [`fit::lpc`], [`signal::wavelet`]).
//! - **\[limb\] the compensation paper**: *Modeling of Lower Limbs for Vibrotactile
//!   Compensation*. The device's response from frequency sweeps, the filter-bank
//!   equalizer, the rheological limb model fitted per user and the table of users
//!   ([`compensation`]).
//!
//! Where a paper is loose (units, signs, what "order" means), the module that implements
//! it says what was chosen and why.
//!
//! [iir]: #references
//! [tile]: #references
//! [limb]: #references
//!
//! # Vocabulary
//!
//! A few words mean one thing each here.
//!
//! - **calibrate**: measure a physical device so that its readings or its output can be
//!   trusted: a force sensor's curve from known loads ([`force::calibration`]), a tile's
//!   response from sweeps and the equalizer that flattens it, a user's limb
//!   ([`compensation`]; the command line's `calibrate` subcommands).
//! - **estimate**: find a physical model's parameters from recordings
//!   ([`physical::estimate`](mod@physical::estimate)).
//! - **fit**: find a filter (or a curve) that matches measured data ([`fit`]).
//! - **normalise**: set a drive's gain from a nominal step, so every material is played
//!   at the level it was recorded at ([`synthesis`]).
//! - **voice**: what plays one channel's material ([`synthesis::voice`]); a physical
//!   aggregate's concurrent micro-impacts are *impacts*, not voices.
//! - **channel**: one actuator with its own force sensors: a tile, or one foot.
//! - **strike**: a heel strike in a recording; **step**: a heel strike detected in force
//!   readings while playing.
//!
//! # Firmware (`no_std`)
//!
//! With default features off (`cargo build -p underfoot --no-default-features`) the
//! crate is `#![no_std]` and keeps what a microcontroller needs to play a material:
//! [`units`], the seeded noise generator ([`signal::noise`]), second-order-section
//! cascades in `f32`, Q15 and Q31 ([`signal::fixed`], the same arithmetic as the C
//! reference that [`export`] writes), and the hard [`safety`] limiter. Math functions go
//! through [`math`]: `libm` without std, std's own methods with it (so renders made
//! with std do not change by a bit). No embedded target is installed on the build
//! machines, so the proof that it builds without std is the host build of the
//! `#![no_std]` crate, in CI next to its clippy run.
//!
//! # Quick start
//!
//! Fit a material from recordings of heel strikes on it, then keep it in a library file.
//! Here the "recording" is made up: two strikes on a floor that rings at 120 Hz.
//!
//! ```
//! use underfoot::material::build::{build_material, BuildConfig};
//! use underfoot::material::Library;
//! use underfoot::recording::Recording;
//! use underfoot::signal::noise::SplitMix64;
//! use underfoot::units::{Hz, SampleRate};
//!
//! let rate = SampleRate(8000);
//! let mut noise = SplitMix64::new(1);
//! let mut samples: Vec<f64> = (0..16_000).map(|_| 1e-4 * noise.symmetric()).collect();
//! for onset in [2_000, 10_000] {
//!     for n in 0..3_000 {
//!         let t = n as f64 / 8000.0;
//!         samples[onset + n] += (-t / 0.05).exp() * (std::f64::consts::TAU * 120.0 * t).sin();
//!     }
//! }
//! // Real recordings come from `underfoot::recording::read(path, None)`.
//! let floor = Recording { name: "floor.wav".into(), rate, samples, sha256: String::new(), excerpt: None };
//!
//! // Conditioning, strike detection, the measured response and the order search,
//! // with the defaults: 2 kHz analysis rate, 20-900 Hz band, order up to 16.
//! let model = build_material("floor", &[floor], &BuildConfig::default(), &mut |_| {})?;
//! assert_eq!(model.fit.strikes, 2);
//! assert!(model.fit.lsd_db < 1.0);
//!
//! // The filter runs as second-order sections; it rings where the floor does.
//! let filter = model.sos().expect("a fitted model has sections");
//! assert!(filter.is_stable());
//! let gain = |f: f64| filter.response(model.sample_rate.omega(Hz(f))).norm();
//! assert!(gain(120.0) > 10.0 * gain(500.0));
//!
//! // A library file holds many materials; `save` replaces the file atomically.
//! let mut library = Library::new();
//! library.upsert(model);
//! let json = library.to_json();
//! assert!(json.contains("underfoot.library/3"));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # Playing a material
//!
//! The engine turns force into vibration. Prepare a bank of materials for the audio rate
//! (off the audio thread), build the engine, move its audio half into the device callback,
//! and send force readings from anywhere else. Here, offline: one heel strike on the
//! built-in gravel, at 48 kHz.
//!
//! ```
//! use underfoot::engine::{self, EngineConfig, Event, MaterialBank, TimedEvent};
//! use underfoot::force::SensorReading;
//! use underfoot::force::gait::nominal_step;
//! use underfoot::material::builtin::builtin;
//! use underfoot::synthesis::VoiceConfig;
//! use underfoot::units::{Newtons, SampleRate};
//!
//! let rate = SampleRate(48_000);
//! let bank = MaterialBank::prepare(
//!     builtin(),
//!     rate,
//!     &VoiceConfig::default(),
//!     &nominal_step(70.0, 1.8, rate.hz()), // calibrates the force drives
//!     Newtons::weight_of(70.0),
//! )?;
//! let gravel = bank.slot("gravel")?;
//! let config = EngineConfig { rate, ..EngineConfig::default() };
//! let (mut controller, mut engine) = engine::build(&config, bank, &[gravel])?;
//!
//! // The foot comes down: the total force rises through the step threshold (60 N).
//! for (frame, newtons) in [(0, 0.0), (96, 20.0), (192, 240.0)] {
//!     let reading = SensorReading::new(&[newtons * 0.7, newtons * 0.3]).unwrap(); // heel, toe
//!     controller.send(TimedEvent::at(frame, Event::Force { channel: 0, reading }))?;
//! }
//! // The audio callback: render into the buffer given, never allocating.
//! let mut buffer = vec![0.0f32; 4800];
//! for block in buffer.chunks_mut(64) {
//!     engine.process(block, 1);
//! }
//! // The strike sounds from the sample of the reading that crossed the threshold.
//! assert!(buffer[..192].iter().all(|v| *v == 0.0));
//! assert!(buffer[192] != 0.0);
//! assert_eq!(controller.telemetry().strikes, 1);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![cfg_attr(not(feature = "std"), no_std)]

// The pipeline proper needs the standard library (files, threads, heap, linear algebra);
// the firmware core below it does not. The gate is here, once, not inside the modules.
#[cfg(feature = "std")]
pub mod analysis;
#[cfg(feature = "std")]
pub mod atomic_file;
#[cfg(feature = "std")]
pub mod compensation;
#[cfg(feature = "std")]
pub mod document;
#[cfg(feature = "std")]
pub mod engine;
#[cfg(feature = "std")]
pub mod excitation;
#[cfg(feature = "std")]
pub mod export;
#[cfg(feature = "std")]
pub mod fit;
#[cfg(feature = "std")]
pub mod force;
#[cfg(feature = "std")]
#[doc(hidden)]
pub mod fuzzing;
#[cfg(feature = "std")]
pub mod interface;
#[cfg(feature = "std")]
pub mod io;
#[cfg(feature = "std")]
pub mod limits;
// A session opens every kind of input and output, so it needs their features too.
#[cfg(all(
    feature = "std",
    feature = "replay",
    feature = "serial",
    feature = "osc",
    feature = "wav"
))]
pub mod live;
#[cfg(feature = "std")]
pub mod material;
#[cfg(feature = "std")]
pub mod numeric;
#[cfg(feature = "std")]
pub mod physical;
#[cfg(feature = "std")]
pub mod recording;
#[cfg(feature = "std")]
pub mod sim;
#[cfg(feature = "std")]
pub mod synthesis;

pub mod math;
pub mod safety;
pub mod signal;
pub mod units;
