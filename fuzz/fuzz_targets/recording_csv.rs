//! `underfoot::fuzzing`'s `recording_csv` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target =
        underfoot::fuzzing::target("recording_csv").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
