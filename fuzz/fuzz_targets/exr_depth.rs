//! cargo-fuzz target `exr_depth`: see `tensorholo_fuzz::exr_depth` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::exr_depth(data));
