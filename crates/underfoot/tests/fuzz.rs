//! The fuzz targets of `underfoot::fuzzing`, on stable: property tests over arbitrary
//! bytes and over structure-aware mutations of each target's seeds, plus a replay of every
//! crasher kept in `tests/fuzz-regressions/<target>/`.
//!
//! Each input must come back without a panic, within [`TIME_LIMIT`], and with at most
//! [`PEAK_LIMIT`] bytes live at once on the thread that parses it (a counting global
//! allocator measures it; a single request beyond [`HARD_CAP`] is refused, which aborts
//! the run with the target named, rather than letting one input take the machine). An
//! input that runs for [`HANG_LIMIT`] stops the whole run from a watchdog thread. A
//! failing input is written to `target/fuzz-findings/<target>/` to become a regression
//! file.
//!
//! `UNDERFOOT_FUZZ_CASES` sets the cases per strategy and target (default 96: the short
//! pass of `cargo test`); `scripts/fuzz` runs the long pass with it. Each test prints its
//! inputs, inputs per second and findings (`--nocapture` to see them).
//!
//! A new target in `underfoot::fuzzing::TARGETS` needs one line in the list at the bottom
//! (a test checks that none is missing).

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use proptest::prelude::*;
use proptest::test_runner::{Config, TestCaseError, TestRunner};
use underfoot::fuzzing::{TARGETS, Target};

/// The longest one input may take.
const TIME_LIMIT: Duration = Duration::from_secs(1);
/// The longest one input may take before the watchdog ends the run (a hang).
const HANG_LIMIT: Duration = Duration::from_secs(20);
/// The most bytes one input may hold live at once.
const PEAK_LIMIT: usize = 256 << 20;
/// A single allocation request larger than this is refused (the run aborts).
const HARD_CAP: usize = 1 << 30;

// ---- the counting allocator ----

struct Counting;

thread_local! {
    // Const-initialised, without destructors: usable from inside the allocator.
    static WATCHING: Cell<Option<&'static str>> = const { Cell::new(None) };
    static LIVE: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
}

fn grow(by: usize) -> bool {
    WATCHING.with(|w| {
        let Some(name) = w.get() else { return true };
        if by > HARD_CAP {
            w.set(None);
            eprintln!("fuzz {name}: one allocation of {by} bytes asked for; refused");
            return false;
        }
        let live = LIVE.get().saturating_add(by);
        LIVE.set(live);
        PEAK.set(PEAK.get().max(live));
        true
    })
}

fn shrink(by: usize) {
    if WATCHING.with(Cell::get).is_some() {
        LIVE.set(LIVE.get().saturating_sub(by));
    }
}

// SAFETY: every call is passed on to the system allocator unchanged; the counters are
// thread-local cells that never allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !grow(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !grow(layout.size()) {
            return std::ptr::null_mut();
        }
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        shrink(layout.size());
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > layout.size() {
            if !grow(new_size - layout.size()) {
                return std::ptr::null_mut();
            }
        } else {
            shrink(layout.size() - new_size);
        }
        // SAFETY: the caller's contract, passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

// ---- one input ----

thread_local! {
    /// The first panic on this thread since the last input began, caught or not: the
    /// library turns a panic inside a decoder it uses into an error, and the harness must
    /// still see it (libFuzzer's hook aborts on any panic, so cargo-fuzz does too).
    static PANIC: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

fn install_panic_hook() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            PANIC.with_borrow_mut(|p| {
                p.get_or_insert_with(|| info.to_string());
            });
            previous(info);
        }));
    });
}

/// What went wrong with one input.
fn check(target: &Target, data: &[u8]) -> Result<(), String> {
    install_panic_hook();
    PANIC.set(None);
    LIVE.set(0);
    PEAK.set(0);
    WATCHING.set(Some(target.name));
    let start = Instant::now();
    let outcome = catch_unwind(AssertUnwindSafe(|| (target.run)(data)));
    let elapsed = start.elapsed();
    WATCHING.set(None);
    let peak = PEAK.get();
    if let Err(panic) = outcome {
        let message = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("(no message)");
        return Err(format!("panic: {message}"));
    }
    if let Some(caught) = PANIC.take() {
        return Err(format!("a panic, caught inside the library: {caught}"));
    }
    let mut faults = Vec::new();
    if elapsed > TIME_LIMIT {
        faults.push(format!("took {elapsed:?} (limit {TIME_LIMIT:?})"));
    }
    if peak > PEAK_LIMIT {
        faults.push(format!("held {peak} bytes at once (limit {PEAK_LIMIT})"));
    }
    if faults.is_empty() {
        Ok(())
    } else {
        Err(faults.join("; "))
    }
}

fn findings_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../target/fuzz-findings")
        .join(target)
}

/// Keeps a failing input where a person can turn it into a regression file.
fn save_finding(target: &str, data: &[u8]) -> PathBuf {
    use std::hash::{DefaultHasher, Hash, Hasher};
    let mut h = DefaultHasher::new();
    data.hash(&mut h);
    let dir = findings_dir(target);
    let path = dir.join(format!("{:016x}", h.finish()));
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(&path, data);
    path
}

/// Ends the process when one input runs past [`HANG_LIMIT`]: a hang must fail the run,
/// not stall it.
/// The input running, and since when.
type Running = Arc<Mutex<Option<(Instant, Vec<u8>)>>>;

struct Watchdog {
    current: Running,
    done: Arc<AtomicBool>,
}

impl Watchdog {
    fn start(target: &'static str) -> Self {
        let current: Running = Arc::default();
        let done = Arc::new(AtomicBool::new(false));
        let (c, d) = (Arc::clone(&current), Arc::clone(&done));
        std::thread::spawn(move || {
            while !d.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(200));
                let guard = c.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
                if let Some((since, data)) = guard.as_ref()
                    && since.elapsed() > HANG_LIMIT
                {
                    let path = save_finding(target, data);
                    eprintln!(
                        "fuzz {target}: an input has run for {HANG_LIMIT:?} (a hang); \
                             saved as {}",
                        path.display()
                    );
                    std::process::exit(101);
                }
            }
        });
        Self { current, done }
    }

    fn run(&self, target: &Target, data: &[u8]) -> Result<(), String> {
        *self.current.lock().expect("watchdog") = Some((Instant::now(), data.to_vec()));
        let result = check(target, data);
        *self.current.lock().expect("watchdog") = None;
        result
    }
}

impl Drop for Watchdog {
    fn drop(&mut self) {
        self.done.store(true, Ordering::Relaxed);
    }
}

// ---- the strategies ----

fn cases() -> u32 {
    std::env::var("UNDERFOOT_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(96)
}

/// Tokens that parsers of these formats treat specially, and numbers at their edges.
const TOKENS: &[&[u8]] = &[
    b"0",
    b"-1",
    b"1e308",
    b"-1e308",
    b"1e-320",
    b"NaN",
    b"nan",
    b"inf",
    b"-inf",
    b"1e999",
    b"18446744073709551616",
    b"4294967295",
    b"65535",
    b"1700000000",
    b"0.0",
    b"-0",
    b"\xEF\xBB\xBF",
    b"\"",
    b",",
    b"\n",
    b"\r\n",
    b"#",
    b"=",
    b"[",
    b"]",
    b"{",
    b"}",
    b":",
    b"\"\"",
    b"[[",
    b"\\u0000",
    b"\x00",
    b"\xFF\xFF\xFF\xFF",
    b"\x00\x00\x00\x80",
    b"\xFF\xFF\xFF\x7F",
    b"null",
    b"true",
    b"[]",
    b"{}",
];

#[derive(Debug, Clone)]
enum Mutation {
    /// Sets the byte at a position.
    Set(usize, u8),
    /// Inserts bytes at a position.
    Insert(usize, Vec<u8>),
    /// Removes up to `n` bytes at a position.
    Remove(usize, usize),
    /// Copies a run of the input to another place (repeats a row, a key, a chunk).
    Duplicate(usize, usize, usize),
    /// Replaces up to `n` bytes at a position with a token.
    Token(usize, usize, usize),
    /// Replaces the number starting at or after a position with a token.
    Number(usize, usize),
    /// Cuts the input at a position.
    Truncate(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        3 => (any::<usize>(), any::<u8>()).prop_map(|(p, b)| Mutation::Set(p, b)),
        2 => (any::<usize>(), prop::collection::vec(any::<u8>(), 1..8))
            .prop_map(|(p, b)| Mutation::Insert(p, b)),
        2 => (any::<usize>(), 1usize..64).prop_map(|(p, n)| Mutation::Remove(p, n)),
        1 => (any::<usize>(), 1usize..256, any::<usize>())
            .prop_map(|(p, n, at)| Mutation::Duplicate(p, n, at)),
        3 => (any::<usize>(), 0usize..4, 0..TOKENS.len())
            .prop_map(|(p, n, t)| Mutation::Token(p, n, t)),
        4 => (any::<usize>(), 0..TOKENS.len()).prop_map(|(p, t)| Mutation::Number(p, t)),
        1 => any::<usize>().prop_map(Mutation::Truncate),
    ]
}

fn apply(data: &mut Vec<u8>, m: &Mutation) {
    let at = |p: usize, len: usize| if len == 0 { 0 } else { p % (len + 1) };
    match *m {
        Mutation::Set(p, b) => {
            if !data.is_empty() {
                let i = p % data.len();
                data[i] = b;
            }
        }
        Mutation::Insert(p, ref bytes) => {
            let i = at(p, data.len());
            data.splice(i..i, bytes.iter().copied());
        }
        Mutation::Remove(p, n) => {
            let i = at(p, data.len());
            let end = (i + n).min(data.len());
            data.drain(i..end);
        }
        Mutation::Duplicate(p, n, to) => {
            let i = at(p, data.len());
            let end = (i + n).min(data.len());
            let run = data[i..end].to_vec();
            let j = at(to, data.len());
            data.splice(j..j, run);
        }
        Mutation::Token(p, n, t) => {
            let i = at(p, data.len());
            let end = (i + n).min(data.len());
            data.splice(i..end, TOKENS[t].iter().copied());
        }
        Mutation::Number(p, t) => {
            let i = at(p, data.len());
            let numeric = |b: &u8| b.is_ascii_digit() || b".-+eE".contains(b);
            if let Some(start) = data[i..].iter().position(u8::is_ascii_digit) {
                let start = i + start;
                let len = data[start..].iter().take_while(|b| numeric(b)).count();
                data.splice(start..start + len, TOKENS[t].iter().copied());
            }
        }
        Mutation::Truncate(p) => {
            let i = at(p, data.len());
            data.truncate(i);
        }
    }
}

/// Seeds from outside the repository: the real recordings, when present, for the audio
/// decoder (read in place, never copied into the repository).
fn extra_seeds(target: &str) -> Vec<Vec<u8>> {
    if target != "audio" {
        return Vec::new();
    }
    let Some(dir) = common::footsteps_dir() else {
        return Vec::new();
    };
    common::footsteps_by_material(&dir)
        .into_iter()
        .filter_map(|(_, files)| files.into_iter().next())
        .take(2)
        .filter_map(|f| std::fs::read(f).ok())
        // The head of a recording: its headers and first packets, and quick to decode.
        .map(|mut bytes| {
            bytes.truncate(48 << 10);
            bytes
        })
        .collect()
}

fn seeds_of(target: &Target) -> Vec<Vec<u8>> {
    let mut seeds = (target.seeds)();
    seeds.extend(extra_seeds(target.name));
    seeds
}

fn regression_files(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz-regressions")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|entries| entries.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.retain(|f| f.is_file());
    files.sort();
    files
}

/// The whole run of one target: its regression files, its seeds, arbitrary bytes and
/// mutated seeds.
fn fuzz(name: &'static str) {
    let target = underfoot::fuzzing::target(name).expect("a target of underfoot::fuzzing");
    let watchdog = Watchdog::start(name);
    let mut failures = Vec::new();
    let saved = |data: &[u8], why: String| {
        let path = save_finding(name, data);
        format!("{why} (input saved as {})", path.display())
    };

    let start = Instant::now();
    let mut inputs = 0u64;
    let regressions = regression_files(name);
    for file in &regressions {
        let data = std::fs::read(file).expect("a regression file is readable");
        inputs += 1;
        if let Err(why) = watchdog.run(target, &data) {
            failures.push(format!("{}: {why}", file.display()));
        }
    }
    let seeds = seeds_of(target);
    assert!(!seeds.is_empty(), "{name} has no seeds");
    for seed in &seeds {
        inputs += 1;
        if let Err(why) = watchdog.run(target, seed) {
            failures.push(saved(seed, format!("a seed: {why}")));
        }
    }

    let config = Config {
        cases: cases(),
        failure_persistence: None,
        // Shrinking replays the input many times; a few hundred steps find a small one.
        max_shrink_iters: 512,
        ..Config::default()
    };
    let counted = Cell::new(0u64);
    let mut runner = TestRunner::new(config.clone());
    let bytes = prop::collection::vec(any::<u8>(), 0..512);
    let outcome = runner.run(&bytes, |data| {
        counted.set(counted.get() + 1);
        watchdog.run(target, &data).map_err(TestCaseError::fail)
    });
    if let Err(e) = outcome {
        let data = match &e {
            proptest::test_runner::TestError::Fail(_, data) => data.clone(),
            proptest::test_runner::TestError::Abort(_) => Vec::new(),
        };
        failures.push(saved(&data, format!("arbitrary bytes: {e}")));
    }

    let mut runner = TestRunner::new(config);
    let mutated = (0..seeds.len(), prop::collection::vec(mutation(), 1..8)).prop_map(|(i, ms)| {
        let mut data = seeds[i].clone();
        for m in &ms {
            apply(&mut data, m);
        }
        data
    });
    let outcome = runner.run(&mutated, |data| {
        counted.set(counted.get() + 1);
        watchdog.run(target, &data).map_err(TestCaseError::fail)
    });
    if let Err(e) = outcome {
        let data = match &e {
            proptest::test_runner::TestError::Fail(_, data) => data.clone(),
            proptest::test_runner::TestError::Abort(_) => Vec::new(),
        };
        failures.push(saved(&data, format!("mutated seeds: {e}")));
    }
    inputs += counted.get();

    let seconds = start.elapsed().as_secs_f64();
    println!(
        "fuzz {name}: {inputs} inputs ({} regression files, {} seeds) in {seconds:.1} s, \
         {:.0} inputs/s, {} findings",
        regressions.len(),
        seeds.len(),
        inputs as f64 / seconds,
        failures.len()
    );
    assert!(failures.is_empty(), "fuzz {name}:\n{}", failures.join("\n"));
}

/// Writes every target's seeds to `UNDERFOOT_FUZZ_WRITE_SEEDS/<target>/`, as the corpus
/// of the cargo-fuzz run in `scripts/fuzz`; does nothing without it.
#[test]
fn write_seeds_when_asked() {
    let Some(out) = std::env::var_os("UNDERFOOT_FUZZ_WRITE_SEEDS") else {
        return;
    };
    for target in TARGETS {
        let dir = Path::new(&out).join(target.name);
        std::fs::create_dir_all(&dir).expect("a corpus folder");
        let seeds = seeds_of(target).into_iter().chain(
            regression_files(target.name)
                .into_iter()
                .map(|f| std::fs::read(f).expect("a regression file is readable")),
        );
        for (i, seed) in seeds.enumerate() {
            std::fs::write(dir.join(format!("seed-{i}")), seed).expect("a seed is written");
        }
    }
}

macro_rules! targets {
    ($($name:ident),* $(,)?) => {
        const TESTED: &[&str] = &[$(stringify!($name)),*];
        $(
            #[test]
            fn $name() {
                fuzz(stringify!($name));
            }
        )*
    };
}

// One line per target of `underfoot::fuzzing::TARGETS`.
targets! {
    library_json,
    audio,
    recording_csv,
    force_track,
    gait_spec,
    interface_toml,
    sensor_csv,
    calibration_json,
    compensation_json,
    osc,
    cli_specs,
    serial,
}

#[test]
fn every_target_has_a_test() {
    for target in TARGETS {
        assert!(
            TESTED.contains(&target.name),
            "{} has no line in the targets! list of tests/fuzz.rs",
            target.name
        );
    }
}

/// The harness can fail: a panic, an input too slow, and one holding too much are each
/// caught (run directly, not through a target of the library).
#[test]
fn the_harness_catches_panics_slow_inputs_and_large_allocations() {
    let panics = Target {
        name: "panics",
        run: |d| assert!(d.is_empty(), "boom"),
        seeds: Vec::new,
    };
    let slow = Target {
        name: "slow",
        run: |_| std::thread::sleep(TIME_LIMIT + Duration::from_millis(50)),
        seeds: Vec::new,
    };
    let greedy = Target {
        name: "greedy",
        run: |_| {
            let v = vec![1u8; PEAK_LIMIT + 1];
            std::hint::black_box(&v);
        },
        seeds: Vec::new,
    };
    let caught = Target {
        name: "caught",
        run: |_| {
            let _ = std::panic::catch_unwind(|| panic!("inside"));
        },
        seeds: Vec::new,
    };
    assert!(check(&caught, b"").unwrap_err().contains("inside"));
    assert!(check(&panics, b"").is_ok());
    assert!(check(&panics, b"x").unwrap_err().contains("boom"));
    assert!(check(&slow, b"").unwrap_err().contains("took"));
    assert!(check(&greedy, b"").unwrap_err().contains("held"));
}

/// The seeds are valid inputs of their formats, so that mutations start from something
/// the parser accepts and reach past its first check.
#[test]
fn the_seeds_parse() {
    use underfoot::compensation::files::{EqualizerFile, LimbFile, ResponseFile};
    use underfoot::compensation::table::UserTable;
    use underfoot::document::from_json;
    use underfoot::force::calibration::{SensorCalibration, session_from_csv_str};
    use underfoot::force::gait::GaitConfig;
    use underfoot::force::track::ForceTrack;
    use underfoot::material::Library;
    use underfoot::recording::{CsvSpec, read_bytes};
    use underfoot::units::SampleRate;

    let seeds = |name| (underfoot::fuzzing::target(name).expect("a target").seeds)();
    let text = |b: &Vec<u8>| String::from_utf8(b.clone()).expect("a text seed is UTF-8");
    for (i, seed) in seeds("audio").iter().enumerate() {
        let rec = read_bytes("seed", seed, None);
        assert!(rec.is_ok(), "audio seed {i}: {rec:?}");
        assert_eq!(rec.unwrap().rate, SampleRate(2000), "audio seed {i}");
    }
    let spec = CsvSpec {
        column: "1".into(),
        rate: SampleRate(1000),
    };
    for seed in seeds("recording_csv") {
        read_bytes("seed.csv", &seed, Some(&spec)).expect("a recording CSV seed");
    }
    for seed in seeds("library_json") {
        Library::from_json(&text(&seed), "seed").expect("a library seed");
    }
    for seed in seeds("force_track") {
        ForceTrack::from_csv_str(&text(&seed), "seed").expect("a track seed");
    }
    for seed in seeds("gait_spec") {
        GaitConfig::from_spec(&text(&seed)).expect("a gait seed");
    }
    for seed in seeds("sensor_csv") {
        let sensors = session_from_csv_str(&text(&seed), "seed").expect("a session seed");
        assert_eq!(sensors.len(), 2);
    }
    let calibration = seeds("calibration_json").remove(0);
    SensorCalibration::from_json_str(&text(&calibration), "seed").expect("a calibration seed");
    for seed in seeds("interface_toml") {
        underfoot::interface::config::InterfaceConfig::parse(
            &text(&seed),
            Path::new("seed.toml"),
            |name| SensorCalibration::from_json_str(&text(&calibration), name),
        )
        .expect("an interface seed");
    }
    let compensation = seeds("compensation_json");
    let origin = "seed.json";
    from_json::<ResponseFile>(&text(&compensation[0]), origin).expect("a response seed");
    from_json::<EqualizerFile>(&text(&compensation[1]), origin).expect("an equalizer seed");
    from_json::<LimbFile>(&text(&compensation[2]), origin).expect("a limb seed");
    from_json::<UserTable>(&text(&compensation[3]), origin).expect("a table seed");
    from_json::<ResponseFile>(&text(&compensation[4]), origin).expect("a legacy response seed");
}

/// The audio crashers are overflows inside the decoder library, which this test build
/// compiles without overflow checks (the dependencies' test profile), so replaying them
/// above cannot fail. What must hold instead: each is refused by the header check before
/// the decoder sees it.
#[test]
fn audio_crashers_are_refused_before_the_decoder() {
    let files = regression_files("audio");
    assert!(!files.is_empty());
    for file in files {
        let bytes = std::fs::read(&file).expect("a regression file is readable");
        let e = underfoot::recording::read_bytes("fuzz", &bytes, None)
            .expect_err("a crasher is refused");
        assert!(
            e.to_string().contains("channels"),
            "{}: refused, but not by the header check: {e}",
            file.display()
        );
    }
}
