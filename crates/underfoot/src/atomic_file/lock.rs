//! The edit lock of a read-modify-write (see the module docs, *Editing a file in place*).

use super::*;

impl OutputFile {
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
                    let edited = crate::limits::reads::begin_edit(target);
                    return Ok(EditLock { file, path, edited });
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
    /// The file being edited, which its edit may read and replace.
    edited: Option<crate::limits::reads::FileId>,
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
        if let Some(id) = self.edited {
            crate::limits::reads::end_edit(id);
        }
    }
}
