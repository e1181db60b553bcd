//! `underfoot::fuzzing`'s `serial` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target = underfoot::fuzzing::target("serial").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
