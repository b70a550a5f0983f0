//! cargo-fuzz target `stray_camera_matrix`: see `tensorholo_fuzz::stray_camera_matrix` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::stray_camera_matrix(data));
