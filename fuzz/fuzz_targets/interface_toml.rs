//! `underfoot::fuzzing`'s `interface_toml` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target =
        underfoot::fuzzing::target("interface_toml").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
