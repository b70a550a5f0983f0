//! cargo-fuzz target `saved_plans`: see `tensorholo_fuzz::saved_plans` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::saved_plans(data));
