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
//!    ([`OutputFile::check_or_stdout`]: `export --out`, `compare --json-out`); binary WAV and
//!    plot outputs need a file;
//! 3. **refuses a read-only file** (no write permission bit, or the open for writing is
//!    denied): replacing it because its *folder* is writable would defeat the user's
//!    `chmod a-w`;
//! 4. **refuses any file the same command reads**: an input is the same file when it has
//!    the same device and inode (hard links, symlinks, `./a` and `a` all agree), or, when
//!    the output does not exist yet, the same canonical path;
//! 5. refuses two outputs of one command naming the same file ([`OutputFile::check_all`]).
//!
//! In a program that asks for it (the CLI does), the rename then refuses any file the
//! process has read (see *Inputs* below).
//!
//! Refusals are [`AtomicWriteError`]s with [`REFUSED`] as their action, naming the path
//! given and the reason.
//!
//! # Inputs
//!
//! A command names its inputs to [`OutputFile::check`] so that a clash is said before any
//! work; but a list per command is a list a new command or option can forget. So, once a
//! program calls [`refuse_outputs_over_reads`] (the CLI does first thing; a library
//! user's `load` then `save` of one file is theirs to decide), the policy also knows
//! every file the process has read: the crate reads files through one
//! function, [`crate::limits::read_capped`] (libraries, documents, tracks, recordings),
//! which notes each regular file's device, inode and change time ([`note_read`](crate::limits::reads::note_read); the
//! streaming readers call it too), and [`OutputFile::persist`], just before the rename
//! that would replace it, refuses a target so noted (the temporary file is removed, the
//! target kept). At the rename it holds whatever the order of reads and checks: an
//! output cannot replace a file the command read, whether or not the command listed it.
//! A read-modify-write is the one exception: the file an [`EditLock`] holds is read and
//! replaced by design (which is why the early [`OutputFile::check`] does not look at the
//! reads: a library read at a session's start may be edited by a fit later).
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
//!
//! # Leftovers
//!
//! A writer killed between creating its temporary file and renaming it (`SIGKILL`, a power
//! cut) leaves `.tmp-PID-N.NAME` beside the target, and a killed editor its `.NAME.lock`.
//! The names say whose they are, so the next [`OutputFile::check`] of the same target
//! removes them: a temporary file whose process is gone (looked up in `/proc`; where
//! there is none, nothing is removed), and a lock file it can lock at once (no one holds
//! it), removed under that lock as a holder removes it. A live recording's partial file
//! (`STEM.partial-PID.EXT`, [`OutputFile::create_partial`]) holds the user's data and is
//! never removed.

use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

mod lock;
mod policy;
mod reads;
pub use reads::refuse_outputs_over_reads;
mod stale;
pub use stale::process_is_gone;
mod write;

pub use lock::EditLock;
use policy::{canonical, check_kind, check_not_input, identity, parent_dir, resolve};

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
        stale::remove_stale(&target);
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
}

/// Writes `contents` to `path` under the output policy of a command that reads nothing:
/// [`OutputFile::check`], then [`OutputFile::write`].
///
/// # Errors
/// [`AtomicWriteError`]: a refusal or the step that failed.
pub fn write_atomic(path: &Path, contents: &[u8]) -> Result<(), AtomicWriteError> {
    OutputFile::check(path, &[])?.write(contents)
}

#[cfg(test)]
mod tests;
