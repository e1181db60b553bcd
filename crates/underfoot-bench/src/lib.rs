//! The benchmarks of [`underfoot`], in `benches/`: `cargo bench -p underfoot-bench`.
//!
//! They are a crate of their own because criterion and its dependencies take about a
//! minute and a half of CPU to build; as dev-dependencies of the library they were built
//! for every `cargo test`. This library holds only what the benches share: the shared
//! recordings, and the timings a bench derives its printed figures from ([`Samples`]).

pub mod anchors;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use underfoot::engine::{Controller, Engine, Event, TimedEvent};
use underfoot::force::SensorReading;
use underfoot::physical::SurfaceMode;
use underfoot::recording::{Recording, read};
use underfoot::units::{Hz, Seconds};

/// The shared recordings of `material` (`../shared/data/footsteps/MATERIAL/*.ogg`, in
/// name order).
///
/// # Panics
/// When they are absent, or one does not read: a bench of real recordings that quietly
/// timed nothing (or something else) would print a figure the README might quote. The
/// message says where the recordings were looked for.
#[must_use]
pub fn shared_recordings(material: &str) -> Vec<Recording> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/footsteps")
        .join(material);
    let entries = std::fs::read_dir(&dir).unwrap_or_else(|e| {
        panic!(
            "this bench times the shared recordings of {material}, which are not at {} ({e}): \
             put the shared data beside the project (see its README)",
            dir.display()
        )
    });
    let mut files: Vec<_> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "ogg"))
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no .ogg recording in {}", dir.display());
    files
        .iter()
        .map(|p| read(p, None).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .collect()
}

/// What each sample of a bench took per unit of work (a sample of audio, a channel's
/// sample), kept so that a bench can print figures derived from criterion's own
/// measurements (channels per core, one bench over another): criterion keeps its
/// estimates to itself. Fed from `Bencher::iter_custom` through [`Samples::time`].
#[derive(Debug, Default, Clone)]
pub struct Samples {
    /// Seconds per unit, one entry per call, warm-up included.
    per_unit: Vec<f64>,
}

impl Samples {
    /// Runs `iterations` times `f`, which returns the units of work it did, and records
    /// the time per unit; returns the time taken, for `iter_custom`.
    pub fn time(&mut self, iterations: u64, mut f: impl FnMut() -> u64) -> Duration {
        let start = Instant::now();
        let mut units = 0u64;
        for _ in 0..iterations {
            units += f();
        }
        let elapsed = start.elapsed();
        if units > 0 {
            self.per_unit.push(elapsed.as_secs_f64() / units as f64);
        }
        elapsed
    }

    /// The median time per unit, in seconds, over the last `sample_size` calls (criterion
    /// calls the routine for its warm-up first, then once per sample), or over all of them
    /// when there were fewer (`--test` runs each bench once); `None` if the bench did not
    /// run (filtered out).
    #[must_use]
    pub fn median(&self, sample_size: usize) -> Option<f64> {
        let start = self.per_unit.len().saturating_sub(sample_size);
        let mut last = self.per_unit[start..].to_vec();
        if last.is_empty() {
            return None;
        }
        last.sort_by(f64::total_cmp);
        let n = last.len();
        Some(if n % 2 == 1 {
            last[n / 2]
        } else {
            0.5 * (last[n / 2 - 1] + last[n / 2])
        })
    }
}

impl Samples {
    /// The median, over the last `sample_size` calls of both, of this bench's time per
    /// unit over `ours`'s: the ratio of two benches timed in the same calls
    /// (interleaved), so that what disturbed one round disturbed both. `None` if either
    /// did not run.
    #[must_use]
    pub fn ratio_to(&self, ours: &Samples, sample_size: usize) -> Option<f64> {
        let n = self.per_unit.len().min(ours.per_unit.len());
        let start = n.saturating_sub(sample_size);
        let mut ratios: Vec<f64> = (start..n)
            .map(|i| self.per_unit[i] / ours.per_unit[i])
            .collect();
        if ratios.is_empty() {
            return None;
        }
        ratios.sort_by(f64::total_cmp);
        let m = ratios.len();
        Some(if m % 2 == 1 {
            ratios[m / 2]
        } else {
            0.5 * (ratios[m / 2 - 1] + ratios[m / 2])
        })
    }
}

/// Prints one figure in the line format `scripts/bench-table` collects:
/// `figure<TAB>group<TAB>what<TAB>value`, `value` already formatted with its unit. Every
/// figure the README's performance table shows is printed this way by a bench.
pub fn figure(group: &str, what: &str, value: &str) {
    println!("figure\t{group}\t{what}\t{value}");
}

/// How many channels one core renders in real time at `rate` Hz when one channel's sample
/// takes `seconds_per_sample`.
#[must_use]
pub fn channels_per_core(seconds_per_sample: f64, rate: f64) -> f64 {
    1.0 / (seconds_per_sample * rate)
}

/// The surface of the impact and aggregate benches, and of their C anchors: `n` modes
/// from 60 Hz up in steps of 1.37, each decaying in eight of its periods, with gains
/// falling as `1 / (1 + k)`. One definition, so that an anchor and the bench it is
/// compared with strike the same modes.
#[must_use]
pub fn surface_modes(n: usize) -> Vec<SurfaceMode> {
    (0..n)
        .map(|k| {
            let f = 60.0 * 1.37f64.powi(k as i32);
            SurfaceMode {
                frequency: Hz(f),
                decay: Seconds(8.0 / f),
                gain: 1e-3 / (1.0 + k as f64),
            }
        })
        .collect()
}

/// One 64-frame block of the engine benches' walk on every channel: a 500 Hz reading
/// every 96 frames (every third block), 700 N for 0.3 s of every 0.5 s, then none; then
/// the block. One definition, so that the engine bench and its C anchor time the same
/// work.
pub fn engine_walk_block(
    controller: &mut Controller,
    engine: &mut Engine,
    out: &mut [f32],
    channels: usize,
    block: u64,
) {
    if block.is_multiple_of(3) {
        let t = block as f32 * 64.0 / 48_000.0;
        let f = if t % 0.5 < 0.3 { 700.0 } else { 0.0 };
        for channel in 0..channels as u16 {
            let _ = controller.send(TimedEvent::now(Event::Force {
                channel,
                reading: SensorReading::single(f),
            }));
        }
    }
    engine.process(std::hint::black_box(out), channels);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[should_panic(
        expected = "this bench times the shared recordings of no-such-ground, which are not at"
    )]
    fn missing_recordings_fail_loudly() {
        let _ = shared_recordings("no-such-ground");
    }
}
