//! Simulators: stand-ins for the hardware and the people the production paths serve.
//!
//! Nothing here is a production path. These exist so that tests, examples and the
//! command line's `--device-under-test simulated` can exercise the real code end to end without a
//! tile, a prosthesis, a sound card or a person: a device with a known response, a user
//! with a known limb, a board speaking the sensor protocol, and the prosthetic interface's board.
//!
//! | simulator | file | stands in for |
//! |---|---|---|
//! | [`SimulatedTile`], [`TileConfig`], [`TileResonance`] | `tile.rs` | a floor tile on its suspension with an actuator and an accelerometer, for the [compensation](crate::compensation) sweeps |
//! | [`SimulatedUser`] | `user.rs` | a person standing on that tile: the compensation's limb model ahead of it |
//! | [`ReferenceSender`] | [`sensor_board`] | a sensor board's firmware: force frames of the serial protocol, written to any port |
//! | [`SimulatedFoot`] | [`prosthetic_board`] | the prosthetic-skin interface's board: an insole under one walking foot, and servos that follow the host's frames; [`open_interface`] runs it on a pseudo-terminal |
//!
//! Layer: above every stage it stands in for (it drives the real compensation, serial
//! and interface code); only [`live`](crate::live), the composition of a running
//! session, may use it, to run an interface whose configuration names a simulated link.

#[cfg(feature = "serial")]
pub mod prosthetic_board;
#[cfg(feature = "serial")]
pub mod sensor_board;
mod tile;
mod user;

#[cfg(feature = "serial")]
pub use prosthetic_board::{SimulatedFoot, SimulatedReport, SimulatorHandle, open_interface};
#[cfg(feature = "serial")]
pub use sensor_board::ReferenceSender;
pub use tile::{SimulatedTile, TileConfig, TileResonance};
pub use user::SimulatedUser;
