//! The output policy's registry of reads (`underfoot::atomic_file`, *Inputs*): once a
//! program turns it on, no output replaces a file the process has read, whether or not
//! the command listed it as an input, and whichever came first, the check or the read.
//! A test binary of its own: turning it on is for the whole process.

use std::fs;

use underfoot::atomic_file::{OutputFile, REFUSED, refuse_outputs_over_reads, write_atomic};
use underfoot::limits::read_capped;
use underfoot::material::Library;

fn on() {
    refuse_outputs_over_reads();
}

#[test]
fn a_file_read_is_never_replaced_even_unlisted_or_through_a_link() {
    on();
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("device.json");
    fs::write(&input, b"the measurement").unwrap();
    read_capped(&input, 1 << 20).unwrap();
    for target in [input.clone(), {
        let link = dir.path().join("link.json");
        std::os::unix::fs::symlink(&input, &link).unwrap();
        link
    }] {
        let e = OutputFile::check(&target, &[])
            .and_then(|out| out.write(b"the equalizer"))
            .unwrap_err();
        assert_eq!(e.action, REFUSED, "{e:?}");
        let why = std::error::Error::source(&e).map(ToString::to_string);
        assert!(why.as_deref().unwrap_or("").contains("has read"), "{why:?}");
    }
    assert_eq!(fs::read(&input).unwrap(), b"the measurement");
    // Another file is written.
    write_atomic(&dir.path().join("eq.json"), b"the equalizer").unwrap();
}

#[test]
fn a_file_read_after_the_check_is_refused_at_the_rename_and_kept() {
    on();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("x.json");
    fs::write(&path, b"the measurement").unwrap();
    // Checked while it was not yet read (a command that checks its outputs first)...
    let out = OutputFile::check(&path, &[]).unwrap();
    // ... then read as an input the command did not list.
    read_capped(&path, 1 << 20).unwrap();
    let e = out.write(b"the equalizer").unwrap_err();
    assert_eq!(e.action, REFUSED, "{e:?}");
    assert_eq!(fs::read(&path).unwrap(), b"the measurement");
    let left: Vec<_> = fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(left.len(), 1, "no temporary file left: {left:?}");
    // write_atomic, the one-call form, goes through the same check.
    assert!(write_atomic(&path, b"x").is_err());
}

#[test]
fn an_edit_under_its_lock_reads_and_replaces_its_file() {
    on();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lab.json");
    underfoot::material::builtin::builtin().save(&path).unwrap();
    // Read before the edit, as a panel reads its library at a session's start.
    let n = Library::load(&path).unwrap().materials.len();
    let out = OutputFile::check(&path, &[]).unwrap();
    // Replaced outside an edit: refused.
    assert!(out.write(b"{}").is_err());
    // The edit: under the lock, the read-modify-write is the library's own business.
    let left = Library::edit(&out, false, |lib| {
        let name = lib.materials[0].name.clone();
        lib.remove(&name)?;
        Ok(lib.materials.len())
    })
    .unwrap();
    assert_eq!(left, n - 1);
    assert_eq!(Library::load(&path).unwrap().materials.len(), n - 1);
    // The new file is one the process read again just now: a second edit works too.
    Library::edit(&out, false, |lib| Ok(lib.materials.len())).unwrap();
}
