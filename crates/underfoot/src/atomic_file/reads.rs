//! The output policy's side of the registry of reads that [`crate::limits`] keeps (see
//! the module docs, *Inputs*).

use super::*;

/// From now on, this process notes every file the crate reads and refuses to replace
/// one ([`OutputFile::persist`]), except under an [`EditLock`]: what a command-line
/// program wants (the `underfoot` CLI turns it on first thing). Not the default, because
/// a library user's `load` then `save` of one file is an edit the crate cannot tell from
/// a mistake.
pub fn refuse_outputs_over_reads() {
    crate::limits::reads::track();
}

/// Refuses `target` if this process has read it (and is not editing it).
pub(super) fn check_not_read(given: &Path, target: &Path) -> Result<(), AtomicWriteError> {
    if crate::limits::reads::was_read(target) {
        return Err(refuse(
            given,
            std::io::ErrorKind::InvalidInput,
            "it is a file this command has read (one of its inputs); choose another output".into(),
        ));
    }
    Ok(())
}
