//! The files this process has read, which no output may replace (see the module docs,
//! *Inputs*).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::AtomicBool;
use std::sync::{Mutex, MutexGuard};

use super::*;

/// A file's device, inode and change time: the time tells a file from a later one that
/// reuses a deleted file's inode (a long-running panel reads uploads, then removes them).
pub(super) type Id = (u64, u64, i64, i64);

#[cfg(unix)]
fn id_of(meta: &fs::Metadata) -> Option<Id> {
    use std::os::unix::fs::MetadataExt;
    meta.is_file()
        .then(|| (meta.dev(), meta.ino(), meta.ctime(), meta.ctime_nsec()))
}

/// Without file identities every file would look the same: nothing is noted, and the
/// commands' own lists of inputs are the only check.
#[cfg(not(unix))]
fn id_of(_: &fs::Metadata) -> Option<Id> {
    None
}

/// Whether reads are noted and refused as outputs: a program's choice
/// ([`refuse_outputs_over_reads`]), because a library user's `load` then `save` of one
/// file is an edit the crate cannot tell from a mistake.
static ENABLED: AtomicBool = AtomicBool::new(false);

/// From now on, this process notes every file the crate reads and refuses to replace
/// one ([`OutputFile::check`] and [`OutputFile::persist`]), except under an
/// [`EditLock`]: what a command-line program wants (the `underfoot` CLI turns it on
/// first thing).
pub fn refuse_outputs_over_reads() {
    ENABLED.store(true, Ordering::SeqCst);
}

struct Reads {
    read: BTreeSet<Id>,
    /// Files under an edit lock of this process, with how many locks: their edit reads
    /// and replaces them.
    editing: BTreeMap<Id, usize>,
}

static READS: Mutex<Reads> = Mutex::new(Reads {
    read: BTreeSet::new(),
    editing: BTreeMap::new(),
});

fn reads() -> MutexGuard<'static, Reads> {
    // The sets stay consistent whatever panicked while they were held.
    READS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Notes that this process read the file of `meta` (a regular file; anything else, a
/// device or a pipe, is never replaced anyway). Called by the crate's one reader,
/// [`crate::limits::read_capped`], and by the streaming readers.
pub fn note_read(meta: &fs::Metadata) {
    if !ENABLED.load(Ordering::Relaxed) {
        return;
    }
    if let Some(id) = id_of(meta) {
        reads().read.insert(id);
    }
}

/// Whether `target` is a regular file this process has read and holds no edit lock on.
fn was_read(target: &Path) -> bool {
    if !ENABLED.load(Ordering::Relaxed) {
        return false;
    }
    let Some(id) = fs::metadata(target).ok().as_ref().and_then(id_of) else {
        return false;
    };
    let reads = reads();
    reads.read.contains(&id) && !reads.editing.contains_key(&id)
}

/// Refuses `target` if this process has read it (and is not editing it).
pub(super) fn check_not_read(given: &Path, target: &Path) -> Result<(), AtomicWriteError> {
    if was_read(target) {
        return Err(refuse(
            given,
            std::io::ErrorKind::InvalidInput,
            "it is a file this command has read (one of its inputs); choose another output".into(),
        ));
    }
    Ok(())
}

/// Marks `target` (if it is a file) as edited under a lock of this process; the
/// returned identity ends it ([`end_edit`]).
pub(super) fn begin_edit(target: &Path) -> Option<Id> {
    let id = id_of(&fs::metadata(target).ok()?)?;
    *reads().editing.entry(id).or_insert(0) += 1;
    Some(id)
}

/// Ends an edit [`begin_edit`] marked.
pub(super) fn end_edit(id: Id) {
    let mut reads = reads();
    if let Some(n) = reads.editing.get_mut(&id) {
        *n -= 1;
        if *n == 0 {
            reads.editing.remove(&id);
        }
    }
}
