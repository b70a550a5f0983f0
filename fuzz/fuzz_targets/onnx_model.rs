//! cargo-fuzz target `onnx_model`: see `tensorholo_fuzz::onnx_model` and docs/FUZZING.md.
//!
//! tract panics on some malformed graphs; the loader catches those panics (`catch_unwind`) and refuses the file
//! (`HoloError::ModelLoad`), which is the behaviour under test. libfuzzer-sys's panic hook aborts on every
//! panic, caught or not, so this target replaces it with a silent one: a panic that escapes the loader still
//! reaches libfuzzer-sys's own `catch_unwind` and aborts, and is reported.
#![no_main]

libfuzzer_sys::fuzz_target!(
    init: {
        std::panic::set_hook(Box::new(|_| {}));
    },
    |data: &[u8]| tensorholo_fuzz::onnx_model(data)
);
