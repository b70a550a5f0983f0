//! cargo-fuzz target `npy`: see `tensorholo_fuzz::npy` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::npy(data));
