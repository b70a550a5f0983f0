//! cargo-fuzz target `manifest`: see `tensorholo_fuzz::manifest` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::manifest(data));
