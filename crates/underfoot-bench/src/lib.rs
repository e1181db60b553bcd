//! The benchmarks of [`underfoot`], in `benches/`: `cargo bench -p underfoot-bench`.
//!
//! They are a crate of their own because criterion and its dependencies take about a
//! minute and a half of CPU to build; as dev-dependencies of the library they were built
//! for every `cargo test`. This library is empty.
