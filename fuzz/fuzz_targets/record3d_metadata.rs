//! cargo-fuzz target `record3d_metadata`: see `tensorholo_fuzz::record3d_metadata` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::record3d_metadata(data));
