//! `underfoot::fuzzing`'s `library_json` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target =
        underfoot::fuzzing::target("library_json").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
