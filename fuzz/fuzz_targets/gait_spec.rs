//! `underfoot::fuzzing`'s `gait_spec` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target = underfoot::fuzzing::target("gait_spec").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
