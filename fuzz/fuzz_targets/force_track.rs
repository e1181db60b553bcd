//! `underfoot::fuzzing`'s `force_track` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target = underfoot::fuzzing::target("force_track").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
