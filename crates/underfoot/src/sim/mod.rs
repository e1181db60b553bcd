//! Simulators: stand-ins for the hardware and the people the production paths serve.
//!
//! Nothing here is a production path. These exist so that tests, examples and the
//! command line's `--device simulated` can exercise the real code end to end without a
//! tile, a prosthesis, a sound card or a person: a device with a known response, a user
//! with a known limb, a board speaking the sensor protocol, an audio loop.
//!
//! Layer: at the top of the crate, beside the fuzzing harness; no production module
//! depends on it.
