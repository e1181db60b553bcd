//! Writing: a temporary file next to the target, flushed, renamed over it.

use super::*;

impl OutputFile {
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
        // pid and counter keep concurrent writers out of each other's way; the name ends
        // with the target's, so a writer that goes by the extension (plots) still can.
        self.create_beside("a temporary file", "creating a temporary file", |target| {
            let name = target.file_name().unwrap_or_default().to_string_lossy();
            super::stale::temporary_name(
                std::process::id(),
                COUNTER.fetch_add(1, Ordering::Relaxed),
                &name,
            )
        })
    }

    /// Creates a new, empty file beside the target that is worth keeping if the writer
    /// never finishes: `STEM.partial-PID.EXT` (`live.partial-4242.wav` for `live.wav`),
    /// visible rather than hidden, because after a crash it holds the user's data. The
    /// writer [`persist`](Self::persist)s it over the target when it is done; until then
    /// the target is as it was. The pid keeps two writers of one target apart.
    ///
    /// # Errors
    /// As [`create_temporary`](Self::create_temporary).
    pub fn create_partial(&self) -> Result<(PathBuf, File), AtomicWriteError> {
        self.create_beside("a partial file", "creating the partial file", |target| {
            let stem = target.file_stem().unwrap_or_default().to_string_lossy();
            let pid = std::process::id();
            match target.extension() {
                Some(ext) => format!("{stem}.partial-{pid}.{}", ext.to_string_lossy()),
                None => format!("{stem}.partial-{pid}"),
            }
        })
    }

    /// Creates the new file `name(target)` in the resolved target's folder (so that the
    /// rename over the target stays on one file system); `kind` names it in the refusal
    /// for standard output, `action` in an I/O error.
    fn create_beside(
        &self,
        kind: &str,
        action: &'static str,
        name: impl FnOnce(&Path) -> String,
    ) -> Result<(PathBuf, File), AtomicWriteError> {
        let Target::File(target) = &self.target else {
            return Err(refuse(
                &self.given,
                std::io::ErrorKind::InvalidInput,
                format!("standard output cannot be written through {kind}"),
            ));
        };
        let path = parent_dir(target).join(name(target));
        let f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(io(&path, action))?;
        Ok((path, f))
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
        let target = self.target();
        if let Ok(meta) = fs::metadata(target) {
            file.set_permissions(meta.permissions())
                .map_err(io(tmp, "copying permissions to the temporary file"))?;
        }
        file.sync_all()
            .map_err(io(tmp, "flushing the temporary file to disk"))?;
        // Once more just before the rename: the check may have been minutes ago (a fit).
        check_kind(&self.given, target)?;
        super::reads::check_not_read(&self.given, target)?;
        fs::rename(tmp, target).map_err(io(&self.given, "renaming the temporary file over it"))?;
        // Make the rename itself durable. Not every platform can open a directory; the
        // data is already safe in the file, so a failure here is not worth failing the save.
        if let Ok(d) = File::open(parent_dir(target)) {
            let _ = d.sync_all();
        }
        Ok(())
    }
}
