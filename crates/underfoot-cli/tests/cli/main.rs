//! The command line's tests, in one binary: each module runs the `underfoot` binary as a
//! user would and checks what it prints and writes.
//!
//! `UNDERFOOT_TEST_BIN` points them at another build of the binary (main's, say, to see
//! a new test fail there first).

mod common;

mod bounds;
mod calibrate_cmd;
mod compare_cmd;
mod demo_cmd;
mod export_cmd;
mod figures;
mod files;
mod fit_cmd;
mod library_cmd;
mod live_offline;
#[cfg(feature = "lsl")]
mod lsl_streams;
#[cfg(feature = "panel")]
mod panel_browser;
#[cfg(feature = "panel")]
mod panel_cmd;
mod readme;
mod render_cmd;
mod run_cmd;
mod serial_link;
mod session_record;
mod silence;
mod step_stats;
mod steps_in_time;
