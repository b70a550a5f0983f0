//! cargo-fuzz target `display_profile`: see `tensorholo_fuzz::display_profile` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::display_profile(data));
