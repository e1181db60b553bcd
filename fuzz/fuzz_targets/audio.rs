//! `underfoot::fuzzing`'s `audio` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target = underfoot::fuzzing::target("audio").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
