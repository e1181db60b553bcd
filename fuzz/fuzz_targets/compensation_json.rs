//! `underfoot::fuzzing`'s `compensation_json` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target =
        underfoot::fuzzing::target("compensation_json").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
