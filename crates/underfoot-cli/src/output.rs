//! Writing results to stdout.

use std::io::{self, Write};

/// Writes `text` to stdout.
///
/// A closed pipe (`underfoot library list | head -1`) is not an error worth reporting:
/// the reader has what it wanted. Other write errors are.
pub fn emit(text: &str) -> anyhow::Result<()> {
    let mut out = io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}
