//! What every test of the binary needs: the binary, a run of it, its output as text.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binary under test; `UNDERFOOT_TEST_BIN` points these tests at another build
/// (e.g. main's, to see each of them fail there).
pub fn bin() -> PathBuf {
    std::env::var_os("UNDERFOOT_TEST_BIN").map_or_else(
        || PathBuf::from(env!("CARGO_BIN_EXE_underfoot")),
        PathBuf::from,
    )
}

/// Runs the binary with `args` to completion. The fit plot looks for fonts; an empty
/// `UNDERFOOT_FONT` keeps the tests independent of the machine's fonts.
pub fn run(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .env("UNDERFOOT_FONT", "")
        .output()
        .expect("run underfoot")
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Asserts that the run succeeded, showing its status and output if not.
pub fn assert_ok(o: &Output) {
    assert!(
        o.status.success(),
        "exit {:?}\nstdout: {}\nstderr: {}",
        o.status.code(),
        stdout(o),
        stderr(o)
    );
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}
