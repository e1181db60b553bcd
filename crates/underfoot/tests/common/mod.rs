//! Helpers shared by the integration tests.
#![allow(dead_code)]

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

/// Every `*.ogg` file one level down in `dir` (one folder per material), sorted.
pub fn footstep_files(dir: &std::path::Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for material in std::fs::read_dir(dir).expect("footsteps dir is readable") {
        let material = material.expect("dir entry").path();
        if !material.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&material).expect("material dir is readable") {
            let f = f.expect("dir entry").path();
            if f.extension().is_some_and(|e| e == "ogg") {
                files.push(f);
            }
        }
    }
    files.sort();
    files
}

/// A small seeded generator (SplitMix64), so tests need no RNG crate and are reproducible.
pub struct Rng(pub u64);

impl Rng {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}
