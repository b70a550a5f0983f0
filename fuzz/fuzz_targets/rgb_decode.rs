//! cargo-fuzz target `rgb_decode`: see `tensorholo_fuzz::rgb_decode` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::rgb_decode(data));
