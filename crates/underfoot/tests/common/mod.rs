//! Helpers shared by the integration tests.

use std::path::PathBuf;

/// The folder of real footstep recordings (`../shared/data/footsteps` from the workspace
/// root), which lives outside the repository.
///
/// When it is absent, prints a note and returns `None` so that the caller can skip,
/// unless `UNDERFOOT_REQUIRE_DATA=1`, in which case it panics: CI sets that so that a
/// missing data folder cannot turn the real-data tests into silent passes.
pub fn footsteps_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/footsteps");
    if dir.is_dir() {
        return Some(dir);
    }
    let required = std::env::var("UNDERFOOT_REQUIRE_DATA").is_ok_and(|v| v == "1");
    assert!(
        !required,
        "UNDERFOOT_REQUIRE_DATA=1 but the footstep recordings are not at {}",
        dir.display()
    );
    eprintln!(
        "note: skipping: footstep recordings not found at {} (set UNDERFOOT_REQUIRE_DATA=1 to fail instead)",
        dir.display()
    );
    None
}

/// The `*.ogg` recordings of each material folder in `dir`, by material name, both sorted.
pub fn footsteps_by_material(dir: &std::path::Path) -> Vec<(String, Vec<PathBuf>)> {
    let mut materials = Vec::new();
    for material in std::fs::read_dir(dir).expect("footsteps dir is readable") {
        let material = material.expect("dir entry").path();
        if !material.is_dir() {
            continue;
        }
        let mut files: Vec<PathBuf> = std::fs::read_dir(&material)
            .expect("material dir is readable")
            .map(|f| f.expect("dir entry").path())
            .filter(|f| f.extension().is_some_and(|e| e == "ogg"))
            .collect();
        files.sort();
        let name = material
            .file_name()
            .expect("a folder has a name")
            .to_string_lossy()
            .into_owned();
        materials.push((name, files));
    }
    materials.sort();
    materials
}
