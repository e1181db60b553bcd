//! The library's integration tests, in one binary: one link instead of one per file.
//!
//! Each module is one contract (a file of its own before they were gathered here). The
//! tests with a counting global allocator (`realtime`, `fuzz`, `audio_device`) stay
//! binaries of their own, since an allocator is per binary.
//!
//! Tiers: the default run is the fast tier. Tests marked
//! `#[ignore = "slow tier: ..."]` (real recordings, refits, real-time pacing) run with
//! `cargo test --workspace -- --include-ignored`, which is what CI runs.

#[path = "../common/mod.rs"]
mod common;

mod builtin;
mod compensation;
mod conditioning;
mod engine;
mod excitation;
mod firmware;
mod fit_oracle;
mod hardware_guide;
mod layers;
mod live_offline;
mod long_recording;
mod physical;
mod quality;
mod real_data;
mod recording;
mod serial_link;
mod signal;
mod silence;
mod walk;
