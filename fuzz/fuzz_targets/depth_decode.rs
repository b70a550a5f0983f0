//! cargo-fuzz target `depth_decode`: see `tensorholo_fuzz::depth_decode` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::depth_decode(data));
