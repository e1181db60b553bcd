//! The files this process has read, kept where they are read (see
//! [`crate::atomic_file`], *Inputs*, for what the output policy does with them).

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard};

/// A file's device, inode and change time: the time tells a file from a later one that
/// reuses a deleted file's inode (a long-running panel reads uploads, then removes them).
pub type FileId = (u64, u64, i64, i64);

#[cfg(unix)]
fn id_of(meta: &fs::Metadata) -> Option<FileId> {
    use std::os::unix::fs::MetadataExt;
    meta.is_file()
        .then(|| (meta.dev(), meta.ino(), meta.ctime(), meta.ctime_nsec()))
}

/// Without file identities every file would look the same: nothing is noted, and the
/// commands' own lists of inputs are the only check.
#[cfg(not(unix))]
fn id_of(_: &fs::Metadata) -> Option<FileId> {
    None
}

/// Whether reads are noted: a program's choice
/// ([`crate::atomic_file::refuse_outputs_over_reads`]).
static ENABLED: AtomicBool = AtomicBool::new(false);

struct Reads {
    read: BTreeSet<FileId>,
    /// Files under an edit lock of this process, with how many locks: their edit reads
    /// and replaces them.
    editing: BTreeMap<FileId, usize>,
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

/// From now on, reads are noted.
pub(crate) fn track() {
    ENABLED.store(true, Ordering::SeqCst);
}

/// Notes that this process read the file of `meta` (a regular file; anything else, a
/// device or a pipe, is never replaced anyway). Called by [`super::read_capped`], the
/// crate's one reader, and by the streaming readers.
pub fn note_read(meta: &fs::Metadata) {
    if !ENABLED.load(Ordering::Relaxed) {
        return;
    }
    if let Some(id) = id_of(meta) {
        reads().read.insert(id);
    }
}

/// Whether `target` is a regular file this process has read and holds no edit lock on.
pub(crate) fn was_read(target: &Path) -> bool {
    if !ENABLED.load(Ordering::Relaxed) {
        return false;
    }
    let Some(id) = fs::metadata(target).ok().as_ref().and_then(id_of) else {
        return false;
    };
    let reads = reads();
    reads.read.contains(&id) && !reads.editing.contains_key(&id)
}

/// Marks `target` (if it is a file) as edited under a lock of this process; the
/// returned identity ends it ([`end_edit`]).
pub(crate) fn begin_edit(target: &Path) -> Option<FileId> {
    let id = id_of(&fs::metadata(target).ok()?)?;
    *reads().editing.entry(id).or_insert(0) += 1;
    Some(id)
}

/// Ends an edit [`begin_edit`] marked.
pub(crate) fn end_edit(id: FileId) {
    let mut reads = reads();
    if let Some(n) = reads.editing.get_mut(&id) {
        *n -= 1;
        if *n == 0 {
            reads.editing.remove(&id);
        }
    }
}
