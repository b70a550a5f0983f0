//! cargo-fuzz target `camera_frame`: see `tensorholo_fuzz::camera_frame` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::camera_frame(data));
