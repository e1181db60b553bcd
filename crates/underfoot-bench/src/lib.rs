//! The benchmarks of [`underfoot`], in `benches/`: `cargo bench -p underfoot-bench`.
//!
//! They are a crate of their own because criterion and its dependencies take about a
//! minute and a half of CPU to build; as dev-dependencies of the library they were built
//! for every `cargo test`. This library holds only what several benches share.

use std::path::PathBuf;

use underfoot::recording::{Recording, read};

/// The shared recordings of `material` (`../shared/data/footsteps/MATERIAL/*.ogg`, in
/// name order), or `None` when they are absent or one does not read: the benches that
/// need them then say so and time nothing.
#[must_use]
pub fn shared_recordings(material: &str) -> Option<Vec<Recording>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/footsteps")
        .join(material);
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "ogg"))
        .collect();
    files.sort();
    files.iter().map(|p| read(p, None).ok()).collect()
}
