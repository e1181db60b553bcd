//! The output policy: no command ever damages a file it was not asked to write.
//!
//! Files are replaced, never overwritten in place: a save that fails half-way (a full
//! disk, a killed process, a power cut) must leave the previous file as it was, because
//! that file may be the only calibration of a user's prosthesis or a library that took
//! an afternoon of recordings.
//!
//! # The policy
//!
//! Every file a command writes goes through an [`OutputFile`], made by
//! [`OutputFile::check`] *before anything is written* (a command checks all its outputs,
//! then computes, then writes). The check:
//!
//! 1. **follows symlinks** to the file they name, so the save replaces the target and the
//!    link stays a link (relative links are resolved from the link's own folder; more
//!    than [`MAX_LINKS`] links in a chain is refused as a loop);
//! 2. **refuses anything but a regular file**: a directory, a character or block device,
//!    a FIFO, a socket. A rename would silently turn `/dev/null` into a file holding the
//!    output; a user who wants standard output says `-`, which only text outputs accept
//!    ([`OutputFile::check_or_stdout`]: `export --out`, `compare --json`); binary WAV and
//!    plot outputs need a file;
//! 3. **refuses a read-only file** (no write permission bit, or the open for writing is
//!    denied): replacing it because its *folder* is writable would defeat the user's
//!    `chmod a-w`;
//! 4. **refuses any file the same command reads**: an input is the same file when it has
//!    the same device and inode (hard links, symlinks, `./a` and `a` all agree), or, when
//!    the output does not exist yet, the same canonical path;
//! 5. refuses two outputs of one command naming the same file ([`OutputFile::check_all`]).
//!
//! Refusals are [`AtomicWriteError`]s with [`REFUSED`] as their action, naming the path
//! given and the reason.
//!
//! # Writing
//!
//! [`OutputFile::write`] writes a temporary file in the resolved target's directory,
//! flushes it to disk and renames it over the target: same directory, so the rename
//! stays on one file system and is atomic. The file type is looked at once more just
//! before the rename, which narrows (it cannot close) the window in which another
//! process could put a device there. Streaming writers (a WAV file) use
//! [`OutputFile::create_temporary`] and [`OutputFile::persist`] instead.
//!
//! # Editing a file in place: the lock
//!
//! A read-modify-write (adding a material to a library) by two processes at once loses
//! one of the edits unless the read and the write happen under one lock. Locking the
//! file itself does not work with rename: the first writer's rename puts a *new* inode
//! under the name, so the second process, which waited on the old inode, gets a lock
//! nobody else will ever contend for and reads a file that is already stale.
//! [`OutputFile::lock`] therefore locks a separate, never-renamed lock file next to the
//! resolved target (`.NAME.lock`, an advisory `flock` through `fs4`), and the caller
//! reads, edits and writes while it holds the [`EditLock`]. So that no lock file is left
//! beside the user's library, the holder removes it *while still holding the lock*; a
//! process that was waiting on the removed inode then finds, once it gets the lock,
//! that the name no longer leads to the inode it locked (device and inode compared), and
//! starts again with a new file. Links to one file share one lock because the lock sits
//! next to the resolved target. Only cooperating processes (this crate) are kept out; an
//! editor is not.

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The [`AtomicWriteError::action`] of a file the policy refuses to write.
pub const REFUSED: &str = "refusing to write";

/// Longest chain of symlinks followed before the path is refused as a loop (Linux's own
/// limit).
pub const MAX_LINKS: usize = 40;

/// A file could not be read or written, or the policy refused it; a file that was there
/// is untouched. The one file error of the crate: every stage's error wraps it rather
/// than repeating its fields.
///
/// Its message is the action and the path; the reason is its [source](std::error::Error::source)
/// (so a chain printed as `{:#}` says it once).
#[derive(Debug, thiserror::Error)]
#[error("{action} {}", path.display())]
pub struct FileError {
    /// The file (or the temporary file next to it).
    pub path: PathBuf,
    /// The step that failed, e.g. `renaming the temporary file over it`, or [`REFUSED`].
    pub action: &'static str,
    /// The underlying error (for a refusal, the reason).
    #[source]
    pub source: std::io::Error,
}

/// The name this error had when only writes used it.
pub type AtomicWriteError = FileError;

impl FileError {
    /// Whether the policy refused the file (as opposed to a failed write).
    #[must_use]
    pub fn is_refusal(&self) -> bool {
        self.action == REFUSED
    }
}

fn io(p: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> AtomicWriteError {
    let p = p.to_path_buf();
    move |source| AtomicWriteError {
        path: p,
        action,
        source,
    }
}

fn refuse(path: &Path, kind: std::io::ErrorKind, reason: String) -> AtomicWriteError {
    AtomicWriteError {
        path: path.to_path_buf(),
        action: REFUSED,
        source: std::io::Error::new(kind, reason),
    }
}

/// Where an [`OutputFile`] goes.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Target {
    /// A regular file (existing or not), symlinks resolved.
    File(PathBuf),
    /// `-`: standard output.
    Stdout,
}

/// An output that passed the policy's checks; see the [module docs](self).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutputFile {
    /// As the user named it (for messages).
    given: PathBuf,
    target: Target,
}

impl OutputFile {
    /// Checks `path` as an output of a command that reads `inputs`.
    ///
    /// # Errors
    /// A refusal ([`REFUSED`]) naming `path` and the reason: a device, FIFO, socket or
    /// directory, a read-only file, one of `inputs`, a symlink loop, `-`, a path without
    /// a file name. An I/O error if the path cannot be looked at.
    pub fn check(path: &Path, inputs: &[&Path]) -> Result<Self, AtomicWriteError> {
        if path.as_os_str() == "-" {
            return Err(refuse(
                path,
                std::io::ErrorKind::InvalidInput,
                "this output cannot go to standard output; name a file".into(),
            ));
        }
        let target = resolve(path)?;
        if target.file_name().is_none() || path.file_name().is_none() {
            return Err(refuse(
                path,
                std::io::ErrorKind::InvalidInput,
                "the path does not name a file".into(),
            ));
        }
        // A missing folder would only show when the temporary file is created, after
        // the command's work: say so now.
        let dir = parent_dir(&target);
        if !dir.is_dir() {
            return Err(refuse(
                path,
                std::io::ErrorKind::NotFound,
                format!("the folder {} does not exist", dir.display()),
            ));
        }
        check_kind(path, &target)?;
        check_not_input(path, &target, inputs)?;
        Ok(Self {
            given: path.to_path_buf(),
            target: Target::File(target),
        })
    }

    /// Like [`check`](Self::check), but `-` means standard output: for text outputs a
    /// user may want to pipe.
    ///
    /// # Errors
    /// As [`check`](Self::check).
    pub fn check_or_stdout(path: &Path, inputs: &[&Path]) -> Result<Self, AtomicWriteError> {
        if path.as_os_str() == "-" {
            return Ok(Self {
                given: path.to_path_buf(),
                target: Target::Stdout,
            });
        }
        Self::check(path, inputs)
    }

    /// Checks every output of a command at once: each as [`check`](Self::check), and no
    /// two naming the same file.
    ///
    /// # Errors
    /// The first refusal.
    pub fn check_all(outputs: &[&Path], inputs: &[&Path]) -> Result<Vec<Self>, AtomicWriteError> {
        let mut checked: Vec<Self> = Vec::with_capacity(outputs.len());
        for path in outputs {
            let out = Self::check(path, inputs)?;
            for earlier in &checked {
                out.distinct_from(earlier)?;
            }
            checked.push(out);
        }
        Ok(checked)
    }

    /// Refuses `self` if it is the same file as `other` (two outputs of one command).
    ///
    /// # Errors
    /// A refusal naming `self`'s path.
    pub fn distinct_from(&self, other: &Self) -> Result<(), AtomicWriteError> {
        if self.same_file_as(other) {
            return Err(refuse(
                &self.given,
                std::io::ErrorKind::InvalidInput,
                format!(
                    "it is the same file as another output of this command ({})",
                    other.given.display()
                ),
            ));
        }
        Ok(())
    }

    fn same_file_as(&self, other: &Self) -> bool {
        match (&self.target, &other.target) {
            (Target::File(a), Target::File(b)) => canonical(a) == canonical(b),
            _ => false,
        }
    }

    /// The path as given.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.given
    }

    /// The file that will be replaced (symlinks resolved); `-` for standard output.
    #[must_use]
    pub fn target(&self) -> &Path {
        match &self.target {
            Target::File(p) => p,
            Target::Stdout => Path::new("-"),
        }
    }

    /// Whether this output is standard output.
    #[must_use]
    pub fn is_stdout(&self) -> bool {
        self.target == Target::Stdout
    }

    /// Writes `contents` atomically: a temporary file next to the target, flushed to
    /// disk, renamed over it. Permissions of a file being replaced are kept. On error the
    /// temporary file is removed and the target is untouched.
    ///
    /// # Errors
    /// [`AtomicWriteError`] naming the file and the step that failed.
    pub fn write(&self, contents: &[u8]) -> Result<(), AtomicWriteError> {
        if self.target == Target::Stdout {
            let mut out = std::io::stdout().lock();
            return out
                .write_all(contents)
                .and_then(|()| out.flush())
                .map_err(io(&self.given, "writing to standard output"));
        }
        let (tmp, mut f) = self.create_temporary()?;
        let result = f
            .write_all(contents)
            .map_err(io(&tmp, "writing the temporary file"))
            .and_then(|()| self.persist(&tmp, &f));
        drop(f);
        if result.is_err() {
            // Best effort: the error that matters is the one being returned.
            let _ = fs::remove_file(&tmp);
        }
        result
    }

    /// Creates a new, empty temporary file next to the target, for a streaming writer
    /// that [`persist`](Self::persist)s it when it is done (or removes it).
    ///
    /// # Errors
    /// [`AtomicWriteError`] if the file cannot be created (missing folder, no
    /// permission), or for standard output.
    pub fn create_temporary(&self) -> Result<(PathBuf, File), AtomicWriteError> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let Target::File(target) = &self.target else {
            return Err(refuse(
                &self.given,
                std::io::ErrorKind::InvalidInput,
                "standard output cannot be written through a temporary file".into(),
            ));
        };
        let dir = parent_dir(target);
        let name = target.file_name().unwrap_or_default().to_string_lossy();
        // pid and counter keep concurrent writers out of each other's way; the name ends
        // with the target's, so a writer that goes by the extension (plots) still can.
        let tmp = dir.join(format!(
            ".tmp-{}-{}.{name}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(io(&tmp, "creating a temporary file"))?;
        Ok((tmp, f))
    }

    /// For a writer that insists on creating the file itself from a path (a plotting
    /// library): `write` writes the temporary file at the path it is given (same
    /// extension as the target), which then replaces the target as in
    /// [`write`](Self::write). On error the temporary file is removed.
    ///
    /// # Errors
    /// `write`'s own, or the [`AtomicWriteError`] of the step that failed.
    pub fn write_with<T, E: From<AtomicWriteError>>(
        &self,
        write: impl FnOnce(&Path) -> Result<T, E>,
    ) -> Result<T, E> {
        let (tmp, f) = self.create_temporary()?;
        drop(f);
        let result = write(&tmp).and_then(|value| {
            let f = fs::OpenOptions::new()
                .write(true)
                .open(&tmp)
                .map_err(io(&tmp, "reopening the temporary file"))?;
            self.persist(&tmp, &f)?;
            Ok(value)
        });
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        result
    }

    /// Completes a temporary file from [`create_temporary`](Self::create_temporary):
    /// copies the permissions of the file it replaces, flushes `file` (the open
    /// temporary) to disk and renames it over the target. The caller removes the
    /// temporary on error.
    ///
    /// # Errors
    /// [`AtomicWriteError`] naming the step that failed, or a refusal if the target has
    /// become something the policy refuses since the check.
    pub fn persist(&self, tmp: &Path, file: &File) -> Result<(), AtomicWriteError> {
        self.persist_with(tmp, file, true)
    }

    /// [`persist`](Self::persist) without waiting for the disk: for a live recording,
    /// whose writer thread must keep pace with a device clock (an `fsync` on a busy disk
    /// can take longer than a buffer). The data are in the kernel, safe from a killed
    /// process; the writer flushes them to disk when it finishes.
    ///
    /// # Errors
    /// As [`persist`](Self::persist).
    pub fn persist_unsynced(&self, tmp: &Path, file: &File) -> Result<(), AtomicWriteError> {
        self.persist_with(tmp, file, false)
    }

    fn persist_with(&self, tmp: &Path, file: &File, sync: bool) -> Result<(), AtomicWriteError> {
        let target = self.target();
        if let Ok(meta) = fs::metadata(target) {
            file.set_permissions(meta.permissions())
                .map_err(io(tmp, "copying permissions to the temporary file"))?;
        }
        if sync {
            file.sync_all()
                .map_err(io(tmp, "flushing the temporary file to disk"))?;
        }
        // Once more just before the rename: the check may have been minutes ago (a fit).
        check_kind(&self.given, target)?;
        fs::rename(tmp, target).map_err(io(&self.given, "renaming the temporary file over it"))?;
        // Make the rename itself durable. Not every platform can open a directory; the
        // data is already safe in the file, so a failure here is not worth failing the save.
        if sync && let Ok(d) = File::open(parent_dir(target)) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// Takes the advisory edit lock of this file (see the module docs, *Editing a file
    /// in place*), waiting for another holder to release it.
    ///
    /// # Errors
    /// [`AtomicWriteError`] if the lock file cannot be created or locked.
    pub fn lock(&self) -> Result<EditLock, AtomicWriteError> {
        let target = self.target();
        let name = target.file_name().unwrap_or_default().to_string_lossy();
        let path = parent_dir(target).join(format!(".{name}.lock"));
        loop {
            let file = fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(io(&path, "creating the lock file"))?;
            fs4::FileExt::lock(&file).map_err(io(&path, "locking"))?;
            // The holder before us may have removed the file while we waited on it:
            // the lock counts only if the name still leads to the inode we locked.
            let held = file.metadata().map_err(io(&path, "locking"))?;
            match fs::metadata(&path) {
                Ok(now) if identity(&now) == identity(&held) => {
                    return Ok(EditLock { file, path });
                }
                _ => {}
            }
        }
    }
}

/// The edit lock of an [`OutputFile`], released when dropped.
#[derive(Debug)]
pub struct EditLock {
    file: File,
    path: PathBuf,
}

impl Drop for EditLock {
    fn drop(&mut self) {
        // Removed while still locked, so no one can lock this inode and believe it
        // current (see `OutputFile::lock`); the flock goes with the descriptor. Where
        // file identities are not available the file stays, which is always safe.
        if cfg!(unix) {
            let _ = fs::remove_file(&self.path);
        }
        let _ = fs4::FileExt::unlock(&self.file);
    }
}

/// Writes `contents` to `path` under the output policy of a command that reads nothing:
/// [`OutputFile::check`], then [`OutputFile::write`].
///
/// # Errors
/// [`AtomicWriteError`]: a refusal or the step that failed.
pub fn write_atomic(path: &Path, contents: &[u8]) -> Result<(), AtomicWriteError> {
    OutputFile::check(path, &[])?.write(contents)
}

fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Follows symlinks from `path` to the name that will be replaced (which may not exist).
fn resolve(path: &Path) -> Result<PathBuf, AtomicWriteError> {
    let mut p = path.to_path_buf();
    for _ in 0..=MAX_LINKS {
        match fs::symlink_metadata(&p) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let link = fs::read_link(&p).map_err(io(&p, "reading the symlink"))?;
                p = if link.is_absolute() {
                    link
                } else {
                    parent_dir(&p).join(link)
                };
            }
            Ok(_) => return Ok(p),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(p),
            Err(e) => return Err(io(path, "looking at the output")(e)),
        }
    }
    Err(refuse(
        path,
        std::io::ErrorKind::InvalidInput,
        format!("more than {MAX_LINKS} symlinks in a chain (a loop?)"),
    ))
}

/// Refuses an existing `target` that is not a writable regular file.
fn check_kind(given: &Path, target: &Path) -> Result<(), AtomicWriteError> {
    let meta = match fs::metadata(target) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(io(given, "looking at the output")(e)),
    };
    let ft = meta.file_type();
    let what = if ft.is_dir() {
        Some("a directory")
    } else if ft.is_file() {
        None
    } else {
        Some(special_kind(&ft))
    };
    if let Some(what) = what {
        let shown = if target == given {
            String::new()
        } else {
            format!(" (through the link, {})", target.display())
        };
        return Err(refuse(
            given,
            std::io::ErrorKind::InvalidInput,
            format!(
                "it is {what}{shown}; outputs are written to regular files only and never \
                 replace a device, FIFO, socket or directory (for standard output give `-` \
                 where the option accepts it: export --out, compare --json)"
            ),
        ));
    }
    // The permission bits first: as root, the open below succeeds on any file.
    let denied = meta.permissions().readonly()
        || matches!(
            fs::OpenOptions::new().write(true).open(target),
            Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied
        );
    if denied {
        return Err(refuse(
            given,
            std::io::ErrorKind::PermissionDenied,
            "the file is read-only; it is not replaced (make it writable, or choose another \
             file)"
                .into(),
        ));
    }
    Ok(())
}

#[cfg(unix)]
fn special_kind(ft: &fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if ft.is_char_device() {
        "a character device"
    } else if ft.is_block_device() {
        "a block device"
    } else if ft.is_fifo() {
        "a FIFO"
    } else if ft.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn special_kind(_: &fs::FileType) -> &'static str {
    "not a regular file"
}

/// The canonical form of a path that may not exist yet: its folder canonicalised, its
/// name appended.
fn canonical(path: &Path) -> PathBuf {
    if let Ok(p) = fs::canonicalize(path) {
        return p;
    }
    match (fs::canonicalize(parent_dir(path)), path.file_name()) {
        (Ok(dir), Some(name)) => dir.join(name),
        _ => path.to_path_buf(),
    }
}

#[cfg(unix)]
fn identity(meta: &fs::Metadata) -> (u64, u64) {
    use std::os::unix::fs::MetadataExt;
    (meta.dev(), meta.ino())
}

#[cfg(not(unix))]
fn identity(_: &fs::Metadata) -> (u64, u64) {
    (0, 0)
}

fn check_not_input(given: &Path, target: &Path, inputs: &[&Path]) -> Result<(), AtomicWriteError> {
    let target_meta = fs::metadata(target).ok();
    let target_canonical = canonical(target);
    for input in inputs {
        let same = match (&target_meta, fs::metadata(input)) {
            (Some(t), Ok(i)) if cfg!(unix) => identity(t) == identity(&i),
            _ => canonical(input) == target_canonical,
        };
        if same {
            return Err(refuse(
                given,
                std::io::ErrorKind::InvalidInput,
                format!(
                    "it is the same file as {}, which this command reads; choose another output",
                    input.display()
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn full(e: &AtomicWriteError) -> String {
        format!("{e}: {}", e.source)
    }

    #[test]
    fn replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.json");
        write_atomic(&path, b"old").unwrap();
        write_atomic(&path, b"new").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"new");
        let names: Vec<_> = fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "a temporary file was left behind");
    }

    #[test]
    fn a_directory_is_refused_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("target");
        fs::create_dir(&path).unwrap();
        fs::write(path.join("keep"), b"kept").unwrap();
        let e = write_atomic(&path, b"new").expect_err("a directory");
        assert!(e.is_refusal(), "{e}");
        assert!(full(&e).contains("a directory"), "{e}");
        assert_eq!(fs::read(path.join("keep")).unwrap(), b"kept");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_missing_folder_is_refused_at_the_check() {
        let dir = tempfile::tempdir().unwrap();
        let e = OutputFile::check(&dir.path().join("missing/a.json"), &[]).expect_err("no folder");
        assert!(
            e.is_refusal() && full(&e).contains("does not exist"),
            "{}",
            full(&e)
        );
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_names_the_step() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("sub");
        fs::create_dir(&sub).unwrap();
        let out = OutputFile::check(&sub.join("a.json"), &[]).unwrap();
        fs::remove_dir(&sub).unwrap();
        let e = out.write(b"new").expect_err("the folder went away");
        assert_eq!(e.action, "creating a temporary file");
    }

    #[cfg(unix)]
    #[test]
    fn keeps_the_permissions_of_the_file_it_replaces() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.json");
        fs::write(&path, b"old").unwrap();
        fs::set_permissions(&path, fs::Permissions::from_mode(0o640)).unwrap();
        write_atomic(&path, b"new").unwrap();
        assert_eq!(
            fs::metadata(&path).unwrap().permissions().mode() & 0o777,
            0o640
        );
    }

    #[test]
    fn a_path_without_a_file_name_is_refused() {
        let e = write_atomic(Path::new("/"), b"x").expect_err("no file name");
        assert!(e.is_refusal(), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn writes_through_a_symlink_and_keeps_the_link() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.json");
        fs::write(&real, b"old").unwrap();
        let sub = dir.path().join("sub");
        fs::create_dir(&sub).unwrap();
        // Relative, from the link's own folder; and a link to a link.
        std::os::unix::fs::symlink("../real.json", sub.join("link.json")).unwrap();
        std::os::unix::fs::symlink("sub/link.json", dir.path().join("link2.json")).unwrap();
        write_atomic(&dir.path().join("link2.json"), b"new").unwrap();
        assert_eq!(fs::read(&real).unwrap(), b"new");
        for link in [sub.join("link.json"), dir.path().join("link2.json")] {
            assert!(fs::symlink_metadata(&link).unwrap().is_symlink());
        }
        // A dangling link creates its target.
        std::os::unix::fs::symlink("made.json", dir.path().join("dangling.json")).unwrap();
        write_atomic(&dir.path().join("dangling.json"), b"made").unwrap();
        assert_eq!(fs::read(dir.path().join("made.json")).unwrap(), b"made");
        // A loop is refused.
        std::os::unix::fs::symlink("loop", dir.path().join("loop")).unwrap();
        assert!(
            write_atomic(&dir.path().join("loop"), b"x")
                .unwrap_err()
                .is_refusal()
        );
    }

    #[cfg(unix)]
    #[test]
    fn devices_fifos_and_links_to_them_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let link = dir.path().join("null.wav");
        std::os::unix::fs::symlink("/dev/null", &link).unwrap();
        let e = write_atomic(&link, b"x").unwrap_err();
        assert!(e.is_refusal(), "{e}");
        assert!(full(&e).contains("character device"), "{e}");
        assert!(full(&e).contains('-'), "{e}");
        assert!(fs::symlink_metadata(&link).unwrap().is_symlink());
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let e = write_atomic(&fifo, b"x").unwrap_err();
            assert!(full(&e).contains("FIFO"), "{e}");
        } else {
            eprintln!("skipped the FIFO case: mkfifo is not available");
        }
        // A socket.
        let sock = dir.path().join("sock");
        let _listener = std::os::unix::net::UnixListener::bind(&sock).unwrap();
        assert!(full(&write_atomic(&sock, b"x").unwrap_err()).contains("socket"));
    }

    #[cfg(unix)]
    #[test]
    fn a_read_only_file_is_refused_even_in_a_writable_folder() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lib.json");
        fs::write(&path, b"old").unwrap();
        fs::set_permissions(&path, fs::Permissions::from_mode(0o444)).unwrap();
        let e = write_atomic(&path, b"new").unwrap_err();
        assert!(e.is_refusal() && full(&e).contains("read-only"), "{e}");
        assert_eq!(fs::read(&path).unwrap(), b"old");
    }

    #[cfg(unix)]
    #[test]
    fn an_input_is_never_an_output() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.wav");
        fs::write(&input, b"recording").unwrap();
        // The same file by another name: a hard link, a symlink, a dotted path.
        fs::hard_link(&input, dir.path().join("hard.wav")).unwrap();
        std::os::unix::fs::symlink("in.wav", dir.path().join("soft.wav")).unwrap();
        for out in ["in.wav", "hard.wav", "soft.wav", "./sub/../in.wav"] {
            fs::create_dir_all(dir.path().join("sub")).unwrap();
            let e = OutputFile::check(&dir.path().join(out), &[&input]).unwrap_err();
            assert!(full(&e).contains("which this command reads"), "{out}: {e}");
        }
        // An input that does not exist yet, by canonical path.
        let ghost = dir.path().join("ghost.json");
        let dotted = dir.path().join("sub/../ghost.json");
        assert!(OutputFile::check(&dotted, &[&ghost]).is_err());
        assert!(OutputFile::check(&dir.path().join("other.wav"), &[&input]).is_ok());
        assert_eq!(fs::read(&input).unwrap(), b"recording");
        // Two outputs naming one file.
        let a = dir.path().join("a.json");
        let e = OutputFile::check_all(&[&a, &dir.path().join("sub/../a.json")], &[]).unwrap_err();
        assert!(full(&e).contains("another output"), "{e}");
    }

    #[test]
    fn dash_is_standard_output_only_where_accepted() {
        assert!(OutputFile::check(Path::new("-"), &[]).is_err());
        assert!(
            OutputFile::check_or_stdout(Path::new("-"), &[])
                .unwrap()
                .is_stdout()
        );
    }

    #[test]
    fn the_lock_is_exclusive_and_outlives_renames() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lib.json");
        let out = OutputFile::check(&path, &[]).unwrap();
        let held = out.lock().unwrap();
        out.write(b"one").unwrap();
        let lock_file = dir.path().join(".lib.json.lock");
        let other = File::open(&lock_file).unwrap();
        assert!(
            fs4::FileExt::try_lock(&other).is_err(),
            "a second lock got in"
        );
        drop(held);
        // Released, and the lock file is gone with it.
        assert!(fs4::FileExt::try_lock(&other).is_ok());
        assert!(!lock_file.exists());
        drop(other);
        // Many holders in turn, some waiting on a file the one before removed.
        let count = std::sync::atomic::AtomicUsize::new(0);
        let inside = std::sync::atomic::AtomicUsize::new(0);
        std::thread::scope(|s| {
            for _ in 0..8 {
                s.spawn(|| {
                    for _ in 0..20 {
                        let _held = out.lock().unwrap();
                        assert_eq!(inside.fetch_add(1, Ordering::SeqCst), 0, "two holders");
                        count.fetch_add(1, Ordering::SeqCst);
                        inside.fetch_sub(1, Ordering::SeqCst);
                    }
                });
            }
        });
        assert_eq!(count.load(Ordering::SeqCst), 160);
        assert!(!lock_file.exists());
    }
}
