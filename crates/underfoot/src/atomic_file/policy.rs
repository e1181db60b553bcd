//! The checks of the output policy: symlinks resolved, file kinds, inputs.

use super::*;

pub(super) fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Follows symlinks from `path` to the name that will be replaced (which may not exist).
pub(super) fn resolve(path: &Path) -> Result<PathBuf, AtomicWriteError> {
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
pub(super) fn check_kind(given: &Path, target: &Path) -> Result<(), AtomicWriteError> {
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
                 where the option accepts it: export --out, compare --json-out)"
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
pub(super) fn special_kind(ft: &fs::FileType) -> &'static str {
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
pub(super) fn special_kind(_: &fs::FileType) -> &'static str {
    "not a regular file"
}

/// The canonical form of a path that may not exist yet: its folder canonicalised, its
/// name appended.
pub(super) fn canonical(path: &Path) -> PathBuf {
    if let Ok(p) = fs::canonicalize(path) {
        return p;
    }
    match (fs::canonicalize(parent_dir(path)), path.file_name()) {
        (Ok(dir), Some(name)) => dir.join(name),
        _ => path.to_path_buf(),
    }
}

#[cfg(unix)]
pub(super) fn identity(meta: &fs::Metadata) -> (u64, u64) {
    use std::os::unix::fs::MetadataExt;
    (meta.dev(), meta.ino())
}

#[cfg(not(unix))]
pub(super) fn identity(_: &fs::Metadata) -> (u64, u64) {
    (0, 0)
}

pub(super) fn check_not_input(
    given: &Path,
    target: &Path,
    inputs: &[&Path],
) -> Result<(), AtomicWriteError> {
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
