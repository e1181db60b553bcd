//! `underfoot::fuzzing`'s `sensor_csv` target.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let target = underfoot::fuzzing::target("sensor_csv").expect("a target of underfoot::fuzzing");
    (target.run)(data);
});
