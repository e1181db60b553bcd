//! `underfoot::fuzzing`'s `cli_specs` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target = underfoot::fuzzing::target("cli_specs").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
