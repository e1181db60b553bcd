//! Simulators: stand-ins for the hardware and the people the production paths serve.
//!
//! Nothing here is a production path. These exist so that tests, examples and the
//! command line's `--device simulated` can exercise the real code end to end without a
//! tile, a prosthesis, a sound card or a person: a device with a known response, a user
//! with a known limb, a board speaking the sensor protocol, an audio loop.
//!
//! | simulator | file | stands in for |
//! |---|---|---|
//! | [`SimulatedTile`], [`TileConfig`], [`TileResonance`] | `tile.rs` | a floor tile on its suspension with an actuator and an accelerometer, for the [compensation](crate::compensation) sweeps |
//! | [`SimulatedUser`] | `user.rs` | a person standing on that tile: the compensation's limb model ahead of it |
//!
//! Layer: at the top of the crate, beside the fuzzing harness; no production module
//! depends on it.

mod tile;
mod user;

pub use tile::{SimulatedTile, TileConfig, TileResonance};
pub use user::SimulatedUser;
