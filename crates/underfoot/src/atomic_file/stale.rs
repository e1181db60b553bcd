//! Leftovers of writers that were killed (see the module docs, *Leftovers*).

use super::*;

/// Removes what killed writers of `target` left beside it: temporary files
/// (`.tmp-PID-N.NAME`) whose process is gone, and an edit lock (`.NAME.lock`) that no one
/// holds. Best effort and conservative: a file whose owner may be alive, or that cannot be
/// looked at, stays; a partial live recording (`STEM.partial-PID.EXT`) is the user's data
/// and always stays.
pub(super) fn remove_stale(target: &Path) {
    let Some(name) = target.file_name().map(|n| n.to_string_lossy().into_owned()) else {
        return;
    };
    let dir = parent_dir(target);
    let Ok(entries) = fs::read_dir(&dir) else {
        return;
    };
    let own = std::process::id();
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(pid) = temporary_owner(&file.to_string_lossy(), &name) else {
            continue;
        };
        if pid != own && process_is_gone(pid) {
            let _ = fs::remove_file(entry.path());
        }
    }
    remove_unheld_lock(&dir.join(format!(".{name}.lock")));
}

/// How a temporary file's name begins: `.tmp-PID-N.NAME`.
const TEMPORARY: &str = ".tmp-";

/// The name of writer `pid`'s `n`th temporary file for the target `name`:
/// `.tmp-PID-N.NAME`, which [`temporary_owner`] reads back.
pub(super) fn temporary_name(pid: u32, n: u64, name: &str) -> String {
    format!("{TEMPORARY}{pid}-{n}.{name}")
}

/// The pid in a temporary file's name `.tmp-PID-N.NAME` for the target `NAME`
/// ([`temporary_name`]).
fn temporary_owner(file: &str, name: &str) -> Option<u32> {
    let rest = file
        .strip_prefix(TEMPORARY)?
        .strip_suffix(name)?
        .strip_suffix('.')?;
    let (pid, counter) = rest.split_once('-')?;
    counter.parse::<u64>().ok()?;
    pid.parse().ok()
}

/// Whether no process has `pid`: only where `/proc` says so (Linux). Elsewhere, or if
/// `/proc` is not mounted, every owner counts as alive, so that what it left is kept.
#[must_use]
pub fn process_is_gone(pid: u32) -> bool {
    let proc = Path::new("/proc");
    proc.join("self").exists() && !proc.join(pid.to_string()).exists()
}

/// Removes a lock file no one holds, under the lock itself: the protocol of
/// [`EditLock`]'s release, so a process that waited on this inode starts again.
fn remove_unheld_lock(path: &Path) {
    if !cfg!(unix) {
        return;
    }
    let Ok(file) = fs::OpenOptions::new().read(true).write(true).open(path) else {
        return;
    };
    if fs4::FileExt::try_lock(&file).is_err() {
        return;
    }
    let same = match (file.metadata(), fs::metadata(path)) {
        (Ok(held), Ok(now)) => identity(&held) == identity(&now),
        _ => false,
    };
    if same {
        let _ = fs::remove_file(path);
    }
    let _ = fs4::FileExt::unlock(&file);
}

#[cfg(test)]
mod round_trip {
    use super::*;

    #[test]
    fn a_temporary_name_reads_back_its_owner() {
        let name = temporary_name(4242, 17, "lab.json");
        assert_eq!(name, ".tmp-4242-17.lab.json");
        assert_eq!(temporary_owner(&name, "lab.json"), Some(4242));
        assert_eq!(temporary_owner(&name, "other.json"), None);
    }
}
