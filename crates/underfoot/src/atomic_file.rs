//! Files are replaced, never overwritten in place: a save that fails half-way (a full
//! disk, a killed process, a power cut) must leave the previous file as it was, because
//! that file may be the only calibration of a user's prosthesis or a library that took
//! an afternoon of recordings.
//!
//! [`write_atomic`] writes a temporary file in the target's directory, flushes it to
//! disk and renames it over the target. Every stage that saves a file uses it and wraps
//! its [`AtomicWriteError`] into its own error enum, so the message still names the file
//! and the step that failed.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// A file could not be written; the file that was there (if any) is untouched.
#[derive(Debug, thiserror::Error)]
#[error("{action} {}: {source}", path.display())]
pub struct AtomicWriteError {
    /// The file (or the temporary file next to it).
    pub path: PathBuf,
    /// The step that failed, e.g. `renaming the temporary file over it`.
    pub action: &'static str,
    /// The underlying error.
    #[source]
    pub source: std::io::Error,
}

/// Writes `contents` to `path` atomically: a temporary file in the same directory,
/// flushed to disk, renamed over `path`.
///
/// If `path` already exists its permissions are kept. On error the temporary file is
/// removed and `path` is untouched.
///
/// # Errors
/// [`AtomicWriteError`] naming the file and the step that failed.
pub fn write_atomic(path: &Path, contents: &[u8]) -> Result<(), AtomicWriteError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let io = |p: &Path, action: &'static str| {
        let p = p.to_path_buf();
        move |source| AtomicWriteError {
            path: p,
            action,
            source,
        }
    };
    let file_name = path.file_name().ok_or_else(|| {
        io(path, "choosing a temporary file")(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path does not name a file",
        ))
    })?;
    // Same directory as the target, so that the rename stays on one file system and is
    // atomic; pid and counter keep concurrent writers out of each other's way.
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let tmp_name = format!(
        ".{}.tmp-{}-{}",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    );
    let tmp = dir.join(tmp_name);

    let result = (|| {
        let mut f = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(io(&tmp, "creating a temporary file"))?;
        f.write_all(contents)
            .map_err(io(&tmp, "writing the temporary file"))?;
        if let Ok(meta) = fs::metadata(path) {
            f.set_permissions(meta.permissions())
                .map_err(io(&tmp, "copying permissions to the temporary file"))?;
        }
        f.sync_all()
            .map_err(io(&tmp, "flushing the temporary file to disk"))?;
        drop(f);
        fs::rename(&tmp, path).map_err(io(path, "renaming the temporary file over it"))
    })();
    if result.is_err() {
        // Best effort: the error that matters is the one being returned.
        let _ = fs::remove_file(&tmp);
        return result;
    }
    // Make the rename itself durable. Not every platform can open a directory; the data
    // is already safe in the file, so a failure here is not worth failing the save.
    if let Ok(d) = fs::File::open(&dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn a_failed_write_keeps_the_old_file_and_names_the_step() {
        let dir = tempfile::tempdir().unwrap();
        // The target is a non-empty directory: the rename over it must fail.
        let path = dir.path().join("target");
        fs::create_dir(&path).unwrap();
        fs::write(path.join("keep"), b"kept").unwrap();
        let e = write_atomic(&path, b"new").expect_err("renaming over a directory");
        assert_eq!(e.action, "renaming the temporary file over it");
        assert!(e.to_string().contains("target"), "{e}");
        assert_eq!(fs::read(path.join("keep")).unwrap(), b"kept");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
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
        assert_eq!(e.action, "choosing a temporary file");
    }
}
