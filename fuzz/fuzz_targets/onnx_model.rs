//! cargo-fuzz target `onnx_model`: see `tensorholo_fuzz::onnx_model` and docs/FUZZING.md.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| tensorholo_fuzz::onnx_model(data));
