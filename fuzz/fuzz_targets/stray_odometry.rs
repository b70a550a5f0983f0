//! cargo-fuzz target `stray_odometry`: see `tensorholo_fuzz::stray_odometry` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::stray_odometry(data));
