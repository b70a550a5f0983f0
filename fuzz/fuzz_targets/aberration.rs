//! cargo-fuzz target `aberration`: see `tensorholo_fuzz::aberration` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::aberration(data));
