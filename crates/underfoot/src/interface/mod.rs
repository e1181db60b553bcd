//! The prosthetic-skin interface, as pure logic: an insole with force sensors under the
//! prosthetic foot (heel, midfoot, toe), servos that press those points on the residual
//! limb, and vibration channels (piezo discs) driven by the same force through the engine.
//!
//! | module | what it does |
//! |---|---|
//! | [`servo`] | insole force to servo pulse widths: range, dead band, rate limit, calibration, input timeout |
//! | [`config`] | the `prosthetic.toml` file: sensors and their scales, servos, vibration channels, link |
//!
//! Nothing here does I/O or needs a cargo feature. The serial link to the interface's
//! board (the servo-target frame and the host loop) is in `io::serial` and
//! `io::prosthetic`, behind the `serial` feature; the simulated foot is in `sim`.
pub mod config;
pub mod servo;
