//! Builds nothing. Cargo counts a package's `[build-dependencies]` only when it has a build
//! script, and the command's one (syn, with the features the Python package's proc-macros
//! ask for) is there so that `cargo run -p underfoot-cli` reuses the build of `cargo test
//! --workspace` (see Cargo.toml).

fn main() {
    // Nothing here depends on a file: never rerun.
    println!("cargo:rerun-if-changed=build.rs");
}
