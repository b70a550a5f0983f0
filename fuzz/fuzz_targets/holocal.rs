//! cargo-fuzz target `holocal`: see `tensorholo_fuzz::holocal` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::holocal(data));
