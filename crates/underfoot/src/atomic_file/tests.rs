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

/// What killed writers left beside a target goes at its next check: temporary files of
/// processes that are gone and a lock no one holds. A live process's temporary file, a
/// held lock, another target's leftovers and a partial recording stay.
#[cfg(target_os = "linux")]
#[test]
fn the_next_check_removes_what_killed_writers_left() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("lib.json");
    // A pid that was alive and is gone: a child that has been reaped.
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let dead = child.id();
    child.wait().unwrap();
    let own = std::process::id();
    let name = |s: String| dir.path().join(s);
    let stale = name(format!(".tmp-{dead}-3.lib.json"));
    let lock = name(".lib.json.lock".into());
    let kept = [
        name(format!(".tmp-{own}-0.lib.json")),
        name(format!(".tmp-{dead}-3.other.json")),
        name(format!("lib.partial-{dead}.json")),
        name(format!(".tmp-{dead}-x.lib.json")),
    ];
    for p in kept.iter().chain([&stale, &lock]) {
        fs::write(p, b"left").unwrap();
    }
    OutputFile::check(&target, &[]).unwrap();
    assert!(!stale.exists(), "a dead writer's temporary file stays");
    assert!(!lock.exists(), "an unheld lock stays");
    for p in &kept {
        assert!(p.exists(), "{} was removed", p.display());
    }

    // A held lock stays.
    let out = OutputFile::check(&target, &[]).unwrap();
    let held = out.lock().unwrap();
    OutputFile::check(&target, &[]).unwrap();
    assert!(lock.exists(), "a held lock was removed");
    drop(held);
}
